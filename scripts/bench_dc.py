"""Benchmark the DC check over a folder of STNU files, the CSTNU Tool's check timed in the same run.

    .venv/bin/python scripts/bench_dc.py ../shared/benchmarks/stnu [--repeat 5] [--summary-only]
        [--algorithm rul2021 --algorithm bypass ... | --algorithm all] [--tool PATH | --no-tool] [--cpu N]

What is timed, on both sides the same: the DC check as a caller makes it on a network it holds, the
conversion to the checker's own structures included, reading the file not. hrc: a fresh `STNU` built
from the links (its validation) and `hrc.temporal.check_dc` on it, both timed, each run (hrc keeps a
network's index arrays per object, so a check repeated on one object would skip its conversion).
The tool: its RUL2021 check (its default) on
a fresh copy of the read graph each run, its own preparation (``initAndCheck``) included, in one
long-running JVM (``scripts/CstnuTimer.java``, compiled here with javac against the oracle's classpath,
``../shared/oracles/cstnu-tool``), so the JVM's start is not timed. Files the tool cannot read as they are
(HEATlab JSON, ``.stnu`` text) are given to it as hrc writes them in GraphML (`write_graphml`: the same
network); HEATlab's decimal bounds are rounded to 0.1 of the file's unit for both sides (`bench_network`:
the tool's weights are 32-bit integers). A network the tool refuses (a contingent link with lower bound
0, which hrc will not write) has no tool time.

Both sides are warmed alike: one untimed pass over every instance (each algorithm and the tool), then the
timed pass, interleaved per instance (hrc's algorithms and the tool one after another, which side goes
first alternating), each with one untimed run and the median of ``--repeat`` timed runs. Prints one row
per instance (unless ``--summary-only``), then per size class and algorithm the median time, the tool's
median over the same instances, their ratio (ours / tool: below 1 is faster) and the median of the
per-instance ratios. ``--algorithm rul2021-py`` is rul2021 without its C core (what a machine without a C
compiler runs). Verdicts are compared with ``verdicts.csv`` when the folder has one, and with the tool's.
``--cpu N`` pins this process (and the JVM) to one core.
"""

from __future__ import annotations

import argparse
import csv
import gc
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from hrc.errors import NetworkFileError  # noqa: E402
from hrc.temporal.dc import ALGORITHMS, DEFAULT_ALGORITHM, check_dc  # noqa: E402
from hrc.temporal.graphml import read_network, write_graphml  # noqa: E402
from hrc.temporal.heatlab import read_heatlab_scaled  # noqa: E402
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink  # noqa: E402
from hrc.temporal.rul import rul2021_check  # noqa: E402

PURE = "rul2021-py"
TOOL = Path(__file__).resolve().parents[2] / "shared" / "oracles" / "cstnu-tool" / "cstnu-check"
CLASSES = [("<50", 0, 49), ("50-199", 50, 199), ("200-399", 200, 399), (">=400", 400, 10**12)]
SUFFIXES = {".stnu", ".stn", ".graphml", ".json", ".cstnu"}
ACCEPT = {"DC": {"DC"}, "consistent-not-DC": {"not DC"}, "inconsistent": {"inconsistent"},
          "not-DC": {"not DC", "inconsistent"}, "unknown": {"DC", "not DC", "inconsistent"}}


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
    return (f"{cpu}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, load average {load}")


def expected_verdicts(folder: Path) -> dict[str, str]:
    path = folder / "verdicts.csv"
    if not path.is_file():
        return {}
    with open(path, newline="", encoding="utf-8") as fh:
        return {row["file"]: row["expected"] for row in csv.DictReader(fh)}


class _PurePython:
    """rul2021 without its C core (what a machine without a C compiler runs), timed like check_dc."""

    def __init__(self, verdict: str, cycle: object) -> None:
        self.verdict = type("V", (), {"value": verdict})()
        self.cycle = cycle


def check(net: STNU, algorithm: str) -> Any:
    if algorithm == PURE:
        verdict, cycle, _ = rul2021_check(net, accelerated=False)
        return _PurePython(verdict, cycle)
    return check_dc(net, algorithm)


def fresh(net: STNU) -> STNU:
    """An equal network in a new object, validated: hrc's per-object caches start empty."""
    return STNU(net.timepoints, net.requirements, net.contingents, net.name)


def time_check(net: STNU, algorithm: str, repeat: int) -> tuple[str, float, float]:
    """Verdict, median ms of the check on fresh copies (conversion included), and ms to build the explaining
    cycle on first access (not DC)."""
    result = check(fresh(net), algorithm)  # warm-up
    times = []
    gc.disable()
    try:
        for _ in range(max(1, repeat)):
            start = time.perf_counter()
            result = check(fresh(net), algorithm)  # building the network (its validation) timed too
            times.append((time.perf_counter() - start) * 1000)
        start = time.perf_counter()
        _ = result.cycle
        explain = (time.perf_counter() - start) * 1000
    finally:
        gc.enable()
    return result.verdict.value, statistics.median(times), explain


