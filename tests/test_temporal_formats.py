"""File formats: GraphML (CSTNU Tool), .stnu text, HEATlab JSON; round trips, semantics, bad files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.cli import main
from hrc.errors import NetworkFileError
from hrc.temporal import STNU, ContingentLink, RequirementLink, check_dc
from hrc.temporal.graph import distance_edges
from hrc.temporal.graphml import TOOL_NAME_RULE, read_graphml, read_network, tool_name, write_graphml
from hrc.temporal.heatlab import read_heatlab, read_heatlab_scaled
from hrc.temporal.network import NetworkError
from hrc.temporal.stnu_text import read_stnu_text, write_stnu_text

R, C = RequirementLink, ContingentLink
ROOT = Path(__file__).resolve().parents[1]
NAMES = st.sampled_from(["A", "B", "C1", "X y", "n&<1>", "Ω", "t'q"])


def _semantics(stnu: STNU) -> tuple:
    """What a network means: its timepoints, the tightest bound per ordered pair (a contingent link's
    bounds hold too, so a requirement bound they imply says nothing more), its contingent links."""
    best: dict[tuple[str, str], int] = {}
    for e in distance_edges(stnu, contingent_as_requirement=True):
        best[(e.source, e.target)] = min(e.value, best.get((e.source, e.target), e.value))
    return stnu.timepoints, best, frozenset(stnu.contingents)


@st.composite
def networks(draw, names=NAMES) -> STNU:
    tps = tuple(dict.fromkeys(draw(st.lists(names, min_size=2, max_size=6))))
    if len(tps) < 2:
        tps = ("P", "Q")
    conts = []
    if len(tps) >= 2 and draw(st.booleans()):  # 0 < lb < ub, or a fixed duration (the tool reads both)
        lb = draw(st.integers(1, 5))
        conts.append(C(tps[0], tps[1], lb, lb + draw(st.integers(0, 5))) if draw(st.booleans())
                     else C(tps[0], tps[1], 0, 0))
    pair = {tps[0], tps[1]} if conts else set()
    reqs = []
    for _ in range(draw(st.integers(0, 8))):
        a, b = draw(st.sampled_from(tps)), draw(st.sampled_from(tps))
        lb = draw(st.one_of(st.none(), st.integers(-10**12, 10)))
        ub = draw(st.one_of(st.none(), st.integers(10, 10**12)))
        if a != b and {a, b} != pair:
            reqs.append(R(a, b, lb, ub))  # often two on one pair: the writer merges them
    if conts and draw(st.booleans()):  # a requirement the contingent link implies: left out
        c = conts[0]
        reqs.append(R(c.source, c.target, c.lb, c.ub + draw(st.integers(0, 3))))
    return STNU(tps, tuple(reqs), tuple(conts), draw(st.sampled_from(["", "net <1> & co"])))


def _as_written(stnu: STNU) -> STNU:
    """What `write_graphml` says, by its documented rules: names through `tool_name`, a fixed duration as
    a requirement link."""
    ren = {v: tool_name(v) for v in stnu.timepoints}
    reqs = [R(ren[r.source], ren[r.target], r.lb, r.ub) for r in stnu.requirements]
    conts = []
    for c in stnu.contingents:
        if c.lb == c.ub:
            reqs.append(R(ren[c.source], ren[c.target], c.lb, c.ub))
        else:
            conts.append(C(ren[c.source], ren[c.target], c.lb, c.ub))
    return STNU(tuple(ren[v] for v in stnu.timepoints), tuple(reqs), tuple(conts), stnu.name)


@settings(max_examples=200, deadline=None, database=None)
@given(networks())
def test_graphml_round_trip_and_determinism(stnu: STNU) -> None:
    ids = [tool_name(v) for v in stnu.timepoints]
    if len(set(ids)) < len(ids):  # two names, one node id: refused, never written ambiguously
        with pytest.raises(NetworkError, match="would both be written as node"):
            write_graphml(stnu)
        return
    text = write_graphml(stnu)
    assert write_graphml(stnu) == text
    back = read_graphml(text.encode(), "mem.graphml")
    assert _semantics(back) == _semantics(_as_written(stnu))
    assert all(TOOL_NAME_RULE.fullmatch(v) for v in back.timepoints)
    assert check_dc(back).verdict is check_dc(stnu).verdict
    assert back.name == stnu.name
    assert write_graphml(back) == write_graphml(STNU(back.timepoints, back.requirements, back.contingents,
                                                     back.name))


@settings(max_examples=100, deadline=None, database=None)
@given(networks(), st.randoms(use_true_random=False))
def test_graphml_written_under_new_names_is_that_of_the_renamed_network(stnu: STNU, rnd) -> None:
    """`write_graphml(stnu, names, name)` (the compile's relabelled plans) against writing
    `STNU.renamed`: the same text, or the same refusal when two new names share a node id."""
    new = [f"t{i}.{v}" for i, v in enumerate(stnu.timepoints)]
    rnd.shuffle(new)
    names = dict(zip(stnu.timepoints, new, strict=True))
    if rnd.random() < 0.2 and len(new) > 1:  # two names one node id apart: "t0.x" / "t0_x"
        names[stnu.timepoints[1]] = names[stnu.timepoints[0]].replace(".", "_")
    try:
        expected = write_graphml(stnu.renamed(names, "renamed"))
    except NetworkError as e:
        with pytest.raises(NetworkError, match="would both be written as node"):
            write_graphml(stnu, names, "renamed")
        assert "would both be written as node" in str(e)
        return
    assert write_graphml(stnu, names, "renamed") == expected



@settings(max_examples=100, deadline=None, database=None)
@given(networks(), networks())
def test_graphml_of_one_network_is_not_touched_by_writing_another(a: STNU, b: STNU) -> None:
    """`write_graphml` lays a network's text out once and keeps it for the next call (a family's plans):
    writing `b` between two writes of `a` changes nothing, and the text is GraphML by ElementTree's
    reading (not ours): one node per timepoint with its tool id, the edge count it declares."""
    import xml.etree.ElementTree as ET

    def written(net: STNU) -> str | None:
        try:
            return write_graphml(net)
        except NetworkError:
            return None

    first = written(a)
    written(b)
    assert written(a) == first
    if first is None:
        return
    ns = {"g": "http://graphml.graphdrawing.org/xmlns/graphml"}
    graph = ET.fromstring(first.encode()).find("g:graph", ns)
    assert graph is not None
    assert [n.get("id") for n in graph.findall("g:node", ns)] == [tool_name(v) for v in a.timepoints]
    declared = {d.get("key"): d.text for d in graph.findall("g:data", ns)}
    assert int(declared["nEdges"] or 0) == len(graph.findall("g:edge", ns))
    assert (declared["Name"] or "") == a.name

@settings(max_examples=200, deadline=None, database=None)
@given(networks(names=st.sampled_from(["A", "B", "C1", "Ω", "x_2"])))
def test_stnu_text_round_trip(stnu: STNU) -> None:
    text = write_stnu_text(stnu)
    back = read_stnu_text(text, "mem.stnu")
    assert _semantics(back) == _semantics(stnu)
    assert write_stnu_text(back) == text


def test_graphml_reads_both_contingent_forms_and_origin(tmp_path: Path) -> None:
    head = '<?xml version="1.0"?><graphml xmlns="http://graphml.graphdrawing.org/xmlns/graphml">'
    keys = ('<key id="Type" for="edge"><default>requirement</default></key>'
            '<key id="Value" for="edge"><default></default></key>')
    body = ('<graph edgedefault="directed"><node id="Z"/><node id="A"/><node id="C"/><node id="X"/>'
            '<edge source="A" target="C"><data key="Type">contingent</data><data key="Value">9</data></edge>'
            '<edge source="C" target="A"><data key="Type">contingent</data><data key="Value">-2</data></edge>'
            '<edge source="X" target="C"><data key="Value">4</data></edge>'
            '<edge source="C" target="X"><data key="Type">derived</data><data key="Value">-100</data></edge>'
            "</graph></graphml>")
    path = tmp_path / "plain.stn"  # the extension does not matter
    path.write_text(head + keys + body)
    net = read_network(path)
    assert net.contingents == (C("A", "C", 2, 9),)
    assert R("Z", "A", 0, None) in net.requirements and R("Z", "X", 0, None) in net.requirements
    assert R("X", "C", None, 4) in net.requirements
    assert all(r.ub != -100 for r in net.requirements)  # derived edges are ignored by default
    assert R("C", "X", None, -100) in read_network(path, derived=True).requirements
    labelled = body.replace('<data key="Value">9</data>', '<data key="LabeledValue">LC(C):2</data>').replace(
        '<data key="Value">-2</data>', '<data key="LabeledValue">UC(C):-9</data>')
    path.write_text(head + keys + labelled)
    assert read_network(path).contingents == (C("A", "C", 2, 9),)


def test_origin_semantics_decide_a_verdict() -> None:
    # Y must be 5 before X, X may be at the origin: DC only if Y may precede the origin
    text = write_graphml(STNU(("Z", "X", "Y"), (R("Y", "X", 5, None), R("Z", "X", None, 3))))
    assert check_dc(read_graphml(text.encode())).verdict.value == "inconsistent"
    renamed = write_graphml(STNU(("O", "X", "Y"), (R("Y", "X", 5, None), R("O", "X", None, 3))))
    assert check_dc(read_graphml(renamed.encode())).verdict.value == "DC"


def test_heatlab_scaling_and_origin(tmp_path: Path) -> None:
    doc = ('{"nodes": [{"node_id": 1}, {"node_id": 2}, {"node_id": 3}, {"node_id": 4}], "constraints": ['
           '{"first_node": 0, "second_node": 1, "type": "stc", "min_duration": 0, "max_duration": "inf"},'
           '{"first_node": 1, "second_node": 2, "type": "stcu", "min_duration": 1.5, "max_duration": 2.25},'
           '{"first_node": 2, "second_node": 3, "type": "stc", "min_duration": 0.1, "max_duration": 3},'
           '{"first_node": 3, "second_node": 4, "type": "stcu", "min_duration": -1.0, "max_duration": 2}]}')
    net, scale = read_heatlab_scaled(doc, "x.json")
    assert scale == 20 and net.timepoints == ("0", "1", "2", "3", "4")
    assert C("1", "2", 30, 45) in net.contingents and R("2", "3", 2, 60) in net.requirements
    assert R("0", "1", 0, None) in net.requirements
    assert C("3", "4", 0, 40) in net.contingents  # a negative contingent lower bound is raised to 0
    path = tmp_path / "h.stnu"  # detected as JSON by content
    path.write_text(doc)
    assert read_network(path) == net
    twice = doc.replace('"first_node": 3, "second_node": 4', '"first_node": 3, "second_node": 2')
    with pytest.raises(NetworkFileError, match="two contingent"):
        read_heatlab(twice, "x.json")


BAD_FILES = [
    ("x.graphml", '<?xml version="1.0"?>\n<graphml>\n<graph>\n<node id="A">\n</graph></graphml>', 5,
     "not well-formed"),
    ("x.graphml", '<graphml>\n<graph>\n<node id="A"/>\n<edge source="A" target="B">\n'
     '<data key="Value">3</data></edge></graph></graphml>', 4, "unknown node 'B'"),
    ("x.graphml", '<graphml>\n<graph>\n<node id="A"/><node id="B"/>\n<edge source="A" target="B">\n'
     '<data key="Value">3.5</data></edge></graph></graphml>', 4, "expected an integer"),
    ("x.graphml", '<graphml>\n<graph>\n<node id="A"/><node id="B"/>\n<edge source="A" target="B">\n'
     '<data key="Type">contingent</data><data key="Value">3</data></edge></graph></graphml>', 4,
     "two opposite contingent"),
    ("x.stnu", "# KIND OF NETWORK\nSTNU\n# Num Time-Points\n2\n# Num Ordinary Edges\n1\n"
     "# Num Contingent Links\n0\n# Time-Point Names\nA B\n# Ordinary Edges\nA 3 Q\n", 12, "unknown time-point"),
    ("x.stnu", "# KIND OF NETWORK\nSTNU\n# Num Time-Points\n2\n# Num Ordinary Edges\n0\n"
     "# Num Contingent Links\n1\n# Time-Point Names\nA B\n# Ordinary Edges\n# Contingent Links\nA 5 2 B\n",
     13, "0 <= lb <= ub"),
    ("x.stnu", "# KIND OF NETWORK\nSTNU\n# Num Time-Points\n3\n# Num Ordinary Edges\n0\n"
     "# Time-Point Names\nA B\n", 8, "declared 3 names"),
    ("x.stnu", "# KIND OF NETWORK\nCSTN\n", 2, "expected STNU or STN"),
    ("x.stnu", "# Bogus\n1\n", 1, "not an STNU file"),
    ("x.stnu", "# KIND OF NETWORK\nSTNU\n# Bogus\n1\n", 3, "unknown section"),
    ("x.json", '{"nodes": [{"node_id": 1}],\n "constraints": [}', 2, "not valid JSON"),
    ("x.json", '{"nodes": [{"node_id": 1}], "constraints": [{"first_node": 1, "second_node": 2, '
     '"type": "stc", "min_duration": 0, "max_duration": 1}]}', None, "unknown node '2'"),
    ("x.txt", "hello", 1, "not an STNU file"),
]


@pytest.mark.parametrize("name, content, line, message", BAD_FILES)
def test_bad_files_give_file_line_and_reason(tmp_path: Path, name: str, content: str, line: int | None,
                                             message: str) -> None:
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(NetworkFileError, match=message) as info:
        read_network(path)
    err = info.value
    assert err.file == str(path) and err.line == line
    assert "\n" not in str(err) and str(err).startswith(str(path))


def test_stnu_text_tolerates_quotes_and_header_case() -> None:
    text = ("# Kind of Network\nSTNU\n# Num Time-Points\n3\n# Num Ordinary Edges\n1\n# Num Contingent Links\n1\n"
            "#Time - Point Names\n'A' 'C' 'X'\n# Ordinary Edges\n'X' -2 'C'\n# Contingent Links\n'A' 1 3 'C'\n")
    net = read_stnu_text(text)
    assert net.timepoints == ("A", "C", "X") and net.contingents == (C("A", "C", 1, 3),)
    assert net.requirements == (R("X", "C", None, -2),)


ORIGIN_TEXT = ("# KIND OF NETWORK\nSTN\n# Num Time-Points\n3\n# Num Ordinary Edges\n2\n# Num Contingent Links\n0\n"
               "# Time-Point Names\nZ X Y\n# Ordinary Edges\nZ 3 X\nX -5 Y\n")


def test_stnu_text_origin_decides_a_verdict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """X at most 3 after Z, Y at least 5 before X: consistent only if Y may precede the origin Z."""
    with_origin, without = read_stnu_text(ORIGIN_TEXT), read_stnu_text(ORIGIN_TEXT, origin=False)
    assert R("Z", "Y", 0, None) in with_origin.requirements and without.requirements == (R("Z", "X", None, 3),
                                                                                          R("X", "Y", None, -5))
    assert check_dc(with_origin).verdict.value == "inconsistent" and check_dc(without).verdict.value == "DC"
    renamed = read_stnu_text(ORIGIN_TEXT.replace("Z", "O"))  # no Z, no origin
    assert check_dc(renamed).verdict.value == "DC"
    path = tmp_path / "o.stnu"
    path.write_text(ORIGIN_TEXT)
    assert main(["check", str(path)]) == 0 and capsys.readouterr().out.startswith("inconsistent\n")
    assert main(["check", "--no-origin", str(path)]) == 0 and capsys.readouterr().out.startswith("DC\n")


@settings(max_examples=300, deadline=None, database=None)
@given(st.text(max_size=12))
def test_tool_name_follows_the_cstnu_tool_rule(name: str) -> None:
    nid = tool_name(name)
    assert TOOL_NAME_RULE.fullmatch(nid) and tool_name(nid) == nid  # valid, and a fixed point
    if TOOL_NAME_RULE.fullmatch(name):
        assert nid == name  # names the tool accepts are kept


def test_writer_maps_names_and_fixed_durations() -> None:
    net = STNU(("Z", "h.a-1.fetch.start", "h.a-1.fetch.end", "r.x.y"),
               (R("Z", "h.a-1.fetch.start", 0, None),),
               (C("h.a-1.fetch.start", "h.a-1.fetch.end", 2, 4), C("Z", "r.x.y", 3, 3)))
    text = write_graphml(net)
    assert 'id="h_a_1_fetch_start"' in text and "LC(h_a_1_fetch_end):2" in text and "UC(h_a_1_fetch_end):-4" in text
    back = read_graphml(text.encode())
    assert back.contingents == (C("h_a_1_fetch_start", "h_a_1_fetch_end", 2, 4),)  # [3, 3] became a requirement
    assert R("Z", "r_x_y", None, 3) in back.requirements and R("r_x_y", "Z", None, -3) in back.requirements
    assert '<data key="nContingent">1</data>' in text
    with pytest.raises(NetworkError, match="0 < lb < ub"):  # the tool refuses it, and no file it reads says it
        write_graphml(STNU(("A", "C"), (), (C("A", "C", 0, 4),)))
    with pytest.raises(NetworkError, match="tighter requirement bound 3 on A->C"):
        write_graphml(STNU(("A", "C"), (R("A", "C", None, 3),), (C("A", "C", 1, 4),)))
    with pytest.raises(NetworkError, match="tighter requirement bound -2 on C->A"):
        write_graphml(STNU(("A", "C"), (R("A", "C", 2, None),), (C("A", "C", 1, 4),)))
    # one activation, two contingent links: the second gets a copy of it, at distance 0 (the tool's rule)
    shared = STNU(("A", "C", "D"), (R("C", "D", 1, None),), (C("A", "C", 1, 4), C("A", "D", 2, 5)))
    back = read_graphml(write_graphml(shared).encode())
    assert back.timepoints == ("A", "C", "D", "A_for_D") and '<data key="nVertices">4</data>' in write_graphml(shared)
    assert back.contingents == (C("A", "C", 1, 4), C("A_for_D", "D", 2, 5))
    assert {R("A", "A_for_D", None, 0), R("A_for_D", "A", None, 0)} <= set(back.requirements)
    assert check_dc(back).verdict is check_dc(shared).verdict
    with pytest.raises(NetworkError, match="named 'A_for_D'"):
        write_graphml(STNU(("A", "C", "D", "A_for_D"), (), shared.contingents))
    # two requirement links on one ordered pair: one edge, the tightest
    two = write_graphml(STNU(("A", "B"), (R("A", "B", 1, 9), R("A", "B", None, 5), R("B", "A", None, -2))))
    assert two.count('source="A" target="B"') == 1 and '<data key="Value">5</data>' in two
    assert two.count('source="B" target="A"') == 1 and '<data key="Value">-2</data>' in two
    assert '<data key="nEdges">2</data>' in two
    with pytest.raises(NetworkError, match="'a.b' and 'a_b' would both be written as node 'a_b'"):
        write_graphml(STNU(("a.b", "a_b")))
    # files of older hrc versions, with dotted names, still read
    old = text.replace("h_a_1_fetch_start", "h.a-1.fetch.start")
    assert "h.a-1.fetch.start" in read_graphml(old.encode()).timepoints


def _cstnu_tool_refusals(data: bytes) -> list[str]:
    """What the CSTNU Tool 5.0 would refuse in a GraphML file, by its sources (TNGraphMLReader,
    STNUEdge.setLabeledValue, ALabelAlphabet.ALETTER_RANGE, STNU.initAndCheck, the graph's one edge per
    ordered pair), read with the standard library's parser (independent of hrc's reader). Where the tool
    itself is installed, `test_cstnu_tool` runs it on the files instead."""
    import xml.etree.ElementTree as ET

    ns = "{http://graphml.graphdrawing.org/xmlns/graphml}"
    root = ET.fromstring(data)
    problems = []
    keys = {k.get("id"): k.get("for") for k in root.iter(f"{ns}key")}
    for needed, domain in (("x", "node"), ("y", "node"), ("Type", "edge"), ("NetworkType", "graph")):
        if keys.get(needed) != domain:
            problems.append(f"no {domain} key {needed}")
    nodes = [n.get("id") or "" for n in root.iter(f"{ns}node")]
    problems += [f"node name {n!r}" for n in nodes if not TOOL_NAME_RULE.fullmatch(n)]
    bounds: dict[str, list[int]] = {}
    weights = []
    pairs = [(e.get("source"), e.get("target")) for e in root.iter(f"{ns}edge")]
    problems += [f"two edges {s}->{t}" for s, t in set(pairs) if pairs.count((s, t)) > 1]
    for e in root.iter(f"{ns}edge"):
        data_of = {d.get("key"): d.text or "" for d in e.iter(f"{ns}data")}
        if "Value" in data_of:
            weights.append(int(data_of["Value"]))
        if data_of.get("Type") == "contingent":
            m = re.fullmatch(r"(LC|UC)\(([^)]*)\):(-?[0-9]+)", data_of.get("LabeledValue", ""))
            if not m or not TOOL_NAME_RULE.fullmatch(m.group(2)):
                problems.append(f"labelled value {data_of.get('LabeledValue')!r}")
                continue
            weights.append(int(m.group(3)))
            bounds.setdefault(m.group(2), []).append(abs(int(m.group(3))))
    for c, (lo, hi) in ((c, sorted(b)) for c, b in bounds.items()):
        if not 0 < lo < hi:
            problems.append(f"contingent link of {c} with bounds [{lo}, {hi}] (the tool wants 0 < x < y)")
    if weights and max(map(abs, weights)) * max(len(nodes) - 1, 1) >= 2**31 - 1:
        problems.append("weights over the tool's 32-bit horizon")
    return problems


def test_compile_writes_graphml_the_cstnu_tool_reads(tmp_path: Path) -> None:
    """Every node id and labelled value the compile writes for the workshop passes the tool's rules, and
    each file, read with the tool's semantics, has the class compiled.json records."""
    out = tmp_path / "out"
    assert main(["compile", str(ROOT / "tasks" / "cube_stacking.yaml"), "--out", str(out), "--jobs", "1",
                 "--no-report", "-q"]) == 0
    files = sorted((out / "stnu").glob("*.graphml"))
    assert len(files) == 32
    recorded = {p["id"]: p["class"] for p in json.loads((out / "compiled.json").read_text("utf-8"))["plans"]}
    verdict_of = {"DC": "DC", "consistent": "not DC", "inconsistent": "inconsistent"}
    for path in files:
        assert _cstnu_tool_refusals(path.read_bytes()) == [], path.name
        # read as the tool reads it (Z the origin, every other timepoint at or after it): the class recorded
        assert check_dc(read_network(path), "morris2014").verdict.value == verdict_of[recorded[path.stem]]
    # the rule checker itself notices what the tool refuses
    assert _cstnu_tool_refusals(b'<graphml xmlns="http://graphml.graphdrawing.org/xmlns/graphml"><graph>'
                                b'<node id="A"/><node id="B"/><edge source="A" target="B"/>'
                                b'<edge source="A" target="B"/></graph></graphml>')
    assert _cstnu_tool_refusals(b'<graphml xmlns="http://graphml.graphdrawing.org/xmlns/graphml"><graph>'
                                b'<node id="a.b"/></graph></graphml>')


def test_hrc_check_on_a_task_file_says_it_is_not_an_stnu_file(capsys: pytest.CaptureFixture[str]) -> None:
    for task in ("cube_stacking.yaml", "kitting.yaml"):
        assert main(["check", str(ROOT / "tasks" / task)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "not an STNU file" in err
        assert "GraphML" in err and ".stnu" in err and "HEATlab" in err
