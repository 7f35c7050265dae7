"""The STPP JSON format: every bad input is one ``error: FILE[:LINE]: KEY.PATH: message`` line, exit 2,
nothing on stdout, never a traceback; and ``load(dump(s)) == s``."""

from __future__ import annotations

import copy
import json
import re
import subprocess
import sys
from typing import Any

import numpy as np
import pytest

from hrc.apa.generator import random_stpp
from hrc.apa.io import dump_stpp, load_stpp
from hrc.cli import main

ERROR_LINE = re.compile(r"^error: (?P<file>[^:\n]+?)(?::(?P<line>\d+))?: (?P<rest>[^\n]*)\n$")

GOOD: dict[str, Any] = {
    "name": "ok",
    "events": ["a", "b", "c"],
    "constraints": [
        {"from": "a", "to": "b", "lb": 1.0, "ub": 5.0,
         "preference": {"kind": "quadratic", "coeffs": [0.0, 6.0, -1.0]}},
        {"from": "b", "to": "c", "lb": 0, "ub": None, "preference": None},
    ],
}


def _set(doc: dict, path: str, value: Any) -> None:
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    for p in parents:
        doc = doc[p]
    doc[last] = value


def _del(doc: dict, path: str) -> None:
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    for p in parents:
        doc = doc[p]
    del doc[last]


CASES = [
    # (id, edit, expected key path, message fragment)
    ("top-list", lambda d: d.clear() or d.update({"x": 1}), "x", "unknown key"),
    ("no-events", lambda d: _del(d, "events"), "events", "missing"),
    ("events-not-list", lambda d: _set(d, "events", "a"), "events", "expected a list"),
    ("events-empty", lambda d: _set(d, "events", []), "events", "at least one event"),
    ("event-dup", lambda d: _set(d, "events", ["a", "b", "a"]), "events[2]", "listed twice"),
    ("event-not-str", lambda d: _set(d, "events.1", 3), "events[1]", "event name"),
    ("name-not-str", lambda d: _set(d, "name", 1), "name", "expected a string"),
    ("constraint-not-obj", lambda d: _set(d, "constraints.0", [1, 2]), "constraints[0]", "expected an object"),
    ("constraint-unknown-key", lambda d: _set(d, "constraints.1.bounds", 1), "constraints[1].bounds",
     "unknown key"),
    ("constraint-no-to", lambda d: _del(d, "constraints.1.to"), "constraints[1].to", "missing"),
    ("unknown-event", lambda d: _set(d, "constraints.1.to", "z"), "constraints[1].to", "unknown event 'z'"),
    ("self", lambda d: _set(d, "constraints.1.to", "b"), "constraints[1].to", "against itself"),
    ("lb-string", lambda d: _set(d, "constraints.0.lb", "1"), "constraints[0].lb", "expected a number"),
    ("lb-bool", lambda d: _set(d, "constraints.0.lb", True), "constraints[0].lb", "expected a number"),
    ("lb-gt-ub", lambda d: _set(d, "constraints.1.lb", 9) or _set(d, "constraints.1.ub", 2),
     "constraints[1]", "lb 9 > ub 2"),
    ("pref-open-interval", lambda d: _set(d, "constraints.0.ub", None), "constraints[0].preference",
     "finite interval"),
    ("pref-not-obj", lambda d: _set(d, "constraints.0.preference", 3), "constraints[0].preference",
     "expected an object"),
    ("pref-kind", lambda d: _set(d, "constraints.0.preference.kind", "cubic"), "constraints[0].preference.kind",
     "expected one of constant, linear, quadratic"),
    ("pref-count", lambda d: _set(d, "constraints.0.preference.coeffs", [1, 2]),
     "constraints[0].preference.coeffs", "takes 3 coefficient"),
    ("pref-convex", lambda d: _set(d, "constraints.0.preference.coeffs", [10, 0, 1]),
     "constraints[0].preference.coeffs[2]", "must be concave"),
    ("pref-negative", lambda d: _set(d, "constraints.0.preference.coeffs", [0, 0, -1]),
     "constraints[0].preference", "non-negative"),
    ("pref-coeff-str", lambda d: _set(d, "constraints.0.preference.coeffs", [0, "6", -1]),
     "constraints[0].preference.coeffs[1]", "expected a number"),
    ("pref-no-kind", lambda d: _del(d, "constraints.0.preference.kind"), "constraints[0].preference.kind",
     "missing"),
]


def _run(path, capsys) -> tuple[int, str, str]:
    code = main(["apa", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_stpp(tmp_path, capsys, case):
    _, edit, key, fragment = case
    doc = copy.deepcopy(GOOD)
    edit(doc)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc, indent=1))
    code, out, err = _run(path, capsys)
    assert code == 2 and out == ""
    m = ERROR_LINE.match(err)
    assert m, err
    assert m["file"] == str(path)
    assert m["rest"].startswith(f"{key}: ") and fragment in m["rest"], err


@pytest.mark.parametrize("text, fragment, line", [
    ('{"events": ["a"],\n "constraints": [,]}', "JSON syntax", 2),
    ('{"events": ["a"], "events": ["b"], "constraints": []}', "duplicate key", None),
    ('{"events": ["a", "b"], "constraints": [{"from": "a", "to": "b", "lb": NaN, "ub": 1}]}', "NaN", None),
    ('', "JSON syntax", 1),
    ('[1]', "expected an object, found a list", None),
])
def test_bad_json(tmp_path, capsys, text, fragment, line):
    path = tmp_path / "bad.json"
    path.write_text(text)
    code, out, err = _run(path, capsys)
    assert code == 2 and out == ""
    m = ERROR_LINE.match(err)
    assert m and fragment in m["rest"], err
    assert (int(m["line"]) if m["line"] else None) == line


def test_missing_file_and_subprocess_has_no_traceback(tmp_path, capsys):
    code, out, err = _run(tmp_path / "nowhere.json", capsys)
    assert code == 2 and "cannot read" in err and err.count("\n") == 1
    doc = copy.deepcopy(GOOD)
    doc["constraints"][0]["preference"]["coeffs"] = [10, 0, 1]
    path = tmp_path / "convex.json"
    path.write_text(json.dumps(doc))
    proc = subprocess.run([sys.executable, "-m", "hrc", "apa", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stdout == "" and "Traceback" not in proc.stderr
    assert ERROR_LINE.match(proc.stderr)


def test_round_trip(tmp_path):
    for seed in range(3):
        s = random_stpp(20, np.random.default_rng(seed))
        dump_stpp(s, tmp_path / "s.json")
        assert load_stpp(tmp_path / "s.json") == s
    (tmp_path / "g.json").write_text(json.dumps(GOOD))
    g = load_stpp(tmp_path / "g.json")
    dump_stpp(g, tmp_path / "g2.json")
    assert load_stpp(tmp_path / "g2.json") == g
