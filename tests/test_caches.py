"""`hrc.caches.make_room`: the oldest entries go first, and trimming never raises while other threads
fill and trim the same cache (a Dask worker's threads compile side by side)."""

from __future__ import annotations

import sys
import threading

from hrc.caches import make_room


def test_the_oldest_entries_go_first():
    cache = {k: k for k in range(10)}
    make_room(cache, 4)
    assert list(cache) == [7, 8, 9]
    make_room(cache, 4)
    assert list(cache) == [7, 8, 9]
    make_room({}, 1)


def test_threads_trimming_one_cache_never_raise():
    cache: dict[int, int] = {}
    errors: list[BaseException] = []
    start = threading.Barrier(4)

    def fill(offset: int) -> None:
        try:
            start.wait()
            for k in range(offset, offset + 20_000):
                make_room(cache, 8)
                cache[k] = k
        except BaseException as err:  # noqa: BLE001 - the test reports any
            errors.append(err)

    threads = [threading.Thread(target=fill, args=(n * 100_000,)) for n in range(4)]
    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # switch threads as often as the interpreter can (the old
    # ``del cache[next(iter(cache))]`` raised KeyError here within a few thousand rounds)
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(switch)
    assert errors == []
    assert len(cache) <= 8 + 3  # each thread may add one after another's trim
