"""Replacing an output folder (`hrc.io.claim`, `hrc.io.atomic`): a kill at every step of the swap leaves
the old folder or the new one (the next claim puts back one moved aside), a killed run's leftovers are
removed by the next claim and nothing else is, a live claim refuses a second one, and what is written is
flushed to the disk before any name points at it (files, then their folder)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import ROOT

import hrc.io.claim as claim
from hrc.errors import InputError
from hrc.io.atomic import atomic_dir, write_text_atomic
from hrc.io.claim import FolderClaim
from hrc.io.durable import exchange

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="kills and /proc are Linux's")

# A process that replaces TARGET's "v" file with "new" through a claim, and kills itself (SIGKILL) at the
# K-th step of the claim (before or after it): each step is a call of a file-system operation the claim
# makes. EXCHANGE=0: as on a file system that cannot exchange two names (the fallback of two renames).
_SWAPPER = textwrap.dedent("""
    import functools, os, signal, sys
    import hrc.io.claim as claim
    target, k, when, can_exchange = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4] == "1"
    calls = [0]

    def step(fn):
        @functools.wraps(fn)
        def wrapped(*args, **kwargs):
            calls[0] += 1
            if calls[0] == k and when == "before":
                os.kill(os.getpid(), signal.SIGKILL)
            out = fn(*args, **kwargs)
            if calls[0] == k and when == "after":
                os.kill(os.getpid(), signal.SIGKILL)
            return out
        return wrapped

    if not can_exchange:
        claim.exchange = lambda a, b: False
    for name in ("exchange", "sync_tree", "fsync_folder", "_remove"):
        setattr(claim, name, step(getattr(claim, name)))
    os.rename, os.mkdir, os.ftruncate = step(os.rename), step(os.mkdir), step(os.ftruncate)
    claim.FolderClaim._append = step(claim.FolderClaim._append)
    with claim.FolderClaim(target) as c, c.staging() as stage:
        (stage / "v").write_text("new")
    print(calls[0])
""")


def _swap_killed_at(target: Path, k: int, when: str, can_exchange: bool) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", _SWAPPER, str(target), str(k), when, str(int(can_exchange))],
                          env=env, capture_output=True, text=True, timeout=60)


def _state(folder: Path) -> str:
    v = folder / "v"
    return v.read_text() if v.is_file() else "missing"


@pytest.mark.parametrize("can_exchange", [True, False])
def test_a_kill_at_any_step_of_the_swap_leaves_the_old_or_the_new_folder(tmp_path, can_exchange):
    """Killed before and after each step in turn: the folder is the old one or the new one (with the
    fallback, between its two renames, missing, with the old one aside); after the next claim, which
    cleans up, it is the old or the new one and nothing else is left beside it."""
    seen = set()
    steps = None
    for k in range(1, 60):
        for when in ("before", "after"):
            case = tmp_path / f"{k}-{when}"
            target = case / "out"
            target.mkdir(parents=True)
            (target / "v").write_text("old")
            done = _swap_killed_at(target, k, when, can_exchange)
            if done.returncode == 0:  # not killed: k is past the last step (or that step raised, as planned)
                assert _state(target) == "new" and sorted(p.name for p in case.iterdir()) == ["out"]
                if int(done.stdout) < k:
                    steps = int(done.stdout)
                continue
            assert done.returncode == -signal.SIGKILL, done.stderr
            now = _state(target)
            seen.add(now)
            if now == "missing":  # only between the fallback's two renames, with the old folder aside
                assert not can_exchange
                aside = [p for p in case.iterdir() if ".aside-" in p.name]
                assert len(aside) == 1 and _state(aside[0]) == "old"
            else:
                assert now in ("old", "new")
            with FolderClaim(target) as c:
                if now == "missing":
                    assert any("put the earlier output back" in line for line in c.recovered), c.recovered
            assert _state(target) == ("old" if now == "missing" else now)
            assert sorted(p.name for p in case.iterdir()) == ["out"], (k, when)
        if steps is not None:
            break
    assert steps is not None and steps >= 8  # every step was tried
    assert seen == ({"old", "new"} if can_exchange else {"old", "new", "missing"})


def test_the_swap_exchanges_the_two_folders_in_one_step(tmp_path, monkeypatch):
    """On Linux (this machine's file system) the swap is one ``renameat2(RENAME_EXCHANGE)``."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "f").write_text("a")
    (b / "f").write_text("b")
    assert exchange(a, b)
    assert (a / "f").read_text() == "b" and (b / "f").read_text() == "a"
    calls = []
    monkeypatch.setattr(claim, "exchange", lambda x, y: calls.append((x, y)) or exchange(x, y))
    with atomic_dir(b) as stage:
        (stage / "f").write_text("new")
    assert len(calls) == 1 and calls[0][1] == b and (b / "f").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]


