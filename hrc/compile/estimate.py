"""What a compile will cost, said before it starts (issue 12): plans, disk, time.

The plan count comes from `hrc.plans.estimate_plan_count` (exact, or an upper bound when counting would
be slow). Disk and time are estimates from the size of one plan's network, calibrated on the bundled
kitting and workshop tasks (`docs/benchmarks.md`); `hrc compile` replaces the time range by the time
it measures on its first plans.

Per plan, with ``L`` legs (one per phase of every action) and ``T = 1 + 4 L`` timepoints:

- its ``compiled.json`` line: about ``JSON_BYTES * L`` bytes (measured: 17 kB for the 14 legs of
  kitting_7picks, 9.3 kB for the workshop's 10; most of it is the plan's passing orders, about 90 per
  kitting plan);
- its GraphML file: about ``GRAPHML_BYTES * T`` bytes (430-520 measured), rounded up to a file
  system block (``--stnu graphml``); deflated in ``stnu.zip`` about `ZIP_RATIO` of that (``--stnu archive``);
- its CPU time: `SECONDS_PER_PLAN`, the range of the mean time per plan and core on the bundled tasks (the
  motion-pattern search dominates; it depends on how often the two agents' routes meet, so single plans
  range from a few milliseconds to over a second). Measured on one core: 2.5-3 ms for kitting_7picks
  (its whole run's CPU time per plan, parent included, 2026-11-25), 31 ms for kitting, about 60 ms for
  the workshop.

`hrc compile` then says what it measured on a sample of plans from allocations spread over the task
(`hrc.plans.spread_families`, `hrc.compile.stream.Sample`): time and disk per plan.

**The calibrated estimate** (`calibrate`, `Calibration.wall`; what ``hrc show TASK`` says): the range
above spans 60 times (52 s - 51 min for kitting_7picks' 45 s) because a plan's CPU time ranges over two
orders of magnitude from task to task. So `calibrate` compiles a sample for real on this machine: the
task's paths (with the roadmap cache, as the compile will), then up to `CALIBRATION_FAMILIES` families
spread over the allocations, twice (the second time with this process's caches filled, as in a long
run's workers), measuring CPU time (not wall: another job on the machine slows the wall clock, not the
work). The compile's wall time is then modelled as

    start-up + the compile's own sample
    + (plans x pace x `PACE_FACTOR` + min(plans, workers x `WARMUP_PLANS`) x (first pace - pace)
       + `FILE_SECONDS` per GraphML file) / (1 + `PARALLEL` x (workers - 1))
    + writing the lines (and the archive) at `WRITE_RATE` + report

with the constants fitted on the bundled tasks (workshop, kitting, kitting_7picks, 2026-11-29, after issue
38's passes made the start-up, the report and the end of a large compile shorter; docs/benchmarks.md,
tests/test_estimate_model.py): within +-50 % of the compile's work and of its wall
time at the load the sample saw (`Calibration.wall` with ``now``). The result is kept in the cache
folder (`hrc.caches`, ``calibration``) by task digest, seed, machine and source, so asking again is
instant (its load figure is then the first sample's).
"""

from __future__ import annotations

import math
import os
import platform
import time
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.compile.defaults import SAMPLE_MIN_PLANS
from hrc.model import Task
from hrc.plans import PlanCount, estimate_plan_count

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan

__all__ = ["CALIBRATION_FAMILIES", "CALIBRATION_MAX_PLANS", "DEFAULT_MAX_PLANS", "FIXED_SECONDS", "GRAPHML_BYTES",
           "JSON_BYTES", "SECONDS_PER_PLAN", "ZIP_RATIO", "Calibration", "Estimate", "calibrate", "estimate",
           "fmt_bytes", "fmt_seconds", "fmt_span", "kept_calibration"]

DEFAULT_MAX_PLANS = 50_000
"""``hrc compile --max-plans`` default: the 40,320 plans of 7 independent picks pass, 8 picks
(362,880) are refused up front."""

