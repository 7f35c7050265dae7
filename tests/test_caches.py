"""`hrc.caches.make_room`: the oldest entries go first, and trimming never raises while other threads
fill and trim the same cache (a Dask worker's threads compile side by side)."""

from __future__ import annotations

import os
import sys
import threading

import pytest
from conftest import WORKSHOP_TASK

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


# -- on disk: the roadmaps of plan_paths ---------------------------------------------------------------
def _library(task, seed=0, *, cache=True):
    from hrc.motion import plan_paths

    return plan_paths(task, seed=seed, cache=cache)


def _same(a, b) -> None:
    assert a == b  # every path, point for point
    assert {c: (r.points, r.edges) for c, r in a.roadmaps.items()} == \
        {c: (r.points, r.edges) for c, r in b.roadmaps.items()}


def test_a_cached_roadmap_gives_the_paths_planned_afresh(tmp_path, monkeypatch):
    """The second plan_paths of the workshop reads every clearance's roadmap from the cache and gives the
    same library as planning without a cache; a duration edited keeps the key, an obstacle moved or
    another seed does not; a damaged file is a miss, never an error; an empty HRC_CACHE_DIR turns it off."""
    import dataclasses

    from hrc.caches import CACHE_ENV, cache_folder
    from hrc.io.task_file import load_task
    from hrc.model import Interval

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    task = load_task(WORKSHOP_TASK)
    fresh = _library(task, cache=False)
    assert fresh.stats["cached"] == 0
    first = _library(task)
    files = sorted((tmp_path / "roadmaps").iterdir())
    assert first.stats["cached"] == 0 and len(files) == first.stats["roadmaps"] >= 1
    again = _library(task)
    assert again.stats["cached"] == again.stats["roadmaps"]
    _same(fresh, first)
    _same(fresh, again)
    # a duration edited: the same map and agents, the same key
    action = task.actions[0]
    phase = dataclasses.replace(action.phases[0], durations=tuple((k, Interval(d.lb + 1, d.ub + 1))
                                                                   for k, d in action.phases[0].durations))
    edited = dataclasses.replace(task, actions=(dataclasses.replace(action, phases=(phase, *action.phases[1:])),
                                                *task.actions[1:]))
    assert _library(edited).stats["cached"] == again.stats["roadmaps"]
    # another seed, an obstacle moved: planned again (and stored beside)
    assert _library(task, seed=1).stats["cached"] == 0
    ws = task.workspace
    ob = ws.obstacles[0]
    moved = dataclasses.replace(ob, polygon=tuple((x + 0.01, y) for x, y in ob.polygon))
    shifted = dataclasses.replace(task, workspace=dataclasses.replace(ws, obstacles=(moved, *ws.obstacles[1:])))
    assert _library(shifted).stats["cached"] == 0
    # a damaged file: a miss, planned again, the same library
    for f in files:
        f.write_bytes(b"not a pickle")
    damaged = _library(task)
    assert damaged.stats["cached"] == 0
    _same(fresh, damaged)
    monkeypatch.setenv(CACHE_ENV, "")
    assert cache_folder("roadmaps") is None and _library(task).stats["cached"] == 0


def test_a_compile_with_a_warm_cache_writes_the_same_bytes(tmp_path, monkeypatch, capsys):
    """``hrc compile`` cold (an empty cache) and warm: the same compiled.json and STNUs, byte for byte;
    ``-v`` says where the time went, and how many roadmaps came from the cache."""
    import re

    from conftest import compiled_folder

    from hrc.caches import CACHE_ENV

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    capsys.readouterr()
    cold = compiled_folder(tmp_path / "cold", WORKSHOP_TASK, "-v")
    said = capsys.readouterr().err
    # the two roadmaps at once: the second in a process of its own (2 cores), the same library
    cores = len(os.sched_getaffinity(0))
    assert ("paths (2 roadmaps, 0 from the cache, 1 planned in a second process" if cores > 1 else
            "paths (2 roadmaps, 0 from the cache)") in said, said
    for stage in ("start-up (imports, reading the task): ", "plans (32, ", "total: "):
        assert stage in said, (stage, said)
    assert all(float(x) >= 0 for x in re.findall(r"(\d+\.\d\d) s", said))
    assert len(list((tmp_path / "cache" / "roadmaps").iterdir())) == 2
    warm = compiled_folder(tmp_path / "warm", WORKSHOP_TASK, "-v")
    assert "paths (2 roadmaps, 2 from the cache)" in capsys.readouterr().err
    for name in ("compiled.json", "stnu.zip"):
        if (cold / name).exists():
            assert (cold / name).read_bytes() == (warm / name).read_bytes(), name
    cold_files = sorted(p.relative_to(cold) for p in cold.rglob("*") if p.is_file())
    assert cold_files == sorted(p.relative_to(warm) for p in warm.rglob("*") if p.is_file())
    for rel in cold_files:
        if rel.parts[0] in ("stnu", "dispatch") or rel.name == "compiled.json":
            assert (cold / rel).read_bytes() == (warm / rel).read_bytes(), rel


