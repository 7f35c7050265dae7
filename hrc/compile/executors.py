"""Where per-plan work runs: in this process, in a local process pool, or on a Dask cluster.

`EXECUTORS` is the registry the CLI offers (``--jobs N`` picks serial or a pool; ``--executor URL``
picks by scheme). Every executor has the same interface, ``map_chunks(fn, task, paths, chunks)``,
yielding ``fn(task, paths, chunk)`` results in completion order, with at most a few chunks in flight
so that plan generation stays a stream, and calling ``poll()`` (when given) between results (a local
pool: at least every `POLL_EVERY` seconds while it waits): the caller's chance to stop safely
(`hrc.cli.interrupt`). No
home-made cluster code: Dask's `distributed` does the rest.

A local pool's workers never outlive the compile: they ignore SIGINT and SIGTERM (the parent alone
decides how to stop, and stops them after their unit of work), and die with the parent when it is killed
(`_die_with_parent`).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
import gc
import multiprocessing as mp
import os
import pickle
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any
from urllib.parse import urlparse

from hrc.errors import ExecutorError

__all__ = ["EXECUTORS", "PARENT_POLL", "POLL_EVERY", "STOP_GRACE", "WORKER_GC_THRESHOLD", "Apart", "DaskExecutor",
           "PoolExecutor", "SerialExecutor", "check_jobs", "default_jobs", "make_executor", "parse_executor_url",
           "probe_scheduler", "run_apart"]

Poll = Callable[[], None]

POLL_EVERY = 0.5
"""Seconds at most between two calls of ``poll`` while an executor waits for results."""


def default_jobs() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


WORKER_GC_THRESHOLD = 10_000
"""A worker's threshold for collecting its youngest generation of objects (Python's default: 700)."""


class SerialExecutor:
    """Runs every chunk in this process, in order."""

    jobs = 1

    def __enter__(self) -> SerialExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any],
                   poll: Poll | None = None) -> Iterator[Any]:
        # the pool workers' threshold for the young objects (`_init_worker`), for as long as this runs
        threshold = gc.get_threshold()
        gc.set_threshold(WORKER_GC_THRESHOLD, *threshold[1:])
        try:
            for chunk in chunks:
                if poll is not None:
                    poll()
                yield fn(task, paths, chunk)
        finally:
            gc.set_threshold(*threshold)


# Per worker process: the shared arguments (task, path library) arrive once, through the pool's
# initializer, and stay for every chunk, with the caches the path library fills as plans use it.
_WORKER_SHARED: dict[str, Any] = {}


PARENT_POLL = 0.5
"""Seconds between a worker's looks at its parent where the system cannot signal it (`_die_with_parent`)."""

_PR_SET_PDEATHSIG = 1


def _die_with_parent(parent: int, direct: bool) -> None:
    """Make this worker process die (SIGKILL) as soon as its parent process `parent` does.

    A worker's work is worth nothing without its parent (results go to the parent's pipe; its files are
    in a staging folder the next compile removes), and a worker left behind holds ~120 MB and waits on
    that pipe for ever (issue 26). On Linux, for a worker the parent started itself (`direct`: fork or
    spawn), the kernel sends the signal (``prctl(PR_SET_PDEATHSIG)``, through ctypes; it fires when the
    thread that started the worker ends: here the main thread, which submits the work and lives as long
    as the process). A parent that died before the call is caught by `os.getppid`: the worker was adopted
    by then. Elsewhere (another system, or a fork server between the two) a daemon thread watches
    `os.getppid` every `PARENT_POLL` seconds: the worker is adopted when the process above it dies."""
    first = os.getppid()
    if direct and first != parent:  # the parent is gone already
        os.kill(os.getpid(), signal.SIGKILL)
    if direct and sys.platform.startswith("linux"):
        try:
            armed = ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):  # pragma: no cover - every Linux C library has prctl
            armed = False
        if armed:
            if os.getppid() != parent:  # it died between the two looks
                os.kill(os.getpid(), signal.SIGKILL)
            return
    threading.Thread(target=_watch_parent, args=(first,), name="hrc-parent-watch", daemon=True).start()


