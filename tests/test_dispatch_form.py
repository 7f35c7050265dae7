"""The dispatch form the compile writes (`hrc.compile.dispatch_form`): what is in it, and what the
dispatcher does with a form that is broken, from another compile, or missing."""

from __future__ import annotations

import hashlib
import json
import shutil

import numpy as np
import pytest
from conftest import ROOT
from reference_dispatch import read_entries

from hrc.cli import main
from hrc.compile.dispatch_form import FORM_FOLDER, build_form, plan_record, read_form
from hrc.compile.output import load_compiled_task
from hrc.dispatch import Dispatcher
from hrc.errors import InputError


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    """The workshop compiled twice, with two seeds (so two forms of the same task that differ), and
    once with --stnu archive."""
    base = tmp_path_factory.mktemp("form")
    out = {}
    for name, extra in (("ws", []), ("ws1", ["--seed", "1"]), ("zip", ["--stnu", "archive"])):
        out[name] = base / name
        assert main(["compile", str(ROOT / "tasks" / "cube_stacking.yaml"), "--out", str(out[name]), "--no-report",
                     "-q", *extra]) == 0
    return out


def _dispatch_error(folder, capsys) -> str:
    assert main(["dispatch", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    return err


def test_the_form_is_the_graphml_files_read_back(compiled):
    """The form the compile wrote equals the one built from the written GraphML files (every array),
    for files and for an archive; twins of identical actions share a shape, no one else does."""
    for name in ("ws", "zip"):
        task, entries, rank_by = read_entries(compiled[name])
        built = build_form(task, rank_by, [(e.id, e.compiled_class, e.preference, e.plan,
                                            plan_record(task, e.plan, e.stnu, e.blocked, graphml_names=True))
                                           for e in entries])
        written = read_form(compiled[name], task, rank_by)
        for field in ("seq", "nodes", "edges_ptr", "edges_u", "edges_v", "edges_w", "conts_ptr", "conts_a",
                      "conts_c", "conts_lb", "conts_ub"):
            assert np.array_equal(np.asarray(getattr(written, field)), getattr(built, field)), field
        for column in ("id", "rank", "cls", "blocked", "n", "shape"):
            assert np.array_equal(written.plans[column], built.plans[column]), column
        assert np.array_equal(written.plans["preference"], built.plans["preference"], equal_nan=True)


def test_each_plans_line_is_where_the_form_says(compiled):
    """``line_at``/``line_len`` point at each plan's line of compiled.json (a console reads one plan's
    motions without the rest)."""
    folder = compiled["ws"]
    data = (folder / "compiled.json").read_bytes()
    form = read_form(folder, load_compiled_task(folder), "worst")
    for p in range(len(form)):
        at, size = int(form.plans["line_at"][p]), int(form.plans["line_len"][p])
        line = json.loads(data[at:at + size])
        assert line["id"] == form.plan_id(p) and line["rank"] == p + 1


@pytest.mark.parametrize("damage, message", [
    ("truncate", "does not match form.json"),
    ("swap", "does not match form.json"),
    ("swap-all", "not the dispatch form compiled.json was written with"),
    ("remove", "does not match form.json"),
    ("form.json", "not the dispatch form compiled.json was written with"),
    ("no form.json", "cannot read the dispatch form"),
    ("routes.npy", "does not match routes.json"),
    ("routes", "not the route signatures of this dispatch form"),
    ("routes.json", "expected version 1"),
])
def test_a_broken_or_foreign_form_is_refused_in_one_line(compiled, tmp_path, capsys, damage, message):
    folder = tmp_path / "out"
    shutil.copytree(compiled["ws"], folder)
    form = folder / FORM_FOLDER
    other = compiled["ws1"] / FORM_FOLDER
    if damage == "truncate":
        data = (form / "edges_w.npy").read_bytes()
        (form / "edges_w.npy").write_bytes(data[:len(data) // 2])
    elif damage == "swap":  # one array from the same task compiled with another seed
        shutil.copyfile(other / "edges_w.npy", form / "edges_w.npy")
    elif damage == "swap-all":  # the other compile's whole form, consistent in itself
        shutil.rmtree(form)
        shutil.copytree(other, form)
    elif damage == "remove":
        (form / "nodes.npy").unlink()
    elif damage == "routes.npy":  # one signature changed
        data = (form / "routes.npy").read_bytes()
        (form / "routes.npy").write_bytes(data[:-4] + bytes(4))
    elif damage == "routes":  # another compile's route signatures, consistent in themselves
        for name in ("routes.npy", "routes.json"):
            shutil.copyfile(other / name, form / name)
    elif damage == "routes.json":
        (form / "routes.json").write_text('{"hrc_routes": 0}')
    elif damage == "form.json":
        meta = json.loads((form / "form.json").read_text())
        meta["plans"] += 1
        (form / "form.json").write_text(json.dumps(meta))
    else:
        (form / "form.json").unlink()
    err = _dispatch_error(folder, capsys)
    assert message in err and str(form) in err


def test_a_compile_without_a_form_still_dispatches_the_same(compiled, tmp_path):
    """An output written before the form existed (no ``dispatch_form`` in compiled.json, no dispatch/) is
    read from its GraphML files: the same decisions."""
    folder = tmp_path / "old"
    shutil.copytree(compiled["zip"], folder)
    shutil.rmtree(folder / FORM_FOLDER)
    text = (folder / "compiled.json").read_text()
    head, rest = text.split(',\n "plans": [', 1)
    header = json.loads(head + "\n}")
    del header["dispatch_form"]
    (folder / "compiled.json").write_text(json.dumps(header, indent=1)[:-2] + ',\n "plans": [' + rest)
    old, new = Dispatcher.from_folder(folder), Dispatcher.from_folder(compiled["zip"])
    assert old.plan_set.source == str(folder) and len(old.plan_set) == len(new.plan_set)
    assert old.decision == new.decision and old.candidates == new.candidates


def test_the_route_signatures_beside_the_form(compiled, tmp_path):
    """routes.json names the form.json it belongs to (the one compiled.json names: compiled.json is the
    same bytes as without it) and routes.npy's digest; read back, they are the ones `build_form` makes.
    A form without them (written before they existed) is still read, its routes made when asked: the
    same decisions."""
    folder = compiled["ws"]
    form_dir = folder / FORM_FOLDER
    meta = json.loads((form_dir / "routes.json").read_text())
    header = json.loads((folder / "compiled.json").read_text().split(',\n "plans": [', 1)[0] + "\n}")
    assert meta["form_sha256"] == header["dispatch_form"]["sha256"] == \
        hashlib.sha256((form_dir / "form.json").read_bytes()).hexdigest()
    assert "routes" not in (form_dir / "form.json").read_text()
    task, entries, rank_by = read_entries(folder)
    built = build_form(task, rank_by, [(e.id, e.compiled_class, e.preference, e.plan,
                                        plan_record(task, e.plan, e.stnu, e.blocked, graphml_names=True))
                                       for e in entries])
    written = read_form(folder, task, rank_by)
    assert written.routes is not None and np.array_equal(np.asarray(written.routes), built.routes)
    old = tmp_path / "old"
    shutil.copytree(folder, old)
    for name in ("routes.json", "routes.npy"):
        (old / FORM_FOLDER / name).unlink()
    assert read_form(old, task, rank_by).routes is None
    a, b = Dispatcher.from_folder(old), Dispatcher.from_folder(folder)
    assert a.decision == b.decision and a.candidates == b.candidates


def test_a_partial_or_stnu_less_output_is_refused(compiled, tmp_path, capsys):
    folder = tmp_path / "partial"
    shutil.copytree(compiled["ws"], folder)
    text = (folder / "compiled.json").read_text()
    (folder / "compiled.json").write_text(text.replace('"counts"', '"partial": true,\n "counts"', 1))
    assert "partial output" in _dispatch_error(folder, capsys)
    assert Dispatcher.from_folder(folder, allow_partial=True).decision.plan is not None
    none = tmp_path / "none"
    assert main(["compile", str(ROOT / "tasks" / "cube_stacking.yaml"), "--out", str(none), "--no-report", "-q",
                 "--stnu", "none"]) == 0
    assert not (none / FORM_FOLDER).exists()
    assert "--stnu none" in _dispatch_error(none, capsys)
    with pytest.raises(InputError):
        Dispatcher.from_folder(none)
