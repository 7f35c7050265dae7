"""The compiler end to end on the workshop, with independent re-checks of what it claims."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from oracles import lp_consistent, orders_schedulable

from hrc.cli import main
from hrc.compile.classify import PlanClass
from hrc.compile.compiler import compile_task, rank_key
from hrc.compile.output import compiled_to_dict, load_compiled_task
from hrc.compile.temporal_net_creator import ORIGIN, create_stnu
from hrc.errors import InputError
from hrc.io.task_file import load_task, task_digest
from hrc.motion import plan_motions
from hrc.plans import agent_legs, generate_plans
from hrc.temporal import check_dc
from hrc.temporal.graph import distance_edges
from hrc.temporal.graphml import read_graphml, read_network, tool_name

ROOT = Path(__file__).resolve().parents[1]
WORKSHOP = ROOT / "tasks" / "cube_stacking.yaml"


@pytest.fixture(scope="module")
def task():
    return load_task(WORKSHOP)


@pytest.fixture(scope="module")
def compiled(task):
    return compile_task(task, seed=0, jobs=1)


def test_workshop_has_32_plans_in_all_three_classes(compiled):
    assert len(compiled.plans) == 32
    classes = {cp.plan_class for cp in compiled.plans}
    assert classes == set(PlanClass), f"the workshop should show every class, found {classes}"


def test_ranks_follow_class_then_makespan(compiled):
    assert [cp.rank for cp in compiled.plans] == list(range(1, 33))
    keys = [rank_key(cp) for cp in compiled.plans]
    assert keys == sorted(keys)
    orders = [cp.plan_class.order for cp in compiled.plans]
    assert orders == sorted(orders)


def test_classes_agree_with_independent_checks(task, compiled):
    """The written STNU is inconsistent exactly when the LP finds no schedule, and an inconsistent plan has
    no passing order at all that an LP could schedule (a MILP over the orders, on the plan's routes and on
    the shortest ones); DC re-checked with the second algorithm."""
    paths = compiled.paths
    for cp in compiled.plans:
        stnu = read_graphml(cp.graphml.encode())
        assert lp_consistent(stnu, ORIGIN) == (cp.plan_class is not PlanClass.INCONSISTENT), cp.plan.id
        assert check_dc(stnu, "morris2014").verdict.value == {"DC": "DC", "consistent": "not DC",
                                                               "inconsistent": "inconsistent"}[cp.plan_class.value]
        if cp.plan_class is PlanClass.INCONSISTENT:
            for motions in ((), cp.motions):
                assert not orders_schedulable(task, cp.plan, paths, motions), cp.plan.id


def test_stnu_encodes_human_as_contingent_and_robot_as_requirement(task):
    plan = next(p for p in generate_plans(task) if len(p.sequence("human")) == 2)
    from hrc.motion import plan_paths

    motions = plan_motions(task, plan, plan_paths(task, seed=0))
    stnu = create_stnu(task, plan, motions).stnu
    human_legs = agent_legs(task, plan, "human")
    robot_legs = agent_legs(task, plan, "robot")
    assert len(stnu.timepoints) == 1 + 4 * (len(human_legs) + len(robot_legs))
    travelling = sum(1 for leg in human_legs if leg.origin != leg.location)
    assert len(stnu.contingents) == len(human_legs) + travelling
    assert all(c.source.startswith("human.") for c in stnu.contingents)
    for leg in robot_legs:
        start, end = f"robot.{leg.phase}.{leg.action}.start", f"robot.{leg.phase}.{leg.action}.end"
        bounds = task.action(leg.action).phase(leg.phase).duration("robot")
        link = next(r for r in stnu.requirements if (r.source, r.target) == (start, end))
        assert (link.lb, link.ub) == (round(bounds.lb * 1000), round(bounds.ub * 1000))
        # the robot drives each route without stopping: a rigid travel link of the route's time
        dep, arr = f"robot.{leg.phase}.{leg.action}.depart", f"robot.{leg.phase}.{leg.action}.arrive"
        travel = next(r for r in stnu.requirements if (r.source, r.target) == (dep, arr))
        m = next(m for m in motions if m.agent == "robot" and m.leg == leg.index)
        assert travel.lb == travel.ub == round(m.time * 1000)
    # deadline on every agent's last end
    deadlines = [r for r in stnu.requirements if r.source == ORIGIN and r.ub is not None]
    assert {r.ub for r in deadlines} == {round(task.deadline * 1000)} and len(deadlines) == 2


def test_makespan_bounds_are_ordered_and_deadline_separates_classes(task, compiled):
    for cp in compiled.plans:
        if cp.classification.makespan is None:  # the co-workers would block each other whatever they do
            assert cp.plan_class is PlanClass.INCONSISTENT
            continue
        lo, hi = cp.classification.makespan
        assert 0 < lo <= hi
        if cp.plan_class is PlanClass.INCONSISTENT:
            continue
        # a DC or consistent plan can finish by the deadline at least when the human is fast
        assert lo <= task.deadline + 1e-9, cp.plan.id
        if cp.plan_class is PlanClass.DC:
            assert not cp.classification.explanation
        else:
            assert cp.classification.explanation


def test_cli_compile_writes_checkable_stnus(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["compile", str(WORKSHOP), "--out", str(out), "--jobs", "1", "--no-report", "-q"]) == 0
    data = json.loads((out / "compiled.json").read_text())
    assert data["schema_version"] == 2 and data["seed"] == 0 and len(data["plans"]) == 32
    assert data["options"] == {"human_waits": True, "rank_by": "worst"}
    for plan in data["plans"]:
        stnu = read_network(out / plan["stnu"])
        verdict = check_dc(stnu).verdict.value
        assert {"DC": "DC", "not DC": "consistent", "inconsistent": "inconsistent"}[verdict] == plan["class"]
        for m in plan["motions"]:
            assert m["time"] >= m["free_time"] >= 0
            assert (m["detour"] is not None or m["park"] is not None) == (m["time"] > m["free_time"])
            assert set(m) >= {"agent", "from", "to", "free_time", "time", "detour"}
        edges: dict[tuple[str, str], list[int]] = {}
        for e in distance_edges(stnu):
            edges.setdefault((e.source, e.target), []).append(e.value)
        for p in plan["passing"]:  # every listed passing order holds in the written STNU: it is the edge on its
            c = p["constraint"]    # pair, or a tighter one is. T(to) - T(from) >= min: to -> from of weight -min
            assert min(edges[(c["to"], c["from"])]) <= -c["min"] * 1000 + 1, p
        assert math.isclose(sum(1 for _ in plan["allocation"]), 5)


@pytest.mark.parametrize("name", ["cube_stacking.yaml", "floorplan_demo.yaml"])
def test_output_folder_carries_the_task_it_was_compiled_from(tmp_path, name):
    """input/ holds the task and map (and DXF floor plan) as compiled; it loads back to the same task,
    and an edited copy is refused by its digest."""
    original = load_task(ROOT / "tasks" / name)
    out = tmp_path / "out"
    assert main(["compile", str(ROOT / "tasks" / name), "--out", str(out), "--jobs", "1", "--no-report",
                 "-q"]) == 0
    copy = load_compiled_task(out)
    assert copy.workspace.obstacles == original.workspace.obstacles
    assert task_digest(copy) == task_digest(original)
    edited = yaml.safe_load((out / "input" / "task.yaml").read_text())
    edited["safety_margin"] = 0.0
    (out / "input" / "task.yaml").write_text(yaml.safe_dump(edited))
    with pytest.raises(InputError, match="differs from the one compiled"):
        load_compiled_task(out)


def test_same_seed_same_bytes_whatever_the_jobs(tmp_path):
    outs = []
    for i, jobs in enumerate(("1", "2", "1")):
        out = tmp_path / f"o{i}"
        assert main(["compile", str(WORKSHOP), "--out", str(out), "--jobs", jobs, "--no-report", "-q"]) == 0
        outs.append(out)
    texts = [(o / "compiled.json").read_bytes() for o in outs]
    assert texts[0] == texts[1] == texts[2]
    names = sorted(p.name for p in (outs[0] / "stnu").iterdir())
    for name in names:
        assert (outs[0] / "stnu" / name).read_bytes() == (outs[1] / "stnu" / name).read_bytes()


def test_dask_cluster_gives_the_same_output(task, compiled):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address.replace("tcp://", "dask://")
        on_dask = compile_task(task, seed=0, executor=address)
    assert json.dumps(compiled_to_dict(on_dask)) == json.dumps(compiled_to_dict(compiled))


def test_bad_executor_is_one_error_line(tmp_path, capsys):
    code = main(["compile", str(WORKSHOP), "--out", str(tmp_path / "o"), "--executor", "ftp://x", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: ")
    assert not (tmp_path / "o").exists()


def test_travel_slack_widens_only_the_human_travel(task):
    """A person's travel is contingent on [t, t * travel_slack]; the robot's stays a requirement."""
    from dataclasses import replace

    from hrc.motion import plan_paths

    plan = next(p for p in generate_plans(task) if p.sequence("human") and p.sequence("robot"))
    motions = plan_motions(task, plan, plan_paths(task, seed=0))
    slower = replace(task, agents=tuple(replace(a, travel_slack=2.0) for a in task.agents))
    base, wide = create_stnu(task, plan, motions).stnu, create_stnu(slower, plan, motions).stnu
    moving = {(m.agent, m.leg): m for m in motions if m.time > 0}
    checked = 0
    for leg in agent_legs(task, plan, "human"):
        m = moving.get(("human", leg.index))
        if m is None:
            continue
        dep, arr = f"human.{leg.phase}.{leg.action}.depart", f"human.{leg.phase}.{leg.action}.arrive"
        b = next(c for c in base.contingents if (c.source, c.target) == (dep, arr))
        w = next(c for c in wide.contingents if (c.source, c.target) == (dep, arr))
        assert b.lb == w.lb == math.floor(m.free_time * 1000 + 1e-9)
        assert b.ub == math.ceil(m.time * 1.25 * 1000 - 1e-9) and w.ub == math.ceil(m.time * 2000 - 1e-9)
        checked += 1
    assert checked
    assert base.requirements == wide.requirements


def test_out_folder_that_is_not_ours_is_left_alone(tmp_path, capsys):
    """--out is replaced whole, so a non-empty folder without compiled.json (or a file) is refused."""
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("keep me")
    a_file = tmp_path / "notes.txt"
    a_file.write_text("keep me too")
    for target in (precious, a_file):
        assert main(["compile", str(WORKSHOP), "--out", str(target), "-q"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {target}: --out: ") and err.count("\n") == 1
    assert (precious / "chapter1.tex").read_text() == "keep me" and a_file.read_text() == "keep me too"


def test_an_output_path_the_machine_refuses_is_one_error_line(tmp_path, capsys):
    """OS errors on output (a folder where a file goes) end as one line and exit 2, not a traceback."""
    assert main(["paths", str(WORKSHOP), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {tmp_path}: is a folder; expected a file name\n"
    assert list(tmp_path.iterdir()) == []


def test_ranking_uses_preference_values(task, compiled):
    """The workshop has one preference (a breather between cube 1 and cube 2): every plan gets APA's
    optimal value on its own STNU, and within a class, among plans that finish in the same second, the
    higher value ranks first (compiled.json carries the value)."""
    from hrc.apa.plan import plan_preference_value
    from hrc.compile.temporal_net_creator import event_timepoint

    valued = [cp for cp in compiled.plans if cp.preference is not None]
    assert len(valued) >= 20
    pref = task.preferences[0]
    for cp in valued[:5]:  # the value is APA's on the written network (read as an STP)
        stnu = read_graphml(cp.graphml.encode())
        ends = (tool_name(event_timepoint(cp.plan, pref.source)), tool_name(event_timepoint(cp.plan, pref.target)))
        res = plan_preference_value(stnu, [(*ends, pref)])
        assert res.consistent and abs(res.value - cp.preference) <= 1e-6 * max(1.0, abs(res.value))
    for a, b in zip(compiled.plans, compiled.plans[1:], strict=False):
        ka, kb = rank_key(a), rank_key(b)
        if ka[:2] == kb[:2]:  # same class, same second of worst-case makespan
            assert ka[2] <= kb[2], (a.plan.id, b.plan.id)
    ranks = {cp.plan.id: cp.rank for cp in compiled.plans}
    assert ranks["42f378b79a"] < ranks["94ba6ad056"]  # 85.27 s, value 9.0 before 85.04 s, value -9.90
    assert compiled_to_dict(compiled)["plans"][0]["preference"] == round(compiled.plans[0].preference, 6)


def test_a_plan_with_no_schedule_ranks_last_in_its_class(compiled):
    """A plan whose co-workers would block each other has no makespan: it still gets a rank key, after
    every inconsistent plan that has a schedule."""
    from dataclasses import replace

    from hrc.compile.classify import Classification

    last = compiled.plans[-1]
    blocked = replace(last, classification=Classification(PlanClass.INCONSISTENT, "blocked", None, (), ()))
    assert rank_key(blocked) > max(rank_key(cp) for cp in compiled.plans)


def test_why_consistent_names_the_human_durations_that_matter(task, compiled):
    """A consistent plan's explanation names human durations such that, were the robot to decide them
    (contingent links made requirement links), the plan would be DC, and none of them can be left out:
    re-checked with the second DC algorithm on the plan's own network."""
    from hrc.compile.motion_pattern import choose_pattern
    from hrc.temporal import STNU, RequirementLink

    def controlled(stnu: STNU, names: set) -> STNU:
        keep = tuple(c for c in stnu.contingents if (c.source, c.target) not in names)
        made = tuple(RequirementLink(c.source, c.target, c.lb, c.ub) for c in stnu.contingents
                     if (c.source, c.target) in names)
        return STNU(stnu.timepoints, stnu.requirements + made, keep, stnu.name)

    consistent = [cp for cp in compiled.plans if cp.plan_class is PlanClass.CONSISTENT]
    assert len(consistent) >= 5
    for cp in consistent:
        choice = choose_pattern(task, cp.plan, compiled.paths)
        assert choice.classification.explanation == cp.classification.explanation
        _, sep, rest = cp.classification.explanation.partition("if the human takes long on: ")
        assert sep, cp.classification.explanation
        by_text = {text: key for key, (kind, text) in choice.net.meaning if kind == "human"}
        named = [by_text[text] for text in rest.split("; ")]
        stnu = choice.net.stnu
        assert check_dc(stnu, "morris2014").verdict.value == "not DC"
        assert check_dc(controlled(stnu, set(named)), "morris2014").is_dc, cp.plan.id
        for link in named:
            assert not check_dc(controlled(stnu, set(named) - {link}), "morris2014").is_dc, (cp.plan.id, link)


