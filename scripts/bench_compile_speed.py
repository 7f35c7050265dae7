"""Benchmark what a person waits for (issue 38): the workshop compile with its report, cold and warm cache.

    .venv/bin/python scripts/bench_compile_speed.py [--before DIR] [--repeat 3]
        [--command "compile tasks/cube_stacking.yaml"] [--modes cold warm]

Each run is a fresh ``python -m hrc COMMAND --out OUT -q`` process (start-up, path planning, the worker
pool and the report counted, as a user sees them), from this checkout and, with ``--before DIR``, from
another checkout of the code (e.g. ``git archive main | tar -x -C DIR`` with its C core built in place):
the same hour, the same load, before and after alternating run by run. *cold*: the path cache
(``HRC_CACHE_DIR``, a temporary folder) emptied
before each run; *warm*: filled by one untimed run first. The table gives each run's wall time and CPU
time (user + sys of the whole process tree: the compile, its workers and the figure processes, from
``getrusage(RUSAGE_CHILDREN)``; less sensitive to a shared machine's load than the wall time), their
medians, and the lowest and highest load average (1 min) seen before each run of the row.

Python's bytecode of each checkout (and of the libraries it imports: one untimed run) is compiled first
into a folder of its own (``PYTHONPYCACHEPREFIX``, nothing written into the checkouts), and the runs read
it, as an installed hrc
does (pip compiles it at install; the first import of a checkout writes it beside the sources). Without
it (``--no-bytecode``; also what a run sees with ``PYTHONDONTWRITEBYTECODE`` set and no ``__pycache__``,
as in these sessions' worktrees) every process compiles hrc's sources again at every run: about 2.3 s of
CPU of the workshop's cold compile (the command's process, and each forked process for the modules it
imports after the fork), which no user pays.

*warm* for a compile of at most `hrc.compile.stream.RESULTS_MAX_PLANS` plans means the same task compiled
before with the same code: its plans come from the cache of whole compiles. The same script times the
simulator (issue 38: 1,000 workshop runs, 4 policies), whose up-front compile is then warm:

    .venv/bin/python scripts/bench_compile_speed.py --before DIR --repeat 1 --modes warm \
        --command "simulate tasks/cube_stacking.yaml --runs 1000 --jobs 2"
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def environment(root: Path, cache: Path, pycache: Path | None) -> dict[str, str]:
    """The environment of a run from `root`: its code, the cache folder `cache`, and its bytecode in
    `pycache` (None: as the caller's environment says)."""
    env = {**os.environ, "PYTHONPATH": str(root), "HRC_CACHE_DIR": str(cache)}
    if pycache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def compile_bytecode(root: Path, pycache: Path, command: list[str], out: Path) -> None:
    """`root`'s hrc compiled to bytecode under `pycache` (untimed, once per checkout), and the libraries'
    modules the command imports (a prefix replaces every ``__pycache__``, the installed libraries' too:
    one untimed run of the command writes theirs)."""
    env = environment(root, pycache, pycache)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(root / "hrc")], cwd=root, env=env, check=True,
                   stdout=subprocess.DEVNULL)
    run_once(root, command, out, pycache / "hrc-cache", pycache)


def run_once(root: Path, command: list[str], out: Path, cache: Path,
             pycache: Path | None = None) -> tuple[float, float]:
    """Wall and CPU seconds (user + sys of the process tree) of one ``hrc COMMAND --out OUT -q`` from `root`
    (the command's output folder `out` removed first; bytecode from `pycache`: `environment`)."""
    shutil.rmtree(out, ignore_errors=True)
    env = environment(root, cache, pycache)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "hrc", *command, "--out", str(out), "-q"], cwd=root, env=env, check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--before", type=Path, default=None, metavar="DIR", help="another checkout to compare with")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--command", default="compile tasks/cube_stacking.yaml")
    ap.add_argument("--modes", nargs="+", default=["cold", "warm"], choices=("cold", "warm"))
    ap.add_argument("--no-bytecode", action="store_true",
                    help="do not compile the checkouts' bytecode first (the environment decides)")
    args = ap.parse_args()
    roots = ([("before", args.before.resolve())] if args.before else []) + [("after", ROOT)]
    command = shlex.split(args.command)
    print(f"`hrc {args.command}`, {args.repeat} runs each, {os.cpu_count()} cores, "
          + ("bytecode as the environment says\n" if args.no_bytecode else "bytecode compiled first\n"))
    print("| code | cache | wall, s (runs) | wall median | CPU, s (runs) | CPU median | load |")
    print("|---|---|---|---:|---|---:|---|")
    with tempfile.TemporaryDirectory(prefix="hrc-bench-speed-") as tmp:
        out = Path(tmp) / "out"
        pycaches: dict[str, Path | None] = {}
        for label, root in roots:
            pycache = None if args.no_bytecode else Path(tmp) / f"pycache-{label}"
            if pycache is not None:
                compile_bytecode(root, pycache, command, out)
            pycaches[label] = pycache
        for mode in args.modes:
            # before and after alternate run by run (the shared machine's pace drifts within minutes)
            walls: dict[str, list[float]] = {label: [] for label, _ in roots}
            cpus: dict[str, list[float]] = {label: [] for label, _ in roots}
            loads: dict[str, list[float]] = {label: [] for label, _ in roots}
            for label, root in roots:
                shutil.rmtree(Path(tmp) / f"cache-{label}", ignore_errors=True)
                if mode == "warm":
                    run_once(root, command, out, Path(tmp) / f"cache-{label}", pycaches[label])
            for _ in range(args.repeat):
                for label, root in roots:
                    cache = Path(tmp) / f"cache-{label}"
                    if mode == "cold":
                        shutil.rmtree(cache, ignore_errors=True)
                    loads[label].append(os.getloadavg()[0])
                    wall, cpu = run_once(root, command, out, cache, pycaches[label])
                    walls[label].append(wall)
                    cpus[label].append(cpu)
            for label, _ in roots:
                runs = ", ".join(f"{w:.2f}" for w in walls[label])
                print(f"| {label} | {mode} | {runs} | **{statistics.median(walls[label]):.2f}** "
                      f"| {', '.join(f'{c:.2f}' for c in cpus[label])} | **{statistics.median(cpus[label]):.2f}** "
                      f"| {min(loads[label]):.1f}-{max(loads[label]):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
