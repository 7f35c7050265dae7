"""The CSTNU Tool's GraphML dialect for STN/STNU (R. Posenato, CSTNU Tool 5.0), and `read_network`.

Dialect (as the tool writes it and ../shared/benchmarks/stnu/INDEX.md records it):

* ``<key>`` elements whose ``id`` is the attribute name: graph keys ``nContingent``, ``NetworkType``
  (``STN``/``STNU``), ``nEdges``, ``nVertices``, ``Name``; node keys ``x``, ``y``; edge keys ``Type``,
  ``Value``, ``LabeledValue``. A key's ``<default>`` applies where an element has no ``<data>``.
* Node ids are the timepoint names. An edge X->Y of type ``requirement`` (older files: ``normal``,
  ``constraint``; also ``derived`` and ``internal``) with ``Value`` w means ``T(Y) - T(X) <= w``.
* A contingent link A->C with duration in [l, u] is two ``contingent`` edges, either plain (A->C
  ``Value`` u, C->A ``Value`` -l) or labelled (A->C ``LabeledValue`` ``LC(C):l``, C->A ``UC(C):-u``).

Reading semantics, applied here so that the algorithms stay format-agnostic:

1. If the network has a timepoint ``Z``, it is the origin: every other X gets ``0 <= T(X) - T(Z)``
   (the tool adds an edge X->Z of weight 0 on loading).
2. A contingent link also bounds ``T(C) - T(A)`` to [l, u] as ordinary edges; the core's distance graph
   always includes that pair (`hrc.temporal.graph.distance_edges`), so nothing is added here.
3. ``derived`` edges are constraints a checker inferred earlier, possibly by DC reductions (a DC-derived
   negative self-loop occurs in the benchmark set): they are ignored by default, which keeps the DC
   verdict (they are implied) and keeps consistency about the written constraints only; ``derived=True``
   reads them as requirements.
4. Node ids are read as they are: files written by older hrc versions (dotted names such as
   ``human.a1.fetch.start``) and by this one (``human_a1_fetch_start``) both read.

Writing for the CSTNU Tool (`write_graphml`): the tool reads a node only if its name matches
`TOOL_NAME_RULE`, ``[A-Za-z0-9_ωΩ? ]+`` (its ``ALabelAlphabet.ALETTER_RANGE``, checked when it turns a
contingent timepoint's name into an A-letter; the same name is in ``LC(C)``/``UC(C)``, split at ``:``).
`tool_name` is the one place that decides the node id of a timepoint: accents are dropped (``é`` -> ``e``),
every other character outside the rule becomes ``_`` (so ``human.a1.fetch.start`` is written
``human_a1_fetch_start``), the empty name becomes ``_``. Code that looks a timepoint up in a written file
goes through it. Two names of one network that would get the same id (``a.b`` and ``a_b``) are refused
with a `NetworkError` naming both: the mapping stays a function of the name alone, so lookups through
`tool_name` stay right. The origin is the timepoint named ``Z`` (`ORIGIN`), as the tool expects.

The tool's graph holds at most one edge per ordered pair of nodes (it refuses a file with two: "Between
node A and node B there exists the edge ..."), so the writer merges: every finite bound of the network is
an edge ``T(Y) - T(X) <= w`` and of the edges on one ordered pair only the tightest is written (the same
constraint: the others are implied); a requirement edge of weight >= 0 from a node to itself says nothing
and is left out. A contingent link with ``lb == ub`` (a fixed duration, which the tool refuses: it wants
``0 < lb < ub``) is written as the requirement link ``[lb, lb]``; nature has no choice in it, so the
network's class (DC, consistent, inconsistent) is the same. A contingent link's two edges take their
ordered pairs: a requirement bound on one of them that the link implies (``T(C) - T(A) <= w`` with
``w >= ub``, or ``>= -w`` with ``-w <= lb``) is left out; a tighter one cannot be written and is refused
(`NetworkError`; such a network is never DC: nature may take the link's whole range).

The tool also wants each activation node to start one contingent link only ("Transform the activation
node in a pair of nodes at distance 0 and associate each to a distinct contingent", its message): so a
timepoint A that activates several contingent links is written as itself for the first and, for each other
link onto C, a copy ``A_for_C`` (node id) held to it by ``T(A_for_C) - T(A) in [0, 0]``: the same network
with one more timepoint per such link, which reads back as that (hrc's networks never have one: each
of a person's steps has its own start).

A contingent link with ``lb == 0`` (nature may finish at once) is refused with a `NetworkError`: the tool
reads only ``0 < lb``, and no network it reads says the same thing (shifting or narrowing the link
changes what the agent knows when). hrc's own networks never have one: the temporal net creator gives a
person's action at least one tick (`hrc.compile.temporal_net_creator`, "a person's action takes at least
1 ms"); hrc still reads such links from other formats and checks them. Weights are written as they are:
the tool stores 32-bit integers.

The output lists the nodes in the network's order, then the merged requirement edges in the order their
ordered pairs first occur among the links, then the contingent edges; equal networks give byte-identical
text.
"""

