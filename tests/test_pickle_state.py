"""The hand-written ``__getstate__`` of the compile's most pickled frozen dataclasses (issue 38) gives
what dataclasses' own gives: every field, in order, so the same pickle bytes (the caches' keys and files
stay those of before) and the same object back."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from hrc.compile.motion_pattern import PassingOrder
from hrc.motion.conflicts import Conflict, Occupancy, Separation, TimeRef


def _objects() -> list[object]:
    a, b = TimeRef("robot", 2, "depart"), TimeRef("human", 1, "arrive")
    robot = Occupancy("robot", "travel", 2, "B", "A", a, TimeRef("robot", 2, "arrive"), 1)
    human = Occupancy("human", "stay", -1, "H", "H", TimeRef.ORIGIN, b)  # type: ignore[attr-defined]
    conflict = Conflict(robot, human, 0, Separation(a, b, 0.5), Separation(b, a, 1.25), (1.5, -2.0),
                        ((0.0, 1.0), (2.0, 3.5)), "A-B")
    return [a, robot, human, Separation(a, b, 0.5), conflict, PassingOrder(conflict, "robot", "chosen")]


@pytest.mark.parametrize("obj", _objects(), ids=lambda o: type(o).__name__)
def test_state_and_pickle_are_dataclasses_own(obj: object, monkeypatch: pytest.MonkeyPatch) -> None:
    mine = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    assert obj.__getstate__() == [getattr(obj, f.name) for f in dataclasses.fields(obj)]  # type: ignore[attr-defined,arg-type]
    assert pickle.loads(mine) == obj
    for cls in {type(o) for o in _objects()}:  # every class's own state, nested ones included
        monkeypatch.setattr(cls, "__getstate__", dataclasses._dataclass_getstate)  # type: ignore[attr-defined]
    assert pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL) == mine