def test_a_live_claim_refuses_a_second_one_and_a_dead_one_is_cleaned(tmp_path, monkeypatch):
    """A second claim while the first is held: one line naming the holder's pid; the folder untouched.
    The holder killed (SIGKILL) with its staging folder made: the next claim removes that folder, and
    only folders a dead claim's journal names."""
    monkeypatch.setattr(claim, "LOCK_WAIT", 0.2)
    target = tmp_path / "out"
    target.mkdir()
    (target / "v").write_text("old")
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent("""
        import sys, time
        from hrc.io.claim import FolderClaim
        with FolderClaim(sys.argv[1]) as c, c.staging() as stage:
            (stage / "v").write_text("new")
            print("staged", flush=True)
            time.sleep(120)
    """), str(target)], env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "staged\n"
        with pytest.raises(InputError, match=rf"another process \(pid {holder.pid}\) is writing this output"):
            with FolderClaim(target):
                pass
    finally:
        holder.kill()
        holder.communicate(timeout=30)
    # someone else's folders beside it, one in our pattern but named by no journal
    (tmp_path / ".out.staging-1-deadbeef").mkdir()
    (tmp_path / ".out.mine").mkdir()
    names = sorted(p.name for p in tmp_path.iterdir())
    staged = [n for n in names if n.startswith(f".out.staging-{holder.pid}-")]
    assert len(staged) == 1 and ".out.lock" in names
    with FolderClaim(target) as c:
        assert c.recovered == [f"removed {staged[0]}, left by a run (pid {holder.pid}) that was killed"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".out.mine", ".out.staging-1-deadbeef", "out"]
    assert _state(target) == "old"


def test_a_journal_names_only_folders_beside_the_target(tmp_path):
    """A journal edited to name other places (another folder, a parent, a name not in the pattern): the
    claim touches none of them."""
    target = tmp_path / "out"
    for name in ("elsewhere", ".out.staging-1-abcdef12x", ".out.aside-2-00000000"):
        (tmp_path / name).mkdir()
    (tmp_path / "elsewhere" / "keep").write_text("keep")
    (tmp_path / ".out.lock").write_text("hrc output claim: pid 1\nstaging ../elsewhere\nstaging elsewhere\n"
                                        "staging .out.staging-1-abcdef12x\nstaging .out.aside-2-00000000\n")
    with FolderClaim(target) as c:
        assert c.recovered == []
    assert sorted(p.name for p in tmp_path.iterdir()) == [".out.aside-2-00000000", ".out.staging-1-abcdef12x",
                                                        "elsewhere"]


def _fd_path(fd: int) -> str:
    return os.readlink(f"/proc/self/fd/{fd}")


def test_an_atomic_write_flushes_the_file_then_its_folder(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: events.append(("fsync", _fd_path(fd))) or real_fsync(fd))
    monkeypatch.setattr(os, "replace", lambda a, b: events.append(("replace", str(b))) or real_replace(a, b))
    target = tmp_path / "f.txt"
    write_text_atomic(target, "text")
    assert target.read_text() == "text"
    (kind0, tmp), replaced, last = events
    assert kind0 == "fsync" and Path(tmp).parent == tmp_path and Path(tmp).name.startswith(".f.txt.")
    assert replaced == ("replace", str(target)) and last == ("fsync", str(tmp_path))


def test_an_atomic_folder_is_flushed_before_the_swap_and_its_parent_after(tmp_path, monkeypatch):
    events = []
    real_sync, real_exchange, real_fsync_folder = claim.sync_tree, claim.exchange, claim.fsync_folder
    monkeypatch.setattr(claim, "sync_tree", lambda p: events.append(("sync", Path(p).parent)) or real_sync(p))
    monkeypatch.setattr(claim, "exchange", lambda a, b: events.append(("exchange", b)) or real_exchange(a, b))
    monkeypatch.setattr(claim, "fsync_folder", lambda p: events.append(("fsync", p)) or real_fsync_folder(p))
    target = tmp_path / "out"
    target.mkdir()
    with atomic_dir(target) as stage:
        (stage / "f").write_text("new")
    assert events[:3] == [("sync", tmp_path), ("exchange", target), ("fsync", tmp_path)], events
    assert (target / "f").read_text() == "new"
