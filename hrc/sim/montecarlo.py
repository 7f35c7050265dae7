"""Many simulated runs per policy on the same seeded people: `simulate` and ``simulation.json``.

`simulate` compiles the task once (motion-aware, `hrc.compile.compiler.compile_task`, or for a task
beyond ``hrc compile``'s ``--max-plans`` the search compile, whose dispatcher then compiles on demand:
`hrc.sim.on_demand`; and motion-blind, `hrc.sim.blind`, if that policy is asked for), then runs
``runs`` simulations per policy: run ``i`` of
every policy has the same person (`hrc.sim.human.draw_human` from ``(seed, i)``). Runs go to an executor
as `hrc compile`'s plans do (`hrc.compile.executors`: serial, a local process pool with ``jobs``, or
Dask), in chunks of one policy; the result does not depend on the executor or the order in which chunks
finish (runs are sorted by policy, then index), so the same seed gives the same ``simulation.json``
bytes. Cost: one compile plus O(runs x policies) runs (about 0.05-0.3 s each on the workshop, most of it
the dispatcher).

``simulation.json`` (schema version 1; times s, distances m, rounded to the millisecond)::

    {"schema_version": 1, "generator": "hrc X.Y.Z",
     "task": {"name", "digest", "deadline"}, "seed": S, "compile_seed": C, "runs": N,
     "settings": {"human": {...HumanModel}, "detection_delay", "slowdown", "tick", "stall", "time_cap"
                  [, "detector": "motion", "sensor": {...SensorModel}]},
     "policies": {NAME: {"description": str, "compile": {"DC": n, "consistent": n, "inconsistent": n},
                         "best_plan": {"id", "class", "makespan": [earliest, worst]},
                         "aggregate": {...hrc.sim.metrics.aggregate},
                         "runs": [{...RunResult.to_json}]}},
     ["comparison": {"buttons_delay": s, "policies": {NAME: {"motion": {...}, "buttons": {...}}}}]}

A team's (issue 37: other than one person and one robot; `run_one` runs it in `hrc.sim.team_run`) runs have
``team`` (per agent, per pair; with `safety:`, ``team.ssm`` per robot) and its aggregate ``team``; a task of
one person and one robot has neither.
With ``--detector motion`` each dispatched policy's aggregate has ``detection``
(`hrc.sim.detection.aggregate_detection`) and each run ``detection``; ``comparison`` holds the same
policies with buttons as late as the detector's median delay, on the same seeds (`comparison`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from hrc import __version__
from hrc.compile.compiler import CompiledPlanSet, compile_task
from hrc.compile.executors import make_executor
from hrc.errors import SimulationError
from hrc.model import Task
from hrc.sim.compile_cache import kept_compile
from hrc.sim.metrics import aggregate
from hrc.sim.policies import POLICIES
from hrc.sim.run import RunResult, SimContext, SimSettings, simulate_run
from hrc.sim.team_floor import is_team

__all__ = ["Simulation", "baseline_delay", "check_policies", "comparison", "run_one", "separation_summary",
           "simulate", "simulation_json"]

Progress = Callable[[str, int, int], None]
CHUNK = 10


@dataclass(frozen=True, slots=True)
class Simulation:
    """Every run of every policy (`results[policy]` in run order), and what they ran on; with the motion
    detector, the dispatched policies' runs with buttons `baseline_delay` seconds late on the same seeds
    (`baseline`), to compare with."""

    context: SimContext
    runs: int
    policies: tuple[str, ...]
    results: dict[str, tuple[RunResult, ...]]
    compile_seed: int = 0
    baseline: dict[str, tuple[RunResult, ...]] | None = None  # with the motion detector: buttons, same seeds
    baseline_delay: float | None = None
    logs: dict[str, dict[int, bytes]] | None = None  # keep_logs: each run's dispatcher log (hrc.sim.runlog)


def _run_all(ctx: SimContext, chosen: Sequence[str], runs: int, executor: str | None, jobs: int | None,
             progress: Progress | None, label: str, logs: dict[str, dict[int, bytes]] | None = None
             ) -> dict[str, tuple[RunResult, ...]]:
    """Every run of every chosen policy; with `logs` (a dict to fill), each run's dispatcher log too."""
    results: dict[str, list[RunResult]] = {p: [] for p in chosen}
    total = runs * len(chosen)
    done = 0
    with make_executor(executor, jobs) as ex:
        for batch in ex.map_chunks(_chunk, ctx, logs is not None, _work(chosen, runs)):
            for r, log in batch:
                results[r.policy].append(r)
                if logs is not None and log is not None:
                    logs.setdefault(r.policy, {})[r.run] = log
            done += len(batch)
            if progress:
                progress(label, done, total)
    return {p: tuple(sorted(rs, key=lambda r: r.run)) for p, rs in results.items()}


