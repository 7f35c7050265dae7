"""File formats: GraphML (CSTNU Tool), .stnu text, HEATlab JSON; round trips, semantics, bad files."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.errors import NetworkFileError
from hrc.temporal import STNU, ContingentLink, RequirementLink, check_dc
from hrc.temporal.graph import distance_edges
from hrc.temporal.graphml import TOOL_NAME_RULE, read_graphml, read_network, tool_name, write_graphml
from hrc.temporal.heatlab import read_heatlab, read_heatlab_scaled
from hrc.temporal.network import NetworkError
from hrc.temporal.stnu_text import read_stnu_text, write_stnu_text

R, C = RequirementLink, ContingentLink
NAMES = st.sampled_from(["A", "B", "C1", "X y", "n&<1>", "Ω", "t'q"])


def _semantics(stnu: STNU) -> tuple:
    """What a network means: its timepoints, the tightest bound per ordered pair, its contingent links."""
    best: dict[tuple[str, str], int] = {}
    for e in distance_edges(stnu, contingent_as_requirement=False):
        best[(e.source, e.target)] = min(e.value, best.get((e.source, e.target), e.value))
    return stnu.timepoints, best, frozenset(stnu.contingents)


@st.composite
def networks(draw, names=NAMES) -> STNU:
    tps = tuple(dict.fromkeys(draw(st.lists(names, min_size=2, max_size=6))))
    if len(tps) < 2:
        tps = ("P", "Q")
    reqs = []
    for _ in range(draw(st.integers(0, 6))):
        a, b = draw(st.sampled_from(tps)), draw(st.sampled_from(tps))
        lb = draw(st.one_of(st.none(), st.integers(-10**12, 10)))
        ub = draw(st.one_of(st.none(), st.integers(10, 10**12)))
        if a != b:
            reqs.append(R(a, b, lb, ub))
    conts = []
    if len(tps) >= 2 and draw(st.booleans()):
        lb = draw(st.integers(0, 5))
        conts.append(C(tps[0], tps[1], lb, lb + draw(st.integers(0, 5))))
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
