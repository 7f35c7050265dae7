"""Streaming compile (`hrc.compile.stream`): the same bytes as the in-memory compile, STNUs as files,
archive or none, partial output on interrupt; plan counts in bounded time; pinning."""

from __future__ import annotations

import itertools
import json
import math
import zipfile

import pytest
from conftest import ROOT, WORKSHOP_TASK, tree_bytes

from hrc.compile.compiler import CompileOptions, compile_task
from hrc.compile.output import load_compiled_task, write_compiled
from hrc.compile.sink import PlanSink
from hrc.compile.stream import compile_stream
from hrc.io.task_file import load_task
from hrc.plans import (
    _TooManyStates,
    count_plans,
    estimate_plan_count,
    family_of,
    generate_plans,
    identical_actions,
    pin_actions,
    plan_code,
    plan_count_bound,
    plan_families,
    plan_from_code,
)


def test_stream_writes_the_bytes_of_the_in_memory_compile(mini_task, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(compile_task(mini_task, jobs=1), a)
    samples = []
    result = compile_stream(mini_task, b, count_plans(mini_task), jobs=1, sample_seconds=0.0,
                            estimate=samples.append, sample_min=1)
    assert not result.partial and result.compiled == len(list(generate_plans(mini_task)))
    assert tree_bytes(a) == tree_bytes(b)  # the sample's plans, compiled twice for the estimate, are written once
    (sample,) = samples
    assert sample.plans >= 1 and sample.seconds_per_plan > 0 and sample.first_seconds_per_plan > 0


def test_a_small_compile_takes_no_sample_and_writes_the_same_bytes(mini_task, tmp_path):
    """Below `SAMPLE_MIN_PLANS` no plan is compiled in the parent for the estimate (issue 38): the
    estimate is never called, and the output is the in-memory compile's, byte for byte."""
    from hrc.compile.stream import SAMPLE_MIN_PLANS

    total = count_plans(mini_task)
    assert total < SAMPLE_MIN_PLANS
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(compile_task(mini_task, jobs=1), a)
    samples = []
    result = compile_stream(mini_task, b, total, jobs=2, estimate=samples.append)
    assert samples == [] and result.seconds_per_plan is None
    assert result.compiled == len(list(generate_plans(mini_task)))
    assert tree_bytes(a) == tree_bytes(b)


def test_stream_writes_the_same_bytes_where_the_kernel_cannot_copy(mini_task, tmp_path, monkeypatch):
    """``compiled.json``'s lines are copied from the spool by ``copy_file_range``; where the kernel
    refuses (another file system on an older kernel), they are read and written instead: the same bytes."""
    import errno
    import os

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(compile_task(mini_task, jobs=1), a)
    calls = []

    def refuse(*args, **kwargs):
        calls.append(args)
        raise OSError(errno.EXDEV, "Invalid cross-device link")

    monkeypatch.setattr(os, "copy_file_range", refuse, raising=False)
    compile_stream(mini_task, b, count_plans(mini_task), jobs=1, sample_seconds=0.0)
    assert tree_bytes(a) == tree_bytes(b)
    assert len(calls) == 1  # tried once, then read and written


@pytest.mark.slow
def test_stream_writes_the_workshop_bytes_of_the_in_memory_compile(tmp_path):
    task = load_task(WORKSHOP_TASK)
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(compile_task(task, jobs=2), a)
    compile_stream(task, b, 32, jobs=2)
    assert tree_bytes(a) == tree_bytes(b)


def test_a_small_report_top_keeps_the_best_plans_with_their_global_ranks(mini_task, tmp_path):
    full = compile_task(mini_task, jobs=1)
    result = compile_stream(mini_task, tmp_path, count_plans(mini_task), jobs=1, keep=1, sample_seconds=0.0)
    held = result.plan_set
    assert held.total == len(full.plans) and held.counts() == full.counts()
    ranks = {cp.plan.id: cp.rank for cp in full.plans}
    assert held.plans[0].plan.id == full.plans[0].plan.id
    assert all(ranks[cp.plan.id] == cp.rank for cp in held.plans)
    best_of = {}
    for cp in full.plans:
        best_of.setdefault(cp.plan_class, cp.plan.id)
    assert set(best_of.values()) <= {cp.plan.id for cp in held.plans}
    summary = held.summary
    assert summary is not None and sum(st.plans for st in summary.stats) == held.total
    assert sum(sum(st.histogram) for st in summary.stats) == sum(st.plans - st.no_schedule for st in summary.stats)


def test_stnu_archive_is_deterministic_and_named_as_the_plans_say(mini_task, tmp_path):
    outs = []
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}"
        out.mkdir()
        compile_stream(mini_task, out, count_plans(mini_task), jobs=jobs, stnu="archive", sample_seconds=0.0)
        outs.append(out)
    assert tree_bytes(outs[0]) == tree_bytes(outs[1])
    data = json.loads((outs[0] / "compiled.json").read_text())
    assert data["stnu_files"] == "archive" and data["stnu_archive"] == "stnu.zip"
    assert not (outs[0] / "stnu").exists()
    with zipfile.ZipFile(outs[0] / "stnu.zip") as zf:
        assert zf.namelist() == [p["stnu"] for p in data["plans"]]
        assert all(zf.read(p["stnu"]).startswith(b"<?xml") for p in data["plans"])