def baseline_delay(results: dict[str, tuple[RunResult, ...]]) -> float:
    """The buttons' delay to compare a motion detector with: its median detection delay (s, >= 0, to the
    10 ms) over every run of every policy."""
    delays = [x for rs in results.values() for r in rs if r.detection is not None for x in r.detection.delays]
    return max(0.0, round(float(np.median(delays)), 2)) if delays else 0.0


def _chunk(ctx: SimContext, keep_logs: object, work: list[tuple[str, int]]) -> list[tuple[RunResult, bytes | None]]:
    """The unit of work sent to an executor: some runs of one policy (module-level, so it pickles), each
    with its dispatcher log when `keep_logs` (`hrc.sim.runlog`: the same run, its exchanges caught)."""
    if not keep_logs:
        return [(run_one(ctx, policy, i), None) for policy, i in work]
    from hrc.sim.runlog import catching, log_bytes

    out: list[tuple[RunResult, bytes | None]] = []
    for policy, i in work:
        exchanges: list = []
        if is_team(ctx.task):  # issue 37: the team's loop, its controllers caught
            from hrc.sim.team_policies import make_team_controller
            from hrc.sim.team_run import simulate_team_run

            result = simulate_team_run(ctx, policy, i, controller=catching(exchanges, make_team_controller))
        else:
            result = simulate_run(ctx, policy, i, controller=catching(exchanges))
        out.append((result, log_bytes(ctx, POLICIES[policy], exchanges)))
    return out


def run_one(ctx: SimContext, policy: str, index: int, record: bool = False) -> RunResult:
    """Run `index` of `policy`: `hrc.sim.run.simulate_run` for one person and one robot, else the team loop
    (`hrc.sim.team_run.simulate_team_run`, issue 37)."""
    if ctx.cache.get("team") is None:
        ctx.cache["team"] = is_team(ctx.task)
    if ctx.cache["team"]:
        from hrc.sim.team_run import simulate_team_run

        return simulate_team_run(ctx, policy, index, record)
    return simulate_run(ctx, policy, index, record)


def _work(policies: Sequence[str], runs: int) -> Iterator[list[tuple[str, int]]]:
    for policy in policies:
        for start in range(0, runs, CHUNK):
            yield [(policy, i) for i in range(start, min(runs, start + CHUNK))]


def check_policies(names: Sequence[str]) -> tuple[str, ...]:
    """`names` in registry order, without repeats; raises `SimulationError` for an unknown one."""
    for n in names:
        if n not in POLICIES:
            raise SimulationError(f"unknown policy {n!r} (expected some of: {', '.join(POLICIES)})")
    return tuple(p for p in POLICIES if p in names)


