"""Shortest distances in an STN's distance graph from the native core (``hrc/temporal/_stncore.c``).

The compiler measures every plan's network several times (earliest and worst-case schedules, the bound
of every route choice, the search's starting matrices); in Python that is most of a plan's time. These
wrappers take a network as index arrays (`hrc.temporal.rul.edge_arrays`: ``T(dst[i]) - T(src[i]) <=
wt[i]``) and return None when the library is not built or the numbers are too large for 64-bit sums:
callers then use their Python implementation, which gives the same numbers (tests compare them).
"""

from __future__ import annotations

import ctypes
from array import array
from collections.abc import Callable, Sequence

import numpy as np

from hrc.temporal.rul import native_library

__all__ = ["MAX_NODES", "MAX_WEIGHT", "native_apsp", "native_distances"]

MAX_WEIGHT = 1 << 40
"""|weight| below this: no sum of a few million of them overflows int64 or loses float64 precision."""
MAX_NODES = 1 << 20
"""Timepoints below this: indices fit the core's 32-bit arrays with room to spare."""
_BAD_INDEX = -2  # the core's answer to an edge end (or z) outside 0..n-1: nothing read or written


def _load() -> tuple[Callable[..., int] | None, Callable[..., int] | None]:
    lib = native_library()
    dist = getattr(lib, "hrc_stn_distances", None) if lib is not None else None
    apsp = getattr(lib, "hrc_stn_apsp", None) if lib is not None else None
    p = ctypes.c_void_p
    if dist is not None:
        dist.argtypes = [ctypes.c_int, ctypes.c_int, p, p, p, ctypes.c_int, p]
        dist.restype = ctypes.c_int
    if apsp is not None:
        apsp.argtypes = [ctypes.c_int, ctypes.c_int, p, p, p, p]
        apsp.restype = ctypes.c_int
    return dist, apsp  # type: ignore[return-value]


_DIST, _APSP = _load()


def _arrays(n: int, src: Sequence[int], dst: Sequence[int], wt: Sequence[int]) -> tuple[array, array, array] | None:
    """The edges as the core's typed arrays; None if the numbers are too large for it. Typed arrays
    already (``array("i")``, ``array("i")``, ``array("q")``, `hrc.compile.classify.packed_graph`) are
    taken as they are: whoever packed them checked their range."""
    if type(wt) is array and type(src) is array and type(dst) is array:
        return src, dst, wt
    if wt and (max(wt) >= MAX_WEIGHT or min(wt) <= -MAX_WEIGHT or n >= MAX_NODES):
        return None
    return array("i", src), array("i", dst), array("q", wt)


def native_distances(n: int, src: Sequence[int], dst: Sequence[int], wt: Sequence[int],
                     z: int | None) -> tuple[bool, list[int]] | None:
    """``(consistent, d)``: ``d[x]`` the shortest distance from x to `z` (queue-based Bellman-Ford; the
    earliest time of x after z is ``-d[x]``; ``2**63 - 1`` where z is not reached), or with ``z=None``
    to a virtual node every node reaches by a 0 edge (a consistency check, whose distances equal those to
    a timepoint every node has a 0 edge to). ``(False, [])`` on a negative cycle; None: no native core.
    An edge end or `z` outside ``0..n-1`` raises ValueError (the core checks before it reads)."""
    fn = _DIST
    if z is not None and not 0 <= z < n:  # a negative z means the virtual node to the core
        raise ValueError(f"native_distances: z = {z} outside 0..{n - 1}")
    arrays = _arrays(n, src, dst, wt) if fn is not None and n > 0 else None
    if fn is None or arrays is None:
        return None
    s, d, w = arrays
    out = array("q", bytes(8 * n))
    rc = fn(n, len(s), s.buffer_info()[0], d.buffer_info()[0], w.buffer_info()[0], -1 if z is None else z,
               out.buffer_info()[0])
    if rc == _BAD_INDEX:
        raise ValueError(f"native_distances: an edge end or z outside 0..{n - 1}")
    if rc < 0:
        return None
    return (True, out.tolist()) if rc == 0 else (False, [])


def native_apsp(n: int, src: Sequence[int], dst: Sequence[int], wt: Sequence[int]) -> tuple[bool, np.ndarray] | None:
    """``(consistent, D)``: the dense all-pairs shortest distances (float64, ``inf`` where there is no
    path; Floyd-Warshall), ``(False, empty)`` on a negative cycle, None without the native core. Self-loops
    must be left out by the caller. An edge end outside ``0..n-1`` raises ValueError."""
    fn = _APSP
    arrays = _arrays(n, src, dst, wt) if fn is not None and n > 0 else None
    if fn is None or arrays is None:
        return None
    s, d, w = arrays
    out = np.empty((n, n))
    rc = fn(n, len(s), s.buffer_info()[0], d.buffer_info()[0], w.buffer_info()[0], out.ctypes.data)
    if rc == _BAD_INDEX:
        raise ValueError(f"native_apsp: an edge end outside 0..{n - 1}")
    return (True, out) if rc == 0 else (False, np.empty((0, 0)))
