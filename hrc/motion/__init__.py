"""Motion acquisition (Strassmair & Taylor 2014, section V.A): travel paths, durations, interference.

    World                  pymunk space + FCL objects of the map; clearance and swept-disc queries
    plan_paths(task)       -> PathLibrary: OMPL PRM* roadmap per clearance, shortened paths, durations
    plan_motions(task, plan, paths) -> (Motion, ...): per leg [free-space time, time with the
                           co-worker in the way] and the co-worker's motions that cause it

Modules: `world` (geometry), `planner` (OMPL), `paths` (library, durations), `interference` (the
co-worker model), `exact` (visibility-graph oracle for tests and the benchmark only).
"""

from hrc.motion.interference import Interference, Motion, plan_motions
from hrc.motion.paths import Path, PathLibrary, plan_paths
from hrc.motion.world import World

__all__ = ["Interference", "Motion", "Path", "PathLibrary", "World", "plan_motions", "plan_paths"]