class ToolTimer:
    """The CSTNU Tool's check in one JVM (`scripts/CstnuTimer.java`), asked one file at a time."""

    def __init__(self, check_script: Path, workdir: Path, cpu: int | None) -> None:
        jars = re.search(r'^JARS="([^"]*)"', check_script.read_text(), re.M)
        if jars is None:
            raise RuntimeError(f"no JARS= line in {check_script}")
        names = jars.group(1).replace("\\\n", " ").split()
        jar_files = [str(check_script.parent / "cstnu-tool.jar"), *(f"/usr/share/java/{j}.jar" for j in names)]
        classpath = ":".join(jar_files)
        source = Path(__file__).with_name("CstnuTimer.java")
        subprocess.run(["javac", "-nowarn", "-cp", classpath, "-d", str(workdir), str(source)], check=True,
                       capture_output=True)
        command = ["java", "-Xss64m", "-cp", f"{workdir}:{classpath}", "CstnuTimer"]
        if cpu is not None:
            command = ["taskset", "-c", str(cpu), *command]
        self.proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, bufsize=1)

    def time(self, path: Path, repeat: int) -> tuple[str, float] | None:
        """(DC or NOT_DC, median ms) of the tool's check of `path`; None when it refuses the file."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(f"{path}\t{repeat}\n")
        self.proc.stdin.flush()
        parts = self.proc.stdout.readline().rstrip("\n").split("\t")
        if parts[0] not in ("DC", "NOT_DC"):
            return None
        return parts[0], int(parts[1]) / 1e6

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def bench_network(path: Path) -> STNU:
    """The network both sides check for `path`: the file as hrc reads it, except HEATlab JSON, whose
    decimal bounds hrc reads exactly (ticks of up to 10^18) while the tool's weights are 32-bit integers:
    those are rounded to 0.1 of the file's unit (as ``peers.md`` had it) for both sides alike."""
    if path.suffix != ".json":
        return read_network(path)
    net, scale = read_heatlab_scaled(path.read_text(encoding="utf-8"), str(path))
    if scale <= 10:
        return net

    def r(v: int | None) -> int | None:
        return None if v is None else round(v * 10 / scale)

    reqs = tuple(RequirementLink(x.source, x.target, r(x.lb), r(x.ub)) for x in net.requirements)
    conts = tuple(ContingentLink(c.source, c.target, r(c.lb) or 0, r(c.ub) or 0) for c in net.contingents)
    return STNU(net.timepoints, reqs, conts, net.name)


