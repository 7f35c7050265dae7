"""Benchmark the DC check over a folder of STNU files, side by side with the CSTNU Tool's times.

    .venv/bin/python scripts/bench_dc.py ../shared/benchmarks/stnu [--repeat 5] [--summary-only]
        [--algorithm rul2021 --algorithm bypass ... | --algorithm all] [--peers FILE] [--cpu N]

``--algorithm rul2021-py`` times rul2021 without its C core (the Python implementation a machine without a
C compiler runs). For every file (any format `hrc check` reads) and algorithm: one warm-up run, then the median of
``--repeat`` runs of `hrc.temporal.check_dc` (the DC check alone, its consistency check included; reading
the file is not timed). Prints one row per instance (unless ``--summary-only``), then per size class and
algorithm the median time, the CSTNU Tool's median over the same instances and their ratio (ours / tool,
so below 1 is faster), and the median of the per-instance ratios. The tool's times come from ``peers.md``
in the folder (or ``--peers``): its per-instance table, column ``RUL2021`` (the tool's default). Verdicts
are compared with ``verdicts.csv`` when the folder has one. ``--cpu N`` pins the process to one core.
"""

from __future__ import annotations

import argparse
import csv
import gc
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hrc.errors import NetworkFileError  # noqa: E402
from hrc.temporal.dc import ALGORITHMS, DEFAULT_ALGORITHM, check_dc  # noqa: E402
from hrc.temporal.graphml import read_network  # noqa: E402
from hrc.temporal.network import STNU  # noqa: E402
from hrc.temporal.rul import rul2021_check  # noqa: E402

PURE = "rul2021-py"
CLASSES = [("<50", 0, 49), ("50-199", 50, 199), ("200-399", 200, 399), (">=400", 400, 10**12)]
SUFFIXES = {".stnu", ".stn", ".graphml", ".json", ".cstnu"}
ACCEPT = {"DC": {"DC"}, "consistent-not-DC": {"not DC"}, "inconsistent": {"inconsistent"},
          "not-DC": {"not DC", "inconsistent"}, "unknown": {"DC", "not DC", "inconsistent"}}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    return (f"{cpu}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, load average {load}")


def peer_times(path: Path) -> dict[str, float]:
    """Per-instance milliseconds of the CSTNU Tool's RUL2021 column in peers.md (rows with a number)."""
    out: dict[str, float] = {}
    if not path.is_file():
        return out
    header: list[str] | None = None
    for line in path.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == "instance":
            header = cells
            continue
        if header is None or len(cells) != len(header) or "RUL2021" not in header:
            continue
        try:
            out[cells[0]] = float(cells[header.index("RUL2021")])
        except ValueError:
            continue  # "–": the tool refused the file
    return out


def expected_verdicts(folder: Path) -> dict[str, str]:
    path = folder / "verdicts.csv"
    if not path.is_file():
        return {}
    with open(path, newline="", encoding="utf-8") as fh:
        return {row["file"]: row["expected"] for row in csv.DictReader(fh)}


class _PurePython:
    """rul2021 without its C core (what a machine without a C compiler runs), timed like check_dc."""

    def __init__(self, verdict: str, cycle: object) -> None:
        self.verdict = type("V", (), {"value": verdict})()
        self.cycle = cycle


def check(net: STNU, algorithm: str) -> Any:
    if algorithm == PURE:
        verdict, cycle, _ = rul2021_check(net, accelerated=False)
        return _PurePython(verdict, cycle)
    return check_dc(net, algorithm)


