"""Bounds on what one message may be, and the one strict JSON reader of every online protocol.

Every JSON text that comes from outside while a run goes on (``hrc dispatch``'s lines, the console's
websocket frames, ROS 2 strings, ``hrc detect``'s traces, the records of a dispatcher's log) is read by
`read_json`, which refuses in one line (`MessageError`), naming the key where one is at fault:

- a text longer than `MAX_LINE` bytes, or nested deeper than `MAX_DEPTH` (Python's ``json.loads``
  recurses once per level: 20,000 ``[`` raised `RecursionError`, issue 26), checked in time linear in
  the text before the parser sees it;
- not UTF-8, or not JSON;
- a key given twice in one object (``{"agent": "robot", "agent": "human"}`` was taken as the human's,
  issue 34): which one was meant cannot be known;
- ``NaN``, ``Infinity``, a number too large for a double (``1e400``), and an integer beyond
  ``±2**53`` (`MAX_INT`: a 310-digit ``t`` overflowed ``float()`` in the console's only worker, issue
  34). These are the rules of I-JSON (RFC 7493, sections 2.2 and 2.3: no duplicate names, numbers
  within IEEE 754 double precision), the profile meant for protocols.

Each check depends only on the text, so a replay refuses the same messages. Cost: one pass to count
brackets, then ``json.loads`` with hooks for objects and numbers (a few microseconds for a message);
only a refused text is walked again, to name the key.

>>> read_json('{"t": 1, "event": "tick"}')
{'t': 1, 'event': 'tick'}
>>> read_json("[" * 20000)
Traceback (most recent call last):
hrc.errors.MessageError: nested deeper than 16 levels
>>> read_json('{"agent": "robot", "agent": "human"}')
Traceback (most recent call last):
hrc.errors.MessageError: key 'agent': given twice in one object
>>> read_json('{"t": 1' + '0' * 309 + '}')
Traceback (most recent call last):
hrc.errors.MessageError: key 't': an integer of 310 digits (at most 2**53 in magnitude)
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

from hrc.errors import MessageError

__all__ = ["MAX_DEPTH", "MAX_INT", "MAX_LINE", "nesting_depth", "parse_message", "read_json"]

MAX_LINE = 65536
"""Longest message accepted, in bytes of UTF-8 (a longer one is refused)."""
MAX_DEPTH = 16
"""Deepest nesting of arrays and objects accepted (a message is depth 1)."""
MAX_INT = 2 ** 53
"""Largest integer magnitude accepted: every integer up to it is exact as a double (RFC 7493, 2.2)."""

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"?', re.DOTALL)  # a JSON string (or an unterminated one, to the end)
_BRACKET = re.compile(r"[\[\]{}]")
_INT_DIGITS = len(str(MAX_INT))


def nesting_depth(text: str) -> int:
    """The deepest nesting of ``[``/``{`` outside strings in `text` (whether or not it is valid JSON).

    O(len(text)): strings are blanked out by one regular expression, then brackets counted.

    >>> nesting_depth('{"a": [1, {"b": "[[["}]}')
    3
    """
    depth = deepest = 0
    for match in _BRACKET.finditer(_STRING.sub('""', text)):
        if match.group() in "[{":
            depth += 1
            deepest = max(deepest, depth)
        else:
            depth = max(0, depth - 1)
    return deepest


class _Bad:
    """Stands in the parsed value where a refused number or a repeated key was (found again by `_where`)."""

    __slots__ = ("why",)

    def __init__(self, why: str) -> None:
        self.why = why


def _where(value: Any, target: _Bad) -> str | None:
    """The key path (``a.b[2]``) of `target` in `value`, None when not found (depth is bounded already)."""
    stack: list[tuple[str, Any]] = [("", value)]
    while stack:
        path, node = stack.pop()
        if node is target:
            return path
        if isinstance(node, dict):
            stack.extend((f"{path}.{k}" if path else str(k), v) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((f"{path}[{i}]", v) for i, v in enumerate(node))
    return None


def read_json(data: str | bytes, *, max_bytes: int = MAX_LINE, max_depth: int = MAX_DEPTH) -> Any:
    """`data` (text, or bytes of UTF-8) read as strict JSON within `max_bytes` and `max_depth` (see the
    module docstring); `MessageError` with one line saying what is wrong, and where, otherwise.

    Never raises anything else, whatever `data` holds.
    """
    if isinstance(data, bytes | bytearray | memoryview):
        if len(data) > max_bytes:
            raise MessageError(f"message longer than {max_bytes} bytes")
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError:
            raise MessageError("message is not UTF-8") from None
    else:
        text = data
        if len(text) > max_bytes or len(text.encode("utf-8", "surrogatepass")) > max_bytes:
            raise MessageError(f"message longer than {max_bytes} bytes")
    # the common case first: a text with few brackets cannot nest deeper than their number
    if text.count("[") + text.count("{") > max_depth and nesting_depth(text) > max_depth:
        raise MessageError(f"nested deeper than {max_depth} levels")
    problems: list[_Bad] = []

    def bad(why: str) -> _Bad:
        problems.append(_Bad(why))
        return problems[-1]

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in items:
            out[key] = bad("given twice in one object") if key in out else value
        return out

    def integer(s: str) -> int | _Bad:
        digits = len(s) - (s[0] == "-")
        if digits > _INT_DIGITS or abs(int(s)) > MAX_INT:
            return bad(f"an integer of {digits} digits (at most 2**53 in magnitude)")
        return int(s)

    def real(s: str) -> float | _Bad:
        value = float(s)
        if not math.isfinite(value):
            return bad(f"{s[:20]}{'...' if len(s) > 20 else ''} is beyond the range of a double")
        return value

    def constant(s: str) -> _Bad:
        return bad(f"{s} is not a number JSON allows")

    try:
        value = json.loads(text, object_pairs_hook=pairs, parse_int=integer, parse_float=real,
                           parse_constant=constant)
    except RecursionError:  # cannot happen within max_depth; a guard all the same
        raise MessageError(f"nested deeper than {max_depth} levels") from None
    except ValueError as err:
        raise MessageError(f"not JSON: {err}") from None
    if problems:
        first = problems[0]
        path = _where(value, first)
        raise MessageError(f"key {path!r}: {first.why}" if path else first.why)
    return value


def parse_message(text: str | bytes) -> Any:
    """A protocol message read by `read_json` with the protocol's bounds (`MAX_LINE`, `MAX_DEPTH`)."""
    return read_json(text)
