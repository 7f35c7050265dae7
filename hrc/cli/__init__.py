"""The `hrc` command line: parse arguments, call one function, print, map errors to exit codes.

Subcommands live one per module in this package and are listed in `COMMANDS` (an explicit registry,
no discovery). Each module has ``add_parser(subparsers)`` which registers ``run(args) -> int``.
Exit status: 0 success, 2 bad input or usage (one ``error:`` line on stderr, never a traceback),
130 interrupted.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from typing import NoReturn

from hrc import __version__
from hrc.errors import HrcError

# name -> (module, one-line help). Only the chosen command's module is imported, so `hrc check` does not
# pay for OMPL, networkx or Dask at start-up.
COMMANDS: dict[str, tuple[str, str]] = {
    "show": ("hrc.cli.show", "print a task, its map and its plan count"),
    "paths": ("hrc.cli.paths", "plan every travel on the map with OMPL; table, JSON or picture"),
    "check": ("hrc.cli.check", "check an STNU file: DC, not DC or inconsistent"),
    "compile": ("hrc.cli.compile", "compile a task into its ranked set of HRC schedules (STNUs)"),
    "apa": ("hrc.cli.apa", "compile an STPP (JSON) into its dispatchably optimal form (APA)"),
    "dispatch": ("hrc.cli.dispatch", "dispatch a compiled plan set online (JSON lines in and out)"),
    "detect": ("hrc.cli.detect", "the human action detector: the person's tracked positions in, observations out"),
    "console": ("hrc.cli.console", "serve the operator console: the person's buttons, the engineer's live view"),
    "simulate": ("hrc.cli.simulate", "simulate a person and the robot doing a task, many times; compare policies"),
    "learn": ("hrc.cli.learn", "learn duration bounds and worker types from recorded runs; write a new task"),
    "ros2": ("hrc.cli.ros2", "serve the dispatcher as a ROS 2 node (topics in, answers and Nav2 goals out)"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2, like every other bad input
        self.exit(2, f"error: {self.prog}: {message}\n")


def build_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """The parser; only the command named in `argv` (if any) gets its full set of arguments."""
    parser = _Parser(prog="hrc", description="Compile, check and explain schedules for a person and a mobile "
                                             "robot sharing a shop floor (see README.md).")
    parser.add_argument("--version", action="version", version=f"hrc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    chosen = next((a for a in argv if a in COMMANDS), None)
    for name, (module, help_text) in COMMANDS.items():
        if name == chosen:
            importlib.import_module(module).add_parser(sub)
        else:
            sub.add_parser(name, help=help_text)
    return parser


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt  # SIGTERM is handled like Ctrl-C: clean up, say so, exit 130


_LATE_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_late: list[int] = []  # signals that came once the command had returned (only when `main` is the process)


def _note_late(signum: int, frame: object) -> None:
    _late.append(signum)


def _exit_late() -> None:
    """The process's last Python code (an ``atexit`` function registered before any other of the run:
    they run last first): SIGINT and SIGTERM are blocked from here to the end, and one that came since the
    command returned, or is pending, ends the process with 130 (issue 34: a SIGTERM in the tenth of a
    second after a compile wrote its output, while the interpreter shut down, killed it: status -15)."""
    signal.pthread_sigmask(signal.SIG_BLOCK, _LATE_SIGNALS)
    pending = signal.sigpending() & set(_LATE_SIGNALS)
    if _late or pending:
        name = signal.Signals(_late[0] if _late else min(pending)).name
        with contextlib.suppress(Exception):
            print(f"error: interrupted ({name}) as hrc ended; what it wrote was complete", file=sys.stderr)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(130)


@contextlib.contextmanager
def _sigterm_as_interrupt(process: bool) -> Iterator[None]:
    """SIGTERM as KeyboardInterrupt for the command. `process`: `main` is the process (its entry point):
    afterwards SIGINT and SIGTERM are only noted until it exits, then exit it with 130 (`_exit_late`),
    rather than the default action killing it (status -15) or a KeyboardInterrupt in its shutdown."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if process:
        atexit.register(_exit_late)
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        yield
    finally:
        if process:
            for sig in _LATE_SIGNALS:
                signal.signal(sig, _note_late)
        else:
            signal.signal(signal.SIGTERM, previous)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command `argv` (default: the process's arguments; then `main` is taken to be the process's
    entry point, and a signal after the command returned still ends the process with 130). Returns the
    exit status."""
    process = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    try:
        with _sigterm_as_interrupt(process):
            return int(args.run(args))
    except HrcError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `hrc paths ... | head`
        return 0
    except OSError as err:  # the machine's answer (a folder where a file goes, no space, no permission)
        where = f"{err.filename}: " if err.filename else ""
        print(f"error: {where}{err.strerror or err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
