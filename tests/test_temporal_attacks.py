"""Hostile and odd network files, in all three formats, against `hrc check` (issue 10).

Each file goes through the real command (``hrc.cli.main(["check", FILE])``) in a child process that runs
under a 2 GiB address-space limit and a per-file alarm, so a hang, a memory blow-up or a traceback shows
as a failed test instead of a stuck or killed test run. A bad file must give exit status 2, an empty
standard output and exactly one ``error:`` line; a file that happens to be a valid network must give a
verdict (exit 0). Every generator is seeded (`SEED`), so a failure replays.

The default run has at least one small case of every kind of attack; the 100,000-timepoint files and the
files near the size limit are marked ``slow``.
"""

from __future__ import annotations

import json
import os
import random
import resource
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import pytest

from hrc.temporal import STNU, ContingentLink, RequirementLink
from hrc.temporal.graphml import write_graphml
from hrc.temporal.limits import MAX_FILE_BYTES
from hrc.temporal.stnu_text import write_stnu_text

ROOT = Path(__file__).resolve().parents[1]
SEED = 20261123
MEMORY_LIMIT = 2 * 2**30
R, C = RequirementLink, ContingentLink

_RUNNER = r"""
import contextlib, io, json, signal, sys, time
from hrc.cli import main

def alarm(signum, frame):
    raise TimeoutError("over the time limit")

signal.signal(signal.SIGALRM, alarm)
limit = int(sys.argv[1])
results = []
for path in sys.argv[2:]:
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    signal.alarm(limit)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = main(["check", path])
    except SystemExit as exc:
        status = exc.code
    except BaseException as exc:  # a traceback, a hang or a memory error: the test fails on it
        status = f"{type(exc).__name__}: {exc}"
    finally:
        signal.alarm(0)
    results.append({"file": path, "status": status, "out": out.getvalue(), "err": err.getvalue(),
                    "seconds": time.perf_counter() - start})
print(json.dumps(results))
"""


