"""Run hrc's fuzz targets (``fuzz/targets.py``) with atheris: ``python scripts/fuzz.py --seconds N``.

Each target runs in its own process for N seconds (libFuzzer's ``-max_total_time``), from its seed
corpus ``fuzz/corpus/TARGET/`` (read, never written: what a run finds goes to a temporary folder,
unless ``--grow``), with a time limit per input (``--timeout``, a hang is a crash) and a memory limit.
At the end one line per target: executions, libFuzzer's coverage (``cov``: edges of the instrumented
Python code; ``ft``: features) and crashes, whose inputs are kept in ``--artifacts``; exit status 1 if
any target crashed.

``--sanitize`` builds the four C cores with AddressSanitizer and UndefinedBehaviorSanitizer (gcc, into
a temporary folder), loads that build through ``HRC_NATIVE_LIBRARY`` (`hrc.temporal.rul.native_library`)
and runs the native targets with gcc's ASan runtime preloaded (and libstdc++, which ASan's ``__cxa_throw``
interceptor needs when libFuzzer is in a Python extension). Caveat, measured: gcc's ASan runtime defines
the coverage hooks libFuzzer needs (``__sanitizer_cov_*``), and preloaded it takes them, so under
``--sanitize`` libFuzzer gets no coverage feedback: it mutates the corpus blindly (a random search
from the corpus a coverage-guided run grew). C code is not coverage-instrumented in either mode (gcc
has no ``-fsanitize-coverage=inline-8bit-counters``); the native targets' structure-aware inputs
(random networks, random dispatch histories) are what reaches their branches.

The targets that dispatch need a compiled workshop: made once per run into a temporary folder (about
a minute), or given with ``--compiled DIR``; the team's target a compiled ``tasks/two_workers.yaml``
(``--team DIR``), the crews' a compiled ``tasks/two_workers_joint.yaml`` (``--crew DIR``).

Examples::

    python scripts/fuzz.py --seconds 10                      # every target 10 s (CI: make fuzz-short)
    python scripts/fuzz.py --seconds 600 --targets graphml   # one target longer
    python scripts/fuzz.py --seconds 60 --sanitize           # the C cores under ASan/UBSan
    python scripts/fuzz.py --run graphml fuzz/corpus/graphml -runs=100   # one target, libFuzzer's options
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "fuzz" / "corpus"
SOURCES = ["hrc/temporal/_rulcore.c", "hrc/temporal/_stncore.c", "hrc/compile/_patterncore.c",
           "hrc/dispatch/_dispatchcore.c"]
_STATS = re.compile(r"#(\d+)\s+(?:DONE|pulse|NEW|REDUCE|INITED)\s+(?:cov: (\d+) ft: (\d+))?")


def _child(name: str, argv: list[str]) -> None:
    """Fuzz target `name` in this process; `argv` is libFuzzer's (corpus folders and options)."""
    import atheris

    sys.path[:0] = [str(ROOT), str(ROOT / "fuzz")]
    with atheris.instrument_imports(include=["hrc", "targets"]):
        import targets

        target = targets.TARGETS[name]
        try:  # imports what the target needs (inside the block: instrumented), builds its state
            target(b"")
        except Exception:  # noqa: BLE001, S110 - the empty input is fuzzed again below, where it counts
            pass
    atheris.Setup([sys.argv[0], *argv], target)
    atheris.Fuzz()


def build_sanitized(folder: Path) -> Path:
    """The C cores as one library built with ``-fsanitize=address,undefined`` into `folder`."""
    out = folder / "_rulcore_asan.so"
    cmd = ["gcc", "-shared", "-fPIC", "-O1", "-g", "-fno-omit-frame-pointer", "-fsanitize=address,undefined",
           "-fno-sanitize-recover=undefined", *(str(ROOT / s) for s in SOURCES), "-o", str(out)]
    subprocess.run(cmd, check=True)
    return out


def _runtime(name: str) -> str:
    found = subprocess.run(["gcc", f"-print-file-name={name}"], capture_output=True, text=True, check=True)
    return os.path.realpath(found.stdout.strip())


def self_check(env: dict[str, str]) -> None:
    """The sanitizer build is the one loaded, and reports: the STN core called through ctypes with an
    output array shorter than the network (64 timepoints, room for 2; the core checks its indices, but
    cannot know the caller's buffer) must be a heap-buffer-overflow. Raises SystemExit otherwise."""
    probe = ("import ctypes\n"
             "import numpy as np\n"
             "from hrc.temporal.rul import native_library\n"
             "f = native_library().hrc_stn_distances\n"
             "p = ctypes.c_void_p\n"
             "f.argtypes = [ctypes.c_int, ctypes.c_int, p, p, p, ctypes.c_int, p]\n"
             "src, dst = np.array([0], dtype=np.int32), np.array([1], dtype=np.int32)\n"
             "wt, out = np.array([1], dtype=np.int64), np.empty(2, dtype=np.int64)\n"
             "f(64, 1, src.ctypes.data, dst.ctypes.data, wt.ctypes.data, 0, out.ctypes.data)\n")
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
    if "AddressSanitizer: heap-buffer-overflow" not in done.stderr:
        raise SystemExit(f"the ASan build did not report the planted overflow: {done.stderr[-2000:]}")
    print("sanitizer self-check: the planted overflow was reported (the ASan build is the one loaded)", flush=True)