JSON_BYTES = 1100
GRAPHML_BYTES = 480
BLOCK = 4096
ZIP_RATIO = 0.1
SECONDS_PER_PLAN = (0.0025, 0.15)
FIXED_SECONDS = (2.0, 25.0)
"""Wall seconds a compile takes whatever its plans: start-up, motion planning (the path library, cached
after the first run) and the report. The workshop's whole compile took 2.4 s without its report and 3.8 s
with it on an idle 2-core machine (2026-11-26), 8-22 s while other jobs loaded it: its 32 plans are a
second of that, so an estimate without this part said "up to 2 s" for a compile of 8-22 s."""


@dataclass(frozen=True, slots=True)
class Estimate:
    """Plans (exact or a bound), bytes on disk per ``--stnu`` mode, CPU seconds (low, high)."""

    plans: PlanCount
    json_bytes: int
    stnu_bytes: dict[str, int]
    cpu_seconds: tuple[float, float]

    def disk(self, stnu: str) -> int:
        return self.json_bytes + self.stnu_bytes[stnu]

    def wall(self, workers: int, per_plan: float | None = None) -> tuple[float, float]:
        """Wall seconds on `workers` cores: with `per_plan` (seconds measured per plan) the plans' part
    alone, else the estimate of the whole run (`FIXED_SECONDS` included)."""
        if per_plan is not None:
            t = self.plans.value * per_plan / max(workers, 1)
            return t, t
        lo, hi = self.cpu_seconds
        return FIXED_SECONDS[0] + lo / max(workers, 1), FIXED_SECONDS[1] + hi / max(workers, 1)


