"""Read YAML keeping line numbers, and check shapes with errors that name file, line and key path.

`read_yaml(path, error_cls)` returns a `Doc`: the plain Python value of the file plus the line of every
node, so that a validator can say ``tasks/x.yaml:12: actions[1].phases[0].duration.human: lb 5 > ub 3``.
Duplicate mapping keys are errors (PyYAML silently keeps the last one).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, NoReturn

import yaml

from hrc.errors import InputError

# what a reader means as a number but YAML 1.1 (PyYAML) reads as a string: 1e300, 1E-3, 2.5e3 (no sign)
_YAML11_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")

Path_ = tuple[str | int, ...]

__all__ = ["Doc", "format_key", "read_yaml"]


def format_key(path: Path_) -> str:
    """``("actions", 1, "phases", 0)`` -> ``actions[1].phases[0]``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


@dataclass
class Doc:
    """A parsed YAML file: its value, the line of each key path, and checkers that raise `error_cls`."""

    file: str
    value: Any
    error_cls: type[InputError]
    lines: dict[Path_, int] = field(default_factory=dict)

    def line(self, path: Path_) -> int | None:
        while True:
            if path in self.lines:
                return self.lines[path]
            if not path:
                return None
            path = path[:-1]

    def fail(self, path: Path_, message: str) -> NoReturn:
        raise self.error_cls(self.file, format_key(path), message, self.line(path))

    # --- shape checks -------------------------------------------------------------------------
    def mapping(
        self, value: Any, path: Path_, required: Iterable[str] = (), optional: Iterable[str] = ()
    ) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.fail(path, f"expected a mapping, found {_kind(value)}")
        required, optional = tuple(required), tuple(optional)
        for key in value:
            if not isinstance(key, str):
                self.fail(path, f"keys must be strings, found {key!r}")
            if key not in required and key not in optional:
                allowed = ", ".join(sorted(required + optional))
                self.fail(path + (key,), f"unknown key (allowed: {allowed})")
        for key in required:
            if key not in value:  # named by its would-be path, at the line of the mapping
                self.fail(path + (key,), "missing (required key)")
        return value

    def sequence(self, value: Any, path: Path_, min_len: int = 0) -> list[Any]:
        if not isinstance(value, list):
            self.fail(path, f"expected a list, found {_kind(value)}")
        if len(value) < min_len:
            self.fail(path, f"expected at least {min_len} item(s), found {len(value)}")
        return value

    def number(
        self, value: Any, path: Path_, *, minimum: float | None = None, positive: bool = False,
        allow_inf: bool = False, maximum: float | None = None, unit: str = "",
    ) -> float:
        if isinstance(value, str) and _YAML11_FLOAT.fullmatch(value.strip()):
            m, _, e = value.strip().lower().partition("e")
            fixed = f"{m if '.' in m else m + '.0'}e{e if e[:1] in '+-' else '+' + e}"
            self.fail(path, f"expected a number, found the string '{value}': YAML 1.1 reads an exponent "
                            f"without a dot and a sign as text; write {fixed}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, f"expected a number, found {_kind(value)}")
        try:
            x = float(value)
        except OverflowError:  # an integer too large for a float
            self.fail(path, f"expected a finite number, found an integer of {len(str(abs(value)))} digits")
        if math.isnan(x) or (math.isinf(x) and not (allow_inf and x > 0)):
            self.fail(path, f"expected a finite number, found {value}")
        if positive and x <= 0:
            self.fail(path, f"expected a positive number, found {value}")
        if minimum is not None and x < minimum:
            self.fail(path, f"expected a number >= {minimum:g}{unit}, found {value}")
        if maximum is not None and abs(x) > maximum and not (allow_inf and math.isinf(x)):
            self.fail(path, f"expected a number of at most {maximum:g}{unit}, found {value}")
        return x

    def ident(self, value: Any, path: Path_) -> str:
        if not isinstance(value, str) or not value:
            self.fail(path, f"expected a non-empty string id, found {_kind(value)}")
        if any(c.isspace() for c in value) or "." in value:
            self.fail(path, f"id '{value}' must not contain spaces or dots")
        return value

    def text(self, value: Any, path: Path_) -> str:
        if not isinstance(value, str):
            self.fail(path, f"expected a string, found {_kind(value)}")
        return value

    def interval(self, value: Any, path: Path_, *, allow_inf: bool = False, maximum: float | None = None,
                 unit: str = "") -> tuple[float, float]:
        """``[lb, ub]`` with ``0 <= lb <= ub`` (at most `maximum`); ``ub`` may be ``.inf`` when `allow_inf`."""
        seq = self.sequence(value, path)
        if len(seq) != 2:
            self.fail(path, f"expected [lb, ub], found a list of {len(seq)}")
        lb = self.number(seq[0], path + (0,), minimum=0, maximum=maximum, unit=unit)
        ub = self.number(seq[1], path + (1,), minimum=0, allow_inf=allow_inf, maximum=maximum, unit=unit)
        if lb > ub:
            self.fail(path, f"lb {lb:g} > ub {ub:g}")
        return lb, ub

    def unique(self, ids: list[str], path: Path_, what: str, key: str = "id") -> None:
        seen: set[str] = set()
        for i, ident in enumerate(ids):
            if ident in seen:
                self.fail(path + ((i, key) if key else (i,)), f"duplicate {what} id '{ident}'")
            seen.add(ident)


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    return {dict: "a mapping", list: "a list", str: "a string", bool: "a boolean"}.get(
        type(value), type(value).__name__
    )


def read_yaml(path: str | os.PathLike[str], error_cls: type[InputError]) -> Doc:
    """Parse `path` into a `Doc`; unreadable files and YAML syntax errors raise `error_cls`."""
    file = os.fspath(path)
    try:
        with open(file, encoding="utf-8") as fh:
            text = fh.read()
    except FileNotFoundError as err:
        raise error_cls(file, "", "file not found") from err
    except (OSError, UnicodeDecodeError) as err:
        raise error_cls(file, "", f"cannot read: {err}") from err
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except RecursionError as err:  # PyYAML composes nested collections recursively
        raise error_cls(file, "", "YAML nesting too deep") from err
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark
        line = mark.line + 1 if mark is not None else None
        problem = " ".join(str(err.problem or err).split())
        raise error_cls(file, "", f"YAML syntax: {problem}", line) from err
    except yaml.YAMLError as err:
        raise error_cls(file, "", f"YAML syntax: {' '.join(str(err).split())}") from err
    doc = Doc(file=file, value=None, error_cls=error_cls)
    try:
        doc.value = _construct(doc, node, (), _Budget()) if node is not None else None
    except RecursionError as err:
        raise error_cls(file, "", "YAML nesting too deep") from err
    return doc


_SCALAR = yaml.SafeLoader(" ")


MAX_VALUES = 100_000  # far beyond any task or map; stops alias "billion laughs" expansions


@dataclass
class _Budget:
    """Guards against aliases: values built so far, and the collection nodes being built (for cycles)."""

    values: int = 0
    open_nodes: set[int] = field(default_factory=set)


def _construct(doc: Doc, node: yaml.Node, path: Path_, budget: _Budget) -> Any:
    doc.lines[path] = node.start_mark.line + 1
    budget.values += 1
    if budget.values > MAX_VALUES:
        doc.fail(path[:1], f"too many values (over {MAX_VALUES}, aliases included)")
    if isinstance(node, yaml.ScalarNode):
        try:
            return _SCALAR.construct_object(node, deep=True)
        except yaml.YAMLError as err:  # e.g. an unsafe tag such as !!python/name
            problem = getattr(err, "problem", None) or str(err)
            doc.fail(path, f"bad value: {' '.join(problem.split())}")
    if id(node) in budget.open_nodes:
        doc.fail(path, "an alias refers to a value that contains it (a recursive structure)")
    budget.open_nodes.add(id(node))
    try:
        if isinstance(node, yaml.SequenceNode):
            return [_construct(doc, item, path + (i,), budget) for i, item in enumerate(node.value)]
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                if not isinstance(key_node, yaml.ScalarNode):
                    doc.fail(path, "mapping keys must be plain strings")
                key = key_node.value
                if key in out:
                    doc.lines[path + (key,)] = key_node.start_mark.line + 1
                    doc.fail(path + (key,), "duplicate key")
                out[key] = _construct(doc, value_node, path + (key,), budget)
                doc.lines[path + (key,)] = key_node.start_mark.line + 1
            return out
    finally:
        budget.open_nodes.discard(id(node))
    doc.fail(path, "unsupported YAML node")