def run_checks(paths: list[Path], seconds: int = 60) -> list[dict[str, object]]:
    """`hrc check` on each path in one child process under `MEMORY_LIMIT` and a per-file alarm."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))

    proc = subprocess.run([sys.executable, "-c", _RUNNER, str(seconds), *map(str, paths)], capture_output=True,
                          text=True, cwd=ROOT, preexec_fn=limit, timeout=seconds * (len(paths) + 1) + 60,
                          check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout)


def assert_refused_or_checked(results: list[dict[str, object]], *, refused: bool | None = True) -> None:
    """Each result: a one-line refusal with exit 2 (``refused=True``), a verdict with exit 0
    (``refused=False``) or either (``None``, for fuzzed files that may still be valid)."""
    for r in results:
        status, out, err = r["status"], str(r["out"]), str(r["err"])
        assert status in (0, 2), r
        if status == 2:
            assert refused is not False, r
            assert out == "" and err.startswith("error: ") and err.count("\n") == 1, r
        else:
            assert refused is not True, r
            assert out.splitlines()[0] in ("DC", "not DC", "inconsistent"), r


# ------------------------------------------------------------------------------------------ sample files
def chain(n: int, every: int = 50, prefix: str = "X") -> STNU:
    """A chain of n timepoints, consecutive ones 1..10 apart, every ``every``-th link contingent."""
    names = tuple(f"{prefix}{i}" for i in range(n))
    reqs, conts = [], []
    for i in range(n - 1):
        if i % every == 0:
            conts.append(C(names[i], names[i + 1], 1, 10))
        else:
            reqs.append(R(names[i], names[i + 1], 1, 10))
    return STNU(names, tuple(reqs), tuple(conts))


def heatlab_text(stnu: STNU) -> str:
    """HEATlab JSON for a network whose timepoints are X0, X1, ... (ids 1, 2, ...)."""
    ids = {v: i + 1 for i, v in enumerate(stnu.timepoints)}
    cons = [{"first_node": ids[r.source], "second_node": ids[r.target], "type": "stc",
             "min_duration": r.lb, "max_duration": r.ub} for r in stnu.requirements]
    cons += [{"first_node": ids[c.source], "second_node": ids[c.target], "type": "stcu",
              "min_duration": c.lb, "max_duration": c.ub} for c in stnu.contingents]
    return json.dumps({"nodes": [{"node_id": i} for i in ids.values()], "constraints": cons})


SAMPLES: dict[str, Callable[[STNU], str]] = {"graphml": write_graphml, "stnu": write_stnu_text,
                                              "json": heatlab_text}

GRAPHML_HEAD = ('<?xml version="1.0" encoding="UTF-8"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns/'
                'graphml">\n<key id="Type" for="edge"><default>requirement</default></key>\n'
                '<key id="Value" for="edge"><default></default></key>\n<graph edgedefault="directed">\n')
STNU_HEAD = "# KIND OF NETWORK\nSTNU\n# Num Time-Points\n"


def hostile_files() -> dict[str, bytes]:
    """Small hostile files of every kind (name -> bytes); all must be refused with one line."""
    laughs = "".join(f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10))
    files = {
        # entity expansion ("billion laughs") and an external entity
        "laughs.graphml": (f'<?xml version="1.0"?><!DOCTYPE g [<!ENTITY l0 "ha">{laughs}]>'
                           '<graphml><graph><node id="&l9;"/></graph></graphml>').encode(),
        "xxe.graphml": (b'<?xml version="1.0"?><!DOCTYPE g [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
                        b'<graphml><graph><node id="&e;"/></graph></graphml>'),
        # deep nesting
        "deep.graphml": (b"<graphml>" + b"<a>" * 5000 + b"</a>" * 5000 + b"</graphml>"),
        "deep.json": b"[" * 1000 + b"]" * 1000,
        "deep_object.json": b'{"nodes": ' + b'{"a": ' * 3000 + b"1" + b"}" * 3000 + b', "constraints": []}',
        # huge numbers: in each format, and numbers Python's int() would choke on
        "bignum.graphml": (GRAPHML_HEAD + '<node id="A"/><node id="B"/><edge source="A" target="B">'
                           f'<data key="Value">{"9" * 5000}</data></edge></graph></graphml>').encode(),
        "bignum_label.graphml": (GRAPHML_HEAD + '<node id="A"/><node id="C"/><edge source="A" target="C">'
                                 '<data key="Type">contingent</data><data key="LabeledValue">LC(C):'
                                 f'{"1" * 4400}</data></edge></graph></graphml>').encode(),
        "bignum.stnu": (STNU_HEAD + "2\n# Num Ordinary Edges\n1\n# Num Contingent Links\n0\n# Time-Point Names\n"
                        f"A B\n# Ordinary Edges\nA {'7' * 5000} B\n").encode(),
        "bigcount.stnu": (STNU_HEAD + "9" * 5000 + "\n").encode(),
        "hugecount.stnu": (STNU_HEAD + "999999999999\n# Num Ordinary Edges\n0\n# Time-Point Names\nA\n").encode(),
        "bigexp.json": b'{"nodes": [{"node_id": 1}, {"node_id": 2}], "constraints": [{"first_node": 1, '
                       b'"second_node": 2, "type": "stc", "min_duration": 0, "max_duration": 1e999999999}]}',
        "tinyexp.json": b'{"nodes": [{"node_id": 1}, {"node_id": 2}], "constraints": [{"first_node": 1, '
                        b'"second_node": 2, "type": "stc", "min_duration": 1e-999999999, "max_duration": 1}]}',
        "bigid.json": b'{"nodes": [{"node_id": 1e999999999}], "constraints": []}',
        "longint.json": b'{"nodes": [{"node_id": ' + b"1" * 5000 + b'}], "constraints": []}',
        "nan.json": b'{"nodes": [{"node_id": 1}, {"node_id": 2}], "constraints": [{"first_node": 1, '
                    b'"second_node": 2, "type": "stc", "min_duration": NaN, "max_duration": 1}]}',
        # digits of other scripts, which str.isdigit() and int() accept
        "arabic_count.stnu": (STNU_HEAD + "\u0663\n").encode(),
        "superscript.stnu": (STNU_HEAD + "\u00b2\n").encode(),
        "fullwidth.graphml": (GRAPHML_HEAD + '<node id="A"/><node id="B"/><edge source="A" target="B">'
                              '<data key="Value">\uff13</data></edge></graph></graphml>').encode(),
        # encodings
        "encoding.graphml": b'<?xml version="1.0" encoding="no-such-encoding"?><graphml/>',
        "utf32.graphml": b'<?xml version="1.0" encoding="utf-32"?><graphml/>',
        "latin1.stnu": (STNU_HEAD + "1\n# Num Ordinary Edges\n0\n# Time-Point Names\n").encode() + b"caf\xe9\n",
        "nul.json": b'{"nodes": [\x00], "constraints": []}',
        # names and ids with line breaks must still give one error line
        "newline_id.graphml": (GRAPHML_HEAD + '<node id="a&#10;b"/><edge source="a&#10;b" target="x&#10;y">'
                               '<data key="Value">1</data></edge></graph></graphml>').encode(),
        "newline_type.json": b'{"nodes": [{"node_id": 1}], "constraints": [{"first_node": 1, "second_node": 1, '
                             b'"type": "s\\ntc"}]}',
        # duplicates, and empty or odd documents
        "dup.graphml": (GRAPHML_HEAD + '<node id="A"/>' * 3 + "</graph></graphml>").encode(),
        "empty.graphml": b"",
        "blank.stnu": b"\n\n   \n",
        "array.json": b"[1, 2, 3]",
        "yaml.stnu": b"# a task file\nname: not a network\n",
        "nested_graph.graphml": b"<graphml><graph><node id='a'><graph/></node></graph></graphml>",
    }
    # text that arrives in many small pieces: 1 MB of line breaks inside one element
    files["newlines.graphml"] = GRAPHML_HEAD.encode() + b'<node id="A"><data key="x">' + b"\n" * 2**20 + \
        b"</data></node><node id='A'/></graph></graphml>"
    return files


def damaged_files(rng: random.Random, count: int) -> dict[str, bytes]:
    """Valid small networks of each format, truncated or with a few random bytes changed."""
    out: dict[str, bytes] = {}
    base = STNU(("Z", "A", "C", "X", "Y"), (R("Z", "A", 0, 5), R("C", "X", 0, 3), R("X", "Y", 1, None)),
                (C("A", "C", 2, 9),))
    for fmt, write in SAMPLES.items():
        text = write(base if fmt != "json" else chain(6)).encode()
        for i in range(count):
            cut = rng.randrange(1, len(text))
            out[f"trunc{i}.{fmt}"] = text[:cut]
            noisy = bytearray(text)
            for _ in range(rng.randint(1, 4)):
                noisy[rng.randrange(len(noisy))] = rng.choice(b'<>&"\'#{}[]:,-0123456789eE.\n \x00\xff\xc3')
            out[f"noise{i}.{fmt}"] = bytes(noisy)
    return out


def write_all(tmp: Path, files: dict[str, bytes]) -> list[Path]:
    paths = []
    for name, data in files.items():
        path = tmp / name
        path.write_bytes(data)
        paths.append(path)
    return paths


# ------------------------------------------------------------------------------------------------- tests
def test_hostile_files_are_refused_on_one_line(tmp_path: Path) -> None:
    paths = write_all(tmp_path, hostile_files())
    results = run_checks(paths, seconds=20)
    assert_refused_or_checked(results, refused=True)
    assert max(float(r["seconds"]) for r in results) < 10  # linear work: nothing here takes long
    by_name = {Path(str(r["file"])).name: str(r["err"]) for r in results}
    assert "entity declarations are not allowed" in by_name["laughs.graphml"]
    assert "nested" in by_name["deep.graphml"] and "nested too deeply" in by_name["deep.json"]
    assert "digits" in by_name["bignum.graphml"] and "digits" in by_name["bignum.stnu"]
    assert "out of range" in by_name["bigexp.json"] and "decimals" in by_name["tinyexp.json"]
    assert "expected a count" in by_name["arabic_count.stnu"]
    assert "node id used twice" in by_name["dup.graphml"] and "used twice" in by_name["newlines.graphml"]
    assert "\\n" in by_name["newline_id.graphml"]  # the line break is shown escaped
    assert "not an STNU file" in by_name["yaml.stnu"] and "not an STNU file" in by_name["array.json"]


def test_damaged_files_never_crash(tmp_path: Path) -> None:
    paths = write_all(tmp_path, damaged_files(random.Random(SEED), 12))
    results = run_checks(paths, seconds=20)
    assert_refused_or_checked(results, refused=None)
    assert sum(r["status"] == 2 for r in results) > len(results) // 2  # most damage is noticed


def test_special_files_and_odd_names(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo.graphml"
    os.mkfifo(fifo)  # opening it for reading would block: it must be refused before
    short = Path(tempfile.mkdtemp(prefix="hrc-"))  # the error shows a path's first characters only: keep
    odd = short / "line\nbreak.stnu"              # the odd name within them (a pytest-xdist path is longer)
    odd.write_text("# KIND OF NETWORK\nCSTN\n")
    sparse = tmp_path / "huge.graphml"
    with open(sparse, "wb") as fh:  # over the size limit, without writing the bytes
        fh.truncate(MAX_FILE_BYTES + 1)
    paths = [fifo, Path("/dev/zero"), tmp_path, tmp_path / "missing.json", odd, sparse]
    try:
        results = run_checks(paths, seconds=20)
    finally:
        shutil.rmtree(short)
    assert_refused_or_checked(results, refused=True)
    errors = [str(r["err"]) for r in results]
    assert "a FIFO" in errors[0] and "a character device" in errors[1] and "a folder" in errors[2]
    assert "No such file" in errors[3] and "line\\nbreak" in errors[4] and "over the limit" in errors[5]


@pytest.mark.parametrize("fmt", sorted(SAMPLES))
def test_chains_check_in_linear_time_and_memory(tmp_path: Path, fmt: str) -> None:
    """A 5,000-timepoint chain with a contingent link every 50 timepoints, in each format."""
    path = tmp_path / f"chain.{fmt}"
    path.write_text(SAMPLES[fmt](chain(5000)))
    (result,) = run_checks([path], seconds=30)
    assert_refused_or_checked([result], refused=False)
    assert str(result["out"]).startswith("DC\n") and float(result["seconds"]) < 10


def test_hrc_check_as_a_process_on_a_hostile_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_bytes(b"[" * 100_000)
    proc = subprocess.run([sys.executable, "-m", "hrc", "check", str(bad)], capture_output=True, text=True,
                          cwd=ROOT, timeout=60, check=False)
    assert proc.returncode == 2 and proc.stdout == "" and proc.stderr.count("\n") == 1, proc.stderr


@pytest.mark.parametrize("fmt", sorted(SAMPLES))
def test_size_limits_are_counted_while_reading(tmp_path: Path, fmt: str,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Timepoints and bounds are counted as a file is read (here with limits of 10 and 20, in-process)."""
    from hrc.errors import NetworkFileError
    from hrc.temporal import graphml, limits, stnu_text
    from hrc.temporal.graphml import read_network

    for module in (limits, graphml, stnu_text):
        monkeypatch.setattr(module, "MAX_TIMEPOINTS", 10, raising=False)
        monkeypatch.setattr(module, "MAX_BOUNDS", 20, raising=False)
    small, wide, long = chain(10), chain(11), chain(10)
    tps = long.timepoints  # 10 timepoints, 18 + 2 * 28 bounds on distinct pairs (GraphML merges a pair's bounds)
    extra = tuple(R(tps[i], tps[j], -100, 100) for i in range(1, 10) for j in range(i + 2, 10))
    long = STNU(tps, long.requirements + extra, long.contingents)
    for net, ok in ((small, True), (wide, False), (long, False)):
        path = tmp_path / f"n.{fmt}"
        path.write_text(SAMPLES[fmt](net))
        if ok:
            assert len(read_network(path).timepoints) == len(net.timepoints)
        else:
            with pytest.raises(NetworkFileError, match="over the limit for a network file"):
                read_network(path)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", sorted(SAMPLES))