def tool_file(path: Path, net: STNU, workdir: Path) -> Path | None:
    """The file the tool checks for `net`: the GraphML file itself, or `net` written by hrc as GraphML."""
    if path.suffix == ".graphml":
        return path
    target = workdir / (path.as_posix().replace("/", "__") + ".graphml")
    try:
        target.write_text(write_graphml(net), encoding="utf-8")
    except NetworkError:
        return None  # a contingent link [0, u]: no GraphML the tool reads says it
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per instance; the median is kept")
    parser.add_argument("--summary-only", action="store_true", help="print only the per-size-class summary")
    parser.add_argument("--algorithm", action="append", choices=[*sorted(ALGORITHMS), PURE, "all"],
                        help=f"DC algorithm, repeatable (default {DEFAULT_ALGORITHM}; 'all' for every one; {PURE}: "
                             "rul2021 without its C core)")
    parser.add_argument("--tool", type=Path, default=TOOL, help=f"the CSTNU Tool's cstnu-check (default {TOOL})")
    parser.add_argument("--no-tool", action="store_true", help="time hrc only")
    parser.add_argument("--cpu", type=int, help="pin the process (and the tool's JVM) to this CPU")
    args = parser.parse_args(argv)
    if args.cpu is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    algorithms = args.algorithm or [DEFAULT_ALGORITHM]
    if "all" in algorithms:
        algorithms = [*sorted(ALGORITHMS), PURE]
    expected = expected_verdicts(args.folder)
    files = sorted(p for p in args.folder.rglob("*") if p.is_file() and p.suffix in SUFFIXES)
    if not files:
        print(f"error: no STNU files under {args.folder}", file=sys.stderr)
        return 2
    nets: list[tuple[str, STNU, Path]] = []
    for path in files:
        try:
            nets.append((path.relative_to(args.folder).as_posix(), bench_network(path), path))
        except NetworkFileError as err:
            print(f"skipped: {err}", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        tool = None
        if not args.no_tool:
            try:
                tool = ToolTimer(args.tool, workdir, args.cpu)
            except (OSError, RuntimeError, subprocess.CalledProcessError) as err:
                print(f"no tool side: {err}", file=sys.stderr)
        for_tool = {name: tool_file(path, net, workdir) for name, net, path in nets} if tool else {}
        # warm both sides alike: one untimed pass over every instance
        for name, net, _ in nets:
            for algorithm in algorithms:
                check(fresh(net), algorithm)
            if tool and for_tool[name] is not None:
                tool.time(for_tool[name], 1)  # type: ignore[arg-type]
        rows: list[tuple[str, int, int, int, str, str, float]] = []  # name, n, m, k, algorithm, verdict, ms
        tool_ms: dict[str, float] = {}
        tool_verdict: dict[str, str] = {}
        explains: dict[str, list[float]] = {a: [] for a in algorithms}  # ms to build the cycle, not DC
        for i, (name, net, _) in enumerate(nets):
            def ours(name: str = name, net: STNU = net) -> None:
                for algorithm in algorithms:
                    verdict, ms, explain = time_check(net, algorithm, args.repeat)
                    rows.append((name, len(net.timepoints), net.n_edges, len(net.contingents), algorithm, verdict,
                                 ms))
                    if verdict != "DC":
                        explains[algorithm].append(explain)

            def theirs(name: str = name) -> None:
                hit = tool.time(for_tool[name], args.repeat) if tool and for_tool[name] is not None else None
                if hit is not None:
                    tool_verdict[name], tool_ms[name] = hit

            for side in ((ours, theirs) if i % 2 == 0 else (theirs, ours)):
                side()
        if tool:
            tool.close()
    if not args.summary_only:
        width = max(len(r[0]) for r in rows)
        print(f"| {'instance':<{width}} | nodes | edges | contingent | algorithm  | verdict      |       ms |"
              " tool ms |")
        print(f"|{'-' * (width + 2)}|------:|------:|-----------:|------------|--------------|---------:|--------:|")
        for name, n, m, k, algorithm, verdict, ms in rows:
            other = f"{tool_ms[name]:7.3f}" if name in tool_ms else "      –"
            print(f"| {name:<{width}} | {n:5d} | {m:5d} | {k:10d} | {algorithm:<10} | {verdict:<12} | {ms:8.3f} |"
                  f" {other} |")
        print()
    print("| timepoints | algorithm  | instances | median ms | tool median ms | ratio | median per-instance ratio |")
    print("|------------|------------|----------:|----------:|---------------:|------:|--------------------------:|")
    for label, lo, hi in CLASSES:
        for algorithm in algorithms:
            in_class = [r for r in rows if lo <= r[1] <= hi and r[4] == algorithm]
            if not in_class:
                continue
            both = [r for r in in_class if r[0] in tool_ms]
            mine_all = statistics.median(r[6] for r in in_class)
            if both:
                theirs_ms = statistics.median(tool_ms[r[0]] for r in both)
                mine = statistics.median(r[6] for r in both)
                ratios = [r[6] / tool_ms[r[0]] for r in both if tool_ms[r[0]] > 0]
                per = f"{statistics.median(ratios):.2f}" if ratios else "–"
                print(f"| {label:<10} | {algorithm:<10} | {len(in_class):9d} | {mine_all:9.3f} | {theirs_ms:14.3f} |"
                      f" {mine / theirs_ms:5.2f} | {per:>25} |")
            else:
                print(f"| {label:<10} | {algorithm:<10} | {len(in_class):9d} | {mine_all:9.3f} | {'–':>14} |"
                      f" {'–':>5} | {'–':>25} |")
    for algorithm, spent in explains.items():
        if spent:
            print(f"{algorithm}: the explaining cycle of a not-DC or inconsistent instance, when first read, took "
                  f"a median {statistics.median(spent):.3f} ms more (max {max(spent):.2f} ms, {len(spent)} "
                  "instances; rul2021 builds it on first access)")
    wrong = [(r[0], r[4], r[5], expected[r[0]]) for r in rows
             if r[0] in expected and r[5] not in ACCEPT.get(expected[r[0]], set())]
    disagree = [(r[0], r[4], r[5], tool_verdict[r[0]]) for r in rows
                if r[0] in tool_verdict and (r[5] == "DC") != (tool_verdict[r[0]] == "DC")]
    print()
    print(f"{len(nets)} instances, algorithms {', '.join(algorithms)}; the network built from its links and "
          f"checked, each run (validation and conversion included, file reading not), one warm pass, then per "
          f"instance one untimed and the median "
          f"of {args.repeat} timed runs, interleaved with the tool's; ratio = our median / the tool's median over "
          f"the {len(tool_ms)} instances the tool checked")
    if expected:
        print(f"verdicts: {sum(1 for r in rows if r[0] in expected) - len(wrong)} agree with verdicts.csv, "
              f"{len(wrong)} differ" + "".join(f"\n  {w}" for w in wrong))
    if tool_verdict:
        print(f"the tool's verdicts: {sum(1 for r in rows if r[0] in tool_verdict) - len(disagree)} agree, "
              f"{len(disagree)} differ" + "".join(f"\n  {w}" for w in disagree))
    print(f"machine: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