def test_stnu_none_says_so(mini_task, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    compile_stream(mini_task, out, count_plans(mini_task), jobs=1, stnu="none", sample_seconds=0.0)
    data = json.loads((out / "compiled.json").read_text())
    assert data["stnu_files"] == "none" and all(p["stnu"] is None for p in data["plans"])
    assert sorted(p.name for p in out.iterdir()) == ["compiled.json", "input"]


def test_an_interrupted_stream_leaves_a_valid_partial_output(tmp_path):
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    seen = []

    def progress(stage: str, done: int, total: int) -> None:
        if stage == "plans":
            seen.append(done)
            if len(seen) == 2:
                raise KeyboardInterrupt

    result = compile_stream(task, tmp_path, 2880, jobs=1, progress=progress, sample_seconds=0.0)
    assert result.partial and 0 < result.compiled < 2880
    data = json.loads((tmp_path / "compiled.json").read_text())
    assert data["partial"] is True and data["plans_expected"] == 2880
    assert len(data["plans"]) == result.compiled == sum(data["counts"].values())
    assert [p["rank"] for p in data["plans"]] == list(range(1, result.compiled + 1))
    assert not list(tmp_path.glob(".*.spool"))
    assert load_compiled_task(tmp_path).name == "kitting"


def test_an_interrupted_stream_on_two_workers_lists_what_it_wrote(tmp_path):
    """Workers write their plans' GraphML and line tails into the folder themselves (`_WorkerFiles`);
    interrupted, the output still lists exactly the STNU files it holds, and no spool is left."""
    import time

    task = load_task(ROOT / "tasks" / "kitting.yaml")
    seen = []

    def progress(stage: str, done: int, total: int) -> None:
        if stage == "plans":
            seen.append(done)
            if len(seen) == 4:  # once the workers have written plans the sink has not taken yet
                deadline = time.monotonic() + 30
                while len(list((tmp_path / "stnu").iterdir())) <= done and time.monotonic() < deadline:
                    time.sleep(0.05)
                raise KeyboardInterrupt

    result = compile_stream(task, tmp_path, 2880, jobs=2, progress=progress, sample_seconds=0.0)
    assert result.partial and 0 < result.compiled < 2880
    data = json.loads((tmp_path / "compiled.json").read_text())
    assert sorted(p.name for p in (tmp_path / "stnu").iterdir()) == sorted(f"{p['id']}.graphml" for p in data["plans"])
    assert [p["rank"] for p in data["plans"]] == list(range(1, result.compiled + 1))
    assert not list(tmp_path.glob(".*.spool"))


def test_two_workers_writing_their_own_files_give_the_same_bytes(mini_task, tmp_path):
    outs = []
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}"
        out.mkdir()
        compile_stream(mini_task, out, count_plans(mini_task), jobs=jobs, sample_seconds=0.0)
        outs.append(out)
    assert tree_bytes(outs[0]) == tree_bytes(outs[1])
    assert not list(outs[1].glob(".*.spool"))


def test_dask_workers_send_their_texts_and_give_the_same_bytes(mini_task, tmp_path):
    """Workers elsewhere (Dask) send the texts that local workers write themselves: the same output."""
    distributed = pytest.importorskip("distributed")
    outs = [tmp_path / "local", tmp_path / "dask"]
    for out in outs:
        out.mkdir()
    compile_stream(mini_task, outs[0], count_plans(mini_task), jobs=2, sample_seconds=0.0)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address.replace("tcp://", "dask://")
        compile_stream(mini_task, outs[1], count_plans(mini_task), executor=address, sample_seconds=0.0)
    assert tree_bytes(outs[0]) == tree_bytes(outs[1])


def test_the_sink_ranks_as_rank_key_does(mini_task, tmp_path):
    """Plans added in any order come out in rank order (the compact records sort as `rank_key`)."""
    full = compile_task(mini_task, jobs=1, options=CompileOptions(rank_by="earliest"))
    sink = PlanSink(mini_task, tmp_path, "none", keep=2, rank_by="earliest")
    from hrc.compile.stream import compile_records

    for cp, tail in reversed(compile_records(full.options, "none", mini_task, full.paths,
                                             [(cp.plan,) for cp in full.plans])):
        sink.add(cp, tail)
    out = sink.finish(0, full.paths, full.options)
    data = json.loads((tmp_path / "compiled.json").read_text())
    assert [p["id"] for p in data["plans"]] == [cp.plan.id for cp in full.plans]
    assert [cp.rank for cp in out.plans[:2]] == [1, 2]