def compile_task(folder: Path, task: str = "cube_stacking.yaml") -> Path:
    """The bundled `task` compiled into `folder` (the workshop for the protocol targets, a team's task for
    the team's)."""
    out = folder / Path(task).stem
    subprocess.run([sys.executable, "-m", "hrc", "compile", str(ROOT / "tasks" / task), "--out",
                    str(out), "--no-report", "-q", "--jobs", "1"], check=True, cwd=folder,
                   env=dict(os.environ, PYTHONPATH=str(ROOT)))
    return out


def run_target(name: str, seconds: int, work: Path, env: dict[str, str], timeout: int, artifacts: Path,
               grow: bool) -> dict[str, object]:
    """One target for `seconds`; its figures from libFuzzer's last status line."""
    new = CORPUS / name if grow else work / "new" / name
    new.mkdir(parents=True, exist_ok=True)
    seeds = [] if grow else [str(CORPUS / name)]
    artifacts.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(Path(__file__).resolve()), "--run", name, str(new), *seeds,
           f"-max_total_time={seconds}", f"-timeout={timeout}", "-rss_limit_mb=3072", "-print_final_stats=1",
           f"-artifact_prefix={artifacts}/{name}-", "-max_len=32768"]
    t0 = time.monotonic()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=work)
    log = done.stdout + done.stderr
    (work / f"{name}.log").write_text(log)
    execs = cov = ft = 0
    for m in _STATS.finditer(log):
        execs = max(execs, int(m.group(1)))
        if m.group(2):
            cov, ft = max(cov, int(m.group(2))), max(ft, int(m.group(3)))
    total = re.search(r"stat::number_of_executed_units:\s*(\d+)", log)
    if total:
        execs = int(total.group(1))
    crashed = done.returncode != 0
    return {"target": name, "execs": execs, "cov": cov, "ft": ft, "seconds": round(time.monotonic() - t0, 1),
            "crash": crashed, "log": str(work / f"{name}.log")}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--run"]:
        _child(argv[1], argv[2:])
        return 0
    sys.path[:0] = [str(ROOT), str(ROOT / "fuzz")]
    import targets

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=int, default=10, help="per target (default 10)")
    p.add_argument("--targets", default=",".join(targets.TARGETS), help="comma-separated (default: all)")
    p.add_argument("--sanitize", action="store_true", help="only the native targets, on the ASan/UBSan build")
    p.add_argument("--compiled", help="a compiled workshop folder to dispatch on (default: compile one)")
    p.add_argument("--team", help="a compiled two_workers folder for the team's target (default: compile one)")
    p.add_argument("--crew", help="a compiled two_workers_joint folder for the crews' target (default: compile one)")
    p.add_argument("--timeout", type=int, default=10, help="seconds per input before it counts as a hang")
    p.add_argument("--artifacts", default=str(ROOT / "fuzz" / "crashes"), help="where crashing inputs go")
    p.add_argument("--grow", action="store_true", help="add what the run finds to fuzz/corpus/ (a long run)")
    args = p.parse_args(argv)
    names = [n for n in args.targets.split(",") if n]
    unknown = [n for n in names if n not in targets.TARGETS]
    if unknown:
        p.error(f"unknown targets {unknown}; known: {', '.join(targets.TARGETS)}")
    if args.sanitize:
        names = [n for n in names if n in targets.NATIVE]
    work = Path(tempfile.mkdtemp(prefix="hrc-fuzz-run-"))
    env = dict(os.environ, PYTHONPATH=str(ROOT), HRC_FUZZ_SCRATCH=str(work))
    try:
        if any(n in targets.COMPILED for n in names):
            env[targets.COMPILED_VARIABLE] = args.compiled or str(compile_task(work))
        if any(n in targets.TEAM for n in names):
            env[targets.TEAM_VARIABLE] = args.team or str(compile_task(work, "two_workers.yaml"))
        if any(n in targets.CREW for n in names):
            env[targets.CREW_VARIABLE] = args.crew or str(compile_task(work, "two_workers_joint.yaml"))
        if args.sanitize:
            env["HRC_NATIVE_LIBRARY"] = str(build_sanitized(work))
            env["LD_PRELOAD"] = f"{_runtime('libasan.so')}:{_runtime('libstdc++.so')}"
            env["ASAN_OPTIONS"] = "detect_leaks=0:abort_on_error=1:symbolize=1"
            env["UBSAN_OPTIONS"] = "halt_on_error=1:print_stacktrace=1"
            self_check(env)
        results = []
        for name in names:
            r = run_target(name, args.seconds, work, env, args.timeout, Path(args.artifacts), args.grow)
            results.append(r)
            print(f"{name:16} {r['execs']:>9,} execs  cov {r['cov']:>5}  ft {r['ft']:>6}  {r['seconds']:>6} s  "
                  f"{'CRASH: see ' + str(r['log']) if r['crash'] else 'clean'}", flush=True)
            if r["crash"]:
                shutil.copy(str(r["log"]), Path(args.artifacts) / f"{name}.log")
        crashed = [r["target"] for r in results if r["crash"]]
        total = sum(int(r["execs"]) for r in results)  # type: ignore[call-overload]
        print(f"{len(results)} targets, {total:,} executions{' (ASan/UBSan build)' * args.sanitize}; "
              + (f"crashed: {', '.join(map(str, crashed))} (inputs in {args.artifacts})" if crashed else "no crash"))
        return 1 if crashed else 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
