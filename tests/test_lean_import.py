"""`hrc.compile.lean_import.import_lean`: scipy's modules imported without their docstring notes compute
what a plain import's compute, the notes are really skipped, and scipy's docstring parser is put back."""

from __future__ import annotations

import json
import subprocess
import sys

from hrc.compile.stream import FORKED_IMPORTS

_PROBE = """
import hashlib, json, sys, time
import numpy as np
t = time.process_time()
if sys.argv[1] == "lean":
    from hrc.compile.lean_import import import_lean
    import_lean(["scipy.sparse.csgraph", "scipy.ndimage", "scipy.spatial"])
else:
    import scipy.ndimage, scipy.sparse.csgraph, scipy.spatial
cpu = time.process_time() - t
import scipy._lib._array_api as api, scipy._lib._docscrape as docscrape, scipy._lib._util as util
from scipy import ndimage, sparse, spatial
rng = np.random.default_rng(7)
grid = rng.random((40, 40)) > 0.6
labels, n = ndimage.label(grid)
dist = ndimage.distance_transform_edt(~grid)
tree = spatial.cKDTree(rng.random((200, 2)))
d, i = tree.query(rng.random((20, 2)), k=3)
graph = sparse.csr_matrix(rng.random((30, 30)) * (rng.random((30, 30)) > 0.7))
sp = sparse.csgraph.dijkstra(graph, indices=[0, 3])
h = hashlib.sha256()
for a in (labels, dist, d, i, sp):
    h.update(np.ascontiguousarray(a).tobytes())
print(json.dumps({"digest": h.hexdigest(), "n": int(n), "cpu": cpu,
                  "restored": api.FunctionDoc is docscrape.FunctionDoc and util.FunctionDoc is docscrape.FunctionDoc,
                  "docs": {f.__name__: f.__doc__ for f in (ndimage.label, ndimage.distance_transform_edt)}}))
"""


def _probe(mode: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def test_lean_imports_compute_the_same_and_skip_only_the_notes() -> None:
    plain, lean = _probe("plain"), _probe("lean")
    assert lean["digest"] == plain["digest"] and lean["n"] == plain["n"]
    assert lean["restored"] and plain["restored"]
    for name, doc in lean["docs"].items():
        full = plain["docs"][name]
        assert doc != full, f"{name}: the note was written anyway"  # the lean import did skip it
        assert doc.split("\n", 1)[0] in full  # the function's own text is kept
    assert "scipy.ndimage" in FORKED_IMPORTS  # what the compile imports this way
