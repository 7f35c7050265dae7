"""How often a person who follows the first plan keeps its promise (issue 32): buttons on time, or an
outside driver seen by the motion detector.

    PYTHONPATH=. .venv/bin/python scripts/measure_promise.py OUT_DIR [--seeds 20] [--robot anywhere|near|earliest]
    PYTHONPATH=. .venv/bin/python scripts/measure_promise.py OUT_DIR --detect motion \\
        [--sensor-sigma 0.05 --sensor-rate 10 --sensor-dropout 0 --sensor-latency 0]
        [--sensing motion | --observation-delay LO:HI]
    PYTHONPATH=. .venv/bin/python scripts/measure_promise.py OUT_DIR --buttons-late 0.5 [--buttons-uniform] [--tick 0.5]

OUT_DIR is an `hrc compile` output. Each seed plays one run through `hrc.dispatch.protocol.handle_line`:

- buttons (default): the independent client of tests/dispatch_client.py, the person following the first
  answer's plan, announcing each next action (``next``) and obeying every hint, their events sent on
  time; a run keeps the promise when every answer is DC, the final plan gives the person the first
  plan's actions in its order, and every link of its STNU holds on the times that happened;
- ``--detect motion``: the outside driver of tests/detect_client.py, which walks the person's planned
  routes and sends only their tracked position (`hrc.detect.sensor`'s noise, rate and dropouts) to the
  dispatcher `hrc dispatch --detect motion` serves (`DetectingDispatcher`, the detector assuming the
  sensor's sigma), reading the answers alone. A run keeps the
  promise when its first plan is classed DC at the compile's sensing, every observation arrived within
  the stated delay (no answer with a ``deviation``), and every link of the final plan's STNU holds on the
  true times. The same seeds are played with buttons on time for the makespan to compare with;
- ``--buttons-late D``: the same outside driver's person (`PressingRun`), heard through buttons instead:
  each of their events pressed D seconds after it truly happened (``--buttons-uniform``: a delay drawn
  uniformly in [0, D]), saying its delay, the next action announced on each end, a tick every ``--tick``
  seconds; judged as the motion path (compile with the matching stated delay, ``sensing: buttons``).

Either way the robot acts anywhere in its windows (``--robot near``: within 2 s of each opening;
``earliest``: at it, as `hrc simulate`'s robot).

The stated delay is the compile's sensing (``compiled.json``'s ``sensing``), or ``--sensing`` (the
path's delay, `hrc.model.SENSING_PATHS`) / ``--observation-delay LO:HI`` (its HI), as `hrc simulate`
takes them; the classes are always the compile's (compile under the sensing to judge at it).
Prints each run and the shares, and the makespan medians.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from dispatch_client import Outcome, Run, broken_links  # noqa: E402

from hrc.dispatch import Dispatcher  # noqa: E402
from hrc.dispatch.plan_set import PlanSet, load_plan_set  # noqa: E402
from hrc.dispatch.protocol import handle_line  # noqa: E402


@dataclass(frozen=True)
class Judged:
    """One run against its promise: the first plan and its class at the compile's sensing, the final plan,
    whether it keeps the first plan's part for the person, the links broken on the true times, answers
    with a late observation, answers not DC, refusals, the makespan (s, the last end)."""

    first: str
    first_class: str
    final: str
    same_part: bool
    broken: tuple[str, ...]
    late: int
    not_dc: int
    refused: int
    makespan: float

    @property
    def dc_within_delay(self) -> bool:
        return self.first_class == "DC" and self.late == 0

    @property
    def kept(self) -> bool:
        return self.dc_within_delay and not self.broken and not self.refused


def judge(plan_set: PlanSet, out: Outcome) -> Judged:
    first = plan_set.entry(plan_set.index(out.first["plan"]))
    final = plan_set.entry(plan_set.index(out.answers[-1]["plan"]))
    same = dict(final.plan.sequences)["human"] == dict(first.plan.sequences)["human"]
    return Judged(first.id, first.compiled_class, final.id, same, tuple(broken_links(final.stnu, out.times)),
                  sum(1 for a in out.answers if "late" in (a.get("deviation") or {})),
                  sum(1 for a in out.answers if a["class"] != "DC"), len(out.refused),
                  max((t for key, t in out.times.items() if key[3] == "end"), default=0.0))


def buttons_run(plan_set: PlanSet, base: Dispatcher, seed: int, robot: str) -> Outcome:
    d = base.fork()
    return Run(plan_set, lambda line, d=d: handle_line(d, line), seed, human_choice="plan", timing="hinted",
               announce=True, robot_window=robot).play()


def routes_of(out_dir: str, plan_set: PlanSet) -> tuple[Any, Any]:
    """The plans' routes (`PlanRoutes.routes`) and the free-space paths planned with the compile's seed."""
    from hrc.compile.output import read_header
    from hrc.dispatch.routes import PlanRoutes, plan_motions
    from hrc.motion import plan_paths

    paths = plan_paths(plan_set.task, seed=int(read_header(out_dir).get("seed", 0)))
    return PlanRoutes(plan_motions(out_dir, plan_set), paths).routes, paths


def stated_delay(out_dir: str, sensing: str | None, delay: str | None) -> float | None:
    """The longest observation delay the promise is judged at (s; None: none stated)."""
    from hrc.model import SENSING_PATHS

    if delay is not None:
        hi = delay.split(":")[-1]
        return None if hi == "inf" else float(hi)
    if sensing is not None:
        return SENSING_PATHS[sensing][0][1]
    found = json.loads(Path(out_dir, "compiled.json").read_text(encoding="utf-8")).get("sensing") \
        if Path(out_dir, "compiled.json").stat().st_size < 50_000_000 else None
    if isinstance(found, dict) and isinstance(found.get("observation_delay"), list):
        return found["observation_delay"][1]
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--robot", choices=("anywhere", "near", "earliest"), default="anywhere")
    ap.add_argument("--detect", choices=("buttons", "motion"), default="buttons")
    ap.add_argument("--sensor-sigma", type=float, default=0.05)
    ap.add_argument("--sensor-rate", type=float, default=10.0)
    ap.add_argument("--sensor-dropout", type=float, default=0.0)
    ap.add_argument("--sensor-latency", type=float, default=0.0)
    ap.add_argument("--buttons-late", type=float, default=None, metavar="D")
    ap.add_argument("--buttons-uniform", action="store_true")
    ap.add_argument("--tick", type=float, default=0.5)
    ap.add_argument("--sensing", choices=("buttons", "motion"), default=None)
    ap.add_argument("--observation-delay", metavar="LO:HI", default=None)
    args = ap.parse_args()
    plan_set = load_plan_set(args.out_dir)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    if args.detect == "buttons" and args.buttons_late is None:
        base = Dispatcher(plan_set, threads=1)
        kept, spans = 0, []
        for seed in seeds:
            j = judge(plan_set, buttons_run(plan_set, base, seed, args.robot))
            good = j.same_part and not j.broken and not j.refused and not j.not_dc
            kept += good
            spans.append(j.makespan)
            print(f"seed {seed}: {'kept' if good else 'BROKEN'} (first {j.first}, final {j.final}"
                  f"{'' if j.same_part else ', another person part'}{', ' + j.broken[0] if j.broken else ''})")
        print(f"{kept} of {args.seeds} runs kept every constraint of the followed plan; makespan median "
              f"{statistics.median(spans):.2f} s")
        return 0
    from detect_client import PressingRun, WalkingRun

    from hrc.detect import DetectingDispatcher, DetectParams
    from hrc.detect.sensor import SensorModel

    sensor = SensorModel(args.sensor_sigma, args.sensor_rate, args.sensor_dropout, args.sensor_latency)
    delay = stated_delay(args.out_dir, args.sensing, args.observation_delay)
    pressing = args.buttons_late is not None
    detecting = Dispatcher(plan_set, threads=1, max_observation_delay=delay) if pressing else \
        DetectingDispatcher(plan_set, params=DetectParams(sigma=max(sensor.sigma, 0.01)), threads=1,
                            max_observation_delay=delay)
    routes, paths = routes_of(args.out_dir, plan_set)
    # buttons on time: no observation delay (the compile's stated one would read each press as up to that
    # late, and undated)
    buttons = Dispatcher(plan_set, threads=1, max_observation_delay=0.0)
    cap = 5 * (plan_set.task.deadline or 120.0)
    judged, spans_b = [], []
    for seed in seeds:
        d = detecting.fork()
        if pressing:
            run: WalkingRun = PressingRun(plan_set, lambda line, d=d: handle_line(d, line), seed, routes=routes,
                                          paths=paths, late=args.buttons_late, uniform=args.buttons_uniform,
                                          tick=args.tick, robot_window=args.robot)
        else:
            run = WalkingRun(plan_set, lambda line, d=d: handle_line(d, line), seed, routes=routes, paths=paths,
                             sensor=sensor, robot_window=args.robot)
        j = judge(plan_set, run.play(cap=cap))
        judged.append(j)
        spans_b.append(judge(plan_set, buttons_run(plan_set, buttons, seed, args.robot)).makespan)
        what = "kept" if j.kept else ("BROKEN" if j.dc_within_delay else "void")
        more = f" (+{len(j.broken) - 1} more)" if len(j.broken) > 1 else ""
        print(f"seed {seed}: {what} (first {j.first} {j.first_class}, final {j.final}"
              f"{'' if j.same_part else ', another person part'}; {j.late} late, {j.not_dc} answers not DC, "
              f"{run.unguided} steps unguided, {len(run.closed)} windows closed, {run.positions} positions; "
              f"makespan {j.makespan:.2f} s{'; ' + j.broken[0] + more if j.broken else ''})", flush=True)
    dc = [j for j in judged if j.first_class == "DC"]
    within = [j for j in dc if j.late == 0]
    md, mb = statistics.median(j.makespan for j in judged), statistics.median(spans_b)
    path = (f"buttons {args.buttons_late:g} s late ({'uniform in [0, D]' if args.buttons_uniform else 'fixed'}, "
            f"tick {args.tick:g} s)" if pressing else
            f"motion detector {sensor.sigma:g} m / {sensor.rate:g} Hz / {100 * sensor.dropout:g} % dropouts / "
            f"{sensor.latency:g} s latency")
    print(f"{path}, "
          f"stated delay {delay} s: {sum(j.kept for j in judged)} of {len(within)} runs on a DC-at-sensing "
          f"first plan with every observation within the delay kept every constraint ({len(dc)} on a DC plan); "
          f"{sum(1 for j in judged if j.late)} of {len(judged)} runs with a late observation "
          f"({sum(j.late for j in judged)} answers); makespan median {md:.2f} s vs {mb:.2f} s with buttons on "
          f"time ({100 * (md - mb) / mb:+.1f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
