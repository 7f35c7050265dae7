"""`hrc simulate TASK.yaml --runs N --seed S [--policy P ...] [--out DIR]`: many simulated runs per policy.

Compiles the task (as `hrc compile`, seed ``--compile-seed``), runs ``--runs`` simulations per policy on
the same seeded people (`hrc.sim`), prints a table (per policy: deadline met, makespan median / p90,
idle times, robot yield time, standoffs per run and time spent making room (robot / person), closest
approach, plan switches, the dispatcher's latency p99, unfinished runs) and writes ``simulation.json``
(deterministic for a seed) and ``figures/`` into the output folder, atomically. A progress bar on a
terminal. ``--record DIR`` also writes each run (or the first ``--record-runs N`` of each policy) as an
MCAP file for Foxglove (docs/record.md). See docs/simulate.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from hrc.cli.argtypes import delay_range, whole
from hrc.cli.compile import _Progress, _stated_sensing
from hrc.errors import InputError, SimulationError
from hrc.io.atomic import atomic_dir
from hrc.io.task_file import load_task

__all__ = ["add_parser", "format_detection", "format_joint", "format_on_demand", "format_promise", "format_ssm",
           "format_table", "format_team", "run"]

POLICY_NAMES = ("hrc", "motion-blind", "feasible-only", "fixed")  # hrc.sim.policies.POLICIES, not imported here


def add_parser(sub: Any) -> None:
    p = sub.add_parser("simulate", help="simulate a person and the robot carrying out a task, many times over")
    p.add_argument("task", help="task YAML file")
    p.add_argument("--runs", type=int, default=100, help="runs per policy (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated people (default 0)")
    p.add_argument("--policy", action="append", metavar="NAME", default=None,
                   help=f"a policy to run (repeat or comma-separate; default all: {', '.join(POLICY_NAMES)})")
    p.add_argument("--out", default=None, help="output folder (default: out/TASK_NAME-simulation)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: one per core; 1 = serial)")
    p.add_argument("--executor", default=None, metavar="URL",
                   help="run on a Dask scheduler instead, e.g. dask://127.0.0.1:8786")
    p.add_argument("--compile-seed", type=int, default=0, help="seed for motion planning (default 0)")
    p.add_argument("--max-plans", type=whole(1), default=None, metavar="N",
                   help="beyond N plans compile the best plans by search and compile on demand in the runs, as "
                        "hrc compile --plans auto (default 50,000)")
    g = p.add_argument_group("the simulated person")
    g.add_argument("--human", choices=("follow", "preferred", "free"), default="follow",
                   help="how the person chooses the next action (default: follow the robot's current plan)")
    g.add_argument("--prefer", default="", metavar="A,B,...", help="preferred order of actions for --human preferred")
    g.add_argument("--durations", choices=("triangular", "uniform"), default="triangular",
                   help="distribution of manipulation durations inside their bounds (default triangular)")
    g.add_argument("--overrun-rate", type=float, default=0.0, help="probability a manipulation overruns its bound")
    g.add_argument("--overrun-max", type=float, default=0.5, help="overrun of up to this fraction of the bound")
    g.add_argument("--absence-rate", type=float, default=0.0, help="probability each person leaves once in a run")
    g.add_argument("--absence-seconds", type=float, nargs=2, default=(10.0, 30.0), metavar=("LO", "HI"),
                   help="how long an absence lasts (uniform, default 10 30)")
    g.add_argument("--leave-for-good-rate", type=float, default=0.0,
                   help="probability that an absence is for good")
    g.add_argument("--true-scale", type=float, default=1.0, metavar="F",
                   help="a hidden true duration model: the person's manipulation times lie on the task's bounds "
                        "times F (default 1: on the bounds), for measuring hrc learn (docs/learn.md)")
    g = p.add_argument_group("the floor and the detector")
    g.add_argument("--detector", choices=("buttons", "motion"), default="buttons",
                   help="buttons: the person's events reach the dispatcher (--detection-delay late); motion: their "
                        "tracked position goes to the motion detector (hrc.detect), its events to the dispatcher")
    g.add_argument("--detection-delay", type=float, default=0.0,
                   help="seconds before the buttons' events are reported (each message says so: its delay)")
    g.add_argument("--sensing", choices=("buttons", "motion"), default=None,
                   help="compile under this sensing path and its stated observation delay (buttons [0, 0.5] s, "
                        "motion 7 s dated; default: the task's sensing:), as the task's sensing: would; the "
                        "dispatcher reads a later observation as a deviation, and the report counts the promise")
    g.add_argument("--observation-delay", metavar="LO:HI", type=delay_range, default=None,
                   help="the stated observation delay in seconds (D, LO:HI), as hrc compile's; overrides the "
                        "task's sensing: or --sensing (its path kept)")
    g.add_argument("--sensor-sigma", type=float, default=0.05, metavar="M",
                   help="--detector motion: the tracker's position noise, m per axis (default 0.05)")
    g.add_argument("--sensor-rate", type=float, default=10.0, metavar="HZ",
                   help="--detector motion: positions per second (default 10)")
    g.add_argument("--sensor-dropout", type=float, default=0.0, metavar="P",
                   help="--detector motion: probability a position is lost (default 0)")
    g.add_argument("--sensor-latency", type=float, default=0.0, metavar="S",
                   help="--detector motion: seconds from measuring a position to delivering it (default 0)")
    g.add_argument("--baseline-delay", type=float, default=None, metavar="S",
                   help="--detector motion: the buttons' delay to compare with (default: the detector's median "
                        "detection delay)")
    g.add_argument("--slowdown", type=float, default=0.0,
                   help="m beyond the safety margin in which the robot slows down (default 0: stops at it)")
    g.add_argument("--tick", type=float, default=0.0,
                   help="report time passing to the dispatcher every S s while the robot waits (default 0: no)")
    p.add_argument("--keep-logs", action="store_true",
                   help="also keep each run's observations and answers as a dispatcher log, runs/POLICY-NNNN.jsonl "
                        "in the output folder (what hrc learn reads; simulation.json is the same either way)")
    p.add_argument("--no-figures", action="store_true", help="write simulation.json only")
    p.add_argument("--record", metavar="DIR", default=None,
                   help="also record runs as MCAP for Foxglove into DIR, one POLICY-NNNN.mcap per run (docs/record.md)")
    p.add_argument("--record-runs", type=int, default=None, metavar="N",
                   help="with --record: only the first N runs of each policy (default: all)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no table")
    p.set_defaults(run=run)


def _check_out(out: str) -> None:
    """The output folder is replaced whole: it must be new, empty, or an earlier simulation's output."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise InputError(out, "--out", "exists and is not a folder")
    if path.is_dir() and any(path.iterdir()) and not (path / "simulation.json").is_file():
        raise InputError(out, "--out", "refusing to replace a folder that is not empty and holds no "
                                       "simulation.json (not an earlier hrc simulate output)")


