"""The STPP JSON format (docs/apa.md): read with one clear error per bad input, write atomically.

::

    {"name": "example",                       (optional)
     "events": ["e0", "e1", ...],
     "constraints": [{"from": "e0", "to": "e1", "lb": 1.0, "ub": 5.0,
                      "preference": null | {"kind": "constant" | "linear" | "quadratic",
                                            "coeffs": [c0, c1, c2]}}]}

``lb <= T(to) - T(from) <= ub`` in seconds; ``lb`` / ``ub`` may be ``null`` (unbounded) unless the
constraint has a preference, whose value is ``c0 + c1*d + c2*d**2`` for ``d = T(to) - T(from)``
(``coeffs`` has 1, 2 or 3 numbers for the three kinds; a missing ``preference`` is ``null``).

`load_stpp` raises `StppFileError` as ``FILE[:LINE]: KEY.PATH: what is wrong`` (JSON gives a line only
for syntax errors); ``load_stpp(dump_stpp(s)) == s`` (tested).
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, NoReturn

from hrc.apa.model import STPP, Constraint, PreferenceFunction
from hrc.errors import ApaError, StppFileError
from hrc.io.atomic import write_text_atomic
from hrc.io.yamldoc import format_key
from hrc.model import PreferenceKind

__all__ = ["dump_stpp", "load_stpp", "parse_stpp", "stpp_to_dict"]

_KINDS = {k.value: k for k in PreferenceKind}


class _Reader:
    def __init__(self, file: str) -> None:
        self.file = file

    def fail(self, path: tuple[str | int, ...], message: str, line: int | None = None) -> NoReturn:
        raise StppFileError(self.file, format_key(path), message, line)

    def mapping(self, raw: Any, path: tuple, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
        if not isinstance(raw, dict):
            self.fail(path, f"expected an object, found {_kind(raw)}")
        for key in raw:
            if key not in required and key not in optional:
                self.fail(path + (key,), f"unknown key (expected {', '.join(required + optional)})")
        for key in required:
            if key not in raw:
                self.fail(path + (key,), "missing")
        return raw

    def sequence(self, raw: Any, path: tuple) -> list:
        if not isinstance(raw, list):
            self.fail(path, f"expected a list, found {_kind(raw)}")
        return raw

    def number(self, raw: Any, path: tuple, *, allow_null: bool = False) -> float:
        if raw is None and allow_null:
            return math.nan  # the caller turns it into the right infinity
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            what = "a number or null" if allow_null else "a number"
            self.fail(path, f"expected {what}, found {_kind(raw)}")
        if not math.isfinite(raw):
            self.fail(path, f"expected a finite number, found {raw}")
        return float(raw)

    def name(self, raw: Any, path: tuple) -> str:
        if not isinstance(raw, str) or not raw.strip() or raw != raw.strip():
            self.fail(path, f"expected a non-empty event name without surrounding spaces, found {_kind(raw)}")
        return raw


def _kind(raw: Any) -> str:
    if raw is None:
        return "null"
    if isinstance(raw, bool):
        return f"a boolean ({str(raw).lower()})"
    if isinstance(raw, dict):
        return "an object"
    if isinstance(raw, list):
        return "a list"
    if isinstance(raw, str):
        return f"the string {raw!r}"
    return repr(raw)


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Duplicate(key)
        out[key] = value
    return out


class _Duplicate(Exception):
    pass


def _reject_constant(text: str) -> NoReturn:
    raise ValueError(f"{text} is not a JSON number")


def parse_stpp(text: str, file: str = "<stpp>") -> STPP:
    """Parse STPP JSON `text` (`file` names it in errors)."""
    r = _Reader(file)
    try:
        raw = json.loads(text, object_pairs_hook=_no_duplicates, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        r.fail((), f"JSON syntax: {err.msg} (column {err.colno})", err.lineno)
    except _Duplicate as err:
        r.fail((str(err),), "duplicate key")
    except ValueError as err:
        r.fail((), f"JSON syntax: {err}")
    top = r.mapping(raw, (), ("events", "constraints"), ("name",))
    name = top.get("name", "")
    if not isinstance(name, str):
        r.fail(("name",), f"expected a string, found {_kind(name)}")
    events = [r.name(e, ("events", i)) for i, e in enumerate(r.sequence(top["events"], ("events",)))]
    if not events:
        r.fail(("events",), "an STPP needs at least one event")
    seen: dict[str, int] = {}
    for i, e in enumerate(events):
        if e in seen:
            r.fail(("events", i), f"event {e!r} is listed twice (first as events[{seen[e]}])")
        seen[e] = i
    constraints = [_constraint(r, raw_c, ("constraints", i), seen)
                   for i, raw_c in enumerate(r.sequence(top["constraints"], ("constraints",)))]
    try:
        return STPP(tuple(events), tuple(constraints), name)
    except ApaError as err:  # every check is made above; this keeps a missed one a located error
        r.fail((), str(err))


def _constraint(r: _Reader, raw: Any, path: tuple, events: dict[str, int]) -> Constraint:
    m = r.mapping(raw, path, ("from", "to", "lb", "ub"), ("preference",))
    ends = []
    for key in ("from", "to"):
        e = r.name(m[key], path + (key,))
        if e not in events:
            r.fail(path + (key,), f"unknown event {e!r}")
        ends.append(e)
    if ends[0] == ends[1]:
        r.fail(path + ("to",), f"an event constrained against itself ({ends[0]!r})")
    lb = r.number(m["lb"], path + ("lb",), allow_null=True)
    ub = r.number(m["ub"], path + ("ub",), allow_null=True)
    lb = -math.inf if math.isnan(lb) else lb
    ub = math.inf if math.isnan(ub) else ub
    if lb > ub:
        r.fail(path, f"lb {lb:g} > ub {ub:g}")
    pref = None
    if m.get("preference") is not None:
        pref = _preference(r, m["preference"], path + ("preference",))
        if not (math.isfinite(lb) and math.isfinite(ub)):
            r.fail(path + ("preference",), f"a preference needs a finite interval, found lb {lb:g}, ub {ub:g}")
        low = pref.min_on(lb, ub)
        if low < 0:
            r.fail(path + ("preference",), f"must be non-negative on [{lb:g}, {ub:g}] (the paper's preferences "
                                           f"are positive-valued), found {low:g}")
    return Constraint(ends[0], ends[1], lb, ub, pref)


def _preference(r: _Reader, raw: Any, path: tuple) -> PreferenceFunction:
    m = r.mapping(raw, path, ("kind", "coeffs"))
    if m["kind"] not in _KINDS:
        r.fail(path + ("kind",), f"expected one of {', '.join(_KINDS)}, found {_kind(m['kind'])}")
    kind = _KINDS[m["kind"]]
    coeffs = [r.number(c, path + ("coeffs", i)) for i, c in enumerate(r.sequence(m["coeffs"], path + ("coeffs",)))]
    want = {PreferenceKind.CONSTANT: 1, PreferenceKind.LINEAR: 2, PreferenceKind.QUADRATIC: 3}[kind]
    if len(coeffs) != want:
        r.fail(path + ("coeffs",), f"a {kind.value} preference takes {want} coefficient(s) [c0, c1, c2 ...], "
                                   f"found {len(coeffs)}")
    if kind is PreferenceKind.QUADRATIC and coeffs[2] > 0:
        r.fail(path + ("coeffs", 2), f"a quadratic preference must be concave (c2 <= 0), found {coeffs[2]:g}: "
                                     f"a convex one would make the QP non-convex")
    return PreferenceFunction(kind, tuple(coeffs))


def load_stpp(path: str | os.PathLike[str]) -> STPP:
    """Read and validate an STPP JSON file; raises `StppFileError` (also for an unreadable file)."""
    file = os.fspath(path)
    try:
        with open(file, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as err:
        raise StppFileError(file, "", f"cannot read: {getattr(err, 'strerror', None) or err}") from err
    return parse_stpp(text, file)


def _bound(v: float) -> float | None:
    return None if math.isinf(v) else v


def stpp_to_dict(stpp: STPP) -> dict[str, Any]:
    """The JSON-ready form of `stpp`."""
    out: dict[str, Any] = {"name": stpp.name} if stpp.name else {}
    out["events"] = list(stpp.events)
    out["constraints"] = [
        {"from": c.source, "to": c.target, "lb": _bound(c.lb), "ub": _bound(c.ub),
         "preference": None if c.preference is None else
         {"kind": c.preference.kind.value, "coeffs": list(c.preference.coefficients)}}
        for c in stpp.constraints]
    return out


def dump_stpp(stpp: STPP, path: str | os.PathLike[str]) -> None:
    """Write `stpp` as JSON to `path`, atomically."""
    write_text_atomic(path, json.dumps(stpp_to_dict(stpp), indent=1) + "\n")
