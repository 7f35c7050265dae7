"""Importing the compile's scipy modules without the notes scipy writes into its docstrings as it
imports them (issue 38: the cold workshop compile's start).

SciPy 1.17 decorates some hundreds of its functions (``scipy._lib._array_api.xp_capabilities``, the
batching and random-generator decorators of ``scipy._lib._util``) with code that parses each function's
numpydoc docstring (``scipy._lib._docscrape.FunctionDoc``), appends a note (which array backends it
supports, how it batches) and writes the docstring back: about 0.3 s of the 0.6 s of CPU that importing
``scipy.sparse.csgraph``, ``scipy.ndimage`` and ``scipy.spatial`` takes, in the compile's process, before
its paths are planned, for text only ``help()`` reads. `import_lean` imports modules with those two
decorators' ``FunctionDoc`` replaced by `_UnparsedDoc`, which leaves each docstring as it is (without the
note), and puts scipy's back afterwards (a later import parses as ever). Nothing else changes: the
functions, their signatures and what they compute are scipy's (the compile's outputs are byte for byte
those of a plain import: tests/test_lean_import.py).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from typing import Any

__all__ = ["import_lean"]

_DECORATING = ("scipy._lib._array_api", "scipy._lib._util")
"""The scipy modules whose decorators parse docstrings through their global ``FunctionDoc``."""


class _UnparsedDoc:
    """Stands in for ``FunctionDoc(f)`` as scipy's decorators use it: sections to read and append to (all
    empty, and what is added to them is dropped) and ``str`` giving a line for the signature (which the
    decorators cut off) then `f`'s docstring unchanged."""

    def __init__(self, f: Any) -> None:
        self._doc = getattr(f, "__doc__", None) or ""
        self._sections: dict[str, list[Any]] = {}

    def __getitem__(self, key: str) -> list[Any]:
        return self._sections.setdefault(key, [])

    def __setitem__(self, key: str, value: Any) -> None:
        pass

    def __str__(self) -> str:
        return "\n" + self._doc


def import_lean(names: Iterable[str]) -> None:
    """Import each of `names` (dotted module names), with scipy's docstring notes skipped for the modules
    imported meanwhile (module docstring). Without scipy, or with a scipy whose decorators are not where
    1.17 has them, a plain import."""
    patched: list[tuple[Any, Any]] = []
    try:
        for name in _DECORATING:
            try:
                module = importlib.import_module(name)
            except ImportError:
                continue
            if hasattr(module, "FunctionDoc"):
                patched.append((module, module.FunctionDoc))
                setattr(module, "FunctionDoc", _UnparsedDoc)  # noqa: B010 - a module attribute mypy cannot see
        for name in names:
            importlib.import_module(name)
    finally:
        for module, original in patched:
            setattr(module, "FunctionDoc", original)  # noqa: B010
