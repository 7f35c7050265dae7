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


class _Windowed:
    """Submit through `submit`, keep at most `window` futures in flight, yield as they complete."""

    window = 4

    def _run(self, submit: Callable[[Any], Any], wait_first: Callable[[set], tuple[set, set]],
             chunks: Iterable[Any]) -> Iterator[Any]:
        pending: set = set()
        for chunk in chunks:
            pending.add(submit(chunk))
            if len(pending) >= self.window:
                done, pending = wait_first(pending)
                for fut in done:
                    yield fut.result()
        while pending:
            done, pending = wait_first(pending)
            for fut in done:
                yield fut.result()


class PoolExecutor(_Windowed):
    """A local process pool of `jobs` workers."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.window = 2 * jobs
        self._pool: cf.ProcessPoolExecutor | None = None

    def __enter__(self) -> PoolExecutor:
        self._pool = cf.ProcessPoolExecutor(max_workers=self.jobs)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any]) -> Iterator[Any]:
        pool = self._pool
        if pool is None:
            raise ExecutorError("PoolExecutor.map_chunks called outside its 'with' block")

        def wait_first(pending: set) -> tuple[set, set]:
            done, rest = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
            return set(done), set(rest)

        return self._run(lambda chunk: pool.submit(fn, task, paths, chunk), wait_first, chunks)


class DaskExecutor(_Windowed):
    """A Dask distributed scheduler at ``dask://HOST:PORT`` (or ``tcp://HOST:PORT``)."""

    def __init__(self, address: str, timeout: float = 10.0) -> None:
        self.address = address
        self.timeout = timeout
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
        from distributed import wait

        client = self._client
        task_f, paths_f = client.scatter([task, paths], broadcast=True, hash=False)

        def wait_first(pending: set) -> tuple[set, set]:
            done, rest = wait(list(pending), return_when="FIRST_COMPLETED")
            return set(done), set(rest)

        return self._run(lambda chunk: client.submit(fn, task_f, paths_f, chunk, pure=False), wait_first, chunks)


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
