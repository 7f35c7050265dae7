"""Benchmark the DC check over a folder of STNU files (any format `hrc check` reads).

    .venv/bin/python scripts/bench_dc.py ../shared/benchmarks/stnu [--repeat 3] [--summary-only]
                                         [--algorithm bypass|morris2014]

Prints one row per instance (instance, nodes, edges, contingent links, verdict, milliseconds of the DC
check alone, the median of ``--repeat`` runs; reading the file is not timed), then the median and maximum
per size class (by number of timepoints), and the machine it ran on.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hrc.errors import NetworkFileError  # noqa: E402
from hrc.temporal.dc import ALGORITHMS, DEFAULT_ALGORITHM, check_dc  # noqa: E402
from hrc.temporal.graphml import read_network  # noqa: E402

CLASSES = [(1, 10), (11, 50), (51, 100), (101, 200), (201, 1000), (1001, 10**9)]
SUFFIXES = {".stnu", ".stn", ".graphml", ".json", ".cstnu"}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}, " \
           f"Python {platform.python_version()}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--repeat", type=int, default=3, help="runs per instance; the median is reported")
    parser.add_argument("--summary-only", action="store_true", help="print only the per-size-class summary")
    parser.add_argument("--algorithm", choices=sorted(ALGORITHMS), default=DEFAULT_ALGORITHM,
                        help=f"DC algorithm (default {DEFAULT_ALGORITHM})")
    args = parser.parse_args(argv)
    files = sorted(p for p in args.folder.rglob("*") if p.is_file() and p.suffix in SUFFIXES)
    if not files:
        print(f"error: no STNU files under {args.folder}", file=sys.stderr)
        return 2
    rows = []
    for path in files:
        try:
            net = read_network(path)
        except NetworkFileError as err:
            print(f"skipped: {err}", file=sys.stderr)
            continue
        times = []
        for _ in range(max(1, args.repeat)):
            start = time.perf_counter()
            result = check_dc(net, args.algorithm)
            times.append((time.perf_counter() - start) * 1000)
        rows.append((str(path.relative_to(args.folder)), len(net.timepoints), net.n_edges, len(net.contingents),
                     result.verdict.value, statistics.median(times)))
    if not args.summary_only:
        width = max(len(r[0]) for r in rows)
        print(f"| {'instance':<{width}} | nodes | edges | contingent | verdict      |       ms |")
        print(f"|{'-' * (width + 2)}|------:|------:|-----------:|--------------|---------:|")
        for name, n, m, k, verdict, ms in rows:
            print(f"| {name:<{width}} | {n:5d} | {m:5d} | {k:10d} | {verdict:<12} | {ms:8.2f} |")
        print()
    print("| nodes     | instances | median ms |   max ms |")
    print("|-----------|----------:|----------:|---------:|")
    for lo, hi in CLASSES:
        in_class = [r[5] for r in rows if lo <= r[1] <= hi]
        if in_class:
            label = f"{lo}-{hi}" if hi < 10**9 else f">{lo - 1}"
            print(f"| {label:<9} | {len(in_class):9d} | {statistics.median(in_class):9.2f} | {max(in_class):8.2f} |")
    print()
    print(f"{len(rows)} instances, algorithm {args.algorithm}, DC check only (file reading not timed), "
          f"median of {args.repeat} runs each")
    print(f"machine: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
