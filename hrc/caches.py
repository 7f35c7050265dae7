"""The per-process caches' one shared rule: keyed by identity (``id(obj)``, with the object kept beside
its value so the id cannot be reused while it is held), bounded, the oldest entry forgotten first.

The compiler reads one network or task many times over (`hrc.temporal.rul.edge_arrays`,
`hrc.compile.classify.packed_graph`, `hrc.temporal.network.lineage`, the links the temporal net creator
builds per task); hashing those frozen objects by value would cost more than what is kept.

On disk (`cache_folder`, `disk_load`, `disk_store`): what does not change between runs on the same map,
such as the roadmaps of `hrc.motion.paths.plan_paths`, keyed by everything they are computed from (the
inputs, and the digest of the code that computes them: `source_digest`), in a folder the user may delete
at any time (``~/.cache/hrc``; ``HRC_CACHE_DIR`` moves it, or turns it off when empty). Each kind's
folder is bounded (``HRC_CACHE_MAX_MB``, default 256 MB a kind): past the bound, the entries used least
recently are deleted until it is down to three quarters (a hit refreshes an entry's time).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import os
import pickle
import sys
import sysconfig
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["CACHE_ENV", "CACHE_MAX_ENV", "cache_folder", "code_digest", "disk_load", "disk_store", "make_room",
           "source_digest"]


def make_room(cache: dict, cap: int) -> None:
    """Forget the oldest entries of `cache` until it holds fewer than `cap`. Never raises, also when
    another thread trims or fills the same cache at once (a Dask worker's threads compile side by side):
    an entry the other thread took first is simply gone, and a dict changing size under the iterator
    ends this round, to be finished by the next call."""
    while len(cache) >= cap:
        try:
            cache.pop(next(iter(cache)), None)
        except (StopIteration, RuntimeError):
            return


# ---------------------------------------------------------------------------------------------- on disk
CACHE_ENV = "HRC_CACHE_DIR"
"""The environment variable naming the folder of hrc's caches on disk (empty: no cache on disk)."""


CACHE_MAX_ENV = "HRC_CACHE_MAX_MB"
"""The environment variable bounding each kind's folder, in MB (default `_DEFAULT_MAX_MB`)."""
_DEFAULT_MAX_MB = 256

_sizes: dict[Path, int] = {}
"""Each folder's bytes as this process last knew them: scanned at its first store, then added to, so
that a store costs one folder scan per process, not one per store."""


def cache_folder(kind: str) -> Path | None:
    """The folder of the on-disk cache `kind` (``roadmaps``): ``$HRC_CACHE_DIR/KIND``, else
    ``$XDG_CACHE_HOME/hrc/KIND``, else ``~/.cache/hrc/KIND``; None when ``HRC_CACHE_DIR`` is set empty.
    Deleting it is always safe: what is in it is made again when needed."""
    base = os.environ.get(CACHE_ENV)
    if base is None:
        base = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "hrc")
    return Path(base) / kind if base else None


def source_digest(*modules: str) -> str:
    """SHA-256 of the source files of `modules` (dotted names): a cache key part that changes whenever
    the code that computed a cached value changes (another branch, another version), so no stale value
    is ever served."""
    h = hashlib.sha256()
    for name in modules:
        spec = importlib.util.find_spec(name)
        origin = spec.origin if spec is not None else None
        h.update(name.encode() + b"\0")
        if origin and os.path.exists(origin):
            h.update(Path(origin).read_bytes())
    return h.hexdigest()


@functools.cache
def code_digest() -> str:
    """SHA-256 of all of hrc's code (every ``.py`` file of the package and its native cores) and of the
    versions of Python and of every installed library (numpy's, scipy's, OMPL's numbers reach the
    outputs): the key part of a cached value computed by much of the package at once (a whole compile's
    plans, `hrc.compile.stream`), so that any change of code, on any branch, is a miss. Computed once per
    process (a few tens of ms)."""
    root = Path(__file__).resolve().parent  # the package's folder (this module is at its top)
    h = hashlib.sha256(sys.version.encode())
    # the installed distributions' names and versions (``numpy-2.1.3.dist-info``): one folder listing
    for lib in sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}):
        with contextlib.suppress(OSError):
            h.update(repr(sorted(n for n in os.listdir(lib) if n.endswith((".dist-info", ".egg-info")))).encode())
    for path in sorted(p for p in root.rglob("*") if p.suffix in (".py", ".so", ".c", ".h") and p.is_file()):
        h.update(str(path.relative_to(root)).encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def disk_load(folder: Path | None, key: str) -> Any:
    """The value stored under `key` in `folder`, or None (no cache, none stored, or unreadable: a damaged
    or foreign file is a miss, never an error). Only pickles that `disk_store` wrote under the key's
    SHA-256 name are read."""
    if folder is None:
        return None
    path = folder / f"{hashlib.sha256(key.encode()).hexdigest()}.pickle"
    try:
        stored_key, value = pickle.loads(path.read_bytes())
    except Exception:  # noqa: BLE001 - missing, truncated, another format: recompute
        return None
    if stored_key != key:
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # used now: the last to be trimmed
    return value


def disk_store(folder: Path | None, key: str, value: Any) -> None:
    """Store `value` under `key` in `folder` (atomically: a reader sees all of it or nothing); quiet when
    the folder cannot be written (the cache is an optimisation, never a requirement)."""
    if folder is None:
        return
    path = folder / f"{hashlib.sha256(key.encode()).hexdigest()}.pickle"
    tmp = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
        with os.fdopen(fd, "wb") as f:
            f.write(pickle.dumps((key, value), protocol=pickle.HIGHEST_PROTOCOL))
        os.replace(tmp, path)
        tmp = None
        _bound(folder, path.stat().st_size)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def _max_bytes() -> int:
    try:
        return max(0, int(float(os.environ.get(CACHE_MAX_ENV, _DEFAULT_MAX_MB)) * 2**20))
    except ValueError:  # a malformed bound is the default, never an error: the cache is an optimisation
        return _DEFAULT_MAX_MB * 2**20


def _bound(folder: Path, added: int) -> None:
    """Keep `folder` within the bound: when this process's count of its bytes passes it, rescan and delete
    the least recently used entries down to three quarters of it. Another process trimming at once only
    makes some deletions fail quietly."""
    cap = _max_bytes()
    known = _sizes.get(folder)
    if known is not None and known + added <= cap:
        _sizes[folder] = known + added
        return
    entries = []
    for entry in os.scandir(folder):
        with contextlib.suppress(OSError):
            if entry.name.endswith(".pickle") and entry.is_file():
                st = entry.stat()
                entries.append((st.st_mtime_ns, entry.name, st.st_size))
    total = sum(size for _, _, size in entries)
    if total > cap:
        for _, name, size in sorted(entries):
            if total <= cap * 3 // 4:
                break
            with contextlib.suppress(OSError):
                os.unlink(folder / name)
                total -= size
    _sizes[folder] = total
