"""`hrc ros2 OUT_DIR`: the dispatcher of `hrc dispatch` as a ROS 2 node (docs/ros2.md).

Messages of ``hrc dispatch``'s protocol come in as ``std_msgs/String`` on ``NAMESPACE/observations`` and
``NAMESPACE/robot/acks``; every answer goes out on ``NAMESPACE/answers`` and the robot's next drive on
``NAMESPACE/robot/goal`` (``geometry_msgs/PoseStamped`` in ``--frame-id``, for Nav2) and
``NAMESPACE/robot/route`` (after the robot's last phase, its way home to its start); with ``--detect
motion`` the person's tracked pose on ``NAMESPACE/human/pose`` goes to the motion detector. The log
(default ``OUT_DIR/runs/ros2-N.jsonl``, never overwritten) replays with ``hrc dispatch OUT_DIR --replay
LOG``; ``--resume LOG`` goes on after a crash; ``--record FILE`` writes an MCAP recording. A team (issue
37) has ``NAMESPACE/ROBOT/goal``, ``/route`` and ``/acks`` per robot and ``NAMESPACE/PERSON/observations``
and ``NAMESPACE/PERSON/pose`` (the motion detector's) per person. SIGINT or SIGTERM stop it cleanly (exit
0, the log whole). Needs the ``ros2`` extra: ``pip install 'hrc[ros2]'``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from hrc.cli.argtypes import real
from hrc.cli.detect import add_detect_options, open_dispatcher
from hrc.cli.record import add_record_format
from hrc.errors import HrcError

__all__ = ["INSTALL", "add_parser", "run"]

INSTALL = "pip install 'hrc[ros2]'"


def add_parser(sub: Any) -> None:
    p = sub.add_parser("ros2", help="serve the dispatcher as a ROS 2 node (topics in, answers and Nav2 goals out)",
                       description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("--namespace", default="/hrc", help="the topics' namespace (default /hrc)")
    p.add_argument("--log", metavar="FILE", help="the run's log (default OUT_DIR/runs/ros2-N.jsonl); must be new")
    p.add_argument("--resume", metavar="LOG", help="continue the run logged in LOG (after a crash), appending to it")
    p.add_argument("--record", metavar="FILE.mcap",
                   help="record the run as MCAP for Foxglove into FILE, a new file (docs/record.md)")
    add_record_format(p)
    p.add_argument("--frame-id", default="map", help="the frame of goals and poses (default map)")
    p.add_argument("--map-origin", nargs=3, type=real(), default=(0.0, 0.0, 0.0), metavar=("X", "Y", "YAW"),
                   help="the pose of hrc's map origin in that frame: metres, metres, radians (default 0 0 0)")
    p.add_argument("--use-sim-time", action="store_true",
                   help="the node's clock is /clock (run seconds): goals stamped with it, --tick from it")
    p.add_argument("--tick", type=real(0, 3600, unit="seconds"), default=0.0,
                   help="with --use-sim-time: tell the dispatcher time passed after this many quiet /clock "
                        "seconds (default 0: never)")
    p.add_argument("--allow-partial", action="store_true",
                   help="dispatch a partial compile output (an interrupted compile: not every plan is in it)")
    p.add_argument("--feasible-only", action="store_true",
                   help="drop plans that are neither DC nor consistent; stop when none is left")
    p.add_argument("--no-preferences", dest="preferences", action="store_false",
                   help="do not narrow the robot's windows to APA's optimal (DO) windows")
    add_detect_options(p, "the person's tracked pose on human/pose (a team's: PERSON/pose) is read "
                          "(buttons: each pose is refused)")
    p.add_argument("--ros-args", dest="ros_args", nargs=argparse.REMAINDER, default=None,
                   help="everything after it goes to ROS 2 (remappings, parameters), as for any ROS 2 node")
    p.set_defaults(run=run)


def _say(text: str) -> None:
    print(f"hrc ros2: {text}", file=sys.stderr, flush=True)


def _next_log(out_dir: str) -> Path:
    folder = Path(out_dir) / "runs"
    n = 1
    while (folder / f"ros2-{n}.jsonl").exists():
        n += 1
    return folder / f"ros2-{n}.jsonl"


def run(args: argparse.Namespace) -> int:
    try:
        from hrc.ros2 import node as ros_node
    except ImportError as err:  # no extra, or its libraries not found
        print(f"error: hrc ros2 needs ROS 2's Python client ({err}): {INSTALL}", file=sys.stderr)
        return 2
    if args.resume and args.log:
        print("error: hrc ros2: --resume and --log cannot be used together", file=sys.stderr)
        return 2
    if args.tick and not args.use_sim_time:
        print("error: hrc ros2: --tick needs --use-sim-time (the node never reads the wall clock)", file=sys.stderr)
        return 2
    from hrc.compile.output import read_header
    from hrc.dispatch.durable import LoggedDispatcher
    from hrc.dispatch.routes import PlanRoutes, plan_motions
    from hrc.motion import plan_paths
    from hrc.ros2.drive import MapFrame

    dispatcher = open_dispatcher(args, "ros2")
    if dispatcher is None:
        return 2
    plan_routes = PlanRoutes(plan_motions(args.out_dir, dispatcher.plan_set),
                             plan_paths(dispatcher.task, seed=int(read_header(args.out_dir).get("seed", 0))))
    routes = plan_routes.routes
    recording = None
    if args.record:
        from hrc.record import open_folder_recording

        recording = open_folder_recording(args.record, args.out_dir, dispatcher, _say, routes, args.record_format,
                                          ways=plan_routes.way)
    opened: list[Any] = []

    def open_log() -> Any:
        try:
            if args.resume:
                logged, resumed = LoggedDispatcher.resume(dispatcher, args.resume)
                if resumed.torn is not None:
                    _say(f"{args.resume}: {resumed.torn}")
                _say(f"resumed {args.resume} after {resumed.messages} messages (each answered as logged)")
                if recording is not None:
                    recording.feed((m.data, m.answer) for m in resumed.replayed)
            else:
                logged = LoggedDispatcher.create(dispatcher, args.log or _next_log(args.out_dir))
        except (HrcError, OSError):
            if recording is not None:
                recording.abort()
            raise
        if recording is not None:
            logged.listeners.append(recording.listener)
        opened.append(logged)
        return logged

    def ready(node: Any) -> None:
        print(f"hrc ros2: node {node.node.get_fully_qualified_name()} serving {node.node.get_namespace()} "
              f"(log: {node.logged.path})", flush=True)

    frame = MapFrame(args.frame_id, *args.map_origin)
    try:
        stopped = ros_node.serve(open_log, ros_args=["--ros-args", *args.ros_args] if args.ros_args else (),
                                 namespace=args.namespace, frame=frame, routes=routes,
                                 use_sim_time=args.use_sim_time, tick=args.tick, ready=ready, report=_say,
                                 ways=plan_routes.way)
    except (HrcError, OSError):
        if recording is not None and not opened:
            recording.abort()  # refused before the run began: no file
            recording = None
        raise
    finally:
        for logged in opened:
            logged.close()
        if recording is not None and recording.close() is not None:
            _say(f"recorded {recording.recorder.exchanges} messages into {recording.path}")
    _say(f"stopped by {stopped.signal} after {stopped.messages} messages; the log {opened[0].path} is complete")
    return 0