def estimate(task: Task, symmetry: bool = False) -> Estimate:
    """The up-front estimate for `task` (see the module docstring); bounded time and memory."""
    count = estimate_plan_count(task, symmetry=symmetry)
    legs = sum(len(a.phases) for a in task.actions)
    n = count.value
    line = JSON_BYTES * legs
    graphml = GRAPHML_BYTES * (1 + 4 * legs)
    blocks = -(-graphml // BLOCK) * BLOCK
    return Estimate(plans=count, json_bytes=n * line,
                    stnu_bytes={"graphml": n * blocks, "archive": int(n * graphml * ZIP_RATIO), "none": 0},
                    cpu_seconds=(n * SECONDS_PER_PLAN[0], n * SECONDS_PER_PLAN[1]))


CALIBRATION_FAMILIES = 16
"""Families `calibrate` compiles at most (spread over the allocations), within `CALIBRATION_SECONDS`."""
CALIBRATION_SECONDS = 1.0
CALIBRATION_MAX_PLANS = 1_000_000
"""``hrc show`` samples a task of at most this many plans (kitting_8picks' 362,880 in 2 s; kitting_12picks'
6.2 billion: finding spread families alone took minutes)."""
AGAIN = 5
"""Times `calibrate` compiles its sample again with the caches filled, keeping the least CPU time: a core
shared with other work (its caches, its hyperthread twin) stretched one such pass up to twice (kitting's
8-16 ms a plan within ten minutes at load 1-2, 2026-11-29); the least of five is steadier. Each costs
about a fifth of the first pass."""
MAX_FAMILY = 64
"""Plans of a family `calibrate` compiles at most (kitting_7picks' are 4)."""

START_SECONDS = 0.6
"""Wall seconds before a compile's first plan: interpreter, imports, reading the task, the plan count
(`hrc compile -v` on the workshop, 2026-11-29: 0.45 s to the first clock, 0.15 s the compiler's imports)."""
SAMPLE_SECONDS = 1.0
"""The compile's own up-front sample (`hrc.compile.stream`, ``sample_seconds``), in its parent process (none
below `hrc.compile.defaults.SAMPLE_MIN_PLANS` plans)."""
PACE_FACTOR = 1.1
"""A long run's CPU per plan over `calibrate`'s second pace (fitted: docs/benchmarks.md; 1.2 before the sample kept
the least of `AGAIN` passes)."""
PARALLEL = 0.85
"""What each further worker adds (kitting_7picks: 1.71 on 2 workers)."""
WARMUP_PLANS = 64
"""Each worker pays the first pace instead of the second for about this many plans (its detours,
conflict geometry and text layouts made once: the workshop's 32 plans all pay it)."""
WRITE_RATE = 400e6
"""Bytes a second the parent writes at the end (the lines copied in rank order, the archive deflated)."""
FILE_SECONDS = 0.1e-3
"""CPU seconds per GraphML file a worker writes (``--stnu graphml``: the file system's create and write,
system time): 0.06 ms a file on a quiet machine (kitting_7picks, 2026-11-29: 27.2 s with its 40,320
files, 26.1 s with ``--stnu archive``), up to 0.7 ms on a loaded one (kitting_6picks, 2026-11-27)."""
REPORT_SECONDS = 0.7
"""The report: 16 figures and the tables (`hrc compile -v`, 2026-11-29: 0.65 s wall on the workshop, 0.76 s
on kitting, 0.51 s on kitting_7picks, figures drawn in two processes; 2.1 s of CPU before issue 38's passes)."""
LOADED = 1.1
"""A sample whose wall time is at most this many times its CPU time ran on an idle core: no load is read
into it (a ratio of 1.0003 would otherwise read as ``cores - 1`` other runnable processes)."""


@dataclass(frozen=True, slots=True)
class Calibration:
    """What `calibrate` measured for a task on this machine: the plans compiled, CPU seconds per plan
    the first time and the second, the paths' wall seconds, bytes per plan of its line and GraphML."""

    plans: int
    families: int
    first_pace: float
    pace: float
    paths_seconds: float
    line_bytes: float
    graphml_bytes: float
    wall_ratio: float = 1.0
    """Wall over CPU seconds of the sample: 1 on an idle machine, 3 when two other jobs share each core."""
    cores: int = 2
    """The machine's cores when the sample ran."""

    def wall(self, total: int, workers: int, stnu: str = "graphml", report: bool = True, now: bool = False) -> float:
        """Wall seconds of ``hrc compile`` on `total` plans with `workers` worker processes on an idle
        machine (the module docstring's model); `now`: at the load the sample saw, read as L other
        runnable processes (the sample got ``cores / (L + 1)`` of a core: `wall_ratio`), which leave the
        serial parts `wall_ratio` times slower and the workers ``(L + workers) / cores`` times (a rough
        guide: the load moves from minute to minute)."""
        workers = max(1, workers)
        warm = min(total, workers * WARMUP_PLANS) * max(self.first_pace - self.pace, 0.0)
        files = total * FILE_SECONDS if stnu == "graphml" else 0.0  # written by the workers
        plans = (total * self.pace * PACE_FACTOR + warm + files) / (1 + PARALLEL * (workers - 1))
        serial, parallel = 1.0, 1.0
        if now:
            others = max(0.0, self.wall_ratio * self.cores - 1) if self.wall_ratio > LOADED else 0.0
            serial = self.wall_ratio
            parallel = max(1.0, (others + workers) / self.cores) * min(workers, self.cores) / workers
        plans *= parallel
        lines = total * self.line_bytes
        if stnu == "archive":
            write = (lines + total * self.graphml_bytes) / WRITE_RATE
        else:
            write = lines / WRITE_RATE
        sample = min(SAMPLE_SECONDS, total * self.first_pace) if total >= SAMPLE_MIN_PLANS else 0.0
        # no paths: `calibrate` left the roadmaps in the cache folder, where the compile finds them
        return plans + serial * (START_SECONDS + sample + write
                                 + (REPORT_SECONDS if report else 0.0))


def _calibration_key(task: Task, seed: int) -> str:
    from hrc.caches import source_digest
    from hrc.io.task_file import task_digest

    return ":".join(("calibration-5", task_digest(task), str(seed), platform.node(), str(os.cpu_count()),
                     source_digest("hrc.compile.estimate", "hrc.compile.compiler", "hrc.compile.motion_pattern",
                                   "hrc.compile.stream", "hrc.compile.output", "hrc.compile.classify")))


def kept_calibration(task: Task, seed: int = 0) -> Calibration | None:
    """The calibration `calibrate` kept for `task` on this machine (``hrc show TASK`` ran with this code),
    or None: looked up, never measured (``hrc compile`` says its estimate from it, up front)."""
    from hrc.caches import cache_folder, disk_load

    found = disk_load(cache_folder("calibration"), _calibration_key(task, seed))
    return found if isinstance(found, Calibration) else None


def calibrate(task: Task, seed: int = 0, families: int = CALIBRATION_FAMILIES,
              seconds: float = CALIBRATION_SECONDS, cache: bool = True) -> Calibration:
    """Compile a spread sample of `task`'s plans here, twice, and say what it cost (`Calibration`; the
    module docstring). Kept in the cache folder by task digest, seed, machine and the compiler's source
    (`cache`). Cost: the paths (from the roadmap cache after the first time) and about `seconds` twice."""
    from hrc.caches import cache_folder, disk_load, disk_store
    from hrc.compile.compiler import CompileOptions
    from hrc.compile.stream import sample_twice
    from hrc.errors import HrcError
    from hrc.motion import plan_paths
    from hrc.plans import spread_families

    key = _calibration_key(task, seed)
    folder = cache_folder("calibration") if cache else None
    found = disk_load(folder, key)
    if isinstance(found, Calibration):
        return found
    t0 = time.perf_counter()
    paths = plan_paths(task, seed=seed)
    paths_seconds = time.perf_counter() - t0
    options = CompileOptions()
    # a family is compiled whole (one motion search, its relabelled twins after it): one of thousands of
    # twins (16 picks in 5 groups of identical ones) would take minutes, so only small families are sampled
    spread = [f for f in spread_families(task, families) if len(f) <= MAX_FAMILY]
    if not spread:
        raise HrcError(f"every sampled family has more than {MAX_FAMILY} plans (identical actions)")
    line = graphml = 0

    def each(cp: CompiledPlan, tail: str) -> None:
        nonlocal line, graphml
        line += len(tail.encode()) + 24
        graphml += len(zlib.compress(cp.graphml.encode(), 1))

    w0 = time.perf_counter()
    done, n, first, second = sample_twice(options, "graphml", task, paths, spread, seconds, math.inf, each,
                                          clock=time.process_time, again=AGAIN)
    w2 = time.perf_counter()
    out = Calibration(plans=n, families=done, first_pace=first / max(n, 1), pace=second / max(n, 1),
                      paths_seconds=paths_seconds, line_bytes=line / max(n, 1), graphml_bytes=graphml / max(n, 1),
                      wall_ratio=max(1.0, (w2 - w0) / max(first + second, 1e-9)), cores=os.cpu_count() or 1)
    disk_store(folder, key, out)
    return out


def fmt_bytes(n: float) -> str:
    """``812 kB``, ``1.3 GB`` (decimal units, two significant figures at most)."""
    if n >= 1e15:
        return f"{n / 1e12:.2g} TB"
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.2g} {unit}" if n / size < 10 else f"{n / size:,.0f} {unit}"
    return f"{int(n)} B"


def fmt_seconds(s: float) -> str:
    """``45 s``, ``12 min``, ``3.5 h``, ``2.1 days``, ``3.4e+06 years``."""
    if s < 90:
        return f"{s:.0f} s"
    if s < 90 * 60:
        return f"{s / 60:.0f} min"
    if s < 48 * 3600:
        return f"{s / 3600:.1f} h"
    if s < 365 * 86400:
        return f"{s / 86400:.1f} days"
    return f"{s / (365.25 * 86400):.2g} years"


def fmt_span(lo: float, hi: float, sep: str = "-", about: bool = False) -> str:
    """A range of seconds as `fmt_seconds` writes them, ``21 s-3 min``; once when both ends read the same
    (``12 s``); ``under 1 s`` for a range that would read ``0 s-0 s`` and ``up to 2 s`` for one that would
    start at ``0 s`` (the workshop's 32 plans). `about`: ``about 21 s-3 min``, where the words allow."""
    if hi < 0.5:
        return "under 1 s"
    a, b = fmt_seconds(lo), fmt_seconds(hi)
    if lo < 0.5:
        return f"up to {b}"
    return ("about " if about else "") + (a if a == b else f"{a}{sep}{b}")
