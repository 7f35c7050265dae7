"""The task format's `preference_sets` (named worker-type preferences, docs/task-format.md): optional
(every existing task loads unchanged), validated like `preferences` with located errors, round-tripped."""

from __future__ import annotations

import dataclasses
import re

import pytest

from hrc.cli import main
from hrc.io.task_file import dump_task, load_task, task_to_dict

ERROR_LINE = re.compile(r"^error: (?P<file>[^:\n]+?)(?::(?P<line>\d+))?: (?P<rest>[^\n]*)\n$")
PREF = {"from": "a1.put.end", "to": "a2.go.start", "domain": [0, 10], "kind": "quadratic",
        "coefficients": [0, 4, -0.5]}


def test_optional_and_round_trip(mini, write_mini, tmp_path):
    task_d, map_d = mini
    plain = load_task(write_mini(task_d, map_d))
    assert plain.preference_sets == ()
    assert "preference_sets" not in task_to_dict(plain)   # older files are written back as they were
    task_d["preference_sets"] = {"fast": [PREF], "slow": [dict(PREF, coefficients=[0, 8, -0.5])]}
    task = load_task(write_mini(task_d, map_d))
    assert [n for n, _ in task.preference_sets] == ["fast", "slow"]
    assert task.preference_set("slow")[0].coefficients == (0, 8, -0.5)
    dump_task(task, tmp_path / "again.yaml")
    again = load_task(tmp_path / "again.yaml")
    assert dataclasses.replace(again, map_path=task.map_path) == task


@pytest.mark.parametrize("value, key, fragment", [
    ([PREF], "preference_sets", "expected a mapping"),
    ({"fast": []}, "preference_sets.fast", "at least 1 item"),
    ({"a.b": [PREF]}, "preference_sets.a.b", "must not contain spaces or dots"),
    ({"fast": [dict(PREF, kind="cubic")]}, "preference_sets.fast[0].kind", "expected one of"),
    ({"fast": [dict(PREF, coefficients=[0, 1, 1])]}, "preference_sets.fast[0].coefficients[2]", "concave"),
    ({"fast": [dict(PREF, to="zz.go.start")]}, "preference_sets.fast[0].to", "unknown action"),
])
def test_bad_preference_sets(mini, write_mini, capsys, value, key, fragment):
    task_d, map_d = mini
    task_d["preference_sets"] = value
    path = write_mini(task_d, map_d)
    assert main(["show", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    m = ERROR_LINE.match(err)
    assert m and m["file"] == str(path), err
    assert m["rest"].startswith(f"{key}: ") and fragment in m["rest"], err