def _watch_parent(first: int) -> None:
    while os.getppid() == first:
        time.sleep(PARENT_POLL)
    os.kill(os.getpid(), signal.SIGKILL)


def _init_worker(task: Any, paths: Any, parent: int, direct: bool) -> None:
    # Ctrl-C reaches the whole process group, and a service manager's stop sends SIGTERM to every process
    # of the service: the parent alone handles them (it stops the workers after their unit of work), so
    # workers ignore both (not through the handlers inherited from the parent); they die with the parent
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _die_with_parent(parent, direct)
    _WORKER_SHARED["args"] = (task, paths)
    # The cyclic garbage collector, tuned for a worker (the advice of the `gc` docs for forked workers):
    # what the parent built before the fork moves to the permanent generation, never scanned again (nor
    # its pages copied on write for the scan's bookkeeping), and the youngest generation is collected
    # less often: a worker allocates millions of short-lived objects, nearly all freed by reference
    # counting before a scan at this threshold reaches them (docs/benchmarks.md, ninth pass).
    gc.freeze()
    gc.set_threshold(WORKER_GC_THRESHOLD, *gc.get_threshold()[1:])


class Apart:
    """`run_apart`'s handle: calling it waits for the result; `cancel` stops the process."""

    def __init__(self, pid: int, read: int) -> None:
        self.pid, self.read = pid, read

    def __call__(self) -> Any:
        """The function's result, or None if it failed (the caller computes it itself then)."""
        try:
            with os.fdopen(self.read, "rb") as pipe:
                self.read = -1
                data = pipe.read()
            os.waitpid(self.pid, 0)
        except BaseException:  # interrupted while waiting: the process is stopped, the interrupt goes on
            self.cancel()
            raise
        self.pid = 0
        try:
            ok, value = pickle.loads(data)
        except Exception:  # noqa: BLE001 - it died before writing all of it
            return None
        return value if ok else None

    def cancel(self) -> None:
        """Stop the process (if its result was not taken) and reap it."""
        if self.read >= 0:
            os.close(self.read)
            self.read = -1
        if self.pid:
            with contextlib.suppress(OSError):
                os.kill(self.pid, signal.SIGKILL)
            with contextlib.suppress(OSError):
                os.waitpid(self.pid, 0)
            self.pid = 0


def run_apart(fn: Callable[[], Any]) -> Apart:
    """Start ``fn()`` in a process forked from this one (it has what this one has: nothing pickled going
    in), at once; the returned `Apart` waits for its result (pickled back through a pipe). Like the pool's
    workers, the process ignores SIGINT and SIGTERM and dies with this one. Used where two independent
    pieces of a compile's start can run on two cores (`hrc.motion.paths.plan_paths`' roadmaps). Call it
    from a process with no other threads (forking copies one)."""
    read, write = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the child: its result, then out without the parent's exit handlers
        code = 0
        try:
            os.close(read)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            _die_with_parent(parent, direct=True)
            try:
                data = pickle.dumps((True, fn()), protocol=pickle.HIGHEST_PROTOCOL)
            except BaseException:  # noqa: BLE001 - the parent computes it itself
                data, code = pickle.dumps((False, None)), 1
            with os.fdopen(write, "wb") as pipe:
                pipe.write(data)
        finally:
            os._exit(code)
    os.close(write)
    return Apart(pid, read)


def _run_in_worker(fn: Callable[..., Any], chunk: Any) -> Any:
    task, paths = _WORKER_SHARED["args"]
    return fn(task, paths, chunk)


STOP_GRACE = 60.0
"""Seconds an interrupted compile waits for its workers to end their units of work before stopping them."""