def simulate(task: Task, runs: int, seed: int, policies: Sequence[str] = tuple(POLICIES),
             settings: SimSettings | None = None, jobs: int | None = None, executor: str | None = None,
             progress: Progress | None = None, compile_seed: int = 0,
             compiles: dict[str, CompiledPlanSet] | None = None, baseline: float | None = None,
             keep_logs: bool = False, max_plans: int | None = None) -> Simulation:
    """Compile (unless `compiles` are given) and run everything (see the module docstring). With the motion
    detector, the dispatched policies again with buttons `baseline` seconds late (default: the detector's
    median delay, `baseline_delay`) on the same seeds. `keep_logs`: each run's observations and answers as
    a dispatcher log too (`Simulation.logs`, for ``hrc learn``; the runs themselves are the same).
    `max_plans`: beyond this many plans the motion-aware compile is the search's (default
    `hrc.compile.estimate.DEFAULT_MAX_PLANS`, as ``hrc compile --plans auto``), compiling on demand in the
    runs, a team's too."""
    if runs < 1:
        raise SimulationError(f"--runs must be at least 1, found {runs}")
    chosen = check_policies(policies)
    settings = settings or SimSettings()
    joint = next((i for i, a in enumerate(task.actions) if a.joint), None)
    if joint is not None and settings.motion and not is_team(task):  # the one-pair loop: the detector would
        # find the person's start and end of each step (a team's loop gives a joint action's to its lead)
        raise SimulationError(f"{task.source}: actions[{joint}].roles: '{task.actions[joint].id}' is a joint action: "
                              f"--detector motion does not take joint actions yet (the robot starts and ends them)")
    settings.human.check(task)
    compiles = dict(compiles or {})
    if "motion" not in compiles:
        compiles["motion"] = _compile(task, compile_seed, jobs, executor, progress, max_plans)
    if "blind" not in compiles and any(POLICIES[p].compile == "blind" for p in chosen):
        from hrc.sim.blind import blind_compile

        compiles["blind"] = kept_compile("blind", task, compile_seed, executor, lambda: blind_compile(
            task, seed=compile_seed, jobs=jobs, executor=executor, progress=progress), progress)
    ctx = SimContext(task, compiles, settings, seed)
    logs: dict[str, dict[int, bytes]] | None = {} if keep_logs else None
    ordered = _run_all(ctx, chosen, runs, executor, jobs, progress, "runs", logs)
    if not settings.motion:
        return Simulation(ctx, runs, chosen, ordered, compile_seed, logs=logs)
    delay = baseline_delay(ordered) if baseline is None else baseline
    if not (delay >= 0 and math.isfinite(delay)):
        raise SimulationError(f"--baseline-delay must be a finite number >= 0, found {delay:g}")
    dispatched = [p for p in chosen if POLICIES[p].dispatched]
    buttons = SimContext(task, compiles, replace(settings, detector="buttons", detection_delay=delay), seed)
    base = _run_all(buttons, dispatched, runs, executor, jobs, progress, "buttons") if dispatched else {}
    return Simulation(ctx, runs, chosen, ordered, compile_seed, base, delay, logs)


def _compile(task: Task, seed: int, jobs: int | None, executor: str | None, progress: Progress | None,
             max_plans: int | None = None) -> CompiledPlanSet:
    """The motion-aware compile: every plan, or beyond `hrc.compile.estimate.DEFAULT_MAX_PLANS` (as ``hrc
    compile --plans auto``) the search's best plans and coverage of the person's first choices, the
    dispatcher compiling on demand what a run needs beyond them (`hrc.dispatch.on_demand`)."""
    from hrc.compile.estimate import DEFAULT_MAX_PLANS, estimate

    limit = DEFAULT_MAX_PLANS if max_plans is None else max_plans
    if estimate(task).plans.value <= limit:  # a small one kept on disk (`hrc.sim.compile_cache`)
        return kept_compile("motion", task, seed, executor, lambda: compile_task(
            task, seed=seed, jobs=jobs, executor=executor, progress=progress), progress)
    from hrc.compile.search import search_in_memory

    return search_in_memory(task, seed=seed)


def _outcome(runs: Sequence[RunResult]) -> dict:
    a = aggregate(runs)
    return {"deadline_met_rate": a["deadline_met_rate"], "makespan_median": a["makespan"]["median"],
            "makespan_p90": a["makespan"]["p90"], "min_distance": a["min_distance"],
            "first_plan_dc": a["first_plan_dc"], "first_plan_dc_kept": a["first_plan_dc_kept"],
            "promise_kept": a["first_plan_dc_kept_all_constraints"],
            "unfinished": a["unfinished"], "refused_observations": a["refused_observations"]}


def comparison(sim: Simulation) -> dict:
    """The motion detector against buttons `baseline_delay` late, per dispatched policy, on the same seeds:
    deadline met, makespan, closest approach, the DC promise kept (runs whose first plan was DC and kept
    every constraint of its STNU, of those that stayed on it: ``first_plan_dc_kept``), unfinished runs."""
    assert sim.baseline is not None
    return {"buttons_delay": sim.baseline_delay,
            "policies": {name: {"motion": _outcome(sim.results[name]), "buttons": _outcome(runs)}
                         for name, runs in sim.baseline.items()}}


BOOTSTRAP = 2000
"""Resamples of the paired bootstrap in `separation_summary` (seeded: the same simulation, the same bytes)."""