def test_each_route_choice_of_a_plan_gets_its_own_travel_links():
    """`create_stnu` builds what does not depend on the routes once per plan and each leg's travel once
    per route: whatever order a plan's route choices (shortest, detours, waiting places) are built in,
    each network has four timepoints per leg and two more per stop at a waiting place, and every robot
    travel is a rigid link of exactly that route's moving time (the motions are the independent truth)."""
    from hrc.compile.motion_pattern import _route_trials
    from hrc.motion import plan_paths

    kitting = load_task(ROOT / "tasks" / "kitting.yaml")
    paths = plan_paths(kitting, seed=0)
    checked = parks = 0
    for plan in list(generate_plans(kitting))[::97]:
        choices = [{}, *_route_trials(kitting, plan, paths, True)]
        for order in (choices, choices[::-1]):
            for routes in order:
                motions = plan_motions(kitting, plan, paths, routes)
                stnu = create_stnu(kitting, plan, motions).stnu
                assert len(stnu.timepoints) == 1 + 4 * len(motions) + 2 * sum(bool(m.park) for m in motions)
                rigid = {(r.source, r.target): (r.lb, r.ub) for r in stnu.requirements}
                for m in motions:
                    if m.agent != "robot" or m.time <= 0:
                        continue
                    leg = agent_legs(kitting, plan, "robot")[m.leg]
                    at = f"robot.{leg.phase}.{leg.action}."
                    if m.park:
                        legs = [(at + "depart", at + "park", m.park_time), (at + "unpark", at + "arrive",
                                                                            m.time - m.park_time)]
                        parks += 1
                    else:
                        legs = [(at + "depart", at + "arrive", m.time)]
                    for a, b, t in legs:
                        assert rigid[(a, b)] == (round(t * 1000), round(t * 1000))
                checked += 1
    assert checked >= 20 and parks  # not vacuous: detours and waiting places among the choices


