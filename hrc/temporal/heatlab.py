"""HEATlab JSON STNUs (read only), as in HEATlab's Prob-in-Ctrl dataset (MIT licence).

``{"nodes": [{"node_id": 1}, ...], "constraints": [{"first_node": A, "second_node": B, "type": "stc" |
"stcu", "min_duration": l, "max_duration": u}, ...]}``: ``stcu`` is a contingent link A -> B with duration in
[l, u] (l == u occurs), ``stc`` the requirement ``l <= T(B) - T(A) <= u``. Timepoints are named by their ids
(``"1"``, ...). Node 0 is the dataset's origin; it becomes a timepoint (``"0"``, listed first) when constraints use it
even if ``nodes`` does not list it (two files in the dataset do that). No implicit constraint comes
with it.

A contingent link's negative ``min_duration`` (four files of the dataset have one, from bounds drawn
around a mean) is raised to 0: nature cannot end a duration before it starts, and the contingent link type
requires ``lb >= 0``.

Bounds are decimal numbers: they are read as exact fractions from the JSON text and multiplied by their
least common denominator (`hrc.temporal.ticks.scale_to_integers`), which keeps every verdict. ``Infinity``,
the string ``"inf"`` (``"-inf"`` for a lower bound) or a missing / ``null`` bound of an ``stc`` means unbounded.
"""

from __future__ import annotations

import json
from decimal import Decimal

from hrc.errors import NetworkFileError
from hrc.temporal.limits import MAX_MAGNITUDE, check_size, show
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink
from hrc.temporal.ticks import scale_to_integers

__all__ = ["MAX_DECIMALS", "MAX_JSON_VALUES", "read_heatlab", "read_heatlab_scaled"]

MAX_JSON_VALUES = 4_000_000
"""Most JSON values (counted as commas and colons, before parsing) in a HEATlab file: parsing builds a
Python object per value, so this bounds the memory a file can take (about 1 GiB)."""
MAX_DECIMALS = 20
"""Most decimals in a HEATlab bound (the dataset prints floats in full, up to 17 significant digits); with
bounds within `MAX_MAGNITUDE` units, the exact scale to integer ticks is then at most 10^20."""
_POS_INF = {"inf", "+inf", "infinity", "+infinity"}
_NEG_INF = {"-inf", "-infinity"}


def read_heatlab(text: str, file: str = "<json>") -> STNU:
    """Parse HEATlab JSON into an integer STNU (see the module docstring)."""
    return read_heatlab_scaled(text, file)[0]