def test_100k_timepoint_files(tmp_path: Path, fmt: str) -> None:
    """100,000 timepoints, a contingent link every 50: checked within 60 s and 2 GiB in every format."""
    path = tmp_path / f"chain.{fmt}"
    path.write_text(SAMPLES[fmt](chain(100_000)))
    (result,) = run_checks([path], seconds=60)
    assert_refused_or_checked([result], refused=False)
    assert str(result["out"]).startswith("DC\n")


@pytest.mark.slow
def test_100k_duplicate_nodes_and_big_refusals(tmp_path: Path) -> None:
    files = {
        "dups.graphml": (GRAPHML_HEAD + "".join(f'<node id="n{i}"/>' for i in range(100_000)) + '<node id="n0"/>'
                         "</graph></graphml>").encode(),
        "values.json": b'{"nodes": [' + b"0," * 3_000_000 + b'0], "constraints": []}',
        "newlines.stnu": STNU_HEAD.encode() + b"\n" * (200 * 2**20) + b"x\n",
        "names.stnu": STNU_HEAD.encode() + b"600000\n# Num Ordinary Edges\n0\n# Time-Point Names\n"
        + b" ".join(b"t%d" % i for i in range(600_000)) + b"\n",
        "nodes.graphml": (GRAPHML_HEAD + "".join(f'<node id="n{i}"/>' for i in range(500_001))
                          + "</graph></graphml>").encode(),
        "laughs_big.graphml": GRAPHML_HEAD.encode() + b"<node id='a'>" + b"<x>" * 60 + b"</x>" * 60
        + b"</node>" * 1 + b"\n" * (32 * 2**20) + b"</graph>",
    }
    results = run_checks(write_all(tmp_path, files), seconds=60)
    assert_refused_or_checked(results, refused=True)


