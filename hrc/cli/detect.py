"""`hrc detect OUT_DIR [TRACE] [--out FILE]`: the human action detector on a trace of positions.

Reads JSON lines ``{"t": 12.3, "x": 4.1, "y": 2.0}`` (the person's position in the map's metres, from
TRACE or standard input; other keys ignored) and writes the observations ``hrc dispatch OUT_DIR`` takes
as the person's (depart, arrive, start, end, at the times the detector estimates they happened), in
time order, to standard output as they are found, or to FILE (written atomically at the end). A bad line
is refused with one line on standard error and skipped. A team's positions (more than one person, issue
37) name their person, ``"agent": "alice"``: one detector per person. See docs/detect.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from hrc.cli.argtypes import real

__all__ = ["add_detect_options", "add_parser", "detect_params", "open_dispatcher", "run"]


def add_detect_options(p: argparse.ArgumentParser, positions: str | None = None) -> None:
    """The detector's settings, shared by `hrc detect`, `hrc dispatch`, `hrc console` and `hrc ros2`; the
    last three also get ``--detect buttons|motion``, `positions` saying where their positions come from."""
    if positions is not None:
        p.add_argument("--detect", choices=("buttons", "motion"), default="buttons",
                       help=f"motion: {positions}, the motion detector reports their events (docs/detect.md)")
    p.add_argument("--sensor-sigma", type=real(0, 5, unit="metres"), default=None, metavar="M",
                   help="the tracker's position noise (m, per axis) the detector assumes (default 0.05)")


def detect_params(args: argparse.Namespace) -> Any:
    from hrc.detect import DetectParams

    return DetectParams() if args.sensor_sigma is None else DetectParams(sigma=max(args.sensor_sigma, 0.01))


def open_dispatcher(args: argparse.Namespace, command: str) -> Any:
    """The dispatcher `hrc dispatch` and `hrc ros2` serve on ``args.out_dir``: with the motion detector in
    front of it (``--detect motion``) or not. None, after one ``error:`` line, for ``--sensor-sigma``
    without ``--detect motion``."""
    from hrc.dispatch import Dispatcher

    options = dict(allow_partial=args.allow_partial, feasible_only=args.feasible_only,
                   use_preferences=args.preferences,
                   max_observation_delay=getattr(args, "max_observation_delay", None))
    if args.detect == "motion":
        from hrc.detect import DetectingDispatcher

        return DetectingDispatcher.from_folder(args.out_dir, params=detect_params(args), **options)
    if args.sensor_sigma is not None:
        print(f"error: hrc {command}: --sensor-sigma needs --detect motion", file=sys.stderr)
        return None
    return Dispatcher.from_folder(args.out_dir, **options)


def add_parser(sub: Any) -> None:
    p = sub.add_parser("detect", help="the human action detector: a trace of positions in, observations out",
                       description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("out_dir", metavar="OUT_DIR", help="an `hrc compile` output folder")
    p.add_argument("trace", metavar="TRACE", nargs="?", default="-",
                   help="JSON lines of positions (default: standard input)")
    p.add_argument("--out", metavar="FILE", help="write the observations to FILE (atomically) instead of stdout")
    p.add_argument("--allow-partial", action="store_true", help="use a partial compile output")
    add_detect_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from hrc.detect import DetectingDispatcher
    from hrc.detect.trace import Refusal, detect_lines
    from hrc.errors import InputError
    from hrc.io.atomic import write_text_atomic

    params = detect_params(args)
    d = DetectingDispatcher.from_folder(args.out_dir, allow_partial=args.allow_partial, params=params)
    assert isinstance(d, DetectingDispatcher)
    if args.trace == "-":
        source = sys.stdin.buffer
    else:
        try:
            source = open(args.trace, "rb")  # noqa: SIM115 - closed below
        except OSError as err:
            raise InputError(args.trace, "", f"cannot read it ({err.strerror or err})") from err
    name = "stdin" if args.trace == "-" else args.trace
    lines: list[str] = []

    try:
        for item in detect_lines(d, source):
            if isinstance(item, Refusal):

                print(f"hrc detect: {name}: {item}", file=sys.stderr, flush=True)
                continue
            text = json.dumps(item)
            if args.out:
                lines.append(text)
            else:
                print(text, flush=True)
    finally:
        if source is not sys.stdin.buffer:
            source.close()
    if args.out:
        write_text_atomic(Path(args.out), "".join(line + "\n" for line in lines))
    return 0
