"""The simulator's compiles of a small task, kept on disk between runs of ``hrc simulate`` (issue 38).

`hrc.sim.montecarlo.simulate` compiles the task before its runs: motion-aware (`compile_task`) and, for the
motion-blind policy, motion-blind (`hrc.sim.blind.blind_compile`). On the workshop that is 2-3 s of wall
time before the first run, every time, though nothing it reads has changed. `kept_compile` keeps the
ranked plans in the disk cache of whole compiles (`hrc.caches.cache_folder` ``results``, the folder
``hrc compile`` keeps its plans in: `hrc.compile.stream.RESULTS_MAX_PLANS`), keyed by everything they are
computed from: the task and its map as loaded (`task_digest`), the motion planner's seed, the kind of
compile and all of the code and libraries (`hrc.caches.code_digest`: any change is a miss). A hit gives
the same plans (unpickled: equal, field by field, to those just compiled), beside the paths they were
compiled on (`plan_paths`, itself cached on disk; `straight_paths` for the blind compile), so the runs and
``simulation.json`` are the same bytes (tests/test_sim_compile_cache.py).

Only a compile of at most `RESULTS_MAX_PLANS` plans on this machine (no `executor` address: a Dask
cluster's machine may be another) is kept, as ``hrc compile`` keeps its own; ``HRC_CACHE_DIR=`` (empty)
turns it off.
"""

from __future__ import annotations

from collections.abc import Callable

from hrc.compile.compiler import CompiledPlanSet
from hrc.model import Task

__all__ = ["kept_compile"]

Progress = Callable[[str, int, int], None]


def kept_compile(kind: str, task: Task, seed: int, executor: str | None, make: Callable[[], CompiledPlanSet],
                 progress: Progress | None = None) -> CompiledPlanSet:
    """`make()` (the compile of `kind`, ``"motion"`` or ``"blind"``, of `task` with `seed`), or its plans
    from the disk cache when the same was compiled before with the same code (module docstring); `progress`
    is told ``(stage, n, n)`` on a hit (`stage`: ``plans`` or ``blind``, as the compiles tell it)."""
    from hrc.caches import cache_folder, code_digest, disk_load, disk_store
    from hrc.compile.stream import RESULTS_MAX_PLANS
    from hrc.io.task_file import task_digest
    from hrc.plans import count_plans

    folder = cache_folder("results") if executor is None and count_plans(task) <= RESULTS_MAX_PLANS else None
    if folder is None:
        return make()
    digest = task_digest(task)
    key = repr(("sim-compile-1", kind, code_digest(), digest, seed))
    found = disk_load(folder, key)
    if isinstance(found, tuple) and found and found[0] == digest:
        _, plans, options = found
        if kind == "blind":
            from hrc.sim.blind import straight_paths

            paths = straight_paths(task, seed)
        else:
            from hrc.motion.paths import plan_paths

            paths = plan_paths(task, seed=seed)
        if progress:
            progress("blind" if kind == "blind" else "plans", len(plans), len(plans))
        return CompiledPlanSet(task=task, seed=seed, digest=digest, paths=paths, plans=plans, options=options)
    made = make()
    if made.summary is None and not made.search and made.stnu_files == "graphml":  # what a hit rebuilds
        disk_store(folder, key, (digest, made.plans, made.options))
    return made