def _policies(values: list[str] | None) -> list[str]:
    if not values:
        return list(POLICY_NAMES)
    out = [v.strip() for value in values for v in value.split(",") if v.strip()]
    for name in out:
        if name not in POLICY_NAMES:
            raise SimulationError(f"unknown policy {name!r} (expected some of: {', '.join(POLICY_NAMES)})")
    return out


def format_table(sim: Any) -> str:
    """The terminal table: one row per policy (see the module docstring)."""
    from hrc.sim.metrics import aggregate, latency_p99

    head = ("policy", "deadline met", "makespan med", "p90", "human idle", "robot idle", "robot yield",
            "standoffs", "aside r/h", "min dist", "switches", "latency p99", "unfinished")
    rows = [head]
    for name in sim.policies:
        runs = sim.results[name]
        a = aggregate(runs)
        lat = latency_p99(runs)

        def s(x: float | None, unit: str = " s", fmt: str = "{:.1f}") -> str:
            return "-" if x is None else fmt.format(x) + unit

        rows.append((name, f"{100 * (a['deadline_met_rate'] or 0):.1f} %", s(a["makespan"]["median"]),
                     s(a["makespan"]["p90"]), s(a["human_idle_median"]), s(a["robot_idle_median"]),
                     s(a["robot_yield_mean"]), s(a["standoffs_mean"], "", "{:.2f}"),
                     f"{a['robot_aside_mean'] or 0:.1f}/{a['human_aside_mean'] or 0:.1f} s",
                     s(a["min_distance"], " m", "{:.2f}"),
                     s(a["plan_switches_mean"], "", "{:.2f}"), "-" if lat is None else f"{1000 * lat:.0f} ms",
                     f"{a['unfinished']}/{a['runs']}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True)))
             for r in rows]
    return "\n".join([lines[0], "  ".join("-" * w for w in widths), *lines[1:]])


def format_promise(sim: Any) -> str:
    """Under a stated sensing (issue 32): per policy, the runs on a plan DC at that sensing, with every
    observation within the stated delay, keeping every constraint; and the runs with a later observation.
    Empty when no delay was stated."""
    from hrc.sim.metrics import aggregate

    sensing = sim.context.task.sensing
    lines = []
    for name in sim.policies:
        p = aggregate(sim.results[name]).get("promise")
        if p is None:
            continue
        n = p["dc_at_sensing_within_delay"]
        lines.append(f"  {name}: {p['kept_every_constraint']}/{n} runs on a plan DC at the sensing, every observation "
                     f"within the delay, kept every constraint ({p['dc_at_sensing']} on such a plan); "
                     f"{p['runs_with_late_observations']}/{len(sim.results[name])} runs with an observation later "
                     f"than stated ({p['late_observations']} observations)")
    return "" if not lines else "\n".join([f"the promise under {sensing}:", *lines])


def format_detection(sim: Any) -> str:
    """With the motion detector: its measures per policy, and the comparison with buttons as late."""
    from hrc.sim.metrics import aggregate
    from hrc.sim.montecarlo import comparison

    s = sim.context.settings.sensor
    lines = [f"motion detector: sigma {s.sigma:g} m, {s.rate:g} Hz, {100 * s.dropout:g} % dropouts, "
             f"{s.latency:g} s latency; events matched within 1 s"]
    comp = comparison(sim)["policies"]
    for name in sim.policies:
        d = aggregate(sim.results[name]).get("detection")
        if d is None:
            continue
        lines.append(f"  {name}: precision {d['precision']:.4f}, recall {d['recall']:.4f}, delay median "
                     f"{d['delay_median']:.2f} s / p90 {d['delay_p90']:.2f} s, next action before arrival "
                     f"{100 * (d['next_before_arrival_rate'] or 0):.1f} % of {d['legs_walked']} legs (median "
                     f"{d['next_lead_median'] or 0:.1f} s ahead), refused {d['refused']}")
        if name in comp:
            m, b = comp[name]["motion"], comp[name]["buttons"]
            lines.append(f"    vs buttons {sim.baseline_delay:g} s late: makespan median {m['makespan_median']} / "
                         f"{b['makespan_median']} s, deadline met {m['deadline_met_rate']} / {b['deadline_met_rate']}, "
                         f"closest {m['min_distance']} / {b['min_distance']} m, DC promise kept {m['promise_kept']} / "
                         f"{b['promise_kept']} of the {m['first_plan_dc_kept']} / {b['first_plan_dc_kept']} runs "
                         f"that stayed on a DC first plan, unfinished {m['unfinished']} / {b['unfinished']}")
    return "\n".join(lines)


def format_ssm(sim: Any) -> str:
    """Under speed and separation monitoring: its counts per policy, the DC plans against their compiled
    worst case, and the motion-aware policy against the motion-blind one (`separation_summary`)."""
    from hrc.sim.metrics import aggregate
    from hrc.sim.montecarlo import separation_summary

    summary = separation_summary(sim)
    lines = ["speed and separation monitoring (ISO/TS 15066): protective stops per run median / mean, their "
             "time and the slowing's (mean), runs closer than S_p, closest robot driving / person walking up"]
    for name in sim.policies:
        m = aggregate(sim.results[name])["ssm"]
        p = summary["policies"][name]
        lines.append(f"  {name}: stops {m['protective_stops_median']:g} / {m['protective_stops_mean']:.2f} "
                     f"({m['runs_with_stops']} runs), {m['stop_time_mean']:.1f} s + {m['slow_time_mean']:.1f} s, "
                     f"closer than S_p in {m['runs_closer_than_separation']} runs, closest "
                     f"{m['min_free_robot_approaching']} / {m['min_free_person_approaching']} m; "
                     f"DC first plan kept in {p['dc_first_plan_kept']} runs, over its compiled worst case in "
                     f"{p['over_compiled_worst_case']}")
    h = summary.get("hrc_vs_motion_blind")
    if h is not None:
        lo, hi = h["faster_ci95"]
        lines.append(f"  hrc vs motion-blind: mean makespan {h['mean_makespan'][0]} / {h['mean_makespan'][1]} s over "
                     f"{h['runs']} runs both finished: {100 * h['faster']:.1f} % faster (95 % CI {100 * lo:.1f} to "
                     f"{100 * hi:.1f} %)")
    return "\n".join(lines)


def format_joint(sim: Any) -> list[str]:
    """A task with joint actions (issue 37): per policy, the joint starts the robot was told before the
    person had arrived (the target: none), the runs on a DC first plan that kept it and every constraint of
    its STNU, the closest approach outside the co-work at the joint spot, and the co-work's seconds."""
    from hrc.sim.metrics import aggregate

    lines = []
    for name in sim.policies:
        m = aggregate(sim.results[name])
        j = m.get("joint")
        if j is None:
            continue
        lines.append(f"joint actions ({name}): told to start {j['told_to_start']}, before its crew was there "
                     f"{j['told_before_arrival']} (in {j['runs_told_before_arrival']} runs); DC first plan "
                     f"{m['first_plan_dc']} runs, kept {m['first_plan_dc_kept']}, every constraint kept "
                     f"{m['first_plan_dc_kept_all_constraints']}; closest outside co-work {m['min_distance']} m, "
                     f"co-work {j['cowork_seconds_mean']} s per run")
    return lines


def format_team(sim: Any) -> list[str]:
    """A team's lines (issue 37): robot-robot contacts and the closest approach of every pair of agents."""
    from hrc.sim.metrics import aggregate

    lines = []
    for name in sim.policies:
        team = aggregate(sim.results[name]).get("team")
        if team is None:
            continue
        pairs = ", ".join(f"{p} {'-' if d is None else f'{d:.2f} m'}" for p, d in team["min_distance"].items())
        lines.append(f"team ({name}): robot-robot contacts {team['robot_contacts']} (in "
                     f"{team['runs_with_robot_contacts']} runs), person-person {team['people_contacts']}; "
                     f"closest per pair: {pairs}")
        if "ssm" in team:  # speed and separation monitoring, each robot's (the line above: all as one)
            lines.append(f"team ({name}) under SSM, per robot: " + ", ".join(
                f"{r} stops {m['protective_stops_median']:g} (median; {m['runs_with_stops']} runs), closer than "
                f"S_p in {m['runs_closer_than_separation']} runs, closest {m['min_free_robot_approaching']} / "
                f"{m['min_free_person_approaching']} m" for r, m in team["ssm"].items()))
    return lines


def format_on_demand(sim: Any) -> list[str]:
    """With a searched compile (a task beyond enumeration): compile on demand's misses, time to recover and
    the wall time of its compiles (excluded from the dispatcher's latency), per dispatched policy."""
    import numpy as np

    from hrc.sim.metrics import aggregate, latency_p99

    lines = []
    for name in sim.policies:
        runs = sim.results[name]
        m = aggregate(runs).get("on_demand")
        if m is None:
            continue
        walls = [x for r in runs for x in r.compile_seconds]
        lat = latency_p99(runs)
        wall = "no compiles" if not walls else (f"{len(walls)} compiles, wall median {np.median(walls):.2f} s, "
                                                f"max {max(walls):.2f} s")
        lines.append(f"compile on demand ({name}): {m['misses']} misses in {m['runs_with_misses']} of {len(runs)} "
                     f"runs, recovered after {m['recovery_median']} s median / {m['recovery_max']} s max run time, "
                     f"{m['unrecovered']} unrecovered; {wall} (not in the answers' latency: p99 "
                     f"{'-' if lat is None else f'{1000 * lat:.0f} ms'})")
    return lines


def run(args: argparse.Namespace) -> int:
    from hrc.sim.human import HumanModel, scaled_truth
    from hrc.sim.montecarlo import run_one, simulate, simulation_json
    from hrc.sim.run import SimSettings

    task = load_task(args.task)
    if args.sensing is not None:
        from dataclasses import replace

        from hrc.model import SENSING_PATHS, Sensing

        delay, dated = SENSING_PATHS[args.sensing]
        task = replace(task, sensing=Sensing(args.sensing, delay, dated))
    if args.observation_delay is not None:
        task = _stated_sensing(task, args.observation_delay)
    out = args.out or f"out/{task.name}-simulation"
    _check_out(out)
    if args.record_runs is not None and (args.record is None or not 1 <= args.record_runs):
        raise SimulationError("--record-runs needs --record DIR and a number of runs >= 1")
    if args.record is not None:
        from hrc.record.sim import check_record_folder

        check_record_folder(args.record, out)
    policies = _policies(args.policy)
    for name, value in (("--detection-delay", args.detection_delay), ("--slowdown", args.slowdown),
                        ("--tick", args.tick)):
        if not value >= 0:
            raise SimulationError(f"{name} must be a number >= 0, found {value:g}")
    from hrc.detect.sensor import SensorModel

    sensor = SensorModel(args.sensor_sigma, args.sensor_rate, args.sensor_dropout, args.sensor_latency)
    if args.detector != "motion" and args.baseline_delay is not None:
        raise SimulationError("--baseline-delay needs --detector motion")
    human = HumanModel(choice=args.human, preferred=tuple(a for a in args.prefer.split(",") if a),
                       durations=args.durations, overrun_rate=args.overrun_rate, overrun_max=args.overrun_max,
                       absence_rate=args.absence_rate, absence_seconds=tuple(args.absence_seconds),
                       leave_for_good_rate=args.leave_for_good_rate,
                       truth=() if args.true_scale == 1.0 else scaled_truth(task, args.true_scale))
    settings = SimSettings(human=human, detection_delay=args.detection_delay, slowdown=args.slowdown,
                           tick=args.tick, detector=args.detector, sensor=sensor)
    bar = _Progress(tty=sys.stderr.isatty(), quiet=args.quiet)
    t0 = time.perf_counter()
    try:
        sim = simulate(task, args.runs, args.seed, policies, settings, jobs=args.jobs, executor=args.executor,
                       progress=bar, compile_seed=args.compile_seed, baseline=args.baseline_delay,
                       keep_logs=args.keep_logs, max_plans=args.max_plans)
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0
    with atomic_dir(out) as stage:
        (stage / "simulation.json").write_text(simulation_json(sim), encoding="utf-8")
        if sim.logs is not None:
            from hrc.sim.runlog import log_name

            (stage / "runs").mkdir()
            for policy, logs in sorted(sim.logs.items()):
                for index, data in sorted(logs.items()):
                    (stage / "runs" / log_name(policy, index)).write_bytes(data)
        if not args.no_figures:
            from hrc.report.simulation import write_simulation_figures

            if not args.quiet:
                print(f"figures: one recorded run per policy into {out}/figures/ ...", file=sys.stderr, flush=True)
            featured = {p: run_one(sim.context, p, 0, record=True) for p in sim.policies}
            write_simulation_figures(sim, featured, stage)
    if not args.quiet:
        print(f"simulated {args.runs} runs x {len(sim.policies)} policies of {task.name} in {elapsed:.1f} s "
              f"(seed {args.seed}, person: {human.choice})")
        print(format_table(sim))
        promise = format_promise(sim)
        if promise:
            print(promise)
        if sim.baseline is not None:
            print(format_detection(sim))
        if task.safety is not None:
            print(format_ssm(sim))
        for line in format_on_demand(sim) + format_joint(sim) + format_team(sim):
            print(line)
        print(f"wrote {out}/simulation.json" + ("" if args.no_figures else f", {out}/figures/")
              + ("" if sim.logs is None else f", {out}/runs/ (one dispatcher log per run)"))
    if args.record is not None:
        from hrc.record.sim import write_recordings

        n = min(args.runs, args.record_runs or args.runs)
        t1 = time.perf_counter()
        size = write_recordings(sim.context, sim.policies, n, args.record, jobs=args.jobs, executor=args.executor)
        if not args.quiet:
            print(f"recorded {n} runs x {len(sim.policies)} policies into {args.record}/ "
                  f"({size / 1e6:.1f} MB, {time.perf_counter() - t1:.1f} s)")
    return 0
