"""The `hrc` command line: parse arguments, call one function, print, map errors to exit codes.

Subcommands live one per module in this package and are listed in `COMMANDS` (an explicit registry,
no discovery). Each module has ``add_parser(subparsers)`` which registers ``run(args) -> int``.
Exit status: 0 success, 2 bad input or usage (one ``error:`` line on stderr, never a traceback),
130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from hrc import __version__
from hrc.errors import HrcError

# name -> module (imported lazily so that `hrc show` does not pay for OMPL or Dask)
COMMANDS: dict[str, str] = {
    "show": "hrc.cli.show",
    "paths": "hrc.cli.paths",
    "check": "hrc.cli.check",
    "compile": "hrc.cli.compile",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2, like every other bad input
        self.exit(2, f"error: {self.prog}: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="hrc", description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--version", action="version", version=f"hrc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for module in COMMANDS.values():
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as err:  # a command whose module is not there yet
            if err.name != module:
                raise
            continue
        mod.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args))
    except HrcError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
