"""`hrc console OUT_DIR [--port 8765] [--host 127.0.0.1] [--simulate-robot] [--speed X] [--log FILE]`:
the operator console, a local web page for the person and the engineer (docs/console.md)."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_parser", "run"]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value <= 1000:
        raise argparse.ArgumentTypeError(f"must lie in (0, 1000], got {text}")
    return value


def add_parser(sub: Any) -> None:
    p = sub.add_parser("console", help="serve the operator console (person's buttons, engineer's view)")
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8765, help="port (default 8765; 0: any free port)")
    p.add_argument("--simulate-robot", action="store_true",
                   help="play the robot: each of its events at the start of its window")
    p.add_argument("--speed", type=_positive, default=1.0,
                   help="run seconds per real second (default 1; e.g. 5 to try a run quickly)")
    p.add_argument("--tick", type=float, default=2.0,
                   help="tell the dispatcher time passed after this many quiet run seconds (0: never)")
    p.add_argument("--log", metavar="FILE", help="the run's log (default OUT_DIR/runs/console-N.jsonl); must be new")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from hrc.console.run import open_console, serve

    server = open_console(args.out_dir, speed=args.speed, log=args.log, simulate_robot=args.simulate_robot,
                          tick=max(0.0, args.tick))

    def ready(url: str) -> None:
        print(f"hrc console: {url}  (log: {server.session.log.path})", flush=True)

    serve(server, args.host, args.port, ready)
    return 0
