"""`hrc.compile.classify.slowest_makespan`: a plan's worst case with every agent at its slowest.

The compile's ``makespan[1]`` takes every human duration at its maximum and the robots at their quickest;
a simulated robot draws its durations within its bounds, so a run can end after ``makespan[1]`` with
every link kept (run 33 of kitting_2robots_iso under `hrc simulate --runs 200`: 0.042 s after it).
`hrc.sim.montecarlo.separation_summary` compares runs with this bound instead. Checked here against a
case worked by hand (both ways the links come: one two-sided link, or two one-sided ones as the GraphML
writes them), and against the compile's own ``makespan[1]`` when no robot is slowed, on every plan of a
real compile read back from its GraphML."""

from __future__ import annotations

import pytest
from conftest import ROOT

from hrc.compile.classify import slowest_makespan
from hrc.compile.compiler import compile_task
from hrc.io.task_file import load_task
from hrc.temporal import STNU, ContingentLink, RequirementLink
from hrc.temporal.graphml import read_graphml


def _net(sep: str, one_sided: bool) -> STNU:
    """robot2 fetches in [4, 5] s from 0 (robot waits 1 s then works [1, 9] s); the person starts putting
    once robot2 has ended and takes [2, 3] s; a 6 s deadline on the person's end (dropped: at their slowest
    the agents need 8 s)."""
    def n(*parts: str) -> str:
        return sep.join(parts)

    r2s, r2e = n("robot2", "fetch", "a", "start"), n("robot2", "fetch", "a", "end")
    rs, re_ = n("robot", "fetch", "b", "start"), n("robot", "fetch", "b", "end")
    hs, he = n("human", "put", "a", "start"), n("human", "put", "a", "end")
    dur = ([RequirementLink(r2s, r2e, None, 5000), RequirementLink(r2e, r2s, None, -4000)] if one_sided
           else [RequirementLink(r2s, r2e, 4000, 5000)])
    return STNU(("Z", r2s, r2e, rs, re_, hs, he),
                (*dur, RequirementLink("Z", r2s, 0, 0), RequirementLink("Z", rs, 1000, 1000),
                 RequirementLink(rs, re_, 1000, 9000), RequirementLink(r2e, hs, 0, None),
                 RequirementLink("Z", he, None, 6000)),
                (ContingentLink(hs, he, 2000, 3000),))


@pytest.mark.parametrize("sep,one_sided", [(".", False), (".", True), ("_", True)])
def test_every_agent_at_its_slowest_by_hand(sep: str, one_sided: bool) -> None:
    net = _net(sep, one_sided)
    agents = ["human", "robot", "robot2"]
    # robots at their quickest: robot2 ends at 4, the person at 4 + 3 = 7; robot ends at 1 + 1 = 2
    assert slowest_makespan(net, agents, set()) == 7.0
    # robot2 at its slowest: 5 + 3 = 8; "robot" is not "robot2" (the longest id owns a timepoint)
    assert slowest_makespan(net, agents, {"robot2"}) == 8.0
    # robot at its slowest too: 1 + 9 = 10 is the last end
    assert slowest_makespan(net, agents, {"robot", "robot2"}) == 10.0


def test_no_robot_slowed_is_the_compiles_worst_case_on_every_plan() -> None:
    task = load_task(ROOT / "tasks" / "two_workers.yaml")
    robots = {a.id for a in task.agents if not a.is_human}
    agents = [a.id for a in task.agents]
    compiled = compile_task(task, seed=0, jobs=1)
    seen = 0
    for cp in compiled.plans:
        if cp.classification.makespan is None:
            continue
        net = read_graphml(cp.graphml.encode())
        assert slowest_makespan(net, agents, set()) == pytest.approx(cp.classification.makespan[1], abs=1e-9)
        assert slowest_makespan(net, agents, robots) >= cp.classification.makespan[1] - 1e-9  # type: ignore[operator]
        seen += 1
    assert seen > 50
