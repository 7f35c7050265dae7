"""Every module's public names are exactly what its ``__all__`` says (as httpx tests its own)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import hrc

OPTIONAL = {"hrc.ros2.node": "ros2"}
"""Modules that import an optional extra (module -> extra): skipped where it is not installed."""
MODULES = sorted(m.name for m in pkgutil.walk_packages(hrc.__path__, "hrc.")
                 if not m.name.endswith("__main__"))


@pytest.mark.parametrize("name", MODULES)
def test_all_lists_what_the_module_defines(name: str) -> None:
    try:
        module = importlib.import_module(name)
    except ImportError as err:
        if name not in OPTIONAL:
            raise
        pytest.skip(f"{name} needs the {OPTIONAL[name]} extra ({err})")
    exported = getattr(module, "__all__", None)
    if exported is None:
        pytest.skip(f"{name} has no __all__ (a package or script module)")
    assert len(exported) == len(set(exported)), f"{name}.__all__ lists a name twice"
    for attr in exported:
        assert hasattr(module, attr), f"{name}.__all__ names {attr!r}, which the module does not have"
    defined = {n for n, obj in vars(module).items()
               if not n.startswith("_") and (inspect.isfunction(obj) or inspect.isclass(obj))
               and getattr(obj, "__module__", None) == name}
    missing = defined - set(exported)
    assert not missing, f"{name} defines public {sorted(missing)} but leaves them out of __all__"
