"""`hrc dispatch OUT_DIR`: the dispatcher on a compiled plan set, as JSON lines on stdin and stdout.

Each line in is an observation (``{"t": 12.5, "agent": "human", "action": "cube2", "phase": "fetch",
"event": "start"}``, ``away`` / ``back``, ``tick``, ``undo``); each gets exactly one line out, flushed at
once: the decision for the robot, or ``"ok": false`` with a one-line reason (nothing changed). End of
input exits 0. ``--log FILE`` appends every message in and out (fsync'd); ``--replay LOG`` re-runs a log
and prints the same answers, exit 1 if one differs from the logged one. See docs/dispatch.md.
"""

from __future__ import annotations

import argparse
import sys


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("dispatch", help="dispatch a compiled plan set online (JSON lines in and out)",
                              description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("--log", metavar="FILE", help="append every message in and out to FILE (fsync'd)")
    p.add_argument("--replay", metavar="LOG", help="re-run a log written with --log and print its answers")
    p.add_argument("--feasible-only", action="store_true",
                   help="drop plans that are neither DC nor consistent; stop when none is left")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import Log, replay, serve

    if args.replay and args.log:
        raise SystemExit("error: hrc dispatch: --replay and --log cannot be used together")
    dispatcher = Dispatcher.from_folder(args.out_dir, feasible_only=args.feasible_only)
    if args.replay:
        differ = 0
        for number, (out, logged) in enumerate(replay(dispatcher, args.replay), 1):
            print(out, flush=True)
            if logged is not None and out != logged and not differ:
                differ = number
        if differ:
            print(f"error: {args.replay}: answer {differ} differs from the logged one", file=sys.stderr)
            return 1
        return 0
    log = Log(args.log, dispatcher) if args.log else None
    try:
        return serve(dispatcher, sys.stdin.buffer, sys.stdout, log)
    finally:
        if log is not None:
            log.close()