def _slowest(task: Task, cps: CompiledPlanSet, ids: set[str | None]) -> dict[str, float]:
    """The compiled plans `ids`' worst cases with every agent at its slowest (`slowest_makespan`: the human's
    durations and the robots' at their maxima), read from each plan's STNU; a plan whose network does not
    fit then keeps its ``makespan[1]``."""
    from hrc.compile.classify import slowest_makespan
    from hrc.temporal.graphml import read_graphml

    agents, robots = [a.id for a in task.agents], frozenset(a.id for a in task.agents if not a.is_human)
    out = {}
    for cp in cps.plans:
        if cp.plan.id in ids and cp.classification.makespan is not None:
            got = slowest_makespan(read_graphml(cp.graphml.encode()), agents, robots) if cp.graphml else None
            out[cp.plan.id] = cp.classification.makespan[1] if got is None else max(got, cp.classification.makespan[1])
    return out


def separation_summary(sim: Simulation) -> dict:
    """Under speed and separation monitoring (a task with `safety:`), per policy: the runs whose first plan
    was DC and which stayed on it, and how many of those finished later than that plan's compiled
    worst case with every agent at its slowest (`_slowest`: 0 expected, the compile assumed the
    controller's rule; the compile's ``makespan[1]`` takes the robots at their quickest, and a robot draws
    its durations within its bounds); and the hypothesis, the
    motion-aware policy (``hrc``) against ``motion-blind`` on the same seeds: the relative difference of
    their mean makespans over the runs both finished, with a 95 % paired bootstrap interval (percentile
    method, Efron & Tibshirani 1993, ch. 13; `BOOTSTRAP` resamples, seed 0)."""
    out: dict = {"policies": {}}
    for name in sim.policies:
        cps = sim.context.compiles[POLICIES[name].compile]
        kept = [r for r in sim.results[name] if r.first_class == "DC" and r.first_kept and r.makespan is not None]
        worst = _slowest(sim.context.task, cps, {r.first_plan for r in kept})
        over = [r for r in kept if r.first_plan in worst and r.makespan is not None
                and r.makespan > worst[r.first_plan] + 1e-3]
        out["policies"][name] = {"dc_first_plan_kept": len(kept), "over_compiled_worst_case": len(over)}
    if "hrc" in sim.results and "motion-blind" in sim.results:
        pairs = [(a.makespan, b.makespan) for a, b in zip(sim.results["hrc"], sim.results["motion-blind"], strict=True)
                 if a.makespan is not None and b.makespan is not None]
        if pairs:
            arr = np.asarray(pairs, dtype=float)
            gain = 1 - arr[:, 0].mean() / arr[:, 1].mean()
            rng = np.random.default_rng(0)
            idx = rng.integers(0, len(arr), size=(BOOTSTRAP, len(arr)))
            boot = 1 - arr[idx, 0].mean(axis=1) / arr[idx, 1].mean(axis=1)
            lo, hi = np.percentile(boot, [2.5, 97.5])
            out["hrc_vs_motion_blind"] = {"runs": len(arr), "mean_makespan": [round(float(arr[:, 0].mean()), 3),
                                                                               round(float(arr[:, 1].mean()), 3)],
                                          "faster": round(float(gain), 4),
                                          "faster_ci95": [round(float(lo), 4), round(float(hi), 4)]}
    return out


def simulation_json(sim: Simulation) -> str:
    """``simulation.json``'s text (see the module docstring): the same simulation, the same bytes."""
    ctx = sim.context
    task = ctx.task
    policies = {}
    for name in sim.policies:
        cps = ctx.compiles[POLICIES[name].compile]
        best = cps.plans[0] if cps.plans else None
        ms = best.classification.makespan if best is not None else None
        policies[name] = {
            "description": POLICIES[name].description,
            "compile": cps.counts(),
            "best_plan": None if best is None else {"id": best.plan.id, "class": best.plan_class.value,
                                                    "makespan": None if ms is None else [round(x, 3) for x in ms]},
            "aggregate": aggregate(sim.results[name]),
            "runs": [r.to_json() for r in sim.results[name]],
        }
    doc = {"schema_version": 1, "generator": f"hrc {__version__}",
           "task": {"name": task.name, "digest": ctx.compiles["motion"].digest, "deadline": task.deadline},
           "seed": ctx.seed, "compile_seed": sim.compile_seed, "runs": sim.runs,
           "settings": ctx.settings.to_json(), "policies": policies}
    if sim.baseline is not None:
        doc["comparison"] = comparison(sim)
    if task.safety is not None:  # a task without safety: keeps its file as it was
        doc["separation"] = separation_summary(sim)
    return json.dumps(doc, indent=1, ensure_ascii=False) + "\n"
