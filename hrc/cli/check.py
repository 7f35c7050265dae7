"""`hrc check FILE`: is an STNU file dynamically controllable?

Prints ``DC``, ``not DC`` (with the semi-reducible negative cycle that proves it) or ``inconsistent``
(with the negative cycle of its STN), the node / edge / contingent-link counts and the time the check
took. ``--json`` prints one JSON object instead. Exit 0 whatever the verdict; 2 for a bad file (one
``error:`` line; a file in none of the formats is "not an STNU file" with the formats accepted).
The format (CSTNU Tool GraphML, ``.stnu`` text, HEATlab JSON) is detected from the content; a timepoint
named ``Z`` in GraphML or ``.stnu`` text is the origin unless ``--no-origin`` (see docs/temporal.md).

``--observation-delay D`` decides controllability when every contingent timepoint is learnt late
(`hrc.temporal.delay`): ``D`` in the file's unit, ``0`` (the DC check), ``1.5`` (fixed), ``inf`` (never:
strong controllability) or ``LO:HI`` (anywhere in between, the observation not saying when the event
happened). A delay finer than the file's integers scales the network exactly (every verdict is kept).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from fractions import Fraction

from hrc.cli.argtypes import delay_range
from hrc.temporal.dc import ALGORITHMS, DEFAULT_ALGORITHM, Verdict, check_dc
from hrc.temporal.delay import ObservationDelay, check_delay
from hrc.temporal.graphml import read_network_scaled
from hrc.temporal.limits import show_path
from hrc.temporal.network import STNU, ContingentLink, RequirementLink

__all__ = ["add_parser", "delay_in_ticks", "run", "scaled"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("check", help="decide whether an STNU file is dynamically controllable",
                              description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("file", metavar="FILE", help="STNU file: CSTNU Tool GraphML, .stnu text or HEATlab JSON")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--derived", action="store_true",
                   help="also read GraphML edges of type 'derived' as requirements (ignored by default)")
    p.add_argument("--no-origin", dest="origin", action="store_false",
                   help="in a .stnu text file, do not read the timepoint Z as the origin (every other "
                        "timepoint at or after it)")
    p.add_argument("--algorithm", choices=sorted(ALGORITHMS), default=DEFAULT_ALGORITHM,
                   help=f"DC algorithm (default {DEFAULT_ALGORITHM})")
    p.add_argument("--observation-delay", metavar="D", type=delay_range, default=None,
                   help="each contingent timepoint is learnt D after it happens (file's unit): 0, 1.5, inf "
                        "(never: strong controllability) or LO:HI (variable)")
    p.set_defaults(run=run)


def scaled(stnu: STNU, k: int) -> STNU:
    """`stnu` with every bound times `k` (> 0): the same verdicts, in finer ticks."""
    if k == 1:
        return stnu

    def m(v: int | None) -> int | None:
        return None if v is None else v * k

    return STNU(stnu.timepoints,
                tuple(RequirementLink(r.source, r.target, m(r.lb), m(r.ub)) for r in stnu.requirements),
                tuple(ContingentLink(c.source, c.target, c.lb * k, c.ub * k) for c in stnu.contingents), stnu.name)


def delay_in_ticks(stnu: STNU, per_unit: int, delay: tuple[Fraction, Fraction | None]) -> tuple[STNU, ObservationDelay,
                                                                                                 int]:
    """The network and the delay in common integer ticks: `delay` (file units) times `per_unit`, the
    network scaled by the least factor that makes both integers. Returns the factor too."""
    lo, hi = (x * per_unit if x is not None else None for x in delay)
    k = math.lcm(*(x.denominator for x in (lo, hi) if x is not None))
    return scaled(stnu, k), ObservationDelay(int(lo * k), None if hi is None else int(hi * k)), k  # type: ignore[operator]


def run(args: argparse.Namespace) -> int:
    stnu, per_unit = read_network_scaled(args.file, derived=args.derived, origin=args.origin)
    delay = None
    if args.observation_delay is not None:
        stnu, delay, factor = delay_in_ticks(stnu, per_unit, args.observation_delay)
        per_unit *= factor
    start = time.perf_counter()
    result = check_dc(stnu, args.algorithm) if delay is None else check_delay(stnu, delay, args.algorithm)
    seconds = time.perf_counter() - start
    edges = stnu.n_edges
    if args.json:
        print(json.dumps({
            "file": str(args.file),
            "algorithm": args.algorithm,
            "verdict": result.verdict.value,
            "consistent": result.consistent,
            "nodes": len(stnu.timepoints),
            "edges": edges,
            "contingent": len(stnu.contingents),
            "seconds": round(seconds, 6),
            "cycle": [e.to_json() for e in result.cycle],
            **({} if delay is None else {"observation_delay": _delay_json(args.observation_delay),
                                         "ticks_per_unit": per_unit}),
        }))
        return 0
    if delay is None:
        print(result.verdict.value)
    else:
        print(f"{result.verdict.value} at observation delay {_delay_text(args.observation_delay)}")
    print(f"{show_path(args.file)}: {len(stnu.timepoints)} nodes, {edges} edges, {len(stnu.contingents)} "
          f"contingent links, checked in {seconds * 1000:.1f} ms")
    if result.cycle:
        what = "negative cycle" if result.verdict is Verdict.INCONSISTENT else "semi-reducible negative cycle"
        if delay is not None and result.verdict is Verdict.NOT_DC:
            what = ("negative cycle of the network as the robot learns it (C@seen: when C is learnt; ticks of "
                    f"1/{per_unit} unit)")
        print(f"{what} (total {sum(e.value for e in result.cycle)}):")
        for e in result.cycle:
            print(f"  {e}")
    return 0


def _delay_text(delay: tuple[Fraction, Fraction | None]) -> str:
    lo, hi = delay
    if hi is None:
        return "inf" if lo == 0 else f"{_num(lo)}:inf"
    return _num(lo) if lo == hi else f"{_num(lo)}:{_num(hi)}"


def _num(x: Fraction) -> str:
    return str(x.numerator) if x.denominator == 1 else f"{float(x):g}"


def _delay_json(delay: tuple[Fraction, Fraction | None]) -> list[float | None]:
    lo, hi = delay
    return [float(lo), None if hi is None else float(hi)]
