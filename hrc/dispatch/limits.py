"""Bounds on what one message may be, checked before the JSON parser sees it.

Python's ``json.loads`` recurses once per nested array or object: 20,000 ``[`` raise `RecursionError`
(issue 26: it ended ``hrc dispatch`` with exit 1 and dropped the console's connection). A message of the
protocol is a flat object (depth 1), so `parse_message` refuses anything longer than `MAX_LINE` bytes or
nested deeper than `MAX_DEPTH` with a one-line `MessageError`, in time linear in the text, and only then
parses. Numbers with more than 4,300 digits are refused by Python itself (``int_max_str_digits``).

>>> parse_message('{"t": 1, "event": "tick"}')
{'t': 1, 'event': 'tick'}
>>> parse_message("[" * 20000)
Traceback (most recent call last):
hrc.errors.MessageError: nested deeper than 16 levels
"""

from __future__ import annotations

import json
import re
from typing import Any

from hrc.errors import MessageError

__all__ = ["MAX_DEPTH", "MAX_LINE", "nesting_depth", "parse_message"]

MAX_LINE = 65536
"""Longest message accepted, in bytes of UTF-8 (a longer one is refused)."""
MAX_DEPTH = 16
"""Deepest nesting of arrays and objects accepted (a message is depth 1)."""

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"?', re.DOTALL)  # a JSON string (or an unterminated one, to the end)
_BRACKET = re.compile(r"[\[\]{}]")


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


def parse_message(text: str) -> Any:
    """`text` parsed as JSON once it is known to be within `MAX_LINE` bytes and `MAX_DEPTH` levels.

    Raises `MessageError` (too long, too deep) or `ValueError` (not JSON), each with a one-line message.
    """
    if len(text) > MAX_LINE or len(text.encode("utf-8", "surrogatepass")) > MAX_LINE:
        raise MessageError(f"message longer than {MAX_LINE} bytes")
    # the common case first: a text with few brackets cannot nest deeper than their number
    if text.count("[") + text.count("{") > MAX_DEPTH and nesting_depth(text) > MAX_DEPTH:
        raise MessageError(f"nested deeper than {MAX_DEPTH} levels")
    return json.loads(text)
