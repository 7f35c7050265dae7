"""Benchmark the observation-delay check against the DC check on a folder of STNU files, in one run.

    .venv/bin/python scripts/bench_delay.py ../shared/benchmarks/stnu [--repeat 3] [--delay 1] [--delay 0:2]

Timed as scripts/bench_dc.py times the DC check: a fresh `STNU` built from the links (its validation) and the
check on it, reading the file not; one untimed run, then the median of ``--repeat`` runs, the DC check and each
delay interleaved per instance. Delays are in the file's ticks: ``G`` a fixed delay, ``LO:HI`` a variable
one, ``inf`` never observed. Prints per size class the median ms of each check, the ratio of medians and the
median of per-instance ratios (delay / DC: 1.5 means half again as long), and how many verdicts the delay
changed.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_dc import CLASSES, SUFFIXES, bench_network, fresh, machine  # noqa: E402

from hrc.errors import NetworkFileError  # noqa: E402
from hrc.temporal.dc import check_dc  # noqa: E402
from hrc.temporal.delay import NEVER, ObservationDelay, check_delay  # noqa: E402
from hrc.temporal.network import STNU, NetworkError  # noqa: E402


def parse_delay(text: str) -> ObservationDelay:
    if text == "inf":
        return NEVER
    lo, _, hi = text.partition(":")
    return ObservationDelay(int(lo), int(hi or lo))


def timed(run, net: STNU, repeat: int) -> tuple[str, float]:  # type: ignore[no-untyped-def]
    result = run(fresh(net))
    times = []
    gc.disable()
    try:
        for _ in range(max(1, repeat)):
            start = time.perf_counter()
            result = run(fresh(net))
            times.append((time.perf_counter() - start) * 1000)
    finally:
        gc.enable()
    return result.verdict.value, statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("folder", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--delay", action="append", default=None, help="G, LO:HI or inf (ticks); repeatable")
    args = ap.parse_args(argv)
    delays = [parse_delay(d) for d in (args.delay or ["1", "0:2"])]
    files = sorted(p for p in args.folder.rglob("*") if p.suffix in SUFFIXES and p.is_file())
    rows: list[tuple[int, float, list[float], list[bool]]] = []
    for path in files:
        try:
            net = bench_network(path)
        except (NetworkFileError, NetworkError):
            continue
        base_verdict, base = timed(check_dc, net, args.repeat)
        ms, changed = [], []
        for d in delays:
            verdict, t = timed(lambda n, d=d: check_delay(n, d), net, args.repeat)
            ms.append(t)
            changed.append(verdict != base_verdict)
        rows.append((len(net.timepoints), base, ms, changed))
    print(f"# {machine()}")
    print(f"# {len(rows)} instances of {args.folder}, median of {args.repeat} runs each")
    head = "| nodes | instances | DC check ms | " + " | ".join(
        f"delay {d} ms | ratio | median ratio | verdict changed" for d in delays) + " |"
    print(head)
    print("|" + "---|" * (3 + 4 * len(delays)))
    for label, lo, hi in [*CLASSES, ("all", 0, 10**12)]:
        sel = [r for r in rows if lo <= r[0] <= hi]
        if not sel:
            continue
        base = statistics.median(r[1] for r in sel)
        cells = [label, str(len(sel)), f"{base:.3f}"]
        for i in range(len(delays)):
            med = statistics.median(r[2][i] for r in sel)
            per = statistics.median(r[2][i] / r[1] for r in sel if r[1] > 0)
            cells += [f"{med:.3f}", f"{med / base:.2f}", f"{per:.2f}", str(sum(r[3][i] for r in sel))]
        print("| " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