_RSS_RUNNER = r"""
import ctypes, gc, os, sys, threading
sys.path.insert(0, "tests")
from test_temporal_attacks import chain
from hrc.temporal import check_dc
net = chain(int(sys.argv[1]), int(sys.argv[2]))
assert check_dc(chain(50, 5)).is_dc  # the C core loaded before measuring
gc.collect()
ctypes.CDLL("libc.so.6").malloc_trim(0)
page = os.sysconf("SC_PAGE_SIZE")

def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page

before, peak, done = rss(), [0], threading.Event()

def watch():
    while not done.is_set():
        peak[0] = max(peak[0], rss())
        done.wait(0.0005)

watcher = threading.Thread(target=watch)
watcher.start()
assert check_dc(net).is_dc  # ctypes releases the GIL: the watcher samples during the C call too
done.set()
watcher.join()
print(max(peak[0], rss()) - before)
"""


@pytest.mark.parametrize("every", [3, 50])
def test_dc_check_memory_grows_linearly(every: int) -> None:
    """The default DC check (rul2021, Python implementation, which also builds the explanations) on
    chains of 1,000 and 4,000 timepoints: peak traced memory about 4 times larger, not 16 (quadratic)."""
    import tracemalloc

    from hrc.temporal.rul import rul2021_check

    peaks = []
    for n in (1000, 4000):
        net = chain(n, every)
        tracemalloc.start()
        assert rul2021_check(net, accelerated=False)[0] == "DC"
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert 2 < peaks[1] / peaks[0] < 6, peaks


@pytest.mark.slow
@pytest.mark.parametrize("every", [3, 50])
def test_dc_check_memory_grows_linearly_with_the_c_core(every: int) -> None:
    """`check_dc` as the compiler calls it (verdict from the C core, whose allocations tracemalloc does not
    see): resident memory sampled during the check, above what it was before, chains of 50,000 and 200,000."""
    grown = []
    for n in (50_000, 200_000):
        proc = subprocess.run([sys.executable, "-c", _RSS_RUNNER, str(n), str(every)], capture_output=True,
                              text=True, cwd=ROOT, timeout=300, check=True)
        grown.append(int(proc.stdout))
    assert 2 < grown[1] / grown[0] < 6, grown
