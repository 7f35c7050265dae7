"""Issue 38, kitting_7picks in 30 s: the compile's per-plan work done once per shared part, or as arrays,
with the same bytes out (`hrc.compile.sink.PlanSink._write_form`, `hrc.plans.code_sequences`, ...)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import ROOT, tree_bytes

from hrc.compile import sink
from hrc.compile.compiler import compile_task
from hrc.compile.dispatch_form import plan_sequences
from hrc.compile.output import write_compiled
from hrc.compile.stream import compile_stream
from hrc.io.task_file import load_task
from hrc.plans import code_sequences, count_plans, generate_plans, plan_code, plan_from_code


@pytest.mark.parametrize("name", ["kitting_6picks", "two_workers", "cube_stacking_joint"])
def test_code_sequences_are_each_codes_plan_sequences(name):
    """The dispatch form's ``seq`` rows read off the plan codes as arrays equal `plan_sequences` of each
    code's plan, for every plan of a two-agent task, a two-person one and one with joint actions."""
    task = load_task(ROOT / "tasks" / f"{name}.yaml")
    codes = [plan_code(task, plan) for plan in generate_plans(task)]
    got = code_sequences(task, np.frombuffer(b"".join(codes), dtype=np.uint16).reshape(len(codes), -1))
    want = np.stack([plan_sequences(task, plan_from_code(task, code)) for code in codes])
    assert got.dtype == want.dtype and np.array_equal(got, want)


def test_the_form_written_in_blocks_is_the_form_written_plan_by_plan(mini_task, tmp_path, monkeypatch):
    """A streamed compile writes its dispatch form in blocks of plans (`FormWriter.add_many`); with blocks
    of 3 plans (every block boundary crossed), the same bytes as `write_compiled`, which adds one plan
    at a time (`FormWriter.add`)."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(compile_task(mini_task, jobs=1), a)
    monkeypatch.setattr(sink, "_FORM_BLOCK", 3)
    compile_stream(mini_task, b, count_plans(mini_task), jobs=1, sample_seconds=0.0)
    assert count_plans(mini_task) > 3
    assert tree_bytes(a) == tree_bytes(b)


def test_conflicts_from_kept_rows_are_those_found_afresh():
    """`find_conflicts` keeps a robot occupancy's conflicts with a whole itinerary of the person as a
    row, reused by every plan with that itinerary: over 600 consecutive kitting_6picks plans (itineraries
    recur) and their route trials (detours, waiting places), the conflicts are those found with every
    per-process table emptied before each plan (nothing kept: each pair computed afresh)."""
    import itertools

    from hrc.compile.motion_pattern import _route_trials
    from hrc.motion import find_conflicts, plan_paths
    from hrc.plans import plan_families

    task = load_task(ROOT / "tasks" / "kitting_6picks.yaml")
    paths = plan_paths(task, seed=0)
    plans = [f[0] for f in itertools.islice(plan_families(task), 1200, 1500)]
    cases = [(plan, routes) for plan in plans for routes in [{}, *_route_trials(task, plan, paths, True)[:2]]]
    warm = [find_conflicts(task, plan, paths, routes) for plan, routes in cases]
    rows = sum(len(v) for k, v in paths.samples.items() if isinstance(k, tuple) and k[0] == "pair-rows")
    assert rows > 0
    for (plan, routes), kept in zip(cases, warm, strict=True):
        for k in [k for k in paths.samples if isinstance(k, tuple) and k[0] in ("pairs", "pair-ids", "occupancies",
                                                                                  "pair-rows", "itineraries")]:
            del paths.samples[k]
        assert find_conflicts(task, plan, paths, routes) == kept


def _zipfile_archive(path, names, texts):
    """`stnu.zip` as `zipfile` writes it (the sink's way before the workers deflated: the reference)."""
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, text in zip(names, texts, strict=True):
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, text, compresslevel=1)


def test_an_archive_of_deflated_entries_is_the_one_zipfile_writes(tmp_path):
    """`write_deflated_zip` lays a zip out around entries deflated elsewhere (`deflated`, in the compile's
    workers): the same bytes as `zipfile` deflating the same files itself, for an empty file, text,
    incompressible bytes and 300 files from two spools; `zipfile` reads it back (CRCs checked)."""
    import os
    import random
    import zipfile

    from hrc.compile.spool import deflated, needs_zip64, write_deflated_zip

    rng = random.Random(38)
    texts = [b"", b"<graphml/>\n" * 50, bytes(rng.randrange(256) for _ in range(5000))]
    texts += [(f"<node id=\"n{k}\"/>\n" * rng.randrange(1, 400)).encode() for k in range(297)]
    names = [f"stnu/{k:010x}.graphml" for k in range(len(texts))]
    spools = [tmp_path / "a.spool", tmp_path / "b.spool"]
    places = []
    with open(spools[0], "wb") as a, open(spools[1], "wb") as b:
        for k, text in enumerate(texts):
            f = (a, b)[k % 2]
            entry = deflated(text)
            places.append((k % 2, f.tell(), len(entry)))
            f.write(entry)
    fds = [os.open(p, os.O_RDONLY) for p in spools]
    try:
        assert not needs_zip64(names, [size for _, _, size in places])
        with open(tmp_path / "mine.zip", "wb") as out:
            write_deflated_zip(out, names, [(fds[s], at, size) for s, at, size in places])
    finally:
        for fd in fds:
            os.close(fd)
    _zipfile_archive(tmp_path / "ref.zip", names, texts)
    assert (tmp_path / "mine.zip").read_bytes() == (tmp_path / "ref.zip").read_bytes()
    with zipfile.ZipFile(tmp_path / "mine.zip") as zf:
        assert zf.testzip() is None and [zf.read(n) for n in names] == texts
    assert needs_zip64(["x"] * 65_536, [10] * 65_536)


def test_a_streamed_archive_is_the_zipfile_archive_of_the_graphml_files(mini_task, tmp_path):
    """With ``--stnu archive`` the GraphML is deflated where each plan is compiled (here, in this process:
    no pool) and laid into ``stnu.zip`` at the end: the archive `zipfile` writes of the GraphML files a
    ``--stnu graphml`` compile writes, in rank order, byte for byte."""
    import json

    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    compile_stream(mini_task, a, count_plans(mini_task), jobs=1, sample_seconds=0.0)
    compile_stream(mini_task, b, count_plans(mini_task), jobs=1, sample_seconds=0.0, stnu="archive")
    ids = [p["id"] for p in sorted(json.loads((a / "compiled.json").read_text())["plans"], key=lambda p: p["rank"])]
    assert len(ids) > 3
    _zipfile_archive(tmp_path / "ref.zip", [f"stnu/{i}.graphml" for i in ids],
                     [(a / "stnu" / f"{i}.graphml").read_bytes() for i in ids])
    assert (b / "stnu.zip").read_bytes() == (tmp_path / "ref.zip").read_bytes()