from __future__ import annotations

import functools
import re
import unicodedata
from collections.abc import Mapping
from pathlib import Path
from xml.parsers import expat

from hrc.errors import NetworkFileError
from hrc.temporal.limits import MAX_BOUNDS, MAX_TIMEPOINTS, check_size, parse_int, read_bounded, show, show_path
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink
from hrc.temporal.xmlread import MAX_DEPTH, hardened_parser, parse

__all__ = ["FORMATS", "ORIGIN", "TOOL_NAME_RULE", "read_graphml", "read_network", "read_network_scaled", "tool_name",
           "write_graphml"]

ORIGIN = "Z"
TOOL_NAME_RULE = re.compile(r"[A-Za-z0-9_ωΩ? ]+")
"""The CSTNU Tool 5.0's rule for timepoint names (Java regex, matched against the whole name)."""
FORMATS = ("CSTNU Tool GraphML (XML with a <graphml> root)",
           "the .stnu text format (first line '# KIND OF NETWORK')",
           "HEATlab JSON (an object with 'nodes' and 'constraints')")
"""The network formats `read_network` accepts, as its messages name them."""

_ORDINARY_TYPES = {"requirement", "normal", "constraint", "derived", "internal"}
_LABELLED = re.compile(r"\s*(LC|UC)\((.+)\)\s*:\s*([-+]?[0-9]+)\s*")
_NOT_TOOL = re.compile(r"[^A-Za-z0-9_ωΩ? ]")


def _escape(text: str) -> str:
    """XML character data escaping (xml.sax.saxutils would pull in urllib at import time)."""
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _quoteattr(text: str) -> str:
    return '"' + _escape(text).replace('"', "&quot;").replace("\n", "&#10;").replace("\t", "&#9;") + '"'


