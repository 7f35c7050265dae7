"""The compile under a stated sensing (task key ``sensing:``, ``hrc compile --observation-delay``).

Each plan's class is checked against the delay check run here on the STNU file the compile wrote (and its
class at delay 0 against the DC check); a compile without sensing has neither key and its report says the
classes assume events learnt at once; bad ``sensing:`` values get one line naming the key and exit 2.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from hrc.cli import main
from hrc.errors import TaskFileError
from hrc.io.task_file import load_task
from hrc.model import SENSING_PATHS, Sensing
from hrc.temporal.dc import check_dc
from hrc.temporal.delay import ObservationDelay, check_delay
from hrc.temporal.graphml import read_network

CLASS = {"DC": "DC", "not DC": "consistent", "inconsistent": "inconsistent"}


def test_sensing_key_reads_with_the_paths_defaults(mini: tuple[dict, dict], write_mini: Any) -> None:
    task, map_ = mini
    assert load_task(write_mini(task, map_)).sensing is None
    task["sensing"] = {"path": "buttons"}
    assert load_task(write_mini(task, map_)).sensing == Sensing("buttons", SENSING_PATHS["buttons"][0], False)
    task["sensing"] = {"path": "motion", "delay": [0.2, 1.5]}
    assert load_task(write_mini(task, map_)).sensing == Sensing("motion", (0.2, 1.5), True)
    task["sensing"] = {"path": "stated", "delay": [0, float("inf")]}
    assert load_task(write_mini(task, map_)).sensing == Sensing("stated", (0.0, None), False)


@pytest.mark.parametrize(("sensing", "where", "what"), [
    ({"path": "radio"}, "sensing.path", "expected one of buttons, motion or stated"),
    ({"delay": [0, 1]}, "sensing", "path"),
    ({"path": "buttons", "delay": [1]}, "sensing.delay", "expected [lo, hi]"),
    ({"path": "buttons", "delay": [-0.1, 1]}, "sensing.delay[0]", ">= 0"),
    ({"path": "buttons", "delay": [2, 1]}, "sensing.delay", "exceeds"),
    ({"path": "buttons", "delay": [0, "soon"]}, "sensing.delay[1]", "expected a number"),
    ({"path": "stated"}, "sensing.delay", "needs a delay"),
    ({"path": "buttons", "delay": [0, 1], "latency": 2}, "sensing", "latency"),
    ("buttons", "sensing", "mapping"),
])
def test_bad_sensing_one_line_exit_2(mini: tuple[dict, dict], write_mini: Any, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str], sensing: Any, where: str, what: str) -> None:
    task, map_ = mini
    task["sensing"] = sensing
    path = write_mini(task, map_)
    with pytest.raises(TaskFileError) as err:
        load_task(path)
    assert where in str(err.value) and what in str(err.value), str(err.value)
    assert main(["compile", str(path), "--out", str(tmp_path / "out"), "-q", "--no-report"]) == 2
    out = capsys.readouterr().err
    assert out.count("\n") == 1 and out.startswith("error: ") and where in out, out
    assert not (tmp_path / "out").exists()


def _classes_checked(out: Path, delay: ObservationDelay) -> dict[str, Any]:
    data = json.loads((out / "compiled.json").read_text())
    for plan in data["plans"]:
        net = read_network(out / plan["stnu"])
        if plan["pattern"]["candidates"] == 0:
            continue  # a blocked plan's file carries its block
        assert plan["class_at_delay_0"] == CLASS[check_dc(net).verdict.value], plan["id"]
        assert plan["class"] == CLASS[check_delay(net, delay).verdict.value], plan["id"]
        if plan["class"] != plan["class_at_delay_0"]:
            assert plan["explanation"].startswith("under ") and "(DC at delay 0)" in plan["explanation"]
    return data


@pytest.fixture(scope="module")
def stated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The minimal task compiled at delay 0 and under a stated delay of 3 s (a human step lasts 1-4 s)."""
    import copy

    import yaml

    from tests.conftest import MIN_MAP, MIN_TASK

    base = tmp_path_factory.mktemp("sensing")
    (base / "map.yaml").write_text(yaml.safe_dump(MIN_MAP), encoding="utf-8")
    task = copy.deepcopy(MIN_TASK)
    task["constraints"] = [{"from": "a1.put.end", "to": "a2.go.start", "bounds": [0, 1]}]
    (base / "task.yaml").write_text(yaml.safe_dump(task), encoding="utf-8")
    plain, late = base / "plain", base / "late"
    assert main(["compile", str(base / "task.yaml"), "--out", str(plain), "-q", "--jobs", "1"]) == 0
    assert main(["compile", str(base / "task.yaml"), "--out", str(late), "-q", "--jobs", "1",
                 "--observation-delay", "3"]) == 0
    return plain, late


def test_compile_under_a_stated_delay(stated: tuple[Path, Path]) -> None:
    plain, late = stated
    data = _classes_checked(late, ObservationDelay(3000, 3000))
    assert data["sensing"]["path"] == "stated" and data["sensing"]["observation_delay"] == [3.0, 3.0]
    moved = [p for p in data["plans"] if p["class"] != p["class_at_delay_0"]]
    assert moved, "the stated delay costs some plan its DC class"
    assert all(p["class_at_delay_0"] == "DC" and p["class"] == "consistent" for p in moved)
    assert data["counts"] == {c: sum(p["class"] == c for p in data["plans"]) for c in ("DC", "consistent",
                                                                                       "inconsistent")}
    form = json.loads((late / "dispatch" / "form.json").read_text())
    assert form["sensing"] == data["sensing"]
    report = (late / "report.md").read_text()
    assert "Sensing: stated (observation delay 3 s)" in report and "lose DC" in report
    assert moved[0]["id"] in report
    task = load_task(late / "input" / "task.yaml") if (late / "input" / "task.yaml").exists() else None
    if task is not None:
        assert task.sensing == Sensing("stated", (3.0, 3.0), False)


def test_compile_without_sensing_says_so_and_adds_no_key(stated: tuple[Path, Path]) -> None:
    plain, _late = stated
    data = json.loads((plain / "compiled.json").read_text())
    assert "sensing" not in data and all("class_at_delay_0" not in p for p in data["plans"])
    assert "sensing" not in json.loads((plain / "dispatch" / "form.json").read_text())
    assert "No sensing stated" in (plain / "report.md").read_text()


def test_bad_observation_delay_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for bad in ("-1", "2:1", "soon"):
        with pytest.raises(SystemExit) as stop:
            main(["compile", "tasks/cube_stacking.yaml", "--out", str(tmp_path / "x"), "--observation-delay", bad])
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--observation-delay" in err


def test_the_dispatcher_holds_observations_to_the_compiles_delay(stated: tuple[Path, Path]) -> None:
    """What the classes were checked under is what the dispatcher holds a message's `delay` to: an
    observation learnt later than the compile's longest delay voids the guarantee, and the answer says so."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.messages import Observation

    plain, late = stated
    assert Dispatcher.from_folder(plain).max_observation_delay is None
    assert Dispatcher.from_folder(late, max_observation_delay=1.0).max_observation_delay == 1.0  # stated wins
    seen = []
    for delay in (2.9, 3.1):
        d = Dispatcher.from_folder(late)
        assert d.max_observation_delay == 3.0
        first = next(o for o in d.human_options() if o.event == "depart")
        seen.append(d.observe(Observation(3.5, "depart", "human", first.action, first.phase, delay=delay)))
    assert seen[0].deviation is None
    assert seen[1].deviation is not None and dict(seen[1].deviation["late"])["max"] == 3.0
