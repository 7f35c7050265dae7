"""The plain-text ``.stnu`` format of Hunsberger's group (also written by the CSTNU Tool's converters).

Example (the CSTNU Tool's converter documentation gives this one)::

    # KIND OF NETWORK
    STNU
    # Num Time-Points
    5
    # Num Ordinary Edges
    4
    # Num Contingent Links
    2
    # Time-Point Names
    A0 C0 A1 C1 X
    # Ordinary Edges
    X 12 C0
    C1 11 C0
    C0 -7 X
    C0 -1 C1
    # Contingent Links
    A0 1 3 C0
    A1 1 10 C1

An ordinary edge ``X w Y`` means ``T(Y) - T(X) <= w``; a contingent link ``A l u C`` means C - A in [l, u].
Section headers are matched ignoring case, spaces and hyphens (Hunsberger's Lisp reader matches them
case-insensitively); names may be wrapped in single quotes (``'A'``), which are dropped. ``KIND`` is
``STNU`` or ``STN``. The declared counts must match the lines found; counts and weights are ASCII
integers within the bounds of `hrc.temporal.limits`.

**The origin.** The format's authors use the timepoint named ``Z`` as the zero timepoint, every other
timepoint occurring at or after it, as the CSTNU Tool does when it loads GraphML; the verdicts its
random-network generator records for ``.stnu`` files hold under that reading (without it, 17 of 110
200-node files labelled not DC read as DC). So, where a network has a timepoint ``Z``, reading adds
``0 <= T(X) - T(Z)`` for every other X; ``origin=False`` (``hrc check --no-origin``) reads the links
alone. The verdict can depend on it: ``X`` at most 3 after ``Z`` and ``Y`` 5 before ``X`` is consistent
only if ``Y`` may precede ``Z``. `write_stnu_text` writes the links only, so a network with a ``Z`` that
did not mean it as the origin reads back with more constraints.
"""

from __future__ import annotations

import re
from collections.abc import Iterator

from hrc.errors import NetworkFileError
from hrc.temporal.limits import MAX_TIMEPOINTS, check_size, parse_int, show
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink

__all__ = ["ORIGIN", "looks_like_stnu_text", "read_stnu_text", "write_stnu_text"]

ORIGIN = "Z"
_NONBLANK = re.compile(r"\S")

_HEADERS = {
    "kindofnetwork": "kind",
    "numtimepoints": "n",
    "numordinaryedges": "m",
    "numcontingentlinks": "k",
    "timepointnames": "names",
    "ordinaryedges": "edges",
    "contingentlinks": "links",
}


def _norm(header: str) -> str:
    return "".join(ch for ch in header.lower() if ch.isalnum())


def _name(tok: str) -> str:
    return tok[1:-1] if len(tok) >= 2 and tok[0] == tok[-1] == "'" else tok


def looks_like_stnu_text(data: bytes) -> bool:
    """True iff the first non-blank line of ``data`` is one of the format's section headers (so that a
    YAML or shell file that merely starts with a ``#`` comment is not taken for one)."""
    for raw in data[:4096].splitlines():
        line = raw.strip()
        if line:
            return line.startswith(b"#") and _norm(line[1:].decode("utf-8", "replace")) in _HEADERS
    return False


def _lines(text: str) -> Iterator[tuple[int, str]]:
    """``(line number, stripped line)`` of the non-blank lines; runs of blank lines are skipped at C speed
    (a file of 256 MiB of line breaks is one regex search), and no list of all lines is made."""
    if "\n" not in text and "\r" in text:  # old Mac line ends
        text = text.replace("\r", "\n")
    pos, lineno = 0, 1
    while True:
        found = _NONBLANK.search(text, pos)
        if found is None:
            return
        start = found.start()
        lineno += text.count("\n", pos, start)
        end = text.find("\n", start)
        if end < 0:
            end = len(text)
        yield lineno, text[start:end].strip()
        pos = end


