"""Worker types (APA, section VI) on the spar assembly shipped in tasks/spar_assembly.yaml.

A scripted mechanic of each group (fixed action times, waiting for the sealant when it is late) and a
robot that seals each hole at the start of its window drive `STPPDispatcher`. The dispatcher starts
with group A's preferences. For a group A mechanic it never switches and the robot seals every 3 s;
for a group B mechanic it switches to group B when the first fastener is torqued before the second
is placed, and from then on the robot seals every 7 s (the paper: "slowing down the rate of sealant
application to every 7 seconds"). Every observed schedule is then checked against the task's hard
constraints (each fastener placed within 3 s of its sealant).
"""

from __future__ import annotations

import dataclasses

import pytest
from conftest import ROOT

from hrc.apa.compile import compile_stpp
from hrc.apa.dispatch import STPPDispatcher
from hrc.apa.plan import ORIGIN, preference_constraint, task_stpp
from hrc.apa.workers import best_worker_type, worker_type_values
from hrc.io.task_file import dump_task, load_task

TPS = 1000
TASK = load_task(ROOT / "tasks" / "spar_assembly.yaml")
SETS = {name: tuple(preference_constraint(str(p.source), str(p.target), p) for p in prefs)
        for name, prefs in TASK.preference_sets}
STPP = task_stpp(TASK)
PLACE, TORQUE = 2.0, 4.2


def human_script(group: str) -> list[tuple[str, str, float]]:
    """(event, event it follows, gap): the mechanic's order and pace."""
    out: list[tuple[str, str, float]] = []
    if group == "A":
        prev = None
        for i in range(1, 5):
            out += [(f"place{i}.place.start", prev or "", 1.0 if prev else 0.0),
                    (f"place{i}.place.end", f"place{i}.place.start", PLACE)]
            prev = f"place{i}.place.end"
        for i in range(1, 5):
            out += [(f"torque{i}.torque.start", prev, 1.0),
                    (f"torque{i}.torque.end", f"torque{i}.torque.start", TORQUE)]
            prev = f"torque{i}.torque.end"
    else:
        prev = None
        for i in range(1, 5):
            out += [(f"place{i}.place.start", prev or "", 0.5 if prev else 0.0),
                    (f"place{i}.place.end", f"place{i}.place.start", PLACE),
                    (f"torque{i}.torque.start", f"place{i}.place.end", 0.3),
                    (f"torque{i}.torque.end", f"torque{i}.torque.start", TORQUE)]
            prev = f"torque{i}.torque.end"
    return out


def run(group: str) -> tuple[STPPDispatcher, list[str], dict[str, float]]:
    disp = STPPDispatcher(STPP, ticks_per_second=TPS, preference_sets=SETS, worker_type="group_A",
                          watch=[e for e in STPP.events if e.startswith(("place", "torque"))])
    script = human_script(group)
    done: dict[str, float] = {}
    statuses: list[str] = []

    def observe(event: str, t: float) -> None:
        statuses.append(disp.observe(event, t).status)
        done[event] = t

    observe(ORIGIN, 0.0)
    while not disp.done:
        now = max(done.values())
        candidates: list[tuple[float, int, str]] = []
        if script:
            event, after, gap = script[0]
            if not after or after in done:
                t = (done[after] if after else 0.0) + gap
                if event.endswith("place.start"):  # the fastener goes in once its hole is sealed
                    seal = event.replace("place", "seal", 2)
                    t = max(t, done[seal.replace(".start", ".end")]) if seal.replace(".start", ".end") in done \
                        else float("inf")
                candidates.append((max(t, now), 1, event))
        for event, lo, _ in disp.next_events().windows:
            if event.startswith("seal"):
                candidates.append((max(now, lo if lo is not None else now), 0, event))
        t, _, event = min(candidates)
        assert t != float("inf"), "deadlock"
        if script and event == script[0][0]:
            script.pop(0)
        observe(event, round(t, 3))
    return disp, statuses, done


def seal_ends(done: dict[str, float]) -> list[float]:
    return [done[f"seal{i}.seal.end"] for i in range(1, 5)]


def test_task_file_carries_two_preference_sets(tmp_path):
    assert [n for n, _ in TASK.preference_sets] == ["group_A", "group_B"]
    dump_task(TASK, tmp_path / "spar.yaml")
    again = load_task(tmp_path / "spar.yaml")
    assert dataclasses.replace(again, map_path=TASK.map_path) == TASK


def test_each_set_alone_gives_its_rhythm():
    """The optimal schedules of the two sets: sealant every 3 s for A, every 7 s for B."""
    for name, gap in (("group_A", 3.0), ("group_B", 7.0)):
        r = compile_stpp(STPP.with_preferences([*STPP.preferred, *SETS[name]]), ticks_per_second=TPS)
        ends = seal_ends(r.schedule())
        assert [round(b - a, 3) for a, b in zip(ends, ends[1:], strict=False)] == [gap] * 3


def test_group_a_mechanic_keeps_group_a():
    disp, statuses, done = run("A")
    assert disp.worker_type == "group_A" and "switched" not in statuses
    ends = seal_ends(done)
    assert [round(b - a, 3) for a, b in zip(ends, ends[1:], strict=False)] == [3.0, 3.0, 3.0]
    assert STPP.violation(done) <= 1e-9


def test_group_b_mechanic_switches_to_group_b():
    disp, statuses, done = run("B")
    assert disp.worker_type == "group_B"
    switch = statuses.index("switched")
    # the switch comes with torque1.start, the first sign of a group B mechanic
    assert list(done)[switch] == "torque1.torque.start"
    assert done["torque1.torque.start"] < done["seal2.seal.start"]
    ends = seal_ends(done)
    assert [round(b - a, 3) for a, b in zip(ends, ends[1:], strict=False)] == [7.0, 7.0, 7.0]
    assert STPP.violation(done) <= 1e-9   # each fastener within 3 s of its sealant, and the rest


def test_values_tell_the_groups_apart():
    observed = {ORIGIN: 0.0, "seal1.seal.start": 0.0, "seal1.seal.end": 0.5, "place1.place.start": 0.5,
                "place1.place.end": 2.5}
    hard = STPP.without_preferences()
    sets = {k: (*STPP.preferred, *v) for k, v in SETS.items()}
    tie = worker_type_values(hard, sets, observed, 2.5, ticks_per_second=TPS)
    assert tie["group_A"] == pytest.approx(tie["group_B"], rel=1e-9)
    assert best_worker_type(hard, sets, observed, 2.5, current="group_A", ticks_per_second=TPS) == "group_A"
    observed["torque1.torque.start"] = 2.8
    values = worker_type_values(hard, sets, observed, 2.8, ticks_per_second=TPS)
    assert values["group_B"] > values["group_A"]
    assert best_worker_type(hard, sets, observed, 2.8, current="group_A", ticks_per_second=TPS) == "group_B"
