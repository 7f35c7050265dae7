"""The `motion-blind` compile: what a scheduler that ignores motion would hand the dispatcher.

Systems such as Chaski (Shah et al.) schedule a human-robot team without modelling how the co-workers
move: a travel takes "the distance over the speed" and the two never get in each other's way. To test
the hypothesis of Strassmair & Taylor 2014 (section VI: taking the co-workers' motion into account
makes the team more efficient), the simulator gives the same dispatcher a compile made that way:

- a `PathLibrary` of straight lines between locations (through shelves and tables, as the distance
  is measured), durations ``length / speed``;
- per plan, no conflicts and so no passing orders, no detours, no waiting places: its STNU is the
  temporal net creator's (`hrc.compile.temporal_net_creator.create_stnu`) on those motions alone, and
  it is classified and ranked as the real compile does (`classify`, `rank_key`).

The agents still walk and drive the real routes on the floor; only the plans and their timing are
blind. Built from the compiler's public functions, without changing the compiler. Cost: one STNU, one
DC check and one preference QP per plan (no motion planning), in the given executor.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import replace

from hrc.compile.classify import classify
from hrc.compile.compiler import CompiledPlan, CompiledPlanSet, CompileOptions, rank_key
from hrc.compile.dispatch_form import plan_record
from hrc.compile.executors import make_executor
from hrc.compile.motion_pattern import MotionPattern
from hrc.compile.preferences import plan_preference
from hrc.compile.temporal_net_creator import create_stnu
from hrc.io.task_file import task_digest
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_motions
from hrc.motion.paths import Path, agent_pairs
from hrc.plans import count_plans, generate_plans
from hrc.temporal.graphml import write_graphml

__all__ = ["blind_compile", "blind_plan", "straight_paths"]


def straight_paths(task: Task, seed: int = 0) -> PathLibrary:
    """Straight segments for every travel an agent may make; duration = distance / speed."""
    locs = {loc.id: loc.xy for loc in task.workspace.locations}
    paths: dict[tuple[str, str, str], Path] = {}
    for agent in task.agents:
        for o, t in agent_pairs(task, agent.id):
            length = math.dist(locs[o], locs[t])
            paths[(agent.id, o, t)] = Path(agent.id, o, t, (locs[o], locs[t]), length, length / agent.speed)
    return PathLibrary(seed=seed, paths=paths, locations=locs, stats={"planned": len(paths)})


def blind_plan(task: Task, plan: Plan, paths: PathLibrary) -> CompiledPlan:
    """One plan on straight-line motions with no interference: STNU, class, preference (rank 0)."""
    motions = plan_motions(task, plan, paths)
    net = create_stnu(task, plan, motions, ())
    stnu = net.stnu
    size = (len(stnu.timepoints), len(stnu.requirements), len(stnu.contingents))
    return CompiledPlan(plan=plan, pattern=MotionPattern(motions, (), 1, True), classification=classify(task, net),
                        stnu_size=size, graphml=write_graphml(stnu), preference=plan_preference(task, plan, net),
                        form=plan_record(task, plan, stnu, blocked=False))


def _blind_chunk(task: Task, paths: PathLibrary, plans: list[Plan]) -> list[CompiledPlan]:
    return [blind_plan(task, plan, paths) for plan in plans]


def blind_compile(task: Task, seed: int = 0, jobs: int | None = None, executor: str | None = None,
                  progress: Callable[[str, int, int], None] | None = None) -> CompiledPlanSet:
    """Every plan of `task`, compiled motion-blind and ranked as `hrc.compile.compiler.compile_task` ranks
    (`progress` told ``("blind", done, total)`` as plans come)."""
    paths = straight_paths(task, seed)
    out: list[CompiledPlan] = []
    it = iter(generate_plans(task))
    chunks = iter(lambda: list(itertools.islice(it, 64)), [])
    total = count_plans(task) if progress else 0
    with make_executor(executor, jobs) as ex:
        for batch in ex.map_chunks(_blind_chunk, task, paths, chunks):
            out.extend(batch)
            if progress:
                progress("blind", len(out), total)
    out.sort(key=rank_key)
    ranked = tuple(replace(cp, rank=i + 1) for i, cp in enumerate(out))
    return CompiledPlanSet(task=task, seed=seed, digest=task_digest(task), paths=paths, plans=ranked,
                           options=CompileOptions())