def read_stnu_text(text: str, file: str = "<stnu>", *, origin: bool = True) -> STNU:
    """Parse the ``.stnu`` text format (with the origin ``Z`` applied unless ``origin=False``, see the
    module docstring) in one pass, within the sizes of `hrc.temporal.limits`. Raises `NetworkFileError`
    with the offending line."""
    singles: dict[str, tuple[int, list[str]]] = {}  # kind, n, m, k: (line, tokens)
    names: list[str] = []
    names_line: int | None = None
    edges: list[tuple[int, list[str]]] = []
    links: list[tuple[int, list[str]]] = []
    seen: set[str] = set()
    current: str | None = None
    for lineno, line in _lines(text):
        if line.startswith("#"):
            key = _HEADERS.get(_norm(line[1:]))
            if key is None:
                raise NetworkFileError(file, "", f"unknown section header {show(line)}", lineno)
            if key in seen:
                raise NetworkFileError(file, "", f"section {show(line)} appears twice", lineno)
            seen.add(key)
            current = key
            continue
        if current is None:
            raise NetworkFileError(file, "", f"expected '# KIND OF NETWORK', found {show(line)}", lineno)
        if current == "names":
            names_line = names_line or lineno
            names.extend(line.split(None, MAX_TIMEPOINTS + 1 - len(names)))
            check_size(len(names), 0, file, lineno)
        elif current == "edges":
            edges.append((lineno, line.split(None, 3)))
            check_size(0, len(edges), file, lineno)
        elif current == "links":
            links.append((lineno, line.split(None, 4)))
            check_size(0, 2 * len(links), file, lineno)
        elif current in singles:
            raise NetworkFileError(file, "", f"expected one value after the header, found another line "
                                             f"{show(line)}", lineno)
        else:
            singles[current] = (lineno, line.split(None, 1))

    def single(key: str, label: str) -> tuple[int, str]:
        entry = singles.get(key)
        if entry is None or len(entry[1]) != 1:
            raise NetworkFileError(file, label, "expected one value on the line after the header",
                                   entry[0] if entry else None)
        return entry[0], entry[1][0]

    def count(key: str, label: str) -> int:
        lineno, tok = single(key, label)
        value = parse_int(tok, file, label, lineno, what="a count")
        if value < 0:
            raise NetworkFileError(file, label, f"expected a count, found {value}", lineno)
        return value

    kind_line, kind = single("kind", "KIND OF NETWORK")
    if kind.upper() not in {"STNU", "STN"}:
        raise NetworkFileError(file, "KIND OF NETWORK", f"expected STNU or STN, found {show(kind)}", kind_line)
    n, m = count("n", "Num Time-Points"), count("m", "Num Ordinary Edges")
    k = count("k", "Num Contingent Links") if "k" in singles else 0
    names = [_name(tok) for tok in names]
    if len(names) != n:
        raise NetworkFileError(file, "Time-Point Names", f"declared {n} names, found {len(names)}", names_line)
    known = set(names)
    if len(known) != len(names):
        repeated: set[str] = set()
        dup = next(t for t in names if t in repeated or repeated.add(t))  # type: ignore[func-returns-value]
        raise NetworkFileError(file, "Time-Point Names", f"time-point {show(dup)} is listed twice", names_line)

    def check_names(label: str, lineno: int, *tps: str) -> None:
        for tp in tps:
            if tp not in known:
                raise NetworkFileError(file, label, f"unknown time-point {show(tp)}", lineno)

    reqs: list[RequirementLink] = []
    for lineno, toks in edges:
        if len(toks) != 3:
            raise NetworkFileError(file, "Ordinary Edges", f"expected 'X w Y', found {show(' '.join(toks))}",
                                   lineno)
        x, y = _name(toks[0]), _name(toks[2])
        check_names("Ordinary Edges", lineno, x, y)
        reqs.append(RequirementLink(x, y, None, parse_int(toks[1], file, "Ordinary Edges", lineno)))
    if len(reqs) != m:
        raise NetworkFileError(file, "Num Ordinary Edges", f"declared {m} edges, found {len(reqs)}")
    contingents: list[ContingentLink] = []
    for lineno, toks in links:
        if len(toks) != 4:
            raise NetworkFileError(file, "Contingent Links", f"expected 'A l u C', found {show(' '.join(toks))}",
                                   lineno)
        a, c = _name(toks[0]), _name(toks[3])
        check_names("Contingent Links", lineno, a, c)
        lb = parse_int(toks[1], file, "Contingent Links", lineno)
        ub = parse_int(toks[2], file, "Contingent Links", lineno)
        try:
            contingents.append(ContingentLink(a, c, lb, ub))
        except NetworkError as err:
            raise NetworkFileError(file, "Contingent Links", str(err), lineno) from err
    if len(contingents) != k:
        raise NetworkFileError(file, "Num Contingent Links", f"declared {k} links, found {len(contingents)}")
    if kind.upper() == "STN" and contingents:
        raise NetworkFileError(file, "KIND OF NETWORK", "an STN with contingent links")
    if origin and ORIGIN in known:
        reqs.extend(RequirementLink(ORIGIN, x, 0, None) for x in names if x != ORIGIN)
    try:
        return STNU(tuple(names), tuple(reqs), tuple(contingents))
    except NetworkError as err:
        raise NetworkFileError(file, "", str(err)) from err


def write_stnu_text(stnu: STNU) -> str:
    """The network in the ``.stnu`` text format (deterministic; names must not contain spaces)."""
    for v in stnu.timepoints:
        if not v or any(ch.isspace() for ch in v) or v.startswith("#"):
            raise NetworkError(f"time-point name {show(v)} cannot be written in the .stnu text format")
    edges = []
    for r in stnu.requirements:
        if r.ub is not None:
            edges.append(f"{r.source} {r.ub} {r.target}")
        if r.lb is not None:
            edges.append(f"{r.target} {-r.lb} {r.source}")
    lines = [
        "# KIND OF NETWORK", "STNU" if stnu.contingents else "STN",
        "# Num Time-Points", str(len(stnu.timepoints)),
        "# Num Ordinary Edges", str(len(edges)),
        "# Num Contingent Links", str(len(stnu.contingents)),
        "# Time-Point Names", " ".join(stnu.timepoints),
        "# Ordinary Edges", *edges,
        "# Contingent Links", *(f"{c.source} {c.lb} {c.ub} {c.target}" for c in stnu.contingents),
    ]
    return "\n".join(lines) + "\n"