class _Reader:
    """The state of one streaming read of a GraphML document; its methods are the expat handlers."""

    def __init__(self, file: str, parser: expat.XMLParserType) -> None:
        self.file = file
        self.parser = parser
        self.names: dict[str, str] = {}  # key id -> attribute name
        self.defaults: dict[str, str] = {}
        self.graphs = 0
        self.root_line = 1
        self.graph_line = 1
        self.graph_data: dict[str, str] = {}
        self.nodes: list[str] = []
        self.known: set[str] = set()
        self.edges: list[tuple[str, str, str, int, dict[str, str]]] = []  # source, target, where, line, data
        self.stack: list[str] = []
        self.owner: dict[str, str] | None = None  # data of the current <graph>/<edge>, or None
        self.key: str | None = None
        self.data_key: str | None = None
        self.text: list[str] | None = None  # text of the current <data> or <default>, else not collected

    def start(self, name: str, attrs: dict[str, str]) -> None:
        tag = name[name.rfind("}") + 1:]
        stack = self.stack
        parent = stack[-1] if stack else ""
        if not stack:
            self.root_line = self.parser.CurrentLineNumber
            if tag != "graphml":
                raise NetworkFileError(self.file, "", f"not an STNU file: the XML root element is {show(tag)}, a "
                                                      "CSTNU Tool GraphML file has <graphml>", self.root_line)
        elif len(stack) >= MAX_DEPTH:
            raise NetworkFileError(self.file, "", f"elements nested more than {MAX_DEPTH} deep",
                                   self.parser.CurrentLineNumber)
        stack.append(tag)
        if tag == "data":
            self.data_key = attrs.get("key", "")
            self.text = []
        elif tag == "node" and parent == "graph":
            nid = attrs.get("id")
            line = self.parser.CurrentLineNumber
            if not nid:
                raise NetworkFileError(self.file, "node", "a node has no id", line)
            if nid in self.known:
                raise NetworkFileError(self.file, f"node {show(nid)}", "node id used twice", line)
            self.known.add(nid)
            self.nodes.append(nid)
            if len(self.nodes) > MAX_TIMEPOINTS:
                check_size(len(self.nodes), 0, self.file, line)
            self.owner = None
        elif tag == "edge" and parent == "graph":
            src, tgt = attrs.get("source", ""), attrs.get("target", "")
            where = f"edge {show(attrs['id'])}" if "id" in attrs else f"edge {show(src)}->{show(tgt)}"
            data: dict[str, str] = {}
            self.edges.append((src, tgt, where, self.parser.CurrentLineNumber, data))
            if len(self.edges) > MAX_BOUNDS:
                check_size(0, len(self.edges), self.file, self.parser.CurrentLineNumber)
            self.owner = data
        elif tag == "key" and parent == "graphml":
            kid = attrs.get("id", "")
            self.names[kid] = attrs.get("attr.name", kid)
            self.key = kid
        elif tag == "default":
            self.text = []
        elif tag == "graph":
            line = self.parser.CurrentLineNumber
            if parent != "graphml":
                raise NetworkFileError(self.file, "graph", "nested graphs are not supported", line)
            self.graphs += 1
            if self.graphs > 1:
                raise NetworkFileError(self.file, "graph", "expected one <graph>, found a second one", line)
            self.graph_line = line
            self.owner = self.graph_data

    def chars(self, text: str) -> None:
        if self.text is not None:
            self.text.append(text)

    def end(self, name: str) -> None:
        tag = self.stack.pop()
        parent = self.stack[-1] if self.stack else ""
        if tag == "data":
            if parent in ("graph", "edge") and self.owner is not None and self.text is not None:
                self.owner[self.names.get(self.data_key or "", self.data_key or "")] = "".join(self.text)
            self.data_key = None
            self.text = None
        elif tag in ("edge", "node"):
            self.owner = self.graph_data
        elif tag == "default":
            if parent == "key" and self.key is not None and self.text is not None:
                self.defaults[self.names[self.key]] = "".join(self.text).strip()
            self.text = None
        elif tag == "key":
            self.key = None


