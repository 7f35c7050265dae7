"""The dispatcher's C core (``hrc/dispatch/_dispatchcore.c``, in the library `hrc.temporal.rul.native_library`
loads) through ctypes: many plans of a dispatch form evaluated under one state in one call.

`NativeForm` holds a `hrc.compile.dispatch_form.DispatchForm`'s arrays in the layout the core reads (the
memory-mapped files themselves where their types fit, small contiguous copies of two columns of
``plans.npy``) and `NativeForm.evaluate` runs the core on a list of plans. Each thread gets its own
workspace (the core's buffers are reused from one plan to the next, and ctypes lets other threads run
during the call). `available` says whether the core is built; without it the dispatcher evaluates in
Python (`hrc.dispatch.fastnet`), with the same results.
"""

from __future__ import annotations

import ctypes
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from hrc.compile.dispatch_form import DispatchForm
from hrc.temporal.rul import native_library

__all__ = ["MODES", "NO_BOUND", "NO_FINISH", "RANK_BY", "NativeForm", "available", "default_threads"]

NO_FINISH = np.iinfo(np.int64).min
"""The finish the core gives a plan that has no schedule at all."""
RANK_BY = {"worst": 0, "earliest": 1, "nominal": 2}
MODES = ("DC", "STN", "EARLIEST")
"""`hrc.temporal.execution.ExecutionMode` by the core's number for it."""
NO_BOUND = np.iinfo(np.int64).max
"""A window's latest tick when it has none."""

_p = ctypes.c_void_p
_I8, _I4, _U1 = np.dtype("<i8"), np.dtype("<i4"), np.dtype("u1")


class _Form(ctypes.Structure):
    _fields_ = [("plans", ctypes.c_int32), ("agents", ctypes.c_int32), ("legs", ctypes.c_int32),
                ("n", _p), ("blocked", _p), ("nodes", _p), ("edges_ptr", _p), ("eu", _p), ("ev", _p),
                ("ew32", _p), ("ew64", _p), ("conts_ptr", _p), ("ca", _p), ("cc", _p), ("clb32", _p),
                ("cub32", _p), ("clb64", _p), ("cub64", _p)]


class _State(ctypes.Structure):
    _fields_ = [("seen", _p), ("legs_seen", _p), ("now", ctypes.c_int64), ("rank_by", ctypes.c_int32)]


def _load() -> tuple[Any, Any, Any, Any] | None:
    lib = native_library()
    if lib is None or not hasattr(lib, "hrc_dispatch_windows"):
        return None
    new, free, run = lib.hrc_dispatch_work_new, lib.hrc_dispatch_work_free, lib.hrc_dispatch_evaluate
    new.argtypes, new.restype = [], _p
    free.argtypes, free.restype = [_p], None
    run.argtypes = [ctypes.POINTER(_Form), ctypes.POINTER(_State), _p, ctypes.c_int, _p, _p, _p, _p, _p]
    run.restype = ctypes.c_int
    windows = lib.hrc_dispatch_windows
    windows.argtypes = [ctypes.POINTER(_Form), ctypes.POINTER(_State), _p, ctypes.c_int64, _p, ctypes.c_int, _p, _p,
                        _p, _p, _p, _p]
    windows.restype = ctypes.c_int
    return new, free, run, windows


_CORE = _load()


def available() -> bool:
    """Whether the C core is built (else the dispatcher evaluates in Python)."""
    return _CORE is not None


class _Workspace:
    """A core workspace, freed with this object."""

    def __init__(self) -> None:
        assert _CORE is not None
        self.handle = _CORE[0]()
        if not self.handle:
            raise MemoryError("the dispatcher's core could not allocate its workspace")

    def __del__(self) -> None:
        if _CORE is not None and getattr(self, "handle", None):
            _CORE[1](self.handle)
            self.handle = None


_LOCAL = threading.local()
_PER_THREAD = 96  # plans: fewer per thread than this and a thread costs more than it saves (~1 ms of work)
_POOLS: dict[int, ThreadPoolExecutor] = {}