@pytest.fixture(scope="module")
def workshop_set():
    return compile_task(load_task(ROOT / "tasks" / "cube_stacking.yaml"), jobs=1)


@pytest.mark.parametrize("order", ["ranked", "shuffled"])
def test_compact_records_keep_what_full_records_keep(workshop_set, tmp_path, order):
    """Workers send a plan's full record only when it beats the parent's bar (`compact_records`,
    `PlanSink.bar`); fed chunk by chunk with the bar of the moment, the sink must keep exactly the plans,
    ranks and bytes that full records give it, in any arrival order (keep=3: most plans fall below)."""
    import random

    from hrc.compile.stream import compact_records, compile_records

    full = workshop_set
    task = full.task
    families = [(cp.plan,) for cp in full.plans]
    if order == "shuffled":
        random.Random(5).shuffle(families)
    sinks = []
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        sinks.append(PlanSink(task, tmp_path / name, "archive", keep=3))
    a, b = sinks
    for cp, tail in compile_records(full.options, "archive", task, full.paths, families):
        a.add(cp, tail)
    sent = 0
    for k in range(0, len(families), 2):
        for record in compact_records(full.options, "archive", task, full.paths, (b.bar(), families[k:k + 2])):
            sent += record[5] is not None
            b.add_record(record)
    assert 0 < sent < len(families) // 2, (sent, len(families))  # the bar held most plans back
    out_a, out_b = a.finish(0, full.paths, full.options), b.finish(0, full.paths, full.options)
    assert out_a.plans == out_b.plans and len(out_a.plans) >= 3
    assert out_a.summary == out_b.summary
    for name in ("compiled.json", "stnu.zip"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


# --- counting ---------------------------------------------------------------------------------------

def test_count_in_bounded_states_or_a_bound(mini_task):
    assert estimate_plan_count(mini_task).exact
    with pytest.raises(_TooManyStates):
        count_plans(load_task(ROOT / "tasks" / "kitting.yaml"), max_states=10)
    kitting = load_task(ROOT / "tasks" / "kitting.yaml")
    bounded = estimate_plan_count(kitting, max_states=10)
    assert not bounded.exact and bounded.value == plan_count_bound(kitting) >= count_plans(kitting) == 2880
    assert str(bounded) == f"at most {bounded.value:,}"


@pytest.mark.parametrize("n", [6, 7, 8])
def test_independent_picks_count_as_factorials(n):
    task = load_task(ROOT / "tasks" / f"kitting_{n}picks.yaml")
    count = estimate_plan_count(task, max_states=10)  # the bound is exact without precedence
    assert count.exact and count.value == math.factorial(n + 1) == plan_count_bound(task)


def test_pinning_an_action_halves_the_plans_and_keeps_the_rest(mini_task):
    pinned = pin_actions(mini_task, {"a2": "robot"})
    plans = list(generate_plans(pinned))
    assert count_plans(pinned) == len(plans) < count_plans(mini_task)
    assert all(dict(p.allocation)["a2"] == "robot" for p in plans)
    full = {p.id for p in generate_plans(mini_task) if dict(p.allocation)["a2"] == "robot"}
    assert {p.id for p in plans} == full


@pytest.mark.parametrize("pins", [{"nope": "robot"}, {"a2": "nobody"}])
def test_pinning_names_what_is_wrong(mini_task, pins):
    from hrc.errors import InputError

    with pytest.raises(InputError, match="--pin"):
        pin_actions(mini_task, pins)


def test_symmetry_keeps_one_plan_per_relabelling():
    """kitting_6picks: pick_f is pick_a's twin (rack A, same durations): every plan has exactly one
    canonical twin, with the same class and makespans."""
    from hrc.plans import is_canonical, symmetry_factor

    task = load_task(ROOT / "tasks" / "kitting_6picks.yaml")
    groups = identical_actions(task)
    assert groups == (("pick_a", "pick_f"),) and symmetry_factor(task) == 2
    full = list(generate_plans(task))
    kept = list(generate_plans(task, symmetry=True))
    assert len(kept) * 2 == len(full) == 5040 and estimate_plan_count(task, symmetry=True).value == len(kept)

    def swap(plan):
        rename = {"pick_a": "pick_f", "pick_f": "pick_a"}
        from hrc.model import Plan

        alloc = dict(plan.allocation)
        return Plan(allocation=tuple((a, alloc[rename.get(a, a)]) for a, _ in plan.allocation),
                    sequences=tuple((ag, tuple(rename.get(x, x) for x in seq)) for ag, seq in plan.sequences))

    kept_ids = {p.id for p in kept}
    for plan in full:
        assert (plan.id in kept_ids) != (swap(plan).id in kept_ids)
        assert is_canonical(task, plan, groups) == (plan.id in kept_ids)


@pytest.mark.slow
def test_symmetric_twins_compile_to_the_same_class_and_makespans():
    from hrc.compile.compiler import compile_plan
    from hrc.motion import plan_paths

    task = load_task(ROOT / "tasks" / "kitting_6picks.yaml")
    paths = plan_paths(task, seed=0)
    plans = {p.id: p for p in generate_plans(task)}
    for plan in list(generate_plans(task, symmetry=True))[::251]:
        rename = {"pick_a": "pick_f", "pick_f": "pick_a"}
        twin = next(p for p in plans.values() if p.sequences == tuple(
            (ag, tuple(rename.get(x, x) for x in seq)) for ag, seq in plan.sequences))
        a, b = compile_plan(task, plan, paths), compile_plan(task, twin, paths)
        assert a.plan_class == b.plan_class and a.classification.makespan == b.classification.makespan


def test_plan_families_are_the_plans_grouped_by_relabelling():
    """`plan_families` yields every plan of `generate_plans` exactly once, in families of
    `symmetry_factor` plans, each headed by its canonical plan and closed under swapping twins."""
    from hrc.plans import is_canonical, symmetry_factor

    task = load_task(ROOT / "tasks" / "kitting_6picks.yaml")
    groups = identical_actions(task)
    families = list(plan_families(task))
    flat = [p for f in families for p in f]
    assert len(flat) == len(set(flat)) == 5040 and set(flat) == set(generate_plans(task))
    assert {len(f) for f in families} == {symmetry_factor(task)} == {2}
    for family in families:
        assert is_canonical(task, family[0], groups) and not any(is_canonical(task, p, groups) for p in family[1:])
        a, b = family
        swap = {"pick_a": "pick_f", "pick_f": "pick_a"}
        assert b.sequences == tuple((ag, tuple(swap.get(x, x) for x in seq)) for ag, seq in a.sequences)


@pytest.mark.parametrize("options", [CompileOptions(), CompileOptions(human_waits=False, rank_by="nominal")])
def test_a_family_compiles_as_each_of_its_plans_does(options):
    """One motion search per family (`compile_family`) gives each plan the very record its own search
    gives (`compile_plan`): kitting_7picks, families of 4 (two pairs of twins)."""
    from hrc.compile.compiler import compile_family, compile_plan
    from hrc.motion import plan_paths
    from hrc.plans import plan_families

    task = load_task(ROOT / "tasks" / "kitting_7picks.yaml")
    paths = plan_paths(task, seed=0)
    families = list(itertools.islice(plan_families(task), 0, 4000, 997))
    assert len(families) == 5 and {len(f) for f in families} == {4}
    for family in families:
        got = compile_family(task, family, paths, options)
        assert [repr(cp) for cp in got] == [repr(compile_plan(task, p, paths, options)) for p in family]


@pytest.mark.parametrize("options", [CompileOptions(), CompileOptions(human_waits=False, rank_by="earliest")])
def test_a_relabelled_record_is_the_record_of_the_relabelled_plan(options):
    """`relabel_record` (a family member's record from its first plan's, names changed) against the
    member compiled and classified on its own STNU with the same pattern (`compile_plan`): equal, GraphML
    and schedules included, on kitting_6picks with an APA preference on two actions that are not twins
    (so the preference value is carried over too). DC and not-DC families both; the latter are refused
    (their explanations name actions) and classified on their own STNU, with the first plan's DC check
    renamed (`relabel_check`): the very verdict and cycle the check finds on the member's STNU."""
    from dataclasses import replace

    from hrc.compile.compiler import compile_family, compile_plan, relabel_check, relabel_record
    from hrc.compile.motion_pattern import apply_pattern, choose_pattern
    from hrc.compile.temporal_net_creator import relabel_timepoints
    from hrc.model import Event, Interval, Preference, PreferenceKind
    from hrc.motion import plan_paths
    from hrc.plans import identical_actions, plan_families
    from hrc.temporal import check_dc

    base = load_task(ROOT / "tasks" / "kitting_6picks.yaml")
    pref = Preference(Event("pick_b", "place", "end"), Event("pick_d", "place", "end"), Interval(-60, 60),
                      PreferenceKind.QUADRATIC, (0.0, 1.0, -0.05))
    task = replace(base, preferences=(pref,))
    assert identical_actions(task) == (("pick_a", "pick_f"),)
    paths = plan_paths(task, seed=0)
    seen = {"DC": 0, "other": 0}
    for family in itertools.islice(plan_families(task), 0, 2520, 157):
        choice = choose_pattern(task, family[0], paths, options.human_waits, options.rank_by)
        first = compile_plan(task, family[0], paths, options, pattern=choice.pattern)
        (member,) = family[1:]
        if first.classification.explanation:
            seen["other"] += 1
            with pytest.raises(ValueError, match="names actions"):
                relabel_record(task, first, choice.net.stnu, member)
            # classified on its own STNU with the first's DC check renamed: the check's own answer
            names = relabel_timepoints(task, family[0], member)
            own = compile_plan(task, member, paths, options, pattern=first.pattern)
            if first.pattern.candidates:
                mine = check_dc(apply_pattern(task, member, first.pattern, options.human_waits).net.stnu)
                renamed = relabel_check(check_dc(choice.net.stnu), names)
                assert (renamed.verdict, renamed.cycle) == (mine.verdict, mine.cycle) and mine.cycle
            assert compile_family(task, family, paths, options)[1] == own
            continue
        seen["DC"] += 1
        assert first.preference is not None
        got = relabel_record(task, first, choice.net.stnu, member)
        assert got == compile_plan(task, member, paths, options, pattern=first.pattern)
        assert got.graphml != first.graphml and got.classification.schedule != first.classification.schedule
    assert seen["DC"] >= 5 and seen["other"] >= 2, seen


def test_the_estimate_samples_plans_from_across_the_task():
    """`spread_families` draws its sample from allocations all over the space (the stream's first plans
    all give the human everything), each a family `plan_families` yields, none twice."""
    from hrc.plans import allocations, plan_families, spread_families

    task = load_task(ROOT / "tasks" / "kitting_7picks.yaml")
    sample = spread_families(task, 16)
    assert len(sample) == len(set(sample)) == 16
    families = set(plan_families(task))
    assert all(f in families for f in sample)
    order = {a: i for i, a in enumerate(allocations(task))}
    where = sorted(order[f[0].allocation] for f in sample)
    assert where[0] < 16 and where[-1] > 100  # of 128 allocations
    assert len({sum(ag == "robot" for _, ag in f[0].allocation) for f in sample}) >= 4  # 0..7 picks to the robot
    assert {len(f) for f in spread_families(task, 4, symmetry=True)} == {1}


def test_a_plan_line_is_its_entry_encoded():
    """`plan_line` splices the passing orders in from the pattern's text parts; the truth is `plan_dict`
    encoded by `json.dumps`: the same text for every plan of the workshop (whose names include detours
    and waiting places) and for families of kitting_7picks, in every `--stnu` mode."""
    from hrc.compile.compiler import compile_family
    from hrc.compile.output import plan_dict, plan_line
    from hrc.motion import plan_paths
    from hrc.plans import plan_families

    def encoded(task, cp, mode):  # noqa: ANN001, ANN202
        return json.dumps(plan_dict(task, cp, mode), separators=(",", ":"))

    workshop = compile_task(load_task(WORKSHOP_TASK), jobs=1)
    checked = 0
    for cp in workshop.plans:
        for mode in ("graphml", "archive", "none", None):
            assert plan_line(workshop.task, cp, mode) == encoded(workshop.task, cp, mode)
            checked += 1
    task = load_task(ROOT / "tasks" / "kitting_7picks.yaml")
    paths = plan_paths(task, seed=0)
    for family in itertools.islice(plan_families(task), 0, 10080, 1999):
        for cp in compile_family(task, family, paths):
            assert plan_line(task, cp, "archive") == encoded(task, cp, "archive")
            checked += 1
    assert checked > 100


# --- the best K of each allocation -------------------------------------------------------------------

@pytest.fixture(scope="module")
def picks4_file(tmp_path_factory):
    """kitting_7picks cut to four picks, pick_f identical to pick_a: 5! = 120 plans, 16 allocations of
    1 to 24 plans, families of two; with a deadline of 60 s, plans of all three classes, some allocations
    with plans of two or three."""
    import yaml

    data = yaml.safe_load((ROOT / "tasks" / "kitting_7picks.yaml").read_text())
    data["map"] = str(ROOT / "maps" / "kitting_cell.yaml")
    data["actions"] = [a for a in data["actions"] if a["id"] in ("pick_a", "pick_b", "pick_c", "pick_f")]
    data["deadline"] = 60
    path = tmp_path_factory.mktemp("picks4") / "picks4.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def picks4(picks4_file, tmp_path_factory):
    """`picks4_file`'s task, its in-memory compile and that compile's output folder."""
    task = load_task(picks4_file)
    full = compile_task(task, jobs=1)
    out = tmp_path_factory.mktemp("picks4_full")
    write_compiled(full, out)
    return task, full, out


def _best_of_each_allocation(plans, k):
    taken, out = {}, []
    for p in plans:
        allocation = json.dumps(p["allocation"], sort_keys=True)
        if taken.get(allocation, 0) < k:
            taken[allocation] = taken.get(allocation, 0) + 1
            out.append({**p, "rank": len(out) + 1})
    return out


@pytest.mark.parametrize(("stnu", "jobs", "best"), [("graphml", 1, 1), ("graphml", 2, 2), ("archive", 2, 1),
                                                    ("none", 1, 3)])
def test_best_per_allocation_keeps_the_best_plans_of_each_allocation(picks4, tmp_path, stnu, jobs, best):
    """The oracle: the in-memory compile of every plan, cut to the first `best` plans of each allocation
    in its rank order. The streamed compile must list exactly those, with the same lines but for the
    rank, the same STNU bytes and no other file, and show the records the full compile has."""
    from dataclasses import replace

    task, full, full_out = picks4
    assert identical_actions(task) == (("pick_a", "pick_f"),)
    result = compile_stream(task, tmp_path, count_plans(task), jobs=jobs, stnu=stnu, keep=3, best=best,
                            sample_seconds=0.0)
    want = _best_of_each_allocation(json.loads((full_out / "compiled.json").read_text())["plans"], best)
    assert len(want) == 16 if best == 1 else 16 < len(want) < 120  # 16 allocations, 120 plans
    data = json.loads((tmp_path / "compiled.json").read_text())
    assert data["best_per_allocation"] == best and data["plans_compiled"] == result.compiled == 120
    assert [{**p, "stnu": None} for p in data["plans"]] == [{**p, "stnu": None} for p in want]
    counts = {c: sum(p["class"] == c for p in want) for c in data["counts"]}
    assert data["counts"] == counts and result.plan_set.total == len(want)
    ids = [p["id"] for p in want]
    expected = {f"{i}.graphml": (full_out / "stnu" / f"{i}.graphml").read_bytes() for i in ids}
    if stnu == "graphml":
        assert {p.name: p.read_bytes() for p in (tmp_path / "stnu").iterdir()} == expected
    elif stnu == "archive":
        with zipfile.ZipFile(tmp_path / "stnu.zip") as zf:
            assert zf.namelist() == [f"stnu/{i}" for i in expected]
            assert all(zf.read(f"stnu/{name}") == text for name, text in expected.items())
    assert not list(tmp_path.glob(".*.spool"))
    by_id = {cp.plan.id: cp for cp in full.plans}
    shown = result.plan_set.plans
    assert [cp.plan.id for cp in shown[:3]] == ids[:3]
    assert {cp.plan_class for cp in shown} == {by_id[i].plan_class for i in ids}
    for cp in shown:
        assert cp == replace(by_id[cp.plan.id], graphml="", form=b"", rank=ids.index(cp.plan.id) + 1)
    summary = result.plan_set.summary
    assert summary is not None and summary.total == len(want) and summary.best == (best, 120)


def test_the_bars_with_best_per_allocation_keep_what_full_records_keep(picks4, tmp_path, monkeypatch):
    """With `best`, a plan's full record is sent only when it beats the bar of the moment, as without;
    the best plan kept of a class may then have been sent without it (a plan of its class that beat it
    was dropped later) and is compiled again (`PlanSink._recover`). In any arrival order the sink must
    show the records that full records give it."""
    import random

    from hrc.compile.stream import compact_records, compile_records

    task, full, _ = picks4
    families = list(plan_families(task))
    recovered = []
    recover = PlanSink._recover
    monkeypatch.setattr(PlanSink, "_recover", lambda self, i, *a: recovered.append(i) or recover(self, i, *a))
    # (a plan among the keep best is never recovered: `_recover` refuses, the bar must have kept it)
    sent = 0
    for seed in range(6):
        random.Random(seed).shuffle(families)
        sinks = []
        for name in ("a", "b"):
            (tmp_path / f"{name}{seed}").mkdir()
            sinks.append(PlanSink(task, tmp_path / f"{name}{seed}", "none", keep=12, best=2))
        a, b = sinks
        for cp, tail in compile_records(full.options, "none", task, full.paths, families):
            a.add(cp, tail)
        for k in range(0, len(families), 3):
            chunk = families[k:k + 3]
            for record in compact_records(full.options, "none", task, full.paths, (b.bar(chunk), chunk)):
                sent += record[5] is not None
                b.add_record(record)
        out_a, out_b = a.finish(0, full.paths, full.options), b.finish(0, full.paths, full.options)
        assert out_a.plans == out_b.plans and len(out_a.plans) >= 12
        assert out_a.summary == out_b.summary
        assert (tmp_path / f"a{seed}" / "compiled.json").read_bytes() == (tmp_path / f"b{seed}" /
                                                                           "compiled.json").read_bytes()
    assert recovered  # some order needed a record compiled again
    assert sent < 6 * len(families)  # the bars held plans back (the allocations' bars most of them)


def test_the_slowest_plan_named_does_not_depend_on_arrival_order(picks4, tmp_path):
    """The summary names the plan of the slowest earliest makespan (the report's sentence on an empty
    class). Plans of identical picks tie there; workers deliver them in any order, so a tie must go to
    the smallest id, whatever came first."""
    import random

    from hrc.compile.stream import compile_records

    task, full, _ = picks4
    records = compile_records(full.options, "none", task, full.paths, list(plan_families(task)))
    early = {cp.plan.id: cp.classification.makespan[0] for cp, _ in records
             if cp.classification.makespan is not None}
    top = max(early.values())
    tied = sorted(pid for pid, ms in early.items() if ms == top)
    assert len(tied) > 1, tied  # else this test could not fail
    for seed in range(4):
        random.Random(seed).shuffle(records)
        (tmp_path / str(seed)).mkdir()
        sink = PlanSink(task, tmp_path / str(seed), "none", keep=5)
        for cp, tail in records:
            sink.add(cp, tail)
        assert sink.finish(0, full.paths, full.options).summary.slowest == (top, tied[0])


def test_a_plan_code_gives_back_its_plan_and_family():
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    widths = set()
    for family in plan_families(task):
        for plan in family:
            code = plan_code(task, plan)
            widths.add(len(code))
            assert plan_from_code(task, code) == plan
            assert family_of(task, plan) == family
    assert widths == {2 * (len(task.actions) + len(task.agents) - 1)}


# --- resuming an interrupted compile -------------------------------------------------------------------

def _interrupted(task, out, after, **kwargs):
    """`compile_stream` into `out`, interrupted once `after` progress lines about plans were given."""
    seen = []

    def progress(stage: str, done: int, total: int) -> None:
        if stage == "plans":
            seen.append(done)
            if len(seen) == after:
                raise KeyboardInterrupt

    out.mkdir()
    return compile_stream(task, out, count_plans(task), progress=progress, sample_seconds=0.0, **kwargs)


def _resumed(task, old, out, **kwargs):
    from hrc.compile.resume import read_resume

    rows = read_resume(old, task, 0, CompileOptions(), kwargs.get("stnu", "graphml"), False, kwargs.get("best"))
    out.mkdir()
    return compile_stream(task, out, count_plans(task), sample_seconds=0.0, resume=(old, rows), **kwargs)


@pytest.mark.parametrize(("stnu", "jobs", "best"), [("graphml", 1, None), ("archive", 2, None), ("graphml", 2, 1),
                                                    ("none", 1, 2)])
def test_a_resumed_compile_writes_what_an_uninterrupted_one_does(picks4, tmp_path, stnu, jobs, best):
    """Interrupted, then resumed (twice: the second resume goes on from a partial resumed output): the
    same files, byte for byte, and the same plans for the report as a compile never interrupted."""
    task = picks4[0]
    whole = tmp_path / "whole"
    whole.mkdir()
    want = compile_stream(task, whole, count_plans(task), jobs=jobs, stnu=stnu, best=best, keep=5,
                          sample_seconds=0.0)
    first = _interrupted(task, tmp_path / "first", 2, jobs=jobs, stnu=stnu, best=best, keep=5)
    assert first.partial and 0 < first.compiled < 120
    assert (tmp_path / "first" / "resume.npy").is_file()
    from hrc.compile.resume import read_resume

    rows = read_resume(tmp_path / "first", task, 0, CompileOptions(), stnu, False, best)
    second = _interrupted(task, tmp_path / "second", 3, jobs=jobs, stnu=stnu, best=best, keep=5,
                          resume=(tmp_path / "first", rows))
    assert second.partial and first.compiled < second.compiled < 120, (first.compiled, second.compiled)
    last = _resumed(task, tmp_path / "second", tmp_path / "last", jobs=jobs, stnu=stnu, best=best, keep=5)
    assert not last.partial and last.compiled == 120
    assert tree_bytes(tmp_path / "last") == tree_bytes(whole)
    assert last.plan_set.plans == want.plan_set.plans and last.plan_set.summary == want.plan_set.summary


def test_a_family_taken_in_part_is_completed_on_resume(picks4, tmp_path):
    """Interrupted between two plans of one family (pick_a and pick_f swapped), the resumed run compiles
    that family again and takes only its missing plan."""
    from hrc.compile.compiler import rank_key
    from hrc.compile.output import write_input
    from hrc.compile.resume import read_resume
    from hrc.compile.stream import compile_records

    task, full, _ = picks4
    whole = tmp_path / "whole"
    whole.mkdir()
    compile_stream(task, whole, count_plans(task), jobs=1, sample_seconds=0.0)
    old = tmp_path / "old"
    old.mkdir()
    write_input(task, old)
    sink = PlanSink(task, old)
    families = [f for f in plan_families(task) if len(f) == 2][:3]
    compiled = compile_records(full.options, "graphml", task, full.paths, families)
    for cp, tail in compiled[:5]:  # two whole families and the first plan of the third
        sink.add(cp, tail)
    cp, tail = compiled[5]  # the sixth interrupted before its last append (an id the sink cannot take)
    with pytest.raises(UnicodeEncodeError):
        sink.add_record((rank_key(cp), "\u00e9" * 10, cp.plan_class.value, cp.graphml, tail, None,
                         plan_code(task, cp.plan), cp.form))
    sink.finish(0, full.paths, full.options, partial=120)
    data = json.loads((old / "compiled.json").read_text())
    assert len(data["plans"]) == 5 and len(list((old / "stnu").iterdir())) == 5
    rows = read_resume(old, task, 0, CompileOptions(), "graphml", False, None)
    assert len(rows) == 5
    new = tmp_path / "new"
    new.mkdir()
    compile_stream(task, new, count_plans(task), jobs=1, sample_seconds=0.0, resume=(old, rows))
    assert tree_bytes(new) == tree_bytes(whole)


def test_resume_refuses_what_it_cannot_go_on_with(picks4, tmp_path):
    from hrc.compile.resume import read_resume
    from hrc.errors import InputError

    task = picks4[0]
    whole = tmp_path / "whole"
    whole.mkdir()
    compile_stream(task, whole, count_plans(task), jobs=1, sample_seconds=0.0)
    with pytest.raises(InputError, match="complete, nothing to resume"):
        read_resume(whole, task, 0, CompileOptions(), "graphml", False, None)
    _interrupted(task, tmp_path / "part", 1, jobs=1)
    for args, words in [((1, CompileOptions(), "graphml", False, None), "seed"),
                        ((0, CompileOptions(rank_by="earliest"), "graphml", False, None), "options.rank_by"),
                        ((0, CompileOptions(), "archive", False, None), "stnu_files"),
                        ((0, CompileOptions(), "graphml", True, None), "identical_actions"),
                        ((0, CompileOptions(), "graphml", False, 1), "best_per_allocation")]:
        with pytest.raises(InputError, match=words):
            read_resume(tmp_path / "part", task, *args)
    other = pin_actions(task, {"pick_a": "robot"})
    with pytest.raises(InputError, match=r"task\.digest.*--pin differ"):
        read_resume(tmp_path / "part", other, 0, CompileOptions(), "graphml", False, None)
    rows = read_resume(tmp_path / "part", task, 0, CompileOptions(), "graphml", False, None)
    lines = (tmp_path / "part" / "compiled.json").read_text().split("\n")
    first = next(k for k, line in enumerate(lines) if line.startswith('{"id":'))
    (tmp_path / "part" / "compiled.json").write_text("\n".join(lines[:first] + lines[first + 1:]))
    with pytest.raises(InputError, match="is not in compiled.json"):
        compile_stream(task, tmp_path / "again", count_plans(task), jobs=1, sample_seconds=0.0,
                       resume=(tmp_path / "part", rows))
    (tmp_path / "part" / "resume.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match="resume.npy"):
        read_resume(tmp_path / "part", task, 0, CompileOptions(), "graphml", False, None)


def test_the_cli_resumes_and_refuses_with_one_line(picks4_file, picks4, tmp_path, capsys):
    from hrc.cli import main

    task = picks4[0]
    assert main(["compile", str(picks4_file), "--out", str(tmp_path / "whole"), "--jobs", "1", "-q"]) == 0
    _interrupted(task, tmp_path / "out", 2, jobs=1)
    before = tree_bytes(tmp_path / "out")
    for args, words in [(["--resume", "--seed", "3"], "seed"), (["--resume", "--stnu", "none"], "stnu_files")]:
        assert main(["compile", str(picks4_file), "--out", str(tmp_path / "out"), "-q", *args]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and words in err and "--resume" in err, err
    assert tree_bytes(tmp_path / "out") == before
    assert main(["compile", str(picks4_file), "--out", str(tmp_path / "nowhere"), "--resume", "-q"]) == 2
    assert "no such output folder" in capsys.readouterr().err and not (tmp_path / "nowhere").exists()
    assert main(["compile", str(picks4_file), "--out", str(tmp_path / "out"), "--resume", "--jobs", "1"]) == 0
    assert "resuming:" in capsys.readouterr().err
    assert tree_bytes(tmp_path / "out") == tree_bytes(tmp_path / "whole")  # the report too
    assert main(["compile", str(picks4_file), "--out", str(tmp_path / "out"), "--resume", "-q"]) == 2
    assert "complete, nothing to resume" in capsys.readouterr().err
