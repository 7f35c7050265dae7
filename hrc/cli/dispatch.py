"""`hrc dispatch OUT_DIR`: the dispatcher on a compiled plan set, as JSON lines on stdin and stdout.

Each line in is an observation (``{"t": 12.5, "agent": "human", "action": "cube2", "phase": "fetch",
"event": "start"}``, ``away`` / ``back``, ``tick``, ``undo``); each gets exactly one line out, flushed at
once: the decision for the robot, or ``"ok": false`` with a one-line reason (nothing changed). End of
input exits 0. ``--log FILE`` writes every message to a new log before it counts (fsync'd);
``--resume LOG`` rebuilds a crashed run from its log and goes on appending to it; ``--replay LOG``
re-runs a log and prints the same answers, exit 1 if one differs from the logged one. ``--record
FILE`` writes the run (the resumed or replayed one too) as an MCAP file for Foxglove (docs/record.md).
See docs/dispatch.md.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hrc.cli.argtypes import real
from hrc.cli.detect import add_detect_options, open_dispatcher
from hrc.cli.record import add_record_format
from hrc.errors import HrcError

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("dispatch", help="dispatch a compiled plan set online (JSON lines in and out)",
                              description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("--log", metavar="FILE", help="log every message in and out to FILE, a new file (fsync'd "
                                                 "before the answer)")
    p.add_argument("--resume", metavar="LOG", help="rebuild the run logged in LOG (after a crash) and go on "
                                                   "appending to it")
    p.add_argument("--replay", metavar="LOG", help="re-run a log written with --log and print its answers")
    p.add_argument("--record", metavar="FILE.mcap",
                   help="record the run as MCAP for Foxglove into FILE, a new file (docs/record.md)")
    add_record_format(p)
    p.add_argument("--allow-partial", action="store_true",
                   help="dispatch a partial compile output (an interrupted compile: not every plan is in it)")
    p.add_argument("--feasible-only", action="store_true",
                   help="drop plans that are neither DC nor consistent; stop when none is left")
    add_detect_options(p, "also take the person's tracked position ({\"t\", \"agent\": \"human\", \"event\": "
                          "\"position\", \"x\", \"y\"})")
    p.add_argument("--max-observation-delay", metavar="S", type=real(0, 3600, unit="seconds"), default=None,
                   help="the longest an observation of the person may reach the dispatcher after it happened "
                        "(its \"delay\"); a later one voids the guarantee and the answer says so "
                        "(\"deviation\"); default: none stated")
    p.add_argument("--no-preferences", dest="preferences", action="store_false",
                   help="do not narrow the robot's windows to APA's optimal (DO) windows where the task has "
                        "preferences")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    given = [f"--{name}" for name in ("log", "resume", "replay") if getattr(args, name)]
    if len(given) > 1:
        print(f"error: hrc dispatch: {' and '.join(given)} cannot be used together", file=sys.stderr)
        return 2
    dispatcher = open_dispatcher(args, "dispatch")
    if dispatcher is None:
        return 2
    recording = None
    if args.record:
        from hrc.record import open_folder_recording

        recording = open_folder_recording(args.record, args.out_dir, dispatcher, report=_say, fmt=args.record_format)
    try:
        status = _run(args, dispatcher, recording)
    except (HrcError, OSError):
        if recording is not None and recording.recorder.exchanges == 0:
            recording.abort()  # refused before anything happened (a log in use, another compiled set): no file
            recording = None
        raise
    finally:
        if recording is not None and recording.close() is not None:
            _say(f"recorded {recording.recorder.exchanges} messages into {recording.path}")
    return status


def _say(text: str) -> None:
    print(f"hrc dispatch: {text}", file=sys.stderr, flush=True)


def _run(args: argparse.Namespace, dispatcher: Any, recording: Any) -> int:
    from hrc.dispatch.durable import LoggedDispatcher
    from hrc.dispatch.logfile import read_log
    from hrc.dispatch.protocol import replay
    from hrc.dispatch.stdio import serve

    if args.replay:
        contents = read_log(args.replay)
        if contents.torn is not None:
            print(f"hrc dispatch: {args.replay}: {contents.torn}", file=sys.stderr, flush=True)
        differ: tuple[int, int] | None = None
        for number, ((out, was), message) in enumerate(zip(replay(dispatcher, contents, args.replay),
                                                           contents.messages, strict=True), 1):
            print(out, flush=True)
            if recording is not None:
                recording.listener(message.data, out)
            if out != was and differ is None:
                differ = (number, message.line)
        if differ is not None:
            print(f"error: {args.replay}:{differ[1]}: answer {differ[0]} differs from the logged one",
                  file=sys.stderr)
            return 1
        return 0
    if args.resume:
        logged, resumed = LoggedDispatcher.resume(dispatcher, args.resume)
        if resumed.torn is not None:
            print(f"hrc dispatch: {args.resume}: {resumed.torn}", file=sys.stderr, flush=True)
        print(f"hrc dispatch: resumed {args.resume} after {resumed.messages} messages (each answered as logged)",
              file=sys.stderr, flush=True)
        if recording is not None:
            recording.feed((m.data, m.answer) for m in resumed.replayed)
    elif args.log:
        logged = LoggedDispatcher.create(dispatcher, args.log)
    else:
        logged = LoggedDispatcher(dispatcher)
    if recording is not None:
        logged.listeners.append(recording.listener)
    try:
        return serve(logged, sys.stdin.fileno(), sys.stdout)
    finally:
        logged.close()
