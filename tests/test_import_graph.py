"""hrc's import graph is one-way: no module imports itself back through others, and every import between
packages goes down the layer table below (data flows model -> plans -> motion -> temporal -> compile ->
dispatch -> front ends -> report -> CLI; ../shared/DESIGN.md, STYLE.md item 1).

The graph is read from the source with `ast` (every ``import`` and ``from ... import``, those inside
functions and under ``TYPE_CHECKING`` included: a lazy import is still a dependency), so it needs no
import of hrc and sees what a grep would.

The layer table: a package may import only packages of a strictly lower layer (and itself). Packages
sharing a layer may not import each other. A new package must be given a layer here.

| layer | packages | why there |
|---:|---|---|
| 0 | ``hrc`` (``__version__``), ``errors``, ``caches`` | leaves every layer may use |
| 1 | ``model`` | the task, map and plan values |
| 2 | ``io``, ``plans`` | loading files into the model; plan generation |
| 3 | ``motion``, ``temporal`` | motion acquisition; STNUs and their checks (independent of each other) |
| 4 | ``apa`` | preferences over a plan's STNU (Jacobs et al.) |
| 5 | ``compile`` | the compiler: motion + temporal net creator + classification + outputs |
| 6 | ``dispatch`` | the online dispatcher over a compiled plan set |
| 7 | ``detect`` | the motion detector, turning tracked positions into the dispatcher's observations |
| 8 | ``sim``, ``ros2`` | the simulated workshop; the dispatcher as a ROS 2 node (independent) |
| 9 | ``record`` | MCAP recordings of a dispatched, simulated or ROS 2 run |
| 10 | ``console``, ``learn`` | the browser console (records its runs); learning from recorded runs |
| 11 | ``report`` | figures and tables of compiles and simulations |
| 12 | ``cli`` | the commands |
| 13 | ``__main__`` | ``python -m hrc`` |
"""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1] / "hrc"

LAYERS: dict[str, int] = {
    "hrc": 0, "errors": 0, "caches": 0,
    "model": 1,
    "io": 2, "plans": 2,
    "motion": 3, "temporal": 3,
    "apa": 4,
    "compile": 5,
    "dispatch": 6,
    "detect": 7,
    "sim": 8, "ros2": 8,
    "record": 9,
    "console": 10, "learn": 10,
    "report": 11,
    "cli": 12,
    "__main__": 13,
}


def module_files(root: Path, package: str = "hrc") -> dict[str, Path]:
    """Dotted module name -> file, for every ``*.py`` under `root` (a package ``__init__`` by its package)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = [package, *path.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def import_graph(root: Path, package: str = "hrc") -> nx.DiGraph:
    """Module -> the modules of `package` it imports (``from P import name`` counts as P.name where that
    is a module, else as P)."""
    files = module_files(root, package)
    graph = nx.DiGraph()
    graph.add_nodes_from(files)
    for module, path in files.items():
        here = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here.split(".")[: len(here.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in files else source for a in node.names]
            for target in targets:
                while target and target not in files:  # `import hrc.a.b` of a name inside a module
                    target = target.rpartition(".")[0]
                if target and target != module:
                    graph.add_edge(module, target)
    return graph


def layer(module: str) -> str:
    """The top-level package of `module` (``hrc`` for the root package itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def cycles(graph: nx.DiGraph) -> list[list[str]]:
    return [sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]


def back_imports(graph: nx.DiGraph, layers: dict[str, int]) -> list[str]:
    """Imports that do not go strictly down the layer table (between two packages)."""
    out = []
    for a, b in graph.edges:
        pa, pb = layer(a), layer(b)
        if pa != pb and not layers[pb] < layers[pa]:
            out.append(f"{a} ({pa}, layer {layers[pa]}) imports {b} ({pb}, layer {layers[pb]})")
    return sorted(out)


@pytest.fixture(scope="module")
def graph() -> nx.DiGraph:
    return import_graph(ROOT)


def test_every_package_has_a_layer(graph: nx.DiGraph) -> None:
    assert {layer(m) for m in graph} <= set(LAYERS), "give the new package a layer in LAYERS (and the table)"


def test_no_import_cycles(graph: nx.DiGraph) -> None:
    assert cycles(graph) == []


def test_imports_go_down_the_layers(graph: nx.DiGraph) -> None:
    assert back_imports(graph, LAYERS) == []


def test_graph_sees_the_known_edges(graph: nx.DiGraph) -> None:
    """Edges of each import form the reader must see (a reader that saw nothing would pass the rest)."""
    assert graph.has_edge("hrc.compile.compiler", "hrc.io.task_file")            # from hrc.io.task_file import
    assert graph.has_edge("hrc.dispatch.plan_set", "hrc.dispatch.messages")      # from .messages import
    assert graph.has_edge("hrc.record.recorder", "hrc.record.scene")             # from hrc.record import scene
    assert graph.has_edge("hrc.record.recorder", "hrc.dispatch.routes")          # a lazy import in a function
    assert graph.has_edge("hrc.console.run", "hrc.dispatch.routes")
    assert graph.number_of_edges() > 300


def test_checks_catch_a_planted_loop_and_a_back_import(tmp_path: Path) -> None:
    """The two checks fail on a small package built to break them."""
    pkg = tmp_path / "hrc"
    for rel, text in {
        "__init__.py": "",
        "model.py": "from hrc.compile.compiler import compile_task\n",          # back: model -> compile
        "compile/__init__.py": "",
        "compile/compiler.py": "def f():\n    from .dispatch_form import plan_record\n",
        "compile/dispatch_form.py": "from hrc.compile.compiler import task_digest\n",  # loop
    }.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    g = import_graph(pkg)
    assert cycles(g) == [["hrc.compile.compiler", "hrc.compile.dispatch_form"]]
    assert back_imports(g, LAYERS) == ["hrc.model (model, layer 1) imports hrc.compile.compiler (compile, layer 5)"]
