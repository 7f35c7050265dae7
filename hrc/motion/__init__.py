"""Motion acquisition (Strassmair & Taylor 2014, section V.A): travel paths, durations, interference."""

from hrc.motion.paths import Path, PathLibrary, plan_paths

__all__ = ["Path", "PathLibrary", "plan_paths"]
