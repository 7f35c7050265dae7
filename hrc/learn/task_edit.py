"""The task file with new duration bounds, everything else kept byte for byte (comments, order, layout).

A careful edit of the scalar values in place rather than a round-trip through a YAML library: PyYAML's
composer gives each scalar node its exact span in the text (``start_mark.index`` .. ``end_mark.index``),
so only the characters of the numbers that change are replaced; nothing else (comments, flow or block
style, alignment, quoting) can move. A round-tripping library (ruamel.yaml) would be a new dependency and
still reflows some layouts; this needs none. New keys (``preference_sets`` for worker types) are appended
as text at the end of the file.

`unified_diff` shows what changed, as ``diff -u`` would.
"""

from __future__ import annotations

import difflib
import json
import re
from collections.abc import Mapping, Sequence

import yaml

from hrc.errors import TaskFileError
from hrc.model import Interval

__all__ = ["format_seconds", "replace_bounds", "replace_top_scalar", "unified_diff"]


def format_seconds(x: float) -> str:
    """A number of seconds as a task file writes it: ``2``, ``2.5``, ``3.25`` (at most 3 decimals).

    >>> format_seconds(2.0), format_seconds(3.2500000001), format_seconds(0.001)
    ('2', '3.25', '0.001')
    """
    text = f"{x:.3f}".rstrip("0").rstrip(".")
    return text if text not in ("-0", "") else "0"


def _get(node: yaml.Node, key: str) -> yaml.Node | None:
    if not isinstance(node, yaml.MappingNode):
        return None
    for k, v in node.value:
        if isinstance(k, yaml.ScalarNode) and k.value == key:
            return v
    return None


def replace_bounds(text: str, new: Mapping[tuple[str, str, str], Interval], file: str = "task") -> str:
    """`text` (a task file) with ``actions[..].phases[..].duration[AGENT]`` set to `new[(agent, action,
    phase)]` where given. Raises `TaskFileError` when a bound to change is not a ``[lb, ub]`` pair of
    plain numbers in the text."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    edits: list[tuple[int, int, str]] = []
    actions = _get(root, "actions") if root is not None else None
    for action in (actions.value if isinstance(actions, yaml.SequenceNode) else ()):
        aid = _get(action, "id")
        phases = _get(action, "phases")
        for phase in (phases.value if isinstance(phases, yaml.SequenceNode) else ()):
            pid = _get(phase, "id")
            duration = _get(phase, "duration")
            if not isinstance(duration, yaml.MappingNode) or aid is None or pid is None:
                continue
            for k, v in duration.value:
                want = new.get((k.value, aid.value, pid.value))
                if want is None:
                    continue
                if not (isinstance(v, yaml.SequenceNode) and len(v.value) == 2
                        and all(isinstance(x, yaml.ScalarNode) and not x.style for x in v.value)):
                    raise TaskFileError(file, f"{aid.value}.{pid.value}.duration.{k.value}",
                                        "not a [lb, ub] pair of plain numbers: cannot rewrite it in place",
                                        v.start_mark.line + 1)
                for x, seconds in zip(v.value, (want.lb, want.ub), strict=True):
                    edits.append((x.start_mark.index, x.end_mark.index, format_seconds(seconds)))
    out = text
    for start, end, written in sorted(edits, reverse=True):
        out = out[:start] + written + out[end:]
    return out


def replace_top_scalar(text: str, key: str, value: str) -> str:
    """`text` with its top-level `key`'s scalar value replaced by `value` (a plain scalar when it is one,
    else a quoted string); unchanged when the key is absent or not a scalar."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    node = _get(root, key) if root is not None else None
    if not isinstance(node, yaml.ScalarNode):
        return text
    plain = re.fullmatch(r"[A-Za-z0-9_./-]+", value) is not None and not value.startswith("-")
    written = value if plain else json.dumps(value)
    return text[:node.start_mark.index] + written + text[node.end_mark.index:]


def unified_diff(old: str, new: str, old_name: str, new_name: str) -> str:
    """``diff -u`` of two texts (empty when equal)."""
    lines: Sequence[str] = list(difflib.unified_diff(old.splitlines(keepends=True), new.splitlines(keepends=True),
                                                     old_name, new_name))
    return "".join(line if line.endswith("\n") else line + "\n" for line in lines)