class PoolExecutor:
    """A local process pool of `jobs` workers; started at the first `map_chunks`. Its workers run on this
    machine (`local_processes`): they can write into the output folder themselves."""

    local_processes = True

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs
        self.window = 2 * jobs
        self._pool: cf.ProcessPoolExecutor | None = None
        self._shared: tuple[Any, Any] = (None, None)  # the task and paths its workers were started with

    def __enter__(self) -> PoolExecutor:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if exc_type is None:
            pool.shutdown(cancel_futures=True)
            return
        # interrupted or failed: drop the chunks not started and let each worker end the one it is on (they
        # ignore SIGINT; a unit of work takes a few seconds at most: `hrc.compile.stream.chunk_size`). Killing
        # them at once could cut a result in the middle of the pipe, and the pool's manager thread would then
        # wait for the rest of it for ever: the process hung at exit, joining that thread (seen in the tests).
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + STOP_GRACE
        for proc in procs:
            proc.join(max(0.0, deadline - time.monotonic()))
        for proc in procs:  # stuck past the grace period: stopped (the risk above is the lesser evil now)
            if proc.is_alive():
                proc.kill()  # SIGKILL: workers ignore SIGTERM
                proc.join(5)

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any],
                   poll: Poll | None = None) -> Iterator[Any]:
        """(Called again with the same `task` and `paths` objects, it keeps its workers: the search compile
        sends a batch per call, `hrc.compile.search`.)"""
        pool = self._pool
        if pool is not None and (self._shared[0] is not task or self._shared[1] is not paths):
            pool.shutdown()
            pool = None
        if pool is None:
            pool = self._pool = cf.ProcessPoolExecutor(max_workers=self.jobs, initializer=_init_worker,
                                                       initargs=(task, paths, os.getpid(),
                                                                 mp.get_start_method() != "forkserver"))
            self._shared = (task, paths)
        pending: set[cf.Future] = set()
        for chunk in chunks:  # at most `window` chunks in flight: plan generation stays a stream
            pending.add(pool.submit(_run_in_worker, fn, chunk))
            while len(pending) >= self.window:
                done, pending = _wait(pending, poll)
                yield from (f.result() for f in done)
        while pending:
            done, pending = _wait(pending, poll)
            yield from (f.result() for f in done)


def _wait(pending: set[cf.Future], poll: Poll | None) -> tuple[set[cf.Future], set[cf.Future]]:
    """The futures of `pending` done within `POLL_EVERY` seconds (maybe none) and the rest; `poll` called
    after the wait."""
    done, rest = cf.wait(pending, timeout=POLL_EVERY if poll is not None else None,
                         return_when=cf.FIRST_COMPLETED)
    if poll is not None:
        poll()
    return done, rest


class DaskExecutor:
    """A Dask distributed scheduler at ``dask://HOST:PORT`` (or ``tcp://HOST:PORT``)."""

    def __init__(self, address: str, timeout: float = 5.0) -> None:
        self.address = address
        self.timeout = timeout
        self.window = 4
        self._client: Any = None
        self._scattered: tuple[Any, ...] | None = None

    def __enter__(self) -> DaskExecutor:
        try:
            from distributed import Client
        except ImportError as err:  # pragma: no cover - a dependency of the package
            raise ExecutorError("the 'distributed' package is needed for --executor dask://") from err
        probe_scheduler(self.address, self.timeout)
        try:
            self._client = Client(self.address, timeout=self.timeout, set_as_default=False)
        except (OSError, TimeoutError) as err:
            raise ExecutorError(f"cannot reach the Dask scheduler at {self.address}: {err}") from err
        workers = len(self._client.scheduler_info().get("workers", {}))
        self.window = max(4, 2 * workers)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._client is not None:
            self._client.close(timeout=self.timeout)

    def map_chunks(self, fn: Callable[..., Any], task: Any, paths: Any, chunks: Iterable[Any],
                   poll: Poll | None = None) -> Iterator[Any]:
        """(``poll`` is called between results: a Dask task is a unit of a few seconds.)"""
        from distributed import as_completed

        client = self._client
        with client.as_current():  # as_completed looks for a current client; ours, not a global default
            if self._scattered is None or self._scattered[0] is not task or self._scattered[1] is not paths:
                self._scattered = (task, paths, *client.scatter([task, paths], broadcast=True, hash=False))
            task_f, paths_f = self._scattered[2:]  # once per task: the search sends a batch per call
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
                    if poll is not None:
                        poll()
            for future in done or ():
                yield future.result()
                if poll is not None:
                    poll()