def read_graphml(data: bytes, file: str = "<graphml>", *, derived: bool = False) -> STNU:
    """Parse CSTNU Tool GraphML (see the module docstring) in one streaming pass. Raises
    `NetworkFileError`."""
    parser = hardened_parser(file)
    reader = _Reader(file, parser)
    parser.StartElementHandler = reader.start
    parser.EndElementHandler = reader.end
    parser.CharacterDataHandler = reader.chars
    parse(parser, data, file)
    if reader.graphs != 1:
        raise NetworkFileError(file, "graph", "expected one <graph>, found none", reader.root_line)
    kind = reader.graph_data.get("NetworkType", reader.defaults.get("NetworkType", "STNU")).strip()
    if kind not in {"STN", "STNU"}:
        raise NetworkFileError(file, "NetworkType", f"expected STN or STNU, found {show(kind)}", reader.graph_line)
    defaults, known = reader.defaults, reader.known
    reqs: list[RequirementLink] = []
    # contingent edges, keyed by the unordered pair: (source, target, value, LC/UC/"", label, line)
    cont: dict[frozenset[str], list[tuple[str, str, int, str, str, int]]] = {}
    for src, tgt, where, line, edata in reader.edges:
        for end in (src, tgt):
            if end not in known:
                raise NetworkFileError(file, where, f"unknown node {show(end)}", line)
        etype = edata.get("Type", defaults.get("Type", "requirement")).strip()
        value_text = edata.get("Value", defaults.get("Value", "")).strip()
        labelled = edata.get("LabeledValue", defaults.get("LabeledValue", "")).strip()
        if etype == "contingent":
            if labelled:
                m = _LABELLED.fullmatch(labelled)
                if not m:
                    raise NetworkFileError(file, where, f"expected LC(C):l or UC(C):-u, found {show(labelled)}",
                                           line)
                value = parse_int(m.group(3), file, where, line)
                entry = (src, tgt, value, m.group(1), m.group(2), line)
            elif value_text:
                entry = (src, tgt, parse_int(value_text, file, where, line), "", "", line)
            else:
                raise NetworkFileError(file, where, "contingent edge without Value or LabeledValue", line)
            cont.setdefault(frozenset((src, tgt)), []).append(entry)
        elif etype in _ORDINARY_TYPES:
            if etype == "derived" and not derived:
                continue
            if not value_text:
                raise NetworkFileError(file, where, f"{etype} edge without a Value", line)
            w = parse_int(value_text, file, where, line)
            reqs.append(_make(RequirementLink, file, where, line, src, tgt, None, w))
        else:
            raise NetworkFileError(file, where, f"unknown edge Type {show(etype)}", line)
    contingents = [_contingent_link(pair_edges, file) for pair_edges in cont.values()]
    if kind == "STN" and contingents:
        raise NetworkFileError(file, "NetworkType", "an STN with contingent edges", reader.graph_line)
    nodes = reader.nodes
    if ORIGIN in known:
        reqs.extend(RequirementLink(ORIGIN, x, 0, None) for x in nodes if x != ORIGIN)
    name = reader.graph_data.get("Name", defaults.get("Name", "")).strip()
    try:
        return STNU(tuple(nodes), tuple(reqs), tuple(contingents), name)
    except NetworkError as err:
        raise NetworkFileError(file, "", str(err)) from err


def _make(cls, file: str, where: str, line: int, *args):  # type: ignore[no-untyped-def]
    try:
        return cls(*args)
    except NetworkError as err:
        raise NetworkFileError(file, where, str(err), line) from err


def _contingent_link(edges: list[tuple[str, str, int, str, str, int]], file: str) -> ContingentLink:
    line = edges[0][5]
    where = f"contingent link {show(edges[0][0])}-{show(edges[0][1])}"
    if len(edges) != 2 or edges[0][:2] == edges[1][:2]:
        raise NetworkFileError(file, where, f"expected two opposite contingent edges, found {len(edges)}", line)
    labels = {e[4] for e in edges if e[3]}
    if len(labels) > 1:
        raise NetworkFileError(file, where, f"contingent edges name different timepoints "
                                            f"{', '.join(show(x) for x in sorted(labels))}", line)
    if labels:
        c = labels.pop()
    else:  # plain form: A->C carries u >= 0, C->A carries -l <= 0
        fwd = max(edges, key=lambda e: e[2])
        if fwd[2] == min(e[2] for e in edges):
            raise NetworkFileError(file, where, "cannot tell the activation from the contingent timepoint", line)
        c = fwd[1]
    try:
        ac = next(e for e in edges if e[1] == c)
        ca = next(e for e in edges if e[0] == c)
    except StopIteration:
        raise NetworkFileError(file, where, f"label names {show(c)}, which is not an end of the link", line) from None
    if (ac[3], ca[3]) == ("LC", "UC"):
        lb, ub = ac[2], -ca[2]
    elif (ac[3], ca[3]) == ("", ""):
        lb, ub = -ca[2], ac[2]
    else:
        raise NetworkFileError(file, where, "expected LC(C) on A->C and UC(C) on C->A, or two plain values", line)
    return _make(ContingentLink, file, where, line, ac[0], c, lb, ub)