def test_a_compile_of_the_same_task_again_is_taken_whole_from_the_cache(tmp_path, monkeypatch, capsys):
    """A small compile is kept whole on disk (`hrc.compile.stream.RESULTS_MAX_PLANS`): compiled again, with
    the compiler made to fail, its plans come from there (``-v`` says so) and every file is the cold
    compile's, byte for byte; the same task with one duration changed is another key (compiled, kept
    beside the first); an empty HRC_CACHE_DIR keeps nothing."""
    from conftest import compiled_folder

    import hrc.compile.stream as stream
    from hrc.caches import CACHE_ENV

    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    capsys.readouterr()
    cold = compiled_folder(tmp_path / "cold", WORKSHOP_TASK, "-v", "--jobs", "1")
    assert "plans (32, 1 worker)" in capsys.readouterr().err
    assert len(list((tmp_path / "cache" / "results").iterdir())) == 1

    def compiled(*args, **kwargs):
        raise AssertionError("compiled again")

    with monkeypatch.context() as m:
        m.setattr(stream, "compile_family", compiled)
        warm = compiled_folder(tmp_path / "warm", WORKSHOP_TASK, "-v", "--jobs", "1")
    assert "plans (32, from the cache of whole compiles)" in capsys.readouterr().err
    files = sorted(p.relative_to(cold) for p in cold.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(warm) for p in warm.rglob("*") if p.is_file())
    assert len(files) > 32 and all((cold / rel).read_bytes() == (warm / rel).read_bytes() for rel in files)

    text = WORKSHOP_TASK.read_text()
    put = "\n      - {id: put,   location: T,  duration: {human: [2, 4], robot: [4, 5]}}"
    edited = text.replace(f"robot: [5, 6]}}}}{put}", f"robot: [5, 7]}}}}{put}", 1)  # cube 1's fetch by the robot
    edited = edited.replace("map: ../maps/", f"map: {WORKSHOP_TASK.parent.parent}/maps/")
    assert edited != text
    (tmp_path / "edited.yaml").write_text(edited)
    compiled_folder(tmp_path / "edited", tmp_path / "edited.yaml", "-v", "--jobs", "1")
    assert "plans (32, 1 worker)" in capsys.readouterr().err
    assert len(list((tmp_path / "cache" / "results").iterdir())) == 2
    assert (tmp_path / "edited" / "compiled.json").read_bytes() != (cold / "compiled.json").read_bytes()

    monkeypatch.setenv(CACHE_ENV, "")
    compiled_folder(tmp_path / "none", WORKSHOP_TASK, "-v", "--jobs", "1")
    assert "plans (32, 1 worker)" in capsys.readouterr().err


# -- on disk: detours ------------------------------------------------------------------------------------
def test_a_cached_detour_is_the_detour_planned_afresh(tmp_path, monkeypatch):
    """`detour` reads a detour planned by another process (another library: its own per-process cache is
    empty) from the disk cache, the same route point for point as planned without the cache, without
    planning it (the planning step made to fail); a moved obstacle is another key; no cache, no files."""
    import dataclasses

    import hrc.motion.detours as detours
    from hrc.caches import CACHE_ENV
    from hrc.io.task_file import load_task

    task = load_task(WORKSHOP_TASK)
    asked = [("R", "S1"), ("S2", "T"), ("S1", "S5")]

    def ways(task, lib):
        out = []
        for o, t in asked:
            pts = lib.get("robot", o, t).points
            out.append(detours.detour(task, lib, "robot", o, t, [(tuple(pts[len(pts) // 2]),)], "cube"))
        return out

    monkeypatch.setenv(CACHE_ENV, "")
    fresh = ways(task, _library(task, cache=False))
    assert all(d is not None and d.via == "cube" for d in fresh)
    monkeypatch.setenv(CACHE_ENV, str(tmp_path))
    assert ways(task, _library(task)) == fresh
    assert len(list((tmp_path / "detours").iterdir())) == len(asked)

    def planned(*args):
        raise AssertionError("planned again")

    with monkeypatch.context() as m:
        m.setattr(detours, "_without", planned)
        assert ways(task, _library(task)) == fresh  # from the disk, not planned
        ws = task.workspace
        ob = ws.obstacles[0]
        moved = dataclasses.replace(ob, polygon=tuple((x + 0.01, y) for x, y in ob.polygon))
        shifted = dataclasses.replace(task, workspace=dataclasses.replace(ws, obstacles=(moved, *ws.obstacles[1:])))
        with pytest.raises(AssertionError, match="planned again"):
            ways(shifted, _library(shifted))



def test_a_disk_cache_past_its_bound_forgets_the_least_recently_used(tmp_path, monkeypatch):
    """Each kind's folder stays within ``HRC_CACHE_MAX_MB``: past it, the entries used least recently go
    first, down to three quarters of the bound; a hit counts as a use; what is kept still loads."""
    import hashlib
    import os

    from hrc import caches

    monkeypatch.setenv(caches.CACHE_MAX_ENV, str(9_000 / 2**20))  # 9 kB
    monkeypatch.setattr(caches, "_sizes", {})
    folder = tmp_path / "kind"

    def path(key: str):
        return folder / f"{hashlib.sha256(key.encode()).hexdigest()}.pickle"

    blob = b"x" * 2000  # 2,025 bytes a pickle: four fit, five do not
    for n in range(4):
        caches.disk_store(folder, f"k{n}", blob)
    for n, when in enumerate([40, 10, 20, 30]):  # k1 stored first ... k0 last (times any file system keeps)
        os.utime(path(f"k{n}"), ns=(when * 10**9,) * 2)
    before = path("k1").stat().st_mtime_ns
    assert caches.disk_load(folder, "k1") == blob and path("k1").stat().st_mtime_ns > before  # a hit: now used
    os.utime(path("k1"), ns=(10 * 10**9,) * 2)  # and back to least recently used, for the order below
    caches.disk_store(folder, "k4", blob)  # 5 x 2,025 > 9,000: down to 6,750, k1 then k2 go
    caches.disk_store(folder, "k5", blob)  # 4 x 2,025: within the bound, nothing goes
    assert [n for n in range(6) if caches.disk_load(folder, f"k{n}") == blob] == [0, 3, 4, 5]
    assert sum(p.stat().st_size for p in folder.iterdir()) <= 9_000