def time_check(net: STNU, algorithm: str, repeat: int) -> tuple[str, float, float]:
    """Verdict, median ms of the check, and ms to build the explaining cycle on first access (not DC)."""
    result = check(net, algorithm)  # warm-up
    times = []
    gc.disable()
    try:
        for _ in range(max(1, repeat)):
            start = time.perf_counter()
            result = check(net, algorithm)
            times.append((time.perf_counter() - start) * 1000)
        start = time.perf_counter()
        _ = result.cycle
        explain = (time.perf_counter() - start) * 1000
    finally:
        gc.enable()
    return result.verdict.value, statistics.median(times), explain


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per instance; the median is kept")
    parser.add_argument("--summary-only", action="store_true", help="print only the per-size-class summary")
    parser.add_argument("--algorithm", action="append", choices=[*sorted(ALGORITHMS), PURE, "all"],
                        help=f"DC algorithm, repeatable (default {DEFAULT_ALGORITHM}; 'all' for every one; {PURE}: "
                             "rul2021 without its C core)")
    parser.add_argument("--peers", type=Path, help="the CSTNU Tool's times (default FOLDER/peers.md)")
    parser.add_argument("--cpu", type=int, help="pin the process to this CPU")
    args = parser.parse_args(argv)
    if args.cpu is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    algorithms = args.algorithm or [DEFAULT_ALGORITHM]
    if "all" in algorithms:
        algorithms = [*sorted(ALGORITHMS), PURE]
    peers = peer_times(args.peers or args.folder / "peers.md")
    expected = expected_verdicts(args.folder)
    files = sorted(p for p in args.folder.rglob("*") if p.is_file() and p.suffix in SUFFIXES)
    if not files:
        print(f"error: no STNU files under {args.folder}", file=sys.stderr)
        return 2
    rows: list[tuple[str, int, int, int, str, str, float]] = []  # name, n, m, k, algorithm, verdict, ms
    explains: dict[str, list[float]] = {a: [] for a in algorithms}  # ms to build the cycle, not DC
    for path in files:
        try:
            net = read_network(path)
        except NetworkFileError as err:
            print(f"skipped: {err}", file=sys.stderr)
            continue
        name = path.relative_to(args.folder).as_posix()
        for algorithm in algorithms:
            verdict, ms, explain = time_check(net, algorithm, args.repeat)
            rows.append((name, len(net.timepoints), net.n_edges, len(net.contingents), algorithm, verdict, ms))
            if verdict != "DC":
                explains[algorithm].append(explain)
    if not args.summary_only:
        width = max(len(r[0]) for r in rows)
        print(f"| {'instance':<{width}} | nodes | edges | contingent | algorithm  | verdict      |       ms |"
              " tool ms |")
        print(f"|{'-' * (width + 2)}|------:|------:|-----------:|------------|--------------|---------:|--------:|")
        for name, n, m, k, algorithm, verdict, ms in rows:
            tool = f"{peers[name]:7.2f}" if name in peers else "      –"
            print(f"| {name:<{width}} | {n:5d} | {m:5d} | {k:10d} | {algorithm:<10} | {verdict:<12} | {ms:8.3f} |"
                  f" {tool} |")
        print()
    print("| timepoints | algorithm  | instances | median ms | tool median ms | ratio | median per-instance ratio |")
    print("|------------|------------|----------:|----------:|---------------:|------:|--------------------------:|")
    for label, lo, hi in CLASSES:
        for algorithm in algorithms:
            in_class = [r for r in rows if lo <= r[1] <= hi and r[4] == algorithm]
            if not in_class:
                continue
            both = [r for r in in_class if r[0] in peers]
            ours = statistics.median(r[6] for r in in_class)
            if both:
                tool_ms = statistics.median(peers[r[0]] for r in both)
                mine = statistics.median(r[6] for r in both)
                ratios = [r[6] / peers[r[0]] for r in both if peers[r[0]] > 0]
                per = f"{statistics.median(ratios):.2f}" if ratios else "–"
                print(f"| {label:<10} | {algorithm:<10} | {len(in_class):9d} | {ours:9.3f} | {tool_ms:14.2f} |"
                      f" {mine / tool_ms:5.2f} | {per:>25} |")
            else:
                print(f"| {label:<10} | {algorithm:<10} | {len(in_class):9d} | {ours:9.3f} | {'–':>14} |"
                      f" {'–':>5} | {'–':>25} |")
    for algorithm, spent in explains.items():
        if spent:
            print(f"{algorithm}: the explaining cycle of a not-DC or inconsistent instance, when first read, took "
                  f"a median {statistics.median(spent):.3f} ms more (max {max(spent):.2f} ms, {len(spent)} "
                  "instances; rul2021 builds it on first access)")
    wrong = [(r[0], r[4], r[5], expected[r[0]]) for r in rows
             if r[0] in expected and r[5] not in ACCEPT.get(expected[r[0]], set())]
    print()
    print(f"{len(files)} files, algorithms {', '.join(algorithms)}; DC check only (file reading not timed), "
          f"one warm-up then the median of {args.repeat} runs; ratio = our median / the tool's median over the "
          f"instances the tool has a time for ({len(peers)} in peers.md)")
    if expected:
        print(f"verdicts: {sum(1 for r in rows if r[0] in expected) - len(wrong)} agree with verdicts.csv, "
              f"{len(wrong)} differ" + "".join(f"\n  {w}" for w in wrong))
    print(f"machine: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
