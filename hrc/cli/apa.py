"""`hrc apa STPP.json`: compile an STPP into its dispatchably optimal form (APA, Fig. 5).

Prints the optimal global preference value, the flexibility ratio, each event's optimal time and DO
window (relative to the first event), and the DO form as interval constraints (its minimal
dispatchable network). ``--json`` prints one object with ``value``, ``times`` (``{event: seconds}``),
``windows``, ``do_form`` (``[{"from", "to", "lb", "ub"}]``, null for an open side), ``flexibility`` (0-1),
``value_tolerance``, ``solver`` and ``consistent``. An inconsistent STPP is an answer (exit 0) naming a
negative cycle; a bad file is one ``error:`` line and exit 2. See docs/apa.md.
"""

from __future__ import annotations

import argparse
import json
import math

from hrc.apa.compile import TICKS_PER_SECOND, compile_stpp, do_form, prune_report
from hrc.apa.io import load_stpp
from hrc.apa.qp import SOLVERS
from hrc.cli.argtypes import whole

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("apa", help="compile an STPP (JSON) into its dispatchably optimal form",
                              description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("file", metavar="STPP.json", help="an STPP in the JSON format of docs/apa.md")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--solver", choices=sorted(SOLVERS), default="piqp", help="QP solver (default piqp)")
    p.add_argument("--ticks-per-second", type=whole(1), default=TICKS_PER_SECOND,
                   help=f"resolution of the exact temporal core (default {TICKS_PER_SECOND})")
    p.add_argument("--no-do-form", action="store_true",
                   help="skip the DO form's constraint list (O(n^3): use for thousands of events)")
    p.add_argument("--prune", action="store_true",
                   help="also count Fig. 5 lines 1-2: APSP edges and those left after pruning (O(n^3))")
    p.set_defaults(run=run)


def _num(v: float | None) -> float | None:
    return None if v is None or math.isinf(v) else v


def run(args: argparse.Namespace) -> int:
    stpp = load_stpp(args.file)
    result = compile_stpp(stpp, solver=args.solver, ticks_per_second=args.ticks_per_second)
    if not result.consistent:
        if args.json:
            print(json.dumps({"file": str(args.file), "consistent": False, "cycle": list(result.cycle)}))
        else:
            print(f"inconsistent: the hard constraints admit no schedule (negative cycle through "
                  f"{' -> '.join(result.cycle)})")
        return 0
    form = () if args.no_do_form else do_form(result)
    prune = prune_report(stpp, args.ticks_per_second) if args.prune else None
    times = result.schedule()
    if args.json:
        out = {
            "file": str(args.file),
            "consistent": True,
            "value": result.value,
            "value_tolerance": result.value_tolerance,
            "flexibility": result.flexibility,
            "solver": result.solver,
            "times": times,
            "windows": {e: list(result.window(e)) for e in stpp.events},
            "do_form": None if args.no_do_form else
            [{"from": c.source, "to": c.target, "lb": _num(c.lb), "ub": _num(c.ub)} for c in form],
        }
        if prune is not None:
            out["prune"] = {"original_edges": prune.original_edges, "apsp_edges": prune.apsp_edges,
                            "pruned_edges": prune.pruned_edges}
        print(json.dumps(out))
        return 0
    print(f"{stpp.name or args.file}: {len(stpp.events)} events, {len(stpp.constraints)} constraints, "
          f"{len(stpp.preferred)} preferences")
    print(f"optimal global preference value: {result.value:.9g} (every DO schedule within "
          f"{result.value_tolerance:.3g})")
    print(f"flexibility kept by the DO form: {100 * (result.flexibility or 0.0):.1f} %")
    if prune is not None:
        print(f"pruning: {prune.apsp_edges} APSP edges -> {prune.pruned_edges} "
              f"({100 * prune.pruned_fraction:.1f} % removed; the original has {prune.original_edges})")
    width = max(5, *(len(e) for e in stpp.events))
    print(f"{'event':<{width}}  {'time':>10}  DO window (s, relative to {stpp.reference})")
    for e in stpp.events:
        lo, hi = result.window(e)
        print(f"{e:<{width}}  {times[e]:>10.6g}  [{'-inf' if lo is None else f'{lo:g}'}, "
              f"{'inf' if hi is None else f'{hi:g}'}]")
    if not args.no_do_form:
        print(f"DO form ({len(form)} constraints, minimal dispatchable):")
        for c in form:
            print(f"  {c.lb:g} <= T({c.target}) - T({c.source}) <= {c.ub:g}")
    return 0
