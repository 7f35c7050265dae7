"""Aggregate measures over many runs of one policy: what `hrc simulate` prints and writes.

Per policy, over its runs (`RunResult`): deadline met (% of all runs; an unfinished run misses it),
every task limit met (deadline and temporal constraints), makespan median / p90 / mean over finished
runs, median idle time of each agent, mean robot yield time (seconds the robot was slowed or stopped by
the person), standoffs (runs with one, resolutions per run) and the mean time each agent spent making
room, the smallest human-robot free distance of all runs and its median per run, disc overlaps
(pymunk contacts; 0 expected), mean plan switches, unfinished runs, runs whose first plan the compile
found blocked (no passing order; `RunResult.first_blocked`), and the check of the guarantee:
among runs whose first plan was DC and carried out as planned, how many kept every constraint of that
plan; with the motion detector, its own measures (``detection``: `hrc.sim.detection.aggregate_detection`).
Percentiles use numpy's linear interpolation. Wall-clock latencies of the dispatcher are measured
too (`latency_p99`), but kept out of `simulation.json`, which is deterministic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hrc.sim.detection import aggregate_detection
from hrc.sim.run import RunResult

__all__ = ["aggregate", "latency_p99"]


def _r(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), 3)


def _pct(values: Sequence[float], q: float) -> float | None:
    return _r(float(np.percentile(values, q))) if values else None


def aggregate(runs: Sequence[RunResult]) -> dict:
    """The policy's aggregate measures (JSON-ready, rounded to the millisecond)."""
    n = len(runs)
    done = [r for r in runs if r.finished]
    spans = [r.makespan for r in done if r.makespan is not None]
    mins = [r.min_distance for r in runs if r.min_distance is not None]
    dc = [r for r in runs if r.first_class == "DC"]
    dc_kept = [r for r in dc if r.first_kept]
    reasons: dict[str, int] = {}
    for r in runs:
        if not r.finished:
            key = r.reason.split(":", 1)[0]
            reasons[key] = reasons.get(key, 0) + 1
    return {
        "runs": n,
        "deadline_met": sum(r.deadline_met for r in runs),
        "deadline_met_rate": _r(sum(r.deadline_met for r in runs) / n) if n else None,
        "limits_met_rate": _r(sum(r.limits_met for r in runs) / n) if n else None,
        "makespan": {"median": _pct(spans, 50), "p90": _pct(spans, 90), "mean": _r(float(np.mean(spans)))
                     if spans else None, "min": _r(min(spans)) if spans else None,
                     "max": _r(max(spans)) if spans else None},
        "human_idle_median": _pct([r.human_idle for r in done], 50),
        "robot_idle_median": _pct([r.robot_idle for r in done], 50),
        "robot_yield_mean": _r(float(np.mean([r.robot_yield for r in runs]))) if runs else None,
        "human_held_mean": _r(float(np.mean([r.human_held for r in runs]))) if runs else None,
        "standoff_runs": sum(1 for r in runs if r.standoffs),
        "standoffs_mean": _r(float(np.mean([r.standoffs for r in runs]))) if runs else None,
        "robot_aside_mean": _r(float(np.mean([r.robot_aside for r in runs]))) if runs else None,
        "human_aside_mean": _r(float(np.mean([r.human_aside for r in runs]))) if runs else None,
        "min_distance": _r(min(mins)) if mins else None,
        "min_distance_median": _pct(mins, 50),
        "overlaps": sum(r.overlaps for r in runs),
        "plan_switches_mean": _r(float(np.mean([r.plan_switches for r in runs]))) if runs else None,
        "unfinished": n - len(done),
        "unfinished_reasons": dict(sorted(reasons.items())),
        "refused_observations": sum(len(r.refused) for r in runs),
        "late_robot_events": sum(r.late for r in runs),
        "robot_travel_excess_mean": _r(float(np.mean([r.robot_travel_excess for r in runs]))) if runs else None,
        "first_plan_blocked": sum(r.first_blocked for r in runs),
        "first_plan_dc": len(dc),
        "first_plan_dc_kept": len(dc_kept),
        "first_plan_dc_kept_all_constraints": sum(1 for r in dc_kept if not r.first_broken),
        **_promise(runs),
        **_detection(runs),
        **_ssm(runs),
        **_on_demand(runs),
        **_joint(runs),
        **_team(runs),
    }


def _team(runs: Sequence[RunResult]) -> dict:
    """A team's (issue 37): robot-robot contacts (pymunk, over all runs; 0 expected) and the runs with one,
    person-person contacts (people are not kept apart by the floor), and per pair of agents the smallest
    free distance of all runs (`min_distance` above is the smallest of the robot-person pairs)."""
    found = [r.team for r in runs if r.team is not None]
    if not found:
        return {}
    pairs: dict[str, list[float]] = {}
    for t in found:
        for pair, d in t["min_distance"].items():
            if d is not None:
                pairs.setdefault(pair, []).append(d)
    out = {"robot_contacts": sum(t["robot_contacts"] for t in found),
           "runs_with_robot_contacts": sum(1 for t in found if t["robot_contacts"]),
           "people_contacts": sum(t["people_contacts"] for t in found),
           "min_distance": {pair: _r(min(ds)) for pair, ds in pairs.items()}}
    if "ssm" in found[0]:  # under speed and separation monitoring: each robot's (`_ssm`: all of them as one)
        out["ssm"] = {robot: _robot_ssm([t["ssm"][robot] for t in found]) for robot in found[0]["ssm"]}
    return {"team": out}