@pytest.mark.parametrize("ub", [5, 0])
def test_a_renamed_network_is_classified_as_classify_does(task, ub):
    """A family's non-DC members take the first plan's numbers, renamed, and say its explanation again in
    their own words (`classify.renamed`); `classify` on the renamed network is the truth. Two hand-made
    networks `measure` notes: a slow human breaks a link (``ub`` 5: no schedule with every duration at
    its maximum), or nothing fits at all (``ub`` 0: no schedule, the co-workers block each other)."""
    from hrc.compile.classify import classify, renamed
    from hrc.compile.temporal_net_creator import PlanNetwork
    from hrc.temporal import STNU, ContingentLink, RequirementLink

    def network(step: str) -> PlanNetwork:
        stnu = STNU((ORIGIN, f"human.fetch.{step}.start", f"human.fetch.{step}.end"),
                    (RequirementLink(ORIGIN, f"human.fetch.{step}.start", 0, None),
                     RequirementLink(ORIGIN, f"human.fetch.{step}.end", None, ub)),
                    (ContingentLink(f"human.fetch.{step}.start", f"human.fetch.{step}.end", 1, 10),), "t")
        return PlanNetwork(stnu, tuple(sorted({
            (ORIGIN, f"human.fetch.{step}.start"): ("order", f"human leaves for {step}"),
            (ORIGIN, f"human.fetch.{step}.end"): ("space", f"passing order: robot before {step}"),
            (f"human.fetch.{step}.start", f"human.fetch.{step}.end"): ("human", f"human's fetch of {step} (1-10 s)"),
        }.items())), (f"human.fetch.{step}.end",))

    first, member = network("cube1"), network("cube2")
    names = dict(zip(first.stnu.timepoints, member.stnu.timepoints, strict=True))
    truth_first = classify(task, first)
    result = check_dc(member.stnu)
    truth = classify(task, member, known=result)
    assert truth.plan_class is not PlanClass.DC and "cube2" in truth.explanation
    assert ("at its maximum" in truth.explanation) == (ub == 5) and (truth.makespan is None) == (ub == 0)
    assert renamed(truth_first, names, member, result) == truth


