"""Run ``hrc`` with a fault injected: a signal sent to this very process at a named point of the code.

Usage (from the fault-injection tests, `tests/test_compile_faults.py`)::

    python tests/fault_driver.py --at MODULE:NAME[.ATTR][@K] --signal TERM|INT|KILL [--after] [--match TEXT] \
        -- compile TASK --out OUT ...
    python tests/fault_driver.py --after-main --signal TERM|INT -- compile TASK --out OUT ...
    python tests/fault_driver.py --in-pymunk-callback TERM -- compile TASK --out OUT ...

``--at``: the K-th call (default 1) of that function (with ``--match``, counting only calls whose
arguments' text holds TEXT) sends the signal to this process just before it runs (``--after``: just
after it returned). A SIGKILL is a power cut there; a SIGTERM or SIGINT is what a user or the system
sends, handled by the real code as it would be at that instant.

``--after-main``: the signal once hrc's ``main`` has returned its status (the process is shutting
down: what remains is the interpreter's exit).

``--in-pymunk-callback``: before the compile plans its paths, a pymunk collision callback (a C callback,
through cffi, which prints and swallows any exception raised in it) sends the signal from inside itself:
the way a SIGTERM lands in pymunk's garbage-collection callbacks during a compile.

No mock replaces anything: the real `hrc.cli.main` runs; only the signal's timing is chosen.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import signal
import sys
from typing import Any


def _signal_self(name: str) -> None:
    os.kill(os.getpid(), getattr(signal, f"SIG{name}"))


def _wrap_at(spec: str, sig: str, after: bool, match: str | None) -> None:
    where, _, nth = spec.partition("@")
    module_name, _, path = where.partition(":")
    owner: Any = importlib.import_module(module_name)
    *parents, attr = path.split(".")
    for part in parents:
        owner = getattr(owner, part)
    real = getattr(owner, attr)
    wanted = int(nth or 1)
    calls = [0]

    @functools.wraps(real)
    def faulty(*args: Any, **kwargs: Any) -> Any:
        if match is None or match in repr((args, kwargs)):
            calls[0] += 1
        hit = calls[0] == wanted and (match is None or match in repr((args, kwargs)))
        if hit and not after:
            _signal_self(sig)
        result = real(*args, **kwargs)
        if hit and after:
            _signal_self(sig)
        return result

    if isinstance(owner, type) and isinstance(owner.__dict__.get(attr), staticmethod):
        setattr(owner, attr, staticmethod(faulty))
    else:
        setattr(owner, attr, faulty)


def _in_pymunk_callback(sig: str) -> None:
    """Wrap the compile's path planning so that it first steps a pymunk space whose collision callback
    signals this process from inside the C callback."""
    import pymunk

    import hrc.compile.stream as stream

    real = stream.plan_paths

    def begin(arbiter: Any, space: Any, data: Any) -> None:
        _signal_self(sig)
        for _ in range(1000):  # bytecodes for the interpreter to run the handler here, inside the callback
            pass

    @functools.wraps(real)
    def planning(*args: Any, **kwargs: Any) -> Any:
        space = pymunk.Space()
        for x in (0.0, 0.5):
            body = pymunk.Body(1, 1)
            body.position = (x, 0)
            space.add(body, pymunk.Circle(body, 1))
        space.on_collision(begin=begin)
        space.step(0.01)
        return real(*args, **kwargs)

    stream.plan_paths = planning


def main() -> int:
    argv = sys.argv[1:]
    cut = argv.index("--")
    p = argparse.ArgumentParser()
    p.add_argument("--at")
    p.add_argument("--signal", default="TERM")
    p.add_argument("--after", action="store_true")
    p.add_argument("--match")
    p.add_argument("--in-pymunk-callback", metavar="SIGNAL")
    p.add_argument("--after-main", action="store_true", help="the signal once hrc's main has returned")
    args = p.parse_args(argv[:cut])
    if args.at:
        _wrap_at(args.at, args.signal, args.after, args.match)
    if args.in_pymunk_callback:
        _in_pymunk_callback(args.in_pymunk_callback)
    from hrc.cli import main as hrc_main

    sys.argv = [sys.argv[0], *argv[cut + 1:]]  # as the `hrc` command runs it: main is the process
    code = hrc_main()
    if args.after_main:
        _signal_self(args.signal)
    return code


if __name__ == "__main__":
    sys.exit(main())