def _robot_ssm(runs: list[dict]) -> dict:
    """One robot of a team under speed and separation monitoring, over the runs (its `SsmMeasures.to_json`
    in each): protective stops (median, runs with one), runs closer than S_p, its closest approaches."""
    def least(key: str) -> float | None:
        found = [m[key] for m in runs if m[key] is not None]
        return min(found) if found else None

    stops = [m["protective_stops"] for m in runs]
    return {"protective_stops_median": _pct(stops, 50), "runs_with_stops": sum(1 for n in stops if n),
            "runs_closer_than_separation": sum(1 for m in runs if m["breaches"]),
            "min_free_robot_approaching": least("min_free_robot_approaching"),
            "min_free_person_approaching": least("min_free_person_approaching")}


def _joint(runs: Sequence[RunResult]) -> dict:
    """A task with joint actions (issue 37): the runs in which the robot was told to start a joint phase
    before the person had arrived there (the target: none), how often, and the co-work at the joint spots
    (seconds per run: the time `min_distance` and `overlaps` leave out, docs/simulate.md)."""
    found = [r.joint for r in runs if r.joint is not None]
    if not found:
        return {}
    return {"joint": {"told_to_start": sum(j["told_to_start"] for j in found),
                      "told_before_arrival": sum(j["told_before_arrival"] for j in found),
                      "runs_told_before_arrival": sum(1 for j in found if j["told_before_arrival"]),
                      "cowork_seconds_mean": _r(float(np.mean([j["cowork_seconds"] for j in found])))}}


def _promise(runs: Sequence[RunResult]) -> dict:
    """Issue 32's measure, when the dispatcher was given a maximum observation delay (the compile's
    sensing): runs with an observation later than it (the guarantee void, and said so: the answers'
    `deviation`) and how many there were; runs on a plan DC at the compile's sensing (the first plan, kept
    to the end); of those, with every observation within the delay; of those, keeping every constraint of
    the plan's STNU (`first_broken` empty: the promise kept)."""
    stated = [r for r in runs if r.late_observations is not None]
    if not stated:
        return {}
    on_dc = [r for r in stated if r.first_sensing_class == "DC" and r.first_kept]
    within = [r for r in on_dc if r.late_observations == 0]
    return {"promise": {"runs_with_late_observations": sum(1 for r in stated if r.late_observations),
                        "late_observations": sum(r.late_observations or 0 for r in stated),
                        "dc_at_sensing": len(on_dc), "dc_at_sensing_within_delay": len(within),
                        "kept_every_constraint": sum(1 for r in within if not r.first_broken)}}


def _on_demand(runs: Sequence[RunResult]) -> dict:
    """Compile on demand's measures (`hrc.sim.on_demand`), for a searched compile only: the misses (answers
    that fell back to the safe fallback after a plan), the runs with one, the time to recover (run seconds
    from a miss to an answer from a plan again: median, p90, max) and the misses never recovered."""
    found = [r.on_demand for r in runs if r.on_demand is not None]
    if not found:
        return {}
    recovery = [x for m in found for x in m["recovery"]]
    return {"on_demand": {
        "misses": sum(m["misses"] for m in found), "runs_with_misses": sum(1 for m in found if m["misses"]),
        "misses_mean": _r(float(np.mean([m["misses"] for m in found]))),
        "recovery_median": _pct(recovery, 50), "recovery_p90": _pct(recovery, 90),
        "recovery_max": _r(max(recovery)) if recovery else None,
        "unrecovered": sum(1 for m in found if m["unrecovered"]),
        "plans_adopted": sum(m["plans_adopted"] for m in found)}}


def _ssm(runs: Sequence[RunResult]) -> dict:
    """Speed and separation monitoring's measures (`hrc.sim.ssm`), for a task with `safety:` only: protective
    stops per run (median, mean), the seconds they and the slowing cost (mean), the runs in which the robot
    drove closer than the protective separation at its speed (0 expected), and the smallest free distance
    while the robot drove towards the person and while the person walked up to the standing robot."""
    found = [r.ssm for r in runs if r.ssm is not None]
    if not found:
        return {}
    stops = [m.protective_stops for m in found]
    robot = [m.min_free_robot_approaching for m in found if m.min_free_robot_approaching is not None]
    person = [m.min_free_person_approaching for m in found if m.min_free_person_approaching is not None]
    return {"ssm": {
        "protective_stops_median": _pct(stops, 50), "protective_stops_mean": _r(float(np.mean(stops))),
        "runs_with_stops": sum(1 for n in stops if n),
        "stop_time_mean": _r(float(np.mean([m.stop_time for m in found]))),
        "slow_time_mean": _r(float(np.mean([m.slow_time for m in found]))),
        "runs_closer_than_separation": sum(1 for m in found if m.breaches),
        "min_free_robot_approaching": _r(min(robot)) if robot else None,
        "min_free_person_approaching": _r(min(person)) if person else None}}


def _detection(runs: Sequence[RunResult]) -> dict:
    """The motion detector's measures (`hrc.sim.detection`), when it was used (a buttons run has none)."""
    found = aggregate_detection([r.detection for r in runs])
    return {} if found is None else {"detection": found}


def latency_p99(runs: Sequence[RunResult]) -> float | None:
    """The 99th percentile (s) of the dispatcher's wall time per observation over `runs` (None: none)."""
    values = [x for r in runs for x in r.latencies]
    return float(np.percentile(values, 99)) if values else None