@functools.lru_cache(maxsize=1 << 14)
def tool_name(name: str) -> str:
    """The node id `write_graphml` gives timepoint ``name`` (the one place that decides it): the name with
    accents dropped and every character outside ``[A-Za-z0-9_ωΩ? ]`` replaced by ``_``.

    >>> tool_name("human.cube-1.fetch.start"), tool_name("Z"), tool_name("café"), tool_name("")
    ('human_cube_1_fetch_start', 'Z', 'cafe', '_')
    """
    plain = "".join(ch for ch in unicodedata.normalize("NFKD", name) if not unicodedata.combining(ch))
    return _NOT_TOOL.sub("_", plain) or "_"


def _node_ids(stnu: STNU, names: Mapping[str, str] | None = None) -> dict[str, str]:
    """`tool_name` of every timepoint (of ``names[t]`` with `names`); raises `NetworkError` if two
    timepoints would share an id."""
    ids: dict[str, str] = {}
    owner: dict[str, str] = {}
    for v in stnu.timepoints:
        shown = v if names is None else names[v]
        nid = tool_name(shown)
        if nid in owner:
            raise NetworkError(f"timepoints {show(owner[nid])} and {show(shown)} would both be written as node "
                               f"{show(nid)} (the CSTNU Tool allows only [A-Za-z0-9_ωΩ? ] in names); rename one")
        owner[nid] = shown
        ids[v] = nid
    return ids


def write_graphml(stnu: STNU, names: Mapping[str, str] | None = None, name: str | None = None) -> str:
    """The network as CSTNU Tool GraphML text (deterministic; node ids by `tool_name`, fixed durations as
    requirement links: see the module docstring). Raises `NetworkError` if two names share an id.

    With `names` and `name`: the text of ``stnu.renamed(names, name)``, without building that network
    (a compile writes one per plan of a family from the first plan's, `hrc.compile.compiler`). The text
    around the node ids and the name depends on the network's links alone, so it is laid out once per
    network (`_layout`, kept for the last network written) and each call fills in its ids."""
    ids = _node_ids(stnu, names)
    for copy in _activation_copies(stnu, ids) if stnu.contingents else ():
        if copy in ids.values():
            raise NetworkError(f"a timepoint is named {show(copy)}, the name the CSTNU Tool's file gives a copy of "
                               "a shared activation timepoint; rename it")
    chunks, slots = _layout(stnu)
    filled = [ids[v] for v in stnu.timepoints]  # tool names hold no XML special character: no escaping
    filled.append(_escape(stnu.name if name is None else name))
    out = [""] * (2 * len(slots) + 1)
    out[0::2] = chunks
    out[1::2] = [filled[s] for s in slots]
    return "".join(out)


_LAYOUT: list[tuple[STNU, list[str], list[int]]] = []
_SLOT = "\x00"  # around a slot's number in `_text`'s output: no id, name or literal of it holds a NUL


def _layout(stnu: STNU) -> tuple[list[str], list[int]]:
    """`write_graphml`'s text of `stnu` as literal chunks between slots: ``chunks[0] + slot 0 + chunks[1]
    + ...``, a slot being a timepoint's index (its node id) or ``len(timepoints)`` (the network's name,
    escaped). Kept for the last network asked for (its family's plans follow it)."""
    entry = _LAYOUT[0] if _LAYOUT else None  # read once: another thread may replace it meanwhile
    if entry is not None and entry[0] is stnu:
        return entry[1], entry[2]
    number = {str(i): i for i in range(len(stnu.timepoints) + 1)}
    marks = {v: f"{_SLOT}{i}{_SLOT}" for i, v in enumerate(stnu.timepoints)}
    parts = _text(stnu, marks, f"{_SLOT}{len(stnu.timepoints)}{_SLOT}").split(_SLOT)
    entry = (stnu, parts[0::2], [number[x] for x in parts[1::2]])
    _LAYOUT[:] = [entry]
    return entry[1], entry[2]


