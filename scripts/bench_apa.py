"""Benchmark APA on the paper's random structured STPPs (Wilcox, Nikolaidis & Shah 2012, section V).

Prints four tables (medians over repeats; the machine may be shared, so read them as such):

1. compile time (Fig. 12) for 50 .. 1,000 events from the paper's generator (uniform random pairs,
   3n constraints, preferences on 20 % of n) and 10,000 events from its banded variant, with the
   optimum checked against clarabel where the sizes are small;
2. flexibility (Fig. 11) by constraint density c/n (n, 1.5n, 3n): the paper's measure (per original
   interval, DO width over original width) beside the project's (event windows from the reference);
3. Fig. 5 lines 1-2: how many APSP edges dominance pruning removes;
4. cumulative recompilation time under frequent small disturbances (Fig. 10): the DO form recompiles
   only when an event leaves its DO window, the point (NLP) solution whenever an event is late at all.

    .venv/bin/python scripts/bench_apa.py [--quick] [--uniform-10000] [--only TABLE]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from hrc.apa.compile import build_qp, compile_stpp, interval_flexibility, prune_report, stpp_network
from hrc.apa.dispatch import STPPDispatcher
from hrc.apa.generator import random_stpp
from hrc.apa.model import STPP
from hrc.apa.qp import solve_qp
from hrc.errors import ApaError

PAPER_COMPILE = {50: "", 150: "< 1 s", 400: "< 5 s", 1000: "(plotted, not in the text)", 10000: "future work"}
PAPER_FLEX = {50: ("74.7 ± 3.3", "1.0 ± 0.3"), 100: ("75.4 ± 3.2", "0.5 ± 0.1"),
              150: ("72.2 ± 3.1", "0.4 ± 0.1"), 200: ("71.7 ± 2.0", "0.2 ± 0.05")}


def compile_table(repeats: int, uniform_big: bool) -> None:
    print("## Compile time (Fig. 12)\n")
    print("| events | pairs | constraints | preferences | compile, median (s) | QP share | "
          "vs clarabel (rel. diff) | target | paper (Java + Gurobi, 2012) |")
    print("|---|---|---|---|---|---|---|---|---|")
    sizes = [(50, None), (150, None), (400, None), (1000, None), (10000, 20)]
    if uniform_big:
        sizes.append((10000, None))
    targets = {400: "< 0.5 s", 1000: "< 2 s", 10000: "< 30 s"}
    for n, loc in sizes:
        stpp = random_stpp(n, np.random.default_rng(n), locality=loc)
        runs, qp = [], []
        reps = 1 if (n >= 10000 and loc is None) else repeats
        for _ in range(reps):
            t = time.perf_counter()
            r = compile_stpp(stpp)
            runs.append(time.perf_counter() - t)
            qp.append(dict(r.seconds)["qp"])
        check = "–"
        if n <= 1000:
            other = compile_stpp(stpp, solver="clarabel")
            check = f"{abs(r.value - other.value) / max(1.0, abs(other.value)):.1e}"
        pairs = "uniform" if loc is None else f"banded ({loc})"
        print(f"| {n:,} | {pairs} | {len(stpp.constraints):,} | {len(stpp.preferred):,} | "
              f"{statistics.median(runs):.3f} | {statistics.median(qp) / statistics.median(runs):.0%} | {check} | "
              f"{targets.get(n, '')} | {PAPER_COMPILE[n]} |", flush=True)


def flexibility_table(problems: int) -> None:
    print(f"\n## Flexibility (Fig. 11) by constraint density, {problems} random problems per row, mean ± sd\n")
    print("c/n: constraints per event (the paper does not state it; our generator's default is 3). The paper's")
    print("measure: per original interval, the width its events keep in the DO form over its original width")
    print("(`interval_flexibility`), averaged; ours: the events' windows from the reference, summed, DO form")
    print("over original (`CompileResult.flexibility`). Constant preferences leave their interval free.\n")
    print("| c/n | events | paper's measure (%) | ours (%) | paper: DO form (%) | paper: NLP solution (%) |")
    print("|---|---|---|---|---|---|")
    for density in (1.0, 1.5, 3.0):
        for n in (50, 100, 150, 200):
            ours, paper = [], []
            for seed in range(problems):
                stpp = random_stpp(n, np.random.default_rng(1000 * n + seed), constraints=round(density * n))
                r = compile_stpp(stpp)
                ours.append(100 * (r.flexibility or 0.0))
                paper.append(100 * (interval_flexibility(r) or 0.0))
            print(f"| {density:g} | {n} | {statistics.mean(paper):.1f} ± {statistics.stdev(paper):.1f} | "
                  f"{statistics.mean(ours):.1f} ± {statistics.stdev(ours):.1f} | {PAPER_FLEX[n][0]} | "
                  f"{PAPER_FLEX[n][1]} |", flush=True)


def prune_table() -> None:
    print("\n## Fig. 5 lines 1-2: APSP and dominance pruning (directed edges)\n")
    print("| events | original | APSP form | pruned (MDN) | removed from the APSP form | paper |")
    print("|---|---|---|---|---|---|")
    for n in (50, 150, 400):
        p = prune_report(random_stpp(n, np.random.default_rng(n)))
        print(f"| {n} | {p.original_edges:,} | {p.apsp_edges:,} | {p.pruned_edges:,} | {p.pruned_fraction:.0%} | "
              f"40-50 % |", flush=True)


def disturbed_run(stpp: STPP, rng: np.random.Generator, late: float) -> tuple[float, int, float, int, int]:
    """Dispatch `stpp` with every event up to `late` s after the start of its window. Returns the DO
    dispatcher's cumulative recompile time and count, and the same for re-solving the point solution
    (the QP) after every late event."""
    disp = STPPDispatcher(stpp)
    do_time, do_count = 0.0, 0
    nlp_time, nlp_count = 0.0, 0
    now = 0.0
    disp.observe(stpp.reference, 0.0)  # the time origin (Fig. 8 line 2)
    while not disp.done:
        wins = disp.next_events().windows
        event, lo, hi = min(wins, key=lambda w: (w[1] if w[1] is not None else now, w[0]))
        base = max(now, lo if lo is not None else now)
        t = base + rng.uniform(0, late)
        pending = [disp.index[e] for e in stpp.events if e not in disp.executed]
        hard_hi = float(disp.hi0[pending].min()) / disp.tps  # late, but never past anyone's hard deadline
        t = round(min(t, hard_hi), 3) if hard_hi >= base else round(t, 3)
        start = time.perf_counter()
        step = disp.observe(event, t)
        spent = time.perf_counter() - start
        if step.status in ("recompiled", "switched"):
            do_time += spent
            do_count += 1
        if step.status == "violation":
            break
        if t > base and len(disp.executed) < len(stpp.events):
            # the point solution is brittle: any lateness means a new QP with the past rigid
            committed = stpp.with_commitments({e: v / disp.tps for e, v in disp.executed.items()}, t)
            start = time.perf_counter()  # the QP alone, as a point-solution scheduler solves it
            try:
                solve_qp(build_qp(committed, stpp_network(committed), disp.tps))
            except ApaError:  # the disturbance left no schedule (the dispatcher will say so next)
                break
            nlp_time += time.perf_counter() - start
            nlp_count += 1
        now = t
    return do_time, do_count, nlp_time, nlp_count, len(disp.executed)


def recompile_table(problems: int) -> None:
    print(f"\n## Cumulative recompilation under small disturbances (Fig. 10), {problems} problems per size\n")
    print("Each event is dispatched a uniform 0-0.1 s after its window opens (never past its hard window); the DO")
    print("dispatcher recompiles when an event leaves its DO window, the point solution after every late event.\n")
    print("| events | dispatched | DO: recompiles | DO: cumulative (s) | point: re-solves | point: cumulative (s) | "
          "reduction |")
    print("|---|---|---|---|---|---|---|")
    for n in (25, 50, 100, 150):
        rows = [disturbed_run(random_stpp(n, np.random.default_rng(7 * n + s)), np.random.default_rng(s), 0.1)
                for s in range(problems)]
        dt, dc, nt, nc, done = (statistics.mean(r[k] for r in rows) for k in range(5))
        print(f"| {n} | {done:.0f} | {dc:.1f} | {dt:.3f} | {nc:.1f} | {nt:.3f} | {1 - dt / nt if nt else 0:.0%} |",
              flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and problems")
    parser.add_argument("--only", choices=("compile", "flexibility", "prune", "recompile"),
                        help="print one table only")
    parser.add_argument("--uniform-10000", action="store_true",
                        help="also compile 10,000 events from uniform pairs (one run; minutes)")
    args = parser.parse_args()
    tables = {"compile": lambda: compile_table(3 if args.quick else 5, args.uniform_10000),
              "flexibility": lambda: flexibility_table(5 if args.quick else 20),
              "prune": prune_table, "recompile": lambda: recompile_table(2 if args.quick else 5)}
    for name, table in tables.items():
        if args.only in (None, name):
            table()


if __name__ == "__main__":
    main()