def probe_scheduler(address: str, timeout: float = 5.0) -> None:
    """Check that ``tcp://HOST:PORT`` answers like a Dask scheduler, within `timeout` seconds.

    A scheduler speaks first on a new connection (Dask's comm handshake: its frames arrive before the
    client sends anything); a web server or another service waits for a request. Without this check,
    `distributed.Client` waits on such a server far past its own timeout. Raises `ExecutorError`.
    """
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as sock:
            sock.settimeout(timeout)
            first = sock.recv(8)
    except TimeoutError as err:
        raise ExecutorError(f"{address} accepted the connection but said nothing within {timeout:g} s: not a "
                            "Dask scheduler (start one with `dask scheduler`)") from err
    except OSError as err:
        raise ExecutorError(f"cannot reach the Dask scheduler at {address}: {err.strerror or err}") from err
    if not first:
        raise ExecutorError(f"{address} closed the connection at once: not a Dask scheduler")


def parse_executor_url(url: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of an executor URL ``SCHEME://HOST:PORT``; raises `ExecutorError` naming
    what is wrong (a port is required: Dask's default would hide a typo)."""
    expected = "expected one of: " + ", ".join(f"{s}://HOST:PORT" for s in EXECUTORS)
    try:
        parsed = urlparse(url)
        port = parsed.port
    except ValueError as err:
        raise ExecutorError(f"bad executor URL {url!r}: {err} ({expected})") from err
    if parsed.scheme not in EXECUTORS or not parsed.hostname:
        raise ExecutorError(f"unknown executor {url!r} ({expected})")
    if port is None or port == 0:
        raise ExecutorError(f"executor URL {url!r} has no port ({expected}, e.g. dask://127.0.0.1:8786)")
    if parsed.path not in ("", "/") or parsed.query or parsed.fragment or parsed.username or parsed.password:
        raise ExecutorError(f"executor URL {url!r} has more than SCHEME://HOST:PORT ({expected})")
    return parsed.scheme, parsed.hostname, port


EXECUTORS: dict[str, Callable[[str], Any]] = {
    "dask": lambda netloc: DaskExecutor(f"tcp://{netloc}"),
    "tcp": lambda netloc: DaskExecutor(f"tcp://{netloc}"),
}


def make_executor(url: str | None, jobs: int | None) -> SerialExecutor | PoolExecutor | DaskExecutor:
    """``url`` None: a pool of `jobs` processes (default: one per core), serial when `jobs` is 1."""
    if url is None:
        n = default_jobs() if jobs is None else check_jobs(jobs)
        return SerialExecutor() if n == 1 else PoolExecutor(n)
    scheme, host, port = parse_executor_url(url)
    return EXECUTORS[scheme](f"[{host}]:{port}" if ":" in host else f"{host}:{port}")


def check_jobs(jobs: int) -> int:
    """`jobs` if it is between 1 and the cores this process may use (more processes than cores only
    slow a CPU-bound compile down); raises `ExecutorError` otherwise."""
    cores = default_jobs()
    if not 1 <= jobs <= cores:
        shown = str(jobs) if len(str(jobs)) <= 12 else f"{str(jobs)[:12]}..."
        raise ExecutorError(f"--jobs {shown}: expected 1 to {cores} (the cores this machine gives hrc); "
                            "for more workers use a Dask cluster: --executor dask://HOST:PORT")
    return jobs