def _activation_copy(activation: str, target: str) -> str:
    """The node id of activation `activation`'s copy for the contingent link onto `target`."""
    return f"{activation}_for_{target}"


def _activation_copies(stnu: STNU, ids: Mapping[str, str]) -> list[str]:
    """The ids of the nodes `_text` adds to `stnu` (written with `ids`): a copy of an activation node for
    each contingent link but the first that it activates."""
    seen: set[str] = set()
    out = []
    for c in stnu.contingents:
        if c.lb != c.ub:
            if c.source in seen:
                out.append(_activation_copy(ids[c.source], ids[c.target]))
            seen.add(c.source)
    return out


def _text(stnu: STNU, ids: Mapping[str, str], label: str) -> str:
    """The GraphML text with node ids `ids` and the network's name written as `label` (already escaped)."""
    best: dict[tuple[str, str], int] = {}  # (source, target) -> the tightest w of T(target) - T(source) <= w

    def bound(s: str, t: str, w: int) -> None:
        old = best.get((s, t))
        if old is None or w < old:
            best[(s, t)] = w

    for r in stnu.requirements:
        if r.ub is not None:
            bound(ids[r.source], ids[r.target], r.ub)
        if r.lb is not None:
            bound(ids[r.target], ids[r.source], -r.lb)
    labelled: list[tuple[str, str, str, str, str]] = []
    extra: list[str] = []  # nodes added: a shared activation's copies (`_activation_copy`)
    activations: set[str] = set()
    for c in stnu.contingents:
        a, t = ids[c.source], ids[c.target]
        if c.lb != c.ub:
            if c.source in activations:  # the tool wants one contingent link per activation node: its own copy
                copy = _activation_copy(a, t)
                extra.append(copy)
                best[(a, copy)] = best[(copy, a)] = 0
                a = copy
            activations.add(c.source)
        if c.lb == c.ub:  # a fixed duration: the same network with a requirement link
            bound(a, t, c.ub)
            bound(t, a, -c.lb)
            continue
        if c.lb == 0:
            raise NetworkError(f"contingent link {c}: the CSTNU Tool reads only 0 < lb < ub, and no network it "
                               "reads says the same; give the duration at least one tick")
        # a requirement bound on the link's pair: the tool holds one edge per ordered pair; one that the link
        # implies is left out, a tighter one cannot be written (and makes the network not DC: nature may
        # take the whole range)
        for pair, implied, shown in (((a, t), c.ub, f"{c.source}->{c.target}"),
                                     ((t, a), -c.lb, f"{c.target}->{c.source}")):
            w = best.pop(pair, None)
            if w is not None and w < implied:
                raise NetworkError(f"contingent link {c} and a tighter requirement bound {w} on {shown}: the "
                                   "CSTNU Tool's format holds one edge per ordered pair")
        labelled.append((a, t, "contingent", "LabeledValue", f"LC({t}):{c.lb}"))
        labelled.append((t, a, "contingent", "LabeledValue", f"UC({t}):{-c.ub}"))
    edges = [(s, t, "requirement", "Value", str(w)) for (s, t), w in best.items() if s != t or w < 0]
    edges += labelled
    contingent = len(labelled) // 2
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<graphml xmlns="http://graphml.graphdrawing.org/xmlns/graphml" '
        'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:schemaLocation="http://graphml.graphdrawing.org/xmlns/graphml">',
    ]
    keys = [
        ("nContingent", "graph", "Number of contingents in the graph", "0"),
        ("NetworkType", "graph", "Network Type", "STNU"),
        ("nEdges", "graph", "Number of edges in the graph", "0"),
        ("nVertices", "graph", "Number of vertices in the graph", "0"),
        ("Name", "graph", "Graph Name", ""),
        ("x", "node", "The x coordinate for the visualization. A positive value.", "0"),
        ("y", "node", "The y coordinate for the visualization. A positive value.", "0"),
        ("Type", "edge", "Type: Possible values: contingent|requirement|derived|internal.", "requirement"),
        ("Value", "edge", "Value for STN edge. Format: 'integer'", ""),
        ("LabeledValue", "edge", "Case Value. Format: 'LC(NodeName):integer' or 'UC(NodeName):integer'", ""),
    ]
    for kid, kfor, desc, default in keys:
        out.append(f'<key id="{kid}" for="{kfor}">')
        out.append(f"<desc>{_escape(desc)}</desc>")
        out.append(f"<default>{default}</default>")
        out.append("</key>")
    out.append('<graph edgedefault="directed">')
    out.append(f'<data key="nContingent">{contingent}</data>')
    out.append(f'<data key="NetworkType">{"STNU" if contingent else "STN"}</data>')
    out.append(f'<data key="nEdges">{len(edges)}</data>')
    out.append(f'<data key="nVertices">{len(stnu.timepoints) + len(extra)}</data>')
    out.append(f'<data key="Name">{label}</data>')
    quoted = {nid: _quoteattr(nid) for nid in [*ids.values(), *extra]}  # once per node, not per edge end
    out += [f'<node id={quoted[nid]}>\n<data key="x">{150.0 * (i % 10):.1f}</data>\n'
            f'<data key="y">{150.0 * (i // 10):.1f}</data>\n</node>'
            for i, nid in enumerate([*(ids[v] for v in stnu.timepoints), *extra])]
    # one string per edge (four lines): values are integers or LC/UC labels of node ids, which the tool's
    # name rule keeps free of XML's special characters, so they need no escaping
    out += [f'<edge id="e{i}" source={quoted[s]} target={quoted[t]}>\n<data key="Type">{etype}</data>\n'
            f'<data key="{key}">{value}</data>\n</edge>' for i, (s, t, etype, key, value) in enumerate(edges)]
    out.append("</graph>")
    out.append("</graphml>")
    return "\n".join(out) + "\n"