def default_threads() -> int:
    """Threads for a large message by default: the cores this process may use, at most 4."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(4, cores))


def _pool(threads: int) -> ThreadPoolExecutor:
    """A pool of `threads` threads, made once per size and kept (the core's calls release the GIL)."""
    pool = _POOLS.get(threads)
    if pool is None:
        pool = _POOLS[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="hrc-rank")
    return pool


def _workspace() -> _Workspace:
    ws = getattr(_LOCAL, "ws", None)
    if ws is None:
        ws = _LOCAL.ws = _Workspace()
    return ws


def _array(values: Any, dtype: str) -> np.ndarray:
    """`values` as a C-contiguous array of `dtype` (the array itself, memory-mapped or not, when it is one)."""
    return np.ascontiguousarray(values, dtype=np.dtype(dtype))


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None else a.ctypes.data


class NativeForm:
    """A dispatch form as the C core reads it (see the module docstring). Raises RuntimeError when the
    core is not built (`available`)."""

    def __init__(self, form: DispatchForm) -> None:
        if _CORE is None:
            raise RuntimeError("the dispatcher's C core is not built (pip install with a C compiler)")
        G, L = form.nodes.shape[1], form.nodes.shape[2]
        wide = form.edges_w.dtype.itemsize == 8 or form.conts_lb.dtype.itemsize == 8
        w = "<i8" if wide else "<i4"
        self._keep = keep = {
            "n": _array(form.plans["n"], "<u2"), "blocked": _array(form.plans["blocked"], "u1"),
            "nodes": _array(form.nodes, "<i2"), "edges_ptr": _array(form.edges_ptr, "<i8"),
            "eu": _array(form.edges_u, "<u2"), "ev": _array(form.edges_v, "<u2"), "ew": _array(form.edges_w, w),
            "conts_ptr": _array(form.conts_ptr, "<i8"), "ca": _array(form.conts_a, "<u2"),
            "cc": _array(form.conts_c, "<u2"), "clb": _array(form.conts_lb, w), "cub": _array(form.conts_ub, w)}
        self.struct = _Form(len(form.plans), G, L, _ptr(keep["n"]), _ptr(keep["blocked"]), _ptr(keep["nodes"]),
                            _ptr(keep["edges_ptr"]), _ptr(keep["eu"]), _ptr(keep["ev"]),
                            None if wide else _ptr(keep["ew"]), _ptr(keep["ew"]) if wide else None,
                            _ptr(keep["conts_ptr"]), _ptr(keep["ca"]), _ptr(keep["cc"]),
                            None if wide else _ptr(keep["clb"]), None if wide else _ptr(keep["cub"]),
                            _ptr(keep["clb"]) if wide else None, _ptr(keep["cub"]) if wide else None)
        self.shape = (G, L)

    def evaluate(self, plans: np.ndarray, seen: np.ndarray, legs_seen: np.ndarray, now: int, rank_by: str,
                 times: np.ndarray | None = None, threads: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(cls, finish, idle)`` of each of `plans` (indices) under the state: `seen` (G, L, 6) int64
        ticks (-1: not seen), `legs_seen` (G,) the legs seen per agent, `now` in ticks. A class of -1
        marks a plan the core could not evaluate (out of memory). `times`: filled with the schedule of
        the last plan (ticks per timepoint) when it has one. `threads`: split a long list of plans into
        that many parts evaluated at once (each plan's result does not depend on the split)."""
        assert _CORE is not None
        plans = np.ascontiguousarray(plans, dtype=_I8)
        seen = np.ascontiguousarray(seen, dtype=_I8)
        legs_seen = np.ascontiguousarray(legs_seen, dtype=_I4)
        state = _State(seen.ctypes.data, legs_seen.ctypes.data, int(now), RANK_BY[rank_by])
        count = len(plans)
        cls = np.empty(count, dtype=np.int8)
        finish = np.empty(count, dtype=np.int64)
        idle = np.empty(count, dtype=np.int64)
        # each array's address asked of numpy once (a message evaluates a few plans: this is most of the call)
        at = (plans.ctypes.data, cls.ctypes.data, finish.ctypes.data, idle.ctypes.data, _ptr(times))
        parts = min(threads, count // _PER_THREAD) if times is None else 1
        if parts > 1:
            def run(lo: int, hi: int) -> None:
                assert _CORE is not None
                _CORE[2](ctypes.byref(self.struct), ctypes.byref(state), _workspace().handle, hi - lo,
                         at[0] + 8 * lo, at[1] + lo, at[2] + 8 * lo, at[3] + 8 * lo, at[4])

            cuts = [count * i // parts for i in range(parts + 1)]
            list(_pool(parts).map(run, cuts[:-1], cuts[1:]))
        elif count:
            _CORE[2](ctypes.byref(self.struct), ctypes.byref(state), _workspace().handle, count, *at)
        return cls, finish, idle

    def windows(self, p: int, seen: np.ndarray, legs_seen: np.ndarray, now: int, mode: str, queries: list[int],
                uncontrolled: np.ndarray) -> tuple[str, list[tuple[int, int] | list[int]]] | None:
        """The execution windows of plan `p`'s timepoints `queries` under the state (see
        `hrc.temporal.execution.RealTimeState.step`; `mode` a name of `MODES`, made stricter where the
        residual says so): the mode used and, per query, ``(earliest, latest)`` (latest `NO_BOUND`: none)
        or the timepoints it must wait for. `uncontrolled` (len(queries), n) bool: the co-worker's own
        executables, per query. None when the core cannot (out of memory, numbers too large)."""
        assert _CORE is not None
        n = int(self._keep["n"][p])
        seen = np.ascontiguousarray(seen, dtype=_I8)
        legs_seen = np.ascontiguousarray(legs_seen, dtype=_I4)
        state = _State(seen.ctypes.data, legs_seen.ctypes.data, int(now), 0)
        nq = len(queries)
        code = ctypes.c_int(MODES.index(mode))
        q = np.array(queries, dtype=np.int32)
        unc = np.ascontiguousarray(uncontrolled, dtype=_U1).reshape(nq, n)
        # the outputs in one block, one address asked of numpy: earliest, latest (int64), waits, until (int32)
        out_ = np.zeros(2 * nq + (nq + max(1, nq * n) + 1) // 2, dtype=np.int64)
        base = out_.ctypes.data
        earliest, latest = out_[:nq], out_[nq:2 * nq]
        small = out_[2 * nq:].view(np.int32)
        waits, until = small[:nq], small[nq:]
        rc = _CORE[3](ctypes.byref(self.struct), ctypes.byref(state), _workspace().handle, p, ctypes.byref(code), nq,
                      q.ctypes.data, unc.ctypes.data, base, base + 8 * nq, base + 16 * nq, base + 16 * nq + 4 * nq)
        if rc != 0:
            return None
        out: list[tuple[int, int] | list[int]] = []
        for i, (w, lo, hi) in enumerate(zip(waits.tolist(), earliest.tolist(), latest.tolist(), strict=True)):
            out.append(until[i * n:i * n + w].tolist() if w else (lo, hi))
        return MODES[code.value], out
