"""`hrc check FILE`: is an STNU file dynamically controllable?

Prints ``DC``, ``not DC`` (with the semi-reducible negative cycle that proves it) or ``inconsistent``
(with the negative cycle of its STN), the node / edge / contingent-link counts and the time the check
took. ``--json`` prints one JSON object instead. Exit 0 whatever the verdict; 2 for a bad file (one
``error:`` line; a file in none of the formats is "not an STNU file" with the formats accepted).
The format (CSTNU Tool GraphML, ``.stnu`` text, HEATlab JSON) is detected from the content; a timepoint
named ``Z`` in GraphML or ``.stnu`` text is the origin unless ``--no-origin`` (see docs/temporal.md).
"""

from __future__ import annotations

import argparse
import json
import time

from hrc.temporal.dc import ALGORITHMS, DEFAULT_ALGORITHM, Verdict, check_dc
from hrc.temporal.graphml import read_network
from hrc.temporal.limits import show_path

__all__ = ["add_parser", "run"]


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
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    stnu = read_network(args.file, derived=args.derived, origin=args.origin)
    start = time.perf_counter()
    result = check_dc(stnu, args.algorithm)
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
        }))
        return 0
    print(result.verdict.value)
    print(f"{show_path(args.file)}: {len(stnu.timepoints)} nodes, {edges} edges, {len(stnu.contingents)} "
          f"contingent links, checked in {seconds * 1000:.1f} ms")
    if result.cycle:
        what = "negative cycle" if result.verdict is Verdict.INCONSISTENT else "semi-reducible negative cycle"
        print(f"{what} (total {sum(e.value for e in result.cycle)}):")
        for e in result.cycle:
            print(f"  {e}")
    return 0