def read_heatlab_scaled(text: str, file: str = "<json>") -> tuple[STNU, int]:
    """Like `read_heatlab`, also returning the scale: ticks per unit of the file's numbers."""
    values = text.count(",") + text.count(":")
    if values > MAX_JSON_VALUES:
        raise NetworkFileError(file, "", f"about {values:,} JSON values, over the limit of {MAX_JSON_VALUES:,} "
                                         "for a network file")
    try:
        doc = json.loads(text, parse_float=Decimal, parse_int=Decimal,
                         parse_constant=lambda c: None if c == "Infinity" else _bad_constant(c))
    except json.JSONDecodeError as err:
        raise NetworkFileError(file, "", f"not valid JSON: {err.msg}", err.lineno) from err
    except RecursionError as err:
        raise NetworkFileError(file, "", "not a network file: JSON nested too deeply") from err
    except ArithmeticError as err:  # decimal.Overflow and friends: an exponent Decimal cannot hold
        raise NetworkFileError(file, "", f"a number is out of range (at most {MAX_MAGNITUDE:.0e} in absolute "
                                         "value)") from err
    except ValueError as err:
        raise NetworkFileError(file, "", show(str(err))[1:-1]) from err
    if not isinstance(doc, dict) or not isinstance(doc.get("nodes"), list) or not isinstance(
        doc.get("constraints"), list
    ):
        raise NetworkFileError(file, "", "not an STNU file: HEATlab JSON is an object with lists 'nodes' and "
                                         "'constraints'")
    check_size(len(doc["nodes"]), 2 * len(doc["constraints"]), file)
    names: list[str] = []
    for i, node in enumerate(doc["nodes"]):
        if not isinstance(node, dict) or "node_id" not in node:
            raise NetworkFileError(file, f"nodes[{i}]", "expected {\"node_id\": ...}")
        names.append(_id(node["node_id"], file, f"nodes[{i}].node_id"))
    # the origin, node 0, may be used by constraints without being listed among the nodes
    if "0" not in names and any(
        isinstance(c, dict) and _is_zero(c.get(k)) for c in doc["constraints"] for k in ("first_node", "second_node")
    ):
        names.insert(0, "0")
    known = set(names)
    raw: list[tuple[str, str, str, Decimal | None, Decimal | None, str]] = []
    for i, con in enumerate(doc["constraints"]):
        key = f"constraints[{i}]"
        if not isinstance(con, dict):
            raise NetworkFileError(file, key, "expected an object")
        a = _id(con.get("first_node"), file, f"{key}.first_node")
        b = _id(con.get("second_node"), file, f"{key}.second_node")
        for end in (a, b):
            if end not in known:
                raise NetworkFileError(file, key, f"unknown node {show(end)}")
        kind = con.get("type")
        if kind not in ("stc", "stcu"):
            raise NetworkFileError(file, f"{key}.type", f"expected 'stc' or 'stcu', found {_what(kind)}")
        lo, hi = con.get("min_duration"), con.get("max_duration")
        # the dataset writes an unbounded side as the string "inf" ("-inf" for a lower bound)
        lo = None if isinstance(lo, str) and lo.strip().lower() in _NEG_INF else lo
        hi = None if isinstance(hi, str) and hi.strip().lower() in _POS_INF else hi
        for label, val in (("min_duration", lo), ("max_duration", hi)):
            if val is not None and not isinstance(val, Decimal):
                raise NetworkFileError(file, f"{key}.{label}", f"expected a number, found {_what(val)}")
            if val is not None:
                _check_bound(val, file, f"{key}.{label}")
        if kind == "stcu" and (lo is None or hi is None):
            raise NetworkFileError(file, key, "a contingent link (stcu) needs finite min and max durations")
        raw.append((a, b, kind, lo, hi, key))
    finite = [v for *_, lo, hi, _k in raw for v in (lo, hi) if v is not None]
    ints, scale = scale_to_integers(finite)
    it = iter(ints)
    reqs: list[RequirementLink] = []
    conts: list[ContingentLink] = []
    for a, b, kind, lo, hi, key in raw:
        lb = None if lo is None else next(it)
        ub = None if hi is None else next(it)
        try:
            if kind == "stcu":
                assert lb is not None and ub is not None
                # a duration cannot be negative: the contingent timepoint follows its activation
                conts.append(ContingentLink(a, b, max(lb, 0), ub))
            else:
                reqs.append(RequirementLink(a, b, lb, ub))
        except NetworkError as err:
            raise NetworkFileError(file, key, str(err)) from err
    try:
        return STNU(tuple(names), tuple(reqs), tuple(conts)), scale
    except NetworkError as err:
        raise NetworkFileError(file, "", str(err)) from err


def _is_zero(value: object) -> bool:
    return isinstance(value, Decimal) and value == 0


def _bad_constant(c: str) -> None:
    raise ValueError(f"unsupported JSON constant {c}")


def _id(value: object, file: str, key: str) -> str:
    if isinstance(value, Decimal) and _within(value) and value == value.to_integral_value():
        return str(int(value))
    if isinstance(value, str) and value:
        return value
    raise NetworkFileError(file, key, f"expected a node id (an integer or a text), found {_what(value)}")


def _check_bound(value: Decimal, file: str, key: str) -> None:
    """A bound must be finite, within ``MAX_MAGNITUDE`` and have at most ``MAX_DECIMALS`` decimals (checked
    on the Decimal, before any exact conversion could take time and memory)."""
    if not _within(value):
        raise NetworkFileError(file, key, f"{_what(value)} is out of range (at most {MAX_MAGNITUDE:.0e} in "
                                          "absolute value)")
    _sign, digits, exponent = value.as_tuple()
    if isinstance(exponent, int) and exponent < 0:
        trailing = len(digits) - len(bytes(digits).rstrip(b"\0"))
        if -exponent - min(trailing, -exponent) > MAX_DECIMALS:
            raise NetworkFileError(file, key, f"{_what(value)} has more than {MAX_DECIMALS} decimals")


def _within(value: Decimal) -> bool:
    """Finite and at most `MAX_MAGNITUDE` in absolute value, decided without the decimal context (which
    would overflow on ``1e999999999``)."""
    return value.is_finite() and (value.is_zero() or value.adjusted() < len(str(MAX_MAGNITUDE)) - 1
                                  or value.copy_abs() == MAX_MAGNITUDE)


def _what(value: object) -> str:
    """A JSON value for an error message, quoted and cut short."""
    if isinstance(value, str):
        return show(value)
    if isinstance(value, Decimal):
        text = str(value)
        return text if len(text) <= 40 else text[:40] + "..."
    if isinstance(value, dict | list):
        return f"a JSON {'object' if isinstance(value, dict) else 'array'}"
    return show(repr(value))[1:-1]
