"""`hrc console OUT_DIR [--port 8765] [--host 127.0.0.1] [--simulate-robot] [--speed X] [--log FILE]`:
the operator console, a local web page for the person and the engineer (docs/console.md).

It prints, once, the address to open with the run's secret (``http://127.0.0.1:8765/?token=...``, as a
notebook server does), and where a robot controller connects with its own secret. ``--token-file`` and
``--robot-token-file`` read the secrets from files (or write new ones there, mode 0600), so that a robot
controller can be given its token before the console starts. Listening on another address than this
machine's loopback needs ``--allow-remote``. A team (issue 37) gets one address per person (their page:
their buttons, with a secret of their own, new each start) after the shared view's, and one controller
address per robot (``/robot?robot=ID``); with ``--detect motion`` a controller's link also takes the
tracker's positions, each naming its person (``"agent": "alice"``), one detector per person.
SIGINT or SIGTERM stop it cleanly, as ``hrc ros2``: the message being handled finishes, then exit 0 with the
log whole ("stopped by SIGTERM after N messages").
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hrc.cli.argtypes import real, whole
from hrc.cli.detect import add_detect_options, detect_params
from hrc.cli.record import add_record_format
from hrc.errors import HrcError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("console", help="serve the operator console (person's buttons, engineer's view)",
                       description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a --host other machines can reach (plain HTTP: the token travels unencrypted)")
    p.add_argument("--port", type=whole(0, 65535, what="a port number"), default=8765,
                   help="port (default 8765; 0: any free port)")
    p.add_argument("--simulate-robot", action="store_true",
                   help="play the robot: each of its events at the start of its window")
    p.add_argument("--speed", type=real(0, 1000, low_open=True), default=1.0,
                   help="run seconds per real second (default 1; e.g. 5 to try a run quickly)")
    p.add_argument("--tick", type=real(0, 3600, unit="run seconds"), default=2.0,
                   help="tell the dispatcher time passed after this many quiet run seconds (0: never)")
    p.add_argument("--log", metavar="FILE", help="the run's log (default OUT_DIR/runs/console-N.jsonl); must be new")
    p.add_argument("--resume", metavar="LOG", help="continue the run logged in LOG (after a crash), appending to it")
    p.add_argument("--record", metavar="FILE.mcap",
                   help="record the run as MCAP for Foxglove into FILE, a new file (docs/record.md)")
    add_record_format(p)
    p.add_argument("--allow-partial", action="store_true",
                   help="serve a partial compile output (an interrupted compile: not every plan is in it)")
    add_detect_options(p, "the robot endpoint also takes the person's tracked position (a team's: "
                          "each naming its person)")
    p.add_argument("--token-file", metavar="FILE",
                   help="the page's secret: read from FILE, or a new one written there (mode 0600)")
    p.add_argument("--robot-token-file", metavar="FILE",
                   help="the robot controller's secret: read from FILE, or a new one written there (mode 0600)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from hrc.console.access import Credentials, is_loopback, load_or_create_token, new_token
    from hrc.console.run import open_console, serve

    if not is_loopback(args.host) and not args.allow_remote:
        print(f"error: hrc console: --host {args.host} is not this machine's loopback: other machines could "
              "reach the console (over plain HTTP); add --allow-remote if that is meant", file=sys.stderr)
        return 2
    if args.sensor_sigma is not None and args.detect != "motion":
        print("error: hrc console: --sensor-sigma needs --detect motion", file=sys.stderr)
        return 2
    if args.resume and args.log:
        print("error: hrc console: --resume and --log cannot be used together", file=sys.stderr)
        return 2
    page = load_or_create_token(args.token_file) if args.token_file else new_token()
    robot = load_or_create_token(args.robot_token_file) if args.robot_token_file else new_token()
    if page == robot:
        print("error: hrc console: the page and the robot must have different tokens", file=sys.stderr)
        return 2
    server = open_console(args.out_dir, speed=args.speed, log=args.log, simulate_robot=args.simulate_robot,
                          tick=args.tick, credentials=Credentials(page, robot), resume=args.resume,
                          allow_partial=args.allow_partial, record=args.record, record_format=args.record_format,
                          detect=detect_params(args) if args.detect == "motion" else None,
                          report=lambda text: print(f"hrc console: {text}", file=sys.stderr, flush=True))
    if not is_loopback(args.host):
        print(f"hrc console: warning: listening on {args.host}: reachable from other machines, and the "
              "token travels unencrypted", file=sys.stderr)

    session = server.session

    def ready(url: str) -> None:
        print(f"hrc console: {url}?token={page}  (log: {session.log_path})", flush=True)
        if session.team:  # each person's page, after the shared view's (issue 37)
            for person, token in server.credentials.people:  # each with their own secret: their page only
                print(f"hrc console: {person}'s page: {url}?token={token}&person={person}", flush=True)
        if not args.simulate_robot:
            where = f"token in {args.robot_token_file}" if args.robot_token_file else f"token {robot}"
            endpoints = ([(f"{r}'s robot controller", f"robot?robot={r}") for r in session.robots] if session.team
                         else [("robot controller", "robot")])
            for who, path in endpoints:
                print(f"hrc console: {who}: ws{url[4:]}{path}  (Authorization: Bearer; {where})", flush=True)

    recording = server.session.recording
    try:
        stopped = serve(server, args.host, args.port, ready)
    except (HrcError, OSError):
        if recording is not None and recording.recorder.exchanges == 0:
            recording.abort()  # it never served (the port is taken): no file
            recording = None
        raise
    finally:
        if recording is not None and recording.close() is not None:
            print(f"hrc console: recorded {recording.recorder.exchanges} messages into {recording.path}",
                  file=sys.stderr, flush=True)
    # as hrc ros2 ends: a stop by SIGINT or SIGTERM is how a server is meant to end (exit 0, the log whole)
    print(f"hrc console: stopped by {stopped or 'the server'} after {server.session.total} messages; the log "
          f"{server.session.log_path} is complete", file=sys.stderr, flush=True)
    return 0