def read_network(path: str | Path, *, derived: bool = False, origin: bool = True) -> STNU:
    """Read an STNU file, detecting the format by content: XML -> CSTNU Tool GraphML (`read_graphml`); a
    first line ``# KIND OF NETWORK`` -> the ``.stnu`` text format (`hrc.temporal.stnu_text`, with the
    origin ``Z`` applied unless ``origin=False``); ``{`` -> HEATlab JSON (`hrc.temporal.heatlab`).

    Reads at most `hrc.temporal.limits.MAX_FILE_BYTES` of a regular file. Raises `NetworkFileError`
    (file, line, what is wrong, on one line); anything else is "not an STNU file" with the accepted
    formats (`FORMATS`).
    """
    return read_network_scaled(path, derived=derived, origin=origin)[0]


def read_network_scaled(path: str | Path, *, derived: bool = False, origin: bool = True) -> tuple[STNU, int]:
    """`read_network`, also returning the ticks per unit of the file's numbers (1 but for HEATlab JSON,
    whose decimal bounds are scaled to integers exactly)."""
    from hrc.temporal import heatlab, stnu_text  # local: those modules are only needed for their format

    file = show_path(path)
    data = read_bounded(path, file)
    body = data[3:] if data.startswith(b"\xef\xbb\xbf") else data
    head = body.lstrip(b" \t\r\n")[:1]
    if head == b"<" or body[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return read_graphml(data, file, derived=derived), 1
    if head in (b"{", b"["):
        return heatlab.read_heatlab_scaled(_decode(data, file), file)
    if head == b"#" and stnu_text.looks_like_stnu_text(body):
        return stnu_text.read_stnu_text(_decode(data, file), file, origin=origin), 1
    raise NetworkFileError(file, "", "not an STNU file: expected " + ", ".join(FORMATS[:-1]) + " or " + FORMATS[-1],
                           1)


def _decode(data: bytes, file: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise NetworkFileError(file, "", "not UTF-8 text", line) from err