_GARBAGE_PROBE = """
import collections, gc, itertools, json, sys
from hrc.compile.compiler import compile_family
from hrc.io.task_file import load_task
from hrc.motion import plan_paths
from hrc.plans import plan_families

task = load_task(sys.argv[1])
paths = plan_paths(task, seed=0)
families = list(itertools.islice(plan_families(task), 0, None, 25))
half = len(families) // 2
for family in families[:half]:
    compile_family(task, family, paths)
gc.collect()
gc.disable()
gc.set_debug(gc.DEBUG_SAVEALL)
compiled = [cp for family in families[half:] for cp in compile_family(task, family, paths)]
gc.collect()
print(json.dumps({"compiled": len(compiled), "classes": sorted({cp.plan_class.name for cp in compiled}),
                  "garbage": collections.Counter(type(o).__name__ for o in gc.garbage).most_common(5)}))
"""


def test_compiling_plans_leaves_no_cyclic_garbage() -> None:
    """Pool workers collect their youngest objects rarely (`executors.WORKER_GC_THRESHOLD`) because a
    plan's compile leaves nothing that only the cyclic collector frees: garbage in cycles would wait for
    it, holding its networks and arrays (the motion search's recursive closure once did, about 140
    objects a search). Plans not seen before (new route trials, detours) included. In a process of its
    own: another test's threads in this one (a server's, a browser driver's) make garbage of their own
    meanwhile."""
    import os
    import subprocess
    import sys

    got = subprocess.run([sys.executable, "-c", _GARBAGE_PROBE, str(ROOT / "tasks" / "kitting.yaml")],
                         capture_output=True, text=True, check=True, timeout=600, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    result = json.loads(got.stdout.splitlines()[-1])
    assert result["compiled"] >= 50 and "DC" in result["classes"]  # not vacuous
    assert result["garbage"] == [], result["garbage"]
