"""Benchmark the dispatcher as a user calls it: load a compiled folder, then answer random runs' messages.

    PYTHONPATH=. .venv/bin/python scripts/bench_dispatch.py [--runs 20] [--repeat 3]
        [--tasks tasks/cube_stacking.yaml tasks/kitting.yaml tasks/kitting_6picks.yaml tasks/kitting_7picks.yaml]
        [--cache /tmp/hrc-bench] [--clock cpu|wall] [--threads N] [--no-reference] [--no-preferences]

Each task is compiled once with ``--stnu archive`` (kept in ``--cache`` between invocations; not timed:
`scripts/bench_compile.py` times compiles). Then, per task and per repeat, a fresh process (cold: nothing
of the dispatcher loaded or cached) times `Dispatcher.from_folder` (wall and CPU seconds, and its peak
resident memory) and plays `--runs` random histories through `hrc.dispatch.protocol.handle_line`, as
`hrc dispatch` answers them: the test client (tests/dispatch_client.py: a person who picks any order the
task allows and goes at once, a robot that acts inside every window). Every answer is timed with
``--clock`` (``cpu``: the process's CPU time, all threads, which a loaded machine disturbs far less than
wall time; ``wall``). The table gives medians over the repeats of: load time and peak memory, the
per-message median, p99 and max, and the first message of a run after its opening tick (the human's
first choice: the most candidates re-ranked). A team's task (other than one person and one robot, issue
37: tasks/kitting_2robots.yaml) is played by tests/team_client.py instead: every person and every robot,
times drawn inside the windows, nature's durations inside the plan's contingent links.

Beside it, in the same process and on the same histories, the peer: the dispatcher by its definitions
(tests/reference_dispatch.py: the GraphML files read into objects, every candidate re-checked from its
residual network in Python, the way `hrc dispatch` worked before the dispatch form), for sets small
enough to load that way (``--reference-max`` plans); its load and p99 are printed next to the
dispatcher's, with the ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

DEFAULT_TASKS = ["tasks/cube_stacking.yaml", "tasks/kitting.yaml", "tasks/kitting_6picks.yaml",
                 "tasks/kitting_7picks.yaml"]


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def _stats(times: list[float], firsts: list[float]) -> dict:
    return {"messages": len(times), "median": statistics.median(times), "p99": _pct(times, 0.99), "max": max(times),
            "first_median": statistics.median(firsts), "first_max": max(firsts)}


def worker(folder: str, runs: int, clock_name: str, threads: int | None, preferences: bool,
           reference_max: int) -> dict:
    """One cold process: load, then play `runs` histories (and the peer on the same lines)."""
    from dispatch_client import Run

    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import handle_line

    clock = time.process_time if clock_name == "cpu" else time.perf_counter
    w0, c0 = time.perf_counter(), time.process_time()
    base = Dispatcher.from_folder(folder, threads=threads, use_preferences=preferences)
    load = {"load_wall": time.perf_counter() - w0, "load_cpu": time.process_time() - c0,
            "load_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "plans": len(base.plan_set)}
    times: list[float] = []
    firsts: list[float] = []
    lines: list[list[str]] = []
    for seed in range(runs):
        d = base.fork()
        mine: list[float] = []
        sent: list[str] = []

        def send(line: str, d: Dispatcher = d, mine: list[float] = mine, sent: list[str] = sent) -> str:
            t = clock()
            answer = handle_line(d, line)
            mine.append((clock() - t) * 1000)
            sent.append(line)
            return answer

        if sorted(a.kind.value for a in base.task.agents) == ["human", "robot"]:
            Run(base.plan_set, send, seed, human_choice="random", timing="eager").play()
        else:
            _team_run(base, d, send, seed)
        firsts.append(mine[1])  # mine[0] is the opening tick (nothing seen: nothing to re-check)
        times += mine
        lines.append(sent)
    out = {**load, **_stats(times, firsts), "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    if len(base.plan_set) <= reference_max:
        from reference_dispatch import ReferenceDispatcher, read_entries

        w0, c0 = time.perf_counter(), time.process_time()
        task, entries, rank_by = read_entries(folder)
        ReferenceDispatcher(task, entries, rank_by, use_preferences=preferences, apa_entry=base.plan_set.entry)
        ref_load = time.process_time() - c0 if clock_name == "cpu" else time.perf_counter() - w0
        ref_times: list[float] = []
        ref_firsts: list[float] = []
        for sent in lines:
            ref = ReferenceDispatcher(task, entries, rank_by, use_preferences=preferences,
                                      apa_entry=base.plan_set.entry)
            mine = []
            for line in sent:
                t = clock()
                handle_line(ref, line)  # type: ignore[arg-type]
                mine.append((clock() - t) * 1000)
            ref_firsts.append(mine[1])
            ref_times += mine
        out["reference"] = {"load": ref_load, **_stats(ref_times, ref_firsts)}
    return out


def _team_run(base, d, send, seed: int) -> None:  # noqa: ANN001 - the worker's own objects
    """One random run of a team (tests/team_client.py), every answer through `send` (timed)."""
    import random

    from team_client import TeamRun

    class _STNUs(dict):
        def __missing__(self, plan: str):  # noqa: ANN204 - the plan's STNU, read when an answer names it
            self[plan] = base.plan_set.entry(base.plan_set.index(plan)).stnu
            return self[plan]

    class _Timed(TeamRun):
        def send(self, message):  # noqa: ANN001, ANN202
            line = json.dumps(message)
            self.sent.append(line)
            out = json.loads(send(line))
            self.answers.append(out)
            return out

    agents = base.task.agents
    _Timed(d, _STNUs(), tuple(a.id for a in agents if not a.is_human), tuple(a.id for a in agents if a.is_human),
           random.Random(seed)).play()


def _compile(task: str, cache: Path) -> Path:
    folder = cache / Path(task).stem
    if not (folder / "compiled.json").is_file():
        subprocess.run([sys.executable, "-m", "hrc", "compile", str(ROOT / task), "--out", str(folder), "--stnu",
                        "archive", "--no-report", "-q"], check=True, cwd=ROOT)
    return folder


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", nargs="+", default=DEFAULT_TASKS)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3, help="cold processes per task (medians are printed)")
    ap.add_argument("--cache", default="/tmp/hrc-bench", help="where the compiled tasks are kept")
    ap.add_argument("--clock", choices=("cpu", "wall"), default="cpu")
    ap.add_argument("--threads", type=int, default=None, help="set ranking's threads (default: the dispatcher's)")
    ap.add_argument("--no-preferences", dest="preferences", action="store_false",
                    help="dispatch without APA's DO windows (hrc dispatch --no-preferences)")
    ap.add_argument("--reference-max", type=int, default=3000,
                    help="time the peer on sets of at most this many plans (0: never)")
    ap.add_argument("--no-reference", dest="reference_max", action="store_const", const=0)
    ap.add_argument("--worker", nargs=1, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker[0], args.runs, args.clock, args.threads, args.preferences,
                                args.reference_max)))
        return 0
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.processor() or platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} "
          f"cores, load average {os.getloadavg()[0]:.1f}; {args.runs} random histories per task, {args.clock} time, "
          f"medians of {args.repeat} cold processes; APA windows {'on' if args.preferences else 'off'}; "
          f"threads {args.threads or 'default'}")
    print("| task | plans | load s | load MB | messages | median ms | p99 ms | max ms | first message median / max ms "
          "| peak MB | peer: load s, p99 ms, first median ms | p99 ratio |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|")
    for task in args.tasks:
        folder = _compile(task, cache)
        found = []
        for _ in range(args.repeat):
            cmd = [sys.executable, __file__, "--worker", str(folder), "--runs", str(args.runs), "--clock", args.clock,
                   "--reference-max", str(args.reference_max)]
            cmd += ["--threads", str(args.threads)] if args.threads else []
            cmd += [] if args.preferences else ["--no-preferences"]
            run = subprocess.run(cmd, check=True, capture_output=True, text=True, cwd=ROOT,
                                 env=dict(os.environ, PYTHONPATH=str(ROOT)))
            found.append(json.loads(run.stdout.strip().splitlines()[-1]))

        def med(key: str, *, of: str | None = None, found: list = found) -> float:
            return statistics.median((r[of] if of else r)[key] for r in found)

        load_key = "load_cpu" if args.clock == "cpu" else "load_wall"
        peer = ratio = "-"
        if all("reference" in r for r in found):
            peer = (f"{med('load', of='reference'):.1f}, {med('p99', of='reference'):.1f}, "
                    f"{med('first_median', of='reference'):.1f}")
            ratio = f"{med('p99', of='reference') / med('p99'):.0f}x"
        print(f"| {Path(task).stem} | {found[0]['plans']} | {med(load_key):.2f} | {med('load_rss_mb'):.0f} | "
              f"{found[0]['messages']} | {med('median'):.2f} | {med('p99'):.2f} | {med('max'):.2f} | "
              f"{med('first_median'):.1f} / {med('first_max'):.1f} | {med('peak_rss_mb'):.0f} | {peer} | {ratio} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
