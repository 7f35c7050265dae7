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

Writing: `write_graphml` emits the labelled contingent form, one edge per finite bound, in a fixed
order, so equal networks give byte-identical text. A network with a node ``Z`` gets the origin
semantics of (1) when the tool (or `read_network`) loads it again.
"""

from __future__ import annotations

import re
from pathlib import Path

from hrc.errors import NetworkFileError
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink
from hrc.temporal.xmlread import XmlElement, parse_xml

__all__ = ["ORIGIN", "read_graphml", "read_network", "tool_name", "write_graphml"]

ORIGIN = "Z"
_ORDINARY_TYPES = {"requirement", "normal", "constraint", "derived", "internal"}
_LABELLED = re.compile(r"^\s*(LC|UC)\((.+)\)\s*:\s*([-+]?\d+)\s*$")


def _escape(text: str) -> str:
    """XML character data escaping (xml.sax.saxutils would pull in urllib at import time)."""
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _quoteattr(text: str) -> str:
    return '"' + _escape(text).replace('"', "&quot;").replace("\n", "&#10;").replace("\t", "&#9;") + '"'


def _int(text: str, file: str, key: str, line: int) -> int:
    try:
        return int(text.strip())
    except ValueError as err:
        raise NetworkFileError(file, key, f"expected an integer, found {text.strip()!r}", line) from err


def read_graphml(data: bytes, file: str = "<graphml>", *, derived: bool = False) -> STNU:
    """Parse CSTNU Tool GraphML (see the module docstring). Raises `NetworkFileError`."""
    root = parse_xml(data, file)
    if root.tag != "graphml":
        raise NetworkFileError(file, "", f"expected a <graphml> root element, found <{root.tag}>", root.line)
    defaults: dict[str, str] = {}
    names: dict[str, str] = {}  # key id -> attribute name
    for key in root.find_all("key"):
        kid = key.attrs.get("id", "")
        names[kid] = key.attrs.get("attr.name", kid)
        for d in key.find_all("default"):
            defaults[names[kid]] = d.text.strip()
    graphs = root.find_all("graph")
    if len(graphs) != 1:
        raise NetworkFileError(file, "graph", f"expected one <graph>, found {len(graphs)}", root.line)
    graph = graphs[0]

    def data_of(el: XmlElement) -> dict[str, str]:
        return {names.get(d.attrs.get("key", ""), d.attrs.get("key", "")): d.text for d in el.find_all("data")}

    gdata = data_of(graph)
    kind = gdata.get("NetworkType", "STNU").strip()
    if kind not in {"STN", "STNU"}:
        raise NetworkFileError(file, "NetworkType", f"expected STN or STNU, found {kind!r}", graph.line)
    nodes: list[str] = []
    for node in graph.find_all("node"):
        nid = node.attrs.get("id")
        if not nid:
            raise NetworkFileError(file, "node", "a node has no id", node.line)
        if nid in nodes:
            raise NetworkFileError(file, f"node {nid}", "node id used twice", node.line)
        nodes.append(nid)
    known = set(nodes)
    reqs: list[RequirementLink] = []
    # contingent edges, keyed by the unordered pair: (source, target, value, LC/UC/"", label, line)
    cont: dict[frozenset[str], list[tuple[str, str, int, str, str, int]]] = {}
    for edge in graph.find_all("edge"):
        src, tgt = edge.attrs.get("source", ""), edge.attrs.get("target", "")
        where = f"edge {edge.attrs.get('id', f'{src}->{tgt}')}"
        for end in (src, tgt):
            if end not in known:
                raise NetworkFileError(file, where, f"unknown node {end!r}", edge.line)
        values = {**defaults, **data_of(edge)}
        etype = values.get("Type", "requirement").strip()
        value_text = values.get("Value", "").strip()
        labelled = values.get("LabeledValue", "").strip()
        if etype == "contingent":
            if labelled:
                m = _LABELLED.match(labelled)
                if not m:
                    raise NetworkFileError(
                        file, where, f"expected LC(C):l or UC(C):-u, found {labelled!r}", edge.line
                    )
                entry = (src, tgt, int(m.group(3)), m.group(1), m.group(2), edge.line)
            elif value_text:
                entry = (src, tgt, _int(value_text, file, where, edge.line), "", "", edge.line)
            else:
                raise NetworkFileError(file, where, "contingent edge without Value or LabeledValue", edge.line)
            cont.setdefault(frozenset((src, tgt)), []).append(entry)
        elif etype in _ORDINARY_TYPES:
            if etype == "derived" and not derived:
                continue
            if not value_text:
                raise NetworkFileError(file, where, f"{etype} edge without a Value", edge.line)
            w = _int(value_text, file, where, edge.line)
            reqs.append(_make(RequirementLink, file, where, edge.line, src, tgt, None, w))
        else:
            raise NetworkFileError(file, where, f"unknown edge Type {etype!r}", edge.line)
    contingents = [_contingent_link(pair_edges, file) for pair_edges in cont.values()]
    if kind == "STN" and contingents:
        raise NetworkFileError(file, "NetworkType", "an STN with contingent edges", graph.line)
    if ORIGIN in known:
        reqs.extend(RequirementLink(ORIGIN, x, 0, None) for x in nodes if x != ORIGIN)
    name = gdata.get("Name", "").strip()
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
    where = f"contingent link {edges[0][0]}-{edges[0][1]}"
    if len(edges) != 2 or edges[0][:2] == edges[1][:2]:
        raise NetworkFileError(file, where, f"expected two opposite contingent edges, found {len(edges)}", line)
    labels = {e[4] for e in edges if e[3]}
    if len(labels) > 1:
        raise NetworkFileError(file, where, f"contingent edges name different timepoints {sorted(labels)}", line)
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
        raise NetworkFileError(file, where, f"label names {c!r}, which is not an end of the link", line) from None
    if (ac[3], ca[3]) == ("LC", "UC"):
        lb, ub = ac[2], -ca[2]
    elif (ac[3], ca[3]) == ("", ""):
        lb, ub = -ca[2], ac[2]
    else:
        raise NetworkFileError(file, where, "expected LC(C) on A->C and UC(C) on C->A, or two plain values", line)
    return _make(ContingentLink, file, where, line, ac[0], c, lb, ub)


def tool_name(name: str) -> str:
    """The node id `write_graphml` gives timepoint `name` (the one place that decides it).

    Code that looks a timepoint up in a written file goes through this function.
    """
    return name


def write_graphml(stnu: STNU) -> str:
    """The network as CSTNU Tool GraphML text (deterministic; see the module docstring)."""
    edges: list[tuple[str, str, str, str, str]] = []  # (source, target, Type, key, value)
    for r in stnu.requirements:
        if r.ub is not None:
            edges.append((r.source, r.target, "requirement", "Value", str(r.ub)))
        if r.lb is not None:
            edges.append((r.target, r.source, "requirement", "Value", str(-r.lb)))
    for c in stnu.contingents:
        edges.append((c.source, c.target, "contingent", "LabeledValue", f"LC({c.target}):{c.lb}"))
        edges.append((c.target, c.source, "contingent", "LabeledValue", f"UC({c.target}):{-c.ub}"))
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
    out.append(f'<data key="nContingent">{len(stnu.contingents)}</data>')
    out.append(f'<data key="NetworkType">{"STNU" if stnu.contingents else "STN"}</data>')
    out.append(f'<data key="nEdges">{len(edges)}</data>')
    out.append(f'<data key="nVertices">{len(stnu.timepoints)}</data>')
    out.append(f'<data key="Name">{_escape(stnu.name)}</data>')
    for i, v in enumerate(stnu.timepoints):
        out.append(f"<node id={_quoteattr(v)}>")
        out.append(f'<data key="x">{150.0 * (i % 10):.1f}</data>')
        out.append(f'<data key="y">{150.0 * (i // 10):.1f}</data>')
        out.append("</node>")
    for i, (s, t, etype, key, value) in enumerate(edges):
        out.append(f'<edge id="e{i}" source={_quoteattr(s)} target={_quoteattr(t)}>')
        out.append(f'<data key="Type">{etype}</data>')
        out.append(f'<data key="{key}">{_escape(value)}</data>')
        out.append("</edge>")
    out.append("</graph>")
    out.append("</graphml>")
    return "\n".join(out) + "\n"


def read_network(path: str | Path, *, derived: bool = False) -> STNU:
    """Read an STNU file, detecting the format by content: XML -> CSTNU Tool GraphML
    (`read_graphml`), ``#`` -> the plain ``.stnu`` text format (`hrc.temporal.stnu_text`), ``{`` -> HEATlab
    JSON (`hrc.temporal.heatlab`). Raises `NetworkFileError` (file, line, what is wrong)."""
    from hrc.temporal import heatlab, stnu_text  # local: formats import this module

    file = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise NetworkFileError(file, "", f"cannot read: {err.strerror or err}") from err
    head = data.lstrip(b"\xef\xbb\xbf \t\r\n")[:1]
    if head == b"<":
        return read_graphml(data, file, derived=derived)
    if head == b"#":
        return stnu_text.read_stnu_text(_decode(data, file), file)
    if head in (b"{", b"["):
        return heatlab.read_heatlab(_decode(data, file), file)
    raise NetworkFileError(file, "", "unknown format: expected GraphML (<), .stnu text (#) or HEATlab JSON ({)", 1)


def _decode(data: bytes, file: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data[: err.start].count(b"\n") + 1
        raise NetworkFileError(file, "", "not UTF-8 text", line) from err
