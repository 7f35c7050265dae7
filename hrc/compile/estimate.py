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
"""

from __future__ import annotations

from dataclasses import dataclass

from hrc.model import Task
from hrc.plans import PlanCount, estimate_plan_count

__all__ = ["DEFAULT_MAX_PLANS", "FIXED_SECONDS", "GRAPHML_BYTES", "JSON_BYTES", "SECONDS_PER_PLAN", "ZIP_RATIO",
           "Estimate", "estimate", "fmt_bytes", "fmt_seconds", "fmt_span"]

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
