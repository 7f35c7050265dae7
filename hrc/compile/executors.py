"""Where per-plan work runs: in this process, in a local process pool, or on a Dask cluster.

`EXECUTORS` is the registry the CLI offers (``--jobs N`` picks serial or a pool; ``--executor URL``
picks by scheme). Every executor has the same interface, ``map_chunks(fn, task, paths, chunks)``,
yielding ``fn(task, paths, chunk)`` results in completion order, with at most a few chunks in flight
so that plan generation stays a stream. No home-made cluster code: Dask's `distributed` does the rest.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
from collections.abc import Callable, Iterable, Iterator
from typing import Any
from urllib.parse import urlparse

from hrc.errors import ExecutorError

__all__ = ["EXECUTORS", "DaskExecutor", "PoolExecutor", "SerialExecutor", "default_jobs", "make_executor"]


def default_jobs() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class SerialExecutor:
    """Runs every chunk in this process, in order."""

    def __enter__(self) -> SerialExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any]) -> Iterator[Any]:
        for chunk in chunks:
            yield fn(task, paths, chunk)


# Per worker process: the shared arguments (task, path library) arrive once, through the pool's
# initializer, and stay for every chunk, with the caches the path library fills as plans use it.
_WORKER_SHARED: dict[str, Any] = {}


def _init_worker(task: Any, paths: Any) -> None:
    _WORKER_SHARED["args"] = (task, paths)


def _run_in_worker(fn: Callable[..., Any], chunk: Any) -> Any:
    task, paths = _WORKER_SHARED["args"]
    return fn(task, paths, chunk)


class PoolExecutor:
    """A local process pool of `jobs` workers; started at the first `map_chunks`."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.window = 2 * jobs
        self._pool: cf.ProcessPoolExecutor | None = None

    def __enter__(self) -> PoolExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any]) -> Iterator[Any]:
        if self._pool is not None:
            self._pool.shutdown()
        pool = self._pool = cf.ProcessPoolExecutor(max_workers=self.jobs, initializer=_init_worker,
                                                   initargs=(task, paths))
        pending: set[cf.Future] = set()
        for chunk in chunks:  # at most `window` chunks in flight: plan generation stays a stream
            pending.add(pool.submit(_run_in_worker, fn, chunk))
            if len(pending) >= self.window:
                done, pending = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
                yield from (f.result() for f in done)
        for future in cf.as_completed(pending):
            yield future.result()


class DaskExecutor:
    """A Dask distributed scheduler at ``dask://HOST:PORT`` (or ``tcp://HOST:PORT``)."""

    def __init__(self, address: str, timeout: float = 10.0) -> None:
        self.address = address
        self.timeout = timeout
        self.window = 4
        self._client: Any = None

    def __enter__(self) -> DaskExecutor:
        try:
            from distributed import Client
        except ImportError as err:  # pragma: no cover - a dependency of the package
            raise ExecutorError("the 'distributed' package is needed for --executor dask://") from err
        try:
            self._client = Client(self.address, timeout=self.timeout, set_as_default=False)
        except (OSError, TimeoutError) as err:
            raise ExecutorError(f"cannot reach the Dask scheduler at {self.address}: {err}") from err
        workers = len(self._client.scheduler_info().get("workers", {}))
        self.window = max(4, 2 * workers)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._client is not None:
            self._client.close()

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any]) -> Iterator[Any]:
        from distributed import as_completed

        client = self._client
        with client.as_current():  # as_completed looks for a current client; ours, not a global default
            task_f, paths_f = client.scatter([task, paths], broadcast=True, hash=False)
            done: Any = None
            in_flight = 0
            for chunk in chunks:
                future = client.submit(fn, task_f, paths_f, chunk, pure=False)
                if done is None:
                    done = as_completed([future])
                else:
                    done.add(future)
                in_flight += 1
                if in_flight >= self.window:
                    yield next(done).result()
                    in_flight -= 1
            for future in done or ():
                yield future.result()


EXECUTORS: dict[str, Callable[[str], Any]] = {
    "dask": lambda netloc: DaskExecutor(f"tcp://{netloc}"),
    "tcp": lambda netloc: DaskExecutor(f"tcp://{netloc}"),
}


def make_executor(url: str | None, jobs: int | None) -> SerialExecutor | PoolExecutor | DaskExecutor:
    """``url`` None: a pool of `jobs` processes (default: one per core), serial when `jobs` is 1."""
    if url is None:
        n = default_jobs() if jobs is None else jobs
        if n < 1:
            raise ExecutorError(f"--jobs must be at least 1, found {n}")
        return SerialExecutor() if n == 1 else PoolExecutor(n)
    parsed = urlparse(url)
    if parsed.scheme not in EXECUTORS or not parsed.netloc:
        raise ExecutorError(f"unknown executor '{url}' (expected one of: "
                            + ", ".join(f"{s}://HOST:PORT" for s in EXECUTORS) + ")")
    return EXECUTORS[parsed.scheme](parsed.netloc)
