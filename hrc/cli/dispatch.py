"""`hrc dispatch OUT_DIR`: the dispatcher on a compiled plan set, as JSON lines on stdin and stdout.

Each line in is an observation (``{"t": 12.5, "agent": "human", "action": "cube2", "phase": "fetch",
"event": "start"}``, ``away`` / ``back``, ``tick``, ``undo``); each gets exactly one line out, flushed at
once: the decision for the robot, or ``"ok": false`` with a one-line reason (nothing changed). End of
input exits 0. ``--log FILE`` writes every message to a new log before it counts (fsync'd);
``--resume LOG`` rebuilds a crashed run from its log and goes on appending to it; ``--replay LOG``
re-runs a log and prints the same answers, exit 1 if one differs from the logged one. ``--record
FILE`` writes the run (the resumed or replayed one too) as an MCAP file for Foxglove (docs/record.md).
Any team is served (issue 37): a task of other than one person and one robot is answered per agent
(``"robots": {ID: step}``, ``"people": {ID: hint}``); with ``--detect motion`` each position names its
person (``"agent": "alice"``), who has a detector of their own (docs/detect.md, "A team").
See docs/dispatch.md.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hrc.cli.argtypes import real, whole
from hrc.cli.detect import add_detect_options, open_dispatcher
from hrc.cli.record import add_record_format
from hrc.errors import HrcError, InputError

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
    p.add_argument("--on-demand", choices=("auto", "on", "off"), default="auto",
                   help="when what the person does leaves every compiled plan: answer with the safe fallback "
                        "and compile plans that extend what was seen in the background (docs/dispatch.md, "
                        "\"Compile on demand\"); auto (default): on for a searched compile (hrc compile "
                        "--plans best:K), off (refuse such a message) for an exhaustive one. --replay and "
                        "--resume take it from the log")
    p.add_argument("--on-demand-plans", metavar="K", type=whole(1, 1000), default=None,
                   help="plans asked for per compile on demand (default 3)")
    p.add_argument("--on-demand-families", metavar="N", type=whole(1, 100000), default=None,
                   help="budget of one compile on demand, in families compiled (default 6: the same plans on "
                        "any machine)")
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
    _on_demand(args, dispatcher)
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


def _on_demand(args: argparse.Namespace, dispatcher: Any) -> None:
    """Compile on demand as asked (``--on-demand``), or as the log to replay or resume was written."""
    from hrc.compile.extend import EXTEND_FAMILIES, EXTEND_K
    from hrc.compile.output import read_header
    from hrc.dispatch.on_demand import OnDemandSettings, enable

    plans = args.on_demand_plans or EXTEND_K
    families = args.on_demand_families or EXTEND_FAMILIES
    log = args.replay or args.resume
    if log:
        from hrc.dispatch.logfile import read_log

        found = read_log(log).header.get("on_demand")
        if not isinstance(found, dict):
            return
        plans, families = found.get("plans", plans), found.get("families", families)
        if isinstance(plans, bool) or not isinstance(plans, int) or isinstance(families, bool) or \
                not isinstance(families, int):
            raise InputError(str(log), "on_demand", "plans and families must be whole numbers")
    elif args.on_demand == "off" or (args.on_demand == "auto" and "search" not in read_header(args.out_dir)):
        return
    if getattr(args, "detect", None) == "motion":  # the detector's belief is over the plans it was given
        if args.on_demand == "on":
            raise InputError("--on-demand", "", "compile on demand does not work with --detect motion yet")
        return
    enable(dispatcher, OnDemandSettings.of_folder(args.out_dir, plans, families))


def _say(text: str) -> None:
    print(f"hrc dispatch: {text}", file=sys.stderr, flush=True)


def _run(args: argparse.Namespace, dispatcher: Any, recording: Any) -> int:
    from hrc.dispatch.durable import LoggedDispatcher
    from hrc.dispatch.logfile import read_log
    from hrc.dispatch.on_demand import Replay
    from hrc.dispatch.stdio import serve

    if args.replay:
        contents = read_log(args.replay)
        if contents.torn is not None:
            print(f"hrc dispatch: {args.replay}: {contents.torn}", file=sys.stderr, flush=True)
        differ: tuple[int, int] | None = None
        for number, ((out, was), message) in enumerate(zip(Replay(dispatcher, contents, args.replay),
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
    on_demand = None
    settings = getattr(dispatcher, "on_demand", None)
    if settings is not None:
        from hrc.dispatch.on_demand import OnDemand, wanted

        on_demand = OnDemand(dispatcher.task, settings)
        on_demand.ask(wanted(logged.dispatcher))  # a resumed run may have been left without a plan
    try:
        return serve(logged, sys.stdin.fileno(), sys.stdout, on_demand)
    finally:
        logged.close()
