"""``compiled.json`` at any plan count (issue 38): above `INLINE_MAX_BYTES` of plan lines the lines go to
``plans.jsonl`` and ``compiled.json`` lists a short row per plan (schema version 3). Every reader gets the
same plans from it as from the single file main writes: the plan set's arrays, the dispatcher's answers,
each plan's motions, resume; ``hrc show OUT --plan ID`` reads one plan from either layout."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT, WORKSHOP_TASK, compiled_folder, tree_bytes
from test_dispatch_oracle import Driver
from test_stream import _interrupted, _resumed, picks4, picks4_file  # noqa: F401 - fixtures

from hrc.cli import main
from hrc.compile.compiler import CompileOptions
from hrc.compile.output import INLINE_MAX_BYTES, PLAN_LINES, iter_plans, read_header, read_plan
from hrc.compile.sink import PlanSink
from hrc.compile.stream import compile_stream
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import content_digest, load_plan_set
from hrc.dispatch.routes import plan_motions
from hrc.plans import count_plans

KITTING = ROOT / "tasks" / "kitting.yaml"
PINS = ("--pin", "pick_a=human", "--pin", "pick_b=human", "--pin", "pick_c=robot", "--pin", "inspect=human",
        "--pin", "label=robot", "--stnu", "archive")


@pytest.fixture(scope="module")
def kits(tmp_path_factory):
    """Kitting with five actions pinned (N of its 2,880 plans), as main writes it (one file: its lines
    are about 2 MB) and again with the threshold at 0 (the split layout every larger compile gets)."""
    base = tmp_path_factory.mktemp("split")
    inline = compiled_folder(base / "inline", KITTING, *PINS)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(PlanSink, "inline_max", 0)
        split = compiled_folder(base / "split", KITTING, *PINS)
    return inline, split


def _lines(path) -> list[bytes]:
    return [x.rstrip(b",\n") for x in path.read_bytes().splitlines(keepends=True) if x.startswith(b'{"id":')]


def test_a_small_output_keeps_its_single_file(kits):
    inline, split = kits
    assert read_header(inline)["schema_version"] == 2 and not (inline / PLAN_LINES).exists()
    assert (inline / "compiled.json").stat().st_size < INLINE_MAX_BYTES


def test_the_split_lines_are_the_single_files_lines_and_the_rows_their_summary(kits):
    inline, split = kits
    whole = _lines(inline / "compiled.json")
    n = len(whole)
    assert n == len(list(iter_plans(inline))) > 50
    text = (split / PLAN_LINES).read_bytes()
    assert text.split(b"\n") == [*whole, b""]  # line k is rank k, byte for byte main's line
    old, new = read_header(inline), read_header(split)
    assert new.pop("plan_lines") == {"path": PLAN_LINES, "bytes": len(text)}
    assert (new.pop("schema_version"), old.pop("schema_version")) == (3, 2)
    assert new.pop("dispatch_form")["path"] == old.pop("dispatch_form")["path"]
    summary = new.pop("ranking_summary")
    assert new == old
    rows = json.loads((split / "compiled.json").read_text())["plans"]
    full = [json.loads(x) for x in whole]
    for cls, said in summary.items():  # the ranking at a glance, against the full lines
        mine = [p for p in full if p["class"] == cls]
        timed = [p["makespan"] for p in mine if p["makespan"] is not None]
        assert said["plans"] == len(mine) and said["no_schedule"] == len(mine) - len(timed)
        if timed:
            assert said["worst"][0] == min(w for _, w in timed) and said["worst"][-1] == max(w for _, w in timed)
            assert said["earliest"][2] == round(float(np.median([e for e, _ in timed])), 3)
    assert [list(r) for r in rows] == [["id", "rank", "class", "sequences", "makespan", "preference"]] * n
    assert rows == [{k: p[k] for k in rows[0]} for p in full]
    assert (split / "compiled.json").stat().st_size < 250 * n + 1000  # about 200 bytes a plan


def test_the_dispatch_form_differs_only_where_the_lines_lie(kits):
    inline, split = kits
    for path in sorted((inline / "dispatch").glob("*.npy")):
        if path.name != "plans.npy":
            assert path.read_bytes() == (split / "dispatch" / path.name).read_bytes(), path.name
    a, b = (load_plan_set(x) for x in kits)
    try:
        for column in a.form.plans.dtype.names:
            same = np.array_equal(a.form.plans[column], b.form.plans[column], equal_nan=column == "preference")
            assert same == (column != "line_at"), column  # the same lines, elsewhere
        assert content_digest(a.form) == content_digest(b.form)
        motions_a, motions_b = plan_motions(inline, a), plan_motions(split, b)
        for p in range(len(a)):
            pid = a.id(p)
            assert motions_b(pid) == motions_a(pid) and motions_a(pid)
            assert read_plan(split, pid) == read_plan(inline, pid)
        assert motions_b("0" * 10) is None and read_plan(split, "0" * 10) is None
        assert list(iter_plans(split)) == list(iter_plans(inline))
    finally:
        a.close()
        b.close()


def test_the_dispatcher_answers_alike_from_either_layout(kits):
    """Random runs (tests/test_dispatch_oracle.py's driver) on the split output, every answer, option,
    candidate set and planned time compared with the single file's dispatcher."""
    inline, split = kits
    base_a, base_b = Dispatcher.from_folder(inline, threads=1), Dispatcher.from_folder(split, threads=1)
    sent = 0
    for seed in range(6):
        driver = Driver(Dispatcher(base_b.plan_set, ranker=base_b.ranker),
                        Dispatcher(base_a.plan_set, ranker=base_a.ranker), seed)
        driver.play(25)
        sent += driver.sent
    assert sent > 60


def test_a_split_partial_output_resumes_to_the_same_files(picks4, tmp_path, monkeypatch):  # noqa: F811
    """Interrupted and resumed in the split layout: the same files, byte for byte, as a compile never
    interrupted (the old lines are taken from the partial output's plans.jsonl)."""
    from hrc.compile.resume import read_resume

    monkeypatch.setattr(PlanSink, "inline_max", 0)
    task = picks4[0]
    whole = tmp_path / "whole"
    whole.mkdir()
    compile_stream(task, whole, count_plans(task), jobs=1, stnu="archive", sample_seconds=0.0)
    first = _interrupted(task, tmp_path / "first", 2, jobs=1, stnu="archive")
    assert first.partial and 0 < first.compiled < 120
    assert read_header(tmp_path / "first")["schema_version"] == 3 and (tmp_path / "first" / PLAN_LINES).is_file()
    last = _resumed(task, tmp_path / "first", tmp_path / "last", jobs=1, stnu="archive")
    assert not last.partial and last.compiled == 120
    assert tree_bytes(tmp_path / "last") == tree_bytes(whole)
    assert read_resume is not None


def test_show_plan_prints_one_plans_detail(tmp_path, capsys):
    """The workshop's best plan, its values as read by hand from compiled.json (seed 0)."""
    out = compiled_folder(tmp_path / "ws")
    capsys.readouterr()
    assert main(["show", str(out), "--plan", "e636cb797a"]) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert lines[0] == f"plan e636cb797a of cube_stacking ({out}): rank 1 of 32, DC"
    assert "  makespan 57.692-64.305 s (earliest-worst case), nominal " in text
    assert "    human: cube1 -> cube3 -> triangle" in lines and "    robot: cube2 -> cube4" in lines
    assert "  allocation: human: cube1, cube3, triangle; robot: cube2, cube4" in lines
    entry = next(p for p in iter_plans(out) if p["id"] == "e636cb797a")
    assert f"  motions ({len(entry['motions'])}):" in lines
    orders = [x for x in lines if x.startswith(("    robot first", "    human first"))]
    assert len(orders) == len(entry["passing"])
    assert lines[-1] == f"  STNU: {out / 'stnu' / 'e636cb797a.graphml'}"
    assert main(["show", str(out), "--plan", "e636cb797a", "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == entry | {"stnu_location": str(out / "stnu" / "e636cb797a.graphml")}
    assert main(["show", str(out)]) == 0
    top = capsys.readouterr().out
    assert "32 plans, 11 DC, 13 consistent, 8 inconsistent" in top and "     1. e636cb797a  DC" in top


def test_show_plan_reads_a_split_output_as_the_single_file(kits, capsys):
    inline, split = kits
    last = read_header(inline)  # the last-ranked plan: the far end of plans.jsonl
    pid = list(iter_plans(inline))[-1]["id"]
    texts = []
    for folder in kits:
        assert main(["show", str(folder), "--plan", pid]) == 0
        texts.append(capsys.readouterr().out.replace(str(folder), "OUT"))
    n = sum(last["counts"].values())
    assert texts[0] == texts[1] and f"rank {n} of {n}" in texts[0] and "stnu.zip: member stnu/" in texts[0]
    assert last["counts"] == read_header(split)["counts"]


def test_a_bad_plan_id_is_one_line_and_exit_2(kits, capsys):
    for folder in kits:
        assert main(["show", str(folder), "--plan", "nosuchplan"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: {folder / 'compiled.json'}: plans: no plan 'nosuchplan'")
        assert err.count("\n") == 1
    assert main(["show", str(WORKSHOP_TASK), "--plan", "e636cb797a"]) == 2
    err = capsys.readouterr().err
    assert "--plan reads an output folder" in err and err.count("\n") == 1
    assert main(["show", str(ROOT / "tasks"), "--plan", "e636cb797a"]) == 2  # a folder, but no output
    err = capsys.readouterr().err
    assert "not an hrc compile output" in err and err.count("\n") == 1


def test_resume_reads_either_schema(picks4, tmp_path):  # noqa: F811
    """`read_resume` takes a partial output of either layout and refuses a schema it does not know."""
    from hrc.compile.resume import read_resume
    from hrc.errors import InputError

    task = picks4[0]
    _interrupted(task, tmp_path / "p", 2, jobs=1)
    compiled = tmp_path / "p" / "compiled.json"
    assert len(read_resume(tmp_path / "p", task, 0, CompileOptions(), "graphml", False, None))
    compiled.write_text(compiled.read_text().replace('"schema_version": 2', '"schema_version": 9', 1))
    with pytest.raises(InputError, match="schema_version: --resume: 9 is no schema"):
        read_resume(tmp_path / "p", task, 0, CompileOptions(), "graphml", False, None)


def test_the_in_memory_writer_splits_as_the_stream_does(picks4, tmp_path, monkeypatch):  # noqa: F811
    """`write_compiled` with the threshold at 0 writes the bytes a streamed compile writes with it."""
    from hrc.compile.output import write_compiled

    task, full, _ = picks4
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    write_compiled(full, a, inline_max=0)
    monkeypatch.setattr(PlanSink, "inline_max", 0)
    compile_stream(task, b, count_plans(task), jobs=1, sample_seconds=0.0)
    assert tree_bytes(a) == tree_bytes(b) and (a / PLAN_LINES).is_file()


def test_a_split_output_lists_at_most_rows_max_rows(picks4, tmp_path, monkeypatch, capsys):  # noqa: F811
    """Past `ROWS_MAX` plans `compiled.json` lists the best that many and says so (``plans_listed``);
    every plan's line is still in plans.jsonl, and one beyond the rows is read by id."""
    import hrc.compile.output as output
    from hrc.compile.output import write_compiled

    task, full, _ = picks4
    monkeypatch.setattr(output, "ROWS_MAX", 5)
    write_compiled(full, tmp_path, inline_max=0)
    data = json.loads((tmp_path / "compiled.json").read_text())
    assert data["plans_listed"] == 5 == len(data["plans"]) and sum(data["counts"].values()) == 120
    every = list(iter_plans(tmp_path))
    assert len(every) == 120 and [r["id"] for r in data["plans"]] == [p["id"] for p in every[:5]]
    assert read_plan(tmp_path, every[-1]["id"]) == every[-1]
    assert main(["show", str(tmp_path), "--top", "3"]) == 0
    assert capsys.readouterr().out.count("\n  ") >= 3


def test_the_rows_of_a_task_with_preferences_are_its_lines_values(tmp_path, monkeypatch):
    """The workshop (an APA preference, so every plan has a preference value) split: each row's values
    (from the sink's rank-key columns: the preference negated and rounded there) as its full line has them."""
    from hrc.io.task_file import load_task

    task = load_task(WORKSHOP_TASK)
    monkeypatch.setattr(PlanSink, "inline_max", 0)
    compile_stream(task, tmp_path, count_plans(task), jobs=1, sample_seconds=0.0)
    rows = json.loads((tmp_path / "compiled.json").read_text())["plans"]
    full = list(iter_plans(tmp_path))
    assert sum(p["preference"] is not None for p in full) == 32
    assert rows == [{k: p[k] for k in rows[0]} for p in full]


def test_the_lines_are_written_here_when_their_process_fails(picks4, tmp_path, monkeypatch):  # noqa: F811
    """`PLAN_LINES` is written in a forked process at the end of a compile (beside the dispatch form); if
    that process fails (its handle answers None), this one writes them: the same bytes."""
    import hrc.compile.sink as sink

    task, _, _ = picks4
    a, b = tmp_path / "a", tmp_path / "b"
    monkeypatch.setattr(PlanSink, "inline_max", 0)
    compile_stream(task, a, count_plans(task), jobs=1, sample_seconds=0.0)
    started = []

    def failing(fn):
        started.append(fn)
        return lambda: None  # as `Apart` answers for a child that raised or died

    monkeypatch.setattr(sink, "run_apart", failing)
    compile_stream(task, b, count_plans(task), jobs=1, sample_seconds=0.0)
    assert len(started) == 1 and tree_bytes(a) == tree_bytes(b) and (b / PLAN_LINES).stat().st_size > 0
