"""Compile on demand in simulated runs (issue 35): the dispatcher's fallback and background compile, as
``hrc dispatch`` does them (`hrc.dispatch.on_demand`), on the simulator's clock.

When a run's person leaves every compiled plan (a searched compile, `hrc.compile.search`, holds the
best plans and the person's first choices, not every plan), the dispatcher answers from the fallback and
asks for plans that extend what was seen (`hrc.dispatch.on_demand.wanted`). Here they are compiled at
once, in the run's process (`hrc.compile.extend.extend_plans`, deterministic: a function of the prefix),
and adopted `COMPILE_DELAY` run seconds later, at the first observation from then on (the run is woken
for it: `due`): the compile's wall time does not enter the run, so the same seed gives the same
``simulation.json``. The measured wall time of each compile is kept (`compile_seconds`; excluded from
the answer latencies: it runs beside the dispatcher).

Per run: `misses` (answers that fell back: a plan was followed before), `recovery` (run seconds from each
miss to the first answer from a plan again) and the compiles. The compiles of one prefix are kept per
process (`Compiles`): a prefix met again in another run costs nothing the second time.

A team's run (issue 37, `hrc.sim.team_run`) compiles on demand the same way (`attach`): the prefix is
every agent's actions seen, every robot answers from its own fallback step meanwhile
(`hrc.dispatch.fallback`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
from hrc.compile.extend import EXTEND_FAMILIES, EXTEND_K, Prefix, extend_plans

__all__ = ["COMPILE_DELAY", "Compiles", "OnDemandRun", "attach"]

COMPILE_DELAY = 2.0
"""Run seconds from a miss to the plans compiled for it (a compile on demand of kitting_12picks takes
1-2 s of wall time on a loaded two-core machine: docs/dispatch.md, "Compile on demand")."""


class Compiles:
    """Plans compiled on demand for one compiled set, per prefix (kept per process: deterministic)."""

    def __init__(self, cps: CompiledPlanSet) -> None:
        from hrc.compile.bounds import NodeBounds

        self.cps = cps
        self.bounds = NodeBounds(cps.task, cps.paths, cps.options.rank_by)
        self.found: dict[Prefix, tuple[CompiledPlan, ...]] = {}
        self.seconds: dict[Prefix, float] = {}

    def plans(self, prefix: Prefix) -> tuple[tuple[CompiledPlan, ...], float | None]:
        """The plans for `prefix`, and the wall time of their compile (None: compiled before, kept)."""
        got = self.found.get(prefix)
        if got is not None:
            return got, None
        t0 = time.perf_counter()
        ext = extend_plans(self.cps.task, self.cps.paths, prefix, k=EXTEND_K, families=EXTEND_FAMILIES,
                           options=self.cps.options, bounds=self.bounds)
        self.found[prefix] = ext.plans
        self.seconds[prefix] = time.perf_counter() - t0
        return ext.plans, self.seconds[prefix]


@dataclass
class OnDemandRun:
    """One run's compile on demand: what is pending, and what was measured."""

    compiles: Compiles
    pending: tuple[Prefix, float] | None = None  # the prefix asked for and when its plans come (run s)
    missed_at: float | None = None  # run time of the miss not yet recovered
    misses: int = 0
    recovery: list[float] = field(default_factory=list)
    compile_seconds: list[float] = field(default_factory=list)
    adopted: int = 0  # plans adopted

    def due(self) -> float | None:
        return None if self.pending is None else self.pending[1]

    def to_json(self) -> dict:
        return {"misses": self.misses, "recovery": [round(x, 3) for x in self.recovery],
                "unrecovered": self.missed_at is not None, "plans_adopted": self.adopted}


def attach(cache: dict, kind: str, cps: CompiledPlanSet, dispatcher: Any) -> OnDemandRun:
    """Make `dispatcher` (a run's, over the searched compile `cps` of kind `kind`) compile on demand as
    ``hrc dispatch`` does (`hrc.dispatch.on_demand.enable`); the run's `OnDemandRun`, its compiles kept in
    `cache` (the process's, per kind) for every run."""
    from hrc.dispatch.on_demand import OnDemandSettings, enable

    compiles = cache.get(("compiles", kind))
    if compiles is None:
        compiles = cache[("compiles", kind)] = Compiles(cps)
    enable(dispatcher, OnDemandSettings(seed=cps.seed, human_waits=cps.options.human_waits,
                                        rank_by=cps.options.rank_by))
    return OnDemandRun(compiles)
