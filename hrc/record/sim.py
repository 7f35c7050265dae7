"""Simulated runs recorded as MCAP (``hrc simulate --record DIR``): what the floor did, what the controller
was told and what it answered.

`record_run` runs `hrc.sim.run.simulate_run` again for one policy and run index (the same seeded person,
so the same run as in ``simulation.json``) with the floor's positions kept, and the controller's every
observation and answer caught as they happen: for the dispatcher's policies each observation is the
protocol's message (`hrc.dispatch.Observation.to_json`) and its answer the decision (or the refusal) the
dispatcher gave; for ``fixed`` (no dispatcher) the answer is the robot's order from the fixed plan. The
agents' positions are the floor's (`hrc.record.FRAME_PERIOD` apart). The recording is built in memory
and returned as bytes, so that any executor (a local pool, Dask) can make it; `record_runs` makes many
in parallel, in a fixed order: the same seed gives the same files, byte for byte.

A team's run (issue 37) is `hrc.sim.team_run.simulate_team_run`'s, its controllers caught the same way
(`hrc.sim.runlog.catching` over `make_team_controller`) and every agent's position from its frames: the
recording is ``hrc dispatch --record``'s team form (a pose channel per agent, a goal channel per robot,
each robot's step in ``/hrc/decision``: `hrc.record.recorder`).
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Sequence
from typing import Any

from hrc.compile.output import plan_dict
from hrc.dispatch.routes import PlanRoutes
from hrc.record.recorder import RunRecorder
from hrc.sim.policies import POLICIES, Policy
from hrc.sim.run import RunResult, SimContext, simulate_run
from hrc.sim.runlog import catching
from hrc.sim.team_floor import is_team

__all__ = ["check_record_folder", "file_name", "record_run", "record_runs", "write_recordings"]


def file_name(policy: str, index: int) -> str:
    """``POLICY-NNNN.mcap``: run `index` of `policy` (sorted as the runs are)."""
    return f"{policy}-{index:04d}.mcap"


def _routes(ctx: SimContext, policy: Policy) -> PlanRoutes:
    """A plan's routes as the console draws them, from the compile in memory (the motions as
    ``compiled.json`` writes them, the floor's paths)."""
    cps = ctx.compiles[policy.compile]
    by_id = {cp.plan.id: cp for cp in cps.plans}

    def motions(plan_id: str) -> list[dict[str, Any]] | None:
        cp = by_id.get(plan_id)
        return None if cp is None else list(plan_dict(cps.task, cp, None)["motions"])

    return PlanRoutes(motions, ctx.paths)


def record_run(ctx: SimContext, policy: str, index: int) -> tuple[bytes, RunResult]:
    """Run `index` of `policy` again, recorded: the MCAP file's bytes and the run's result."""
    exchanges: list[tuple[float, bytes, str]] = []
    team = is_team(ctx.task)
    if team:  # issue 37: the team's loop, every agent's frames
        from hrc.sim.team_policies import make_team_controller
        from hrc.sim.team_run import simulate_team_run

        result = simulate_team_run(ctx, policy, index, record=True,
                                   controller=catching(exchanges, make_team_controller))
    else:
        result = simulate_run(ctx, policy, index, record=True, controller=catching(exchanges))
    human = next(a.id for a in ctx.task.agents if a.is_human)
    robot = next(a.id for a in ctx.task.agents if not a.is_human)
    ids = [a.id for a in ctx.task.agents]
    frames_of: Sequence[Any] = result.agent_frames if team else result.frames
    # frames (positions after the floor advanced to t) before the exchanges at t: events happen there
    timeline: list[tuple[float, int, Any]] = [(f[0], 0, f) for f in frames_of]
    timeline += [(t, 1, (data, answer)) for t, data, answer in exchanges]
    timeline.sort(key=lambda item: (item[0], item[1]))
    sink = io.BytesIO()
    from hrc.io.task_file import task_digest

    meta = {"policy": policy, "run": str(index), "seed": str(ctx.seed), "finished": str(result.finished).lower(),
            "makespan": "" if result.makespan is None else f"{result.makespan:.3f}",
            "task_digest": task_digest(ctx.task)}  # what `hrc learn` checks a recording against
    planned = _routes(ctx, POLICIES[policy])
    rec = RunRecorder(sink, ctx.task, planned.routes, measured=True, metadata=meta, ways=planned.way)
    frames = len(frames_of)
    seen = 0
    for t, kind, item in timeline:
        if kind == 0:
            seen += 1
            if team:
                where = item[1]
                rec.positions(t, {a: (x, y) for a, (x, y, _) in zip(ids, where, strict=True)},
                              {a: bool(here) for a, (_, _, here) in zip(ids, where, strict=True)}, last=seen == frames)
                continue
            _, hx, hy, rx, ry, present = item
            rec.positions(t, {human: (hx, hy), robot: (rx, ry)}, {human: bool(present), robot: True},
                          last=seen == frames)
        else:
            rec.exchange(*item)
    rec.finish()
    return sink.getvalue(), result


def _chunk(ctx: SimContext, _: object, work: Sequence[tuple[str, int]]) -> list[tuple[str, int, bytes]]:
    """The unit of work sent to an executor (module-level, so that it pickles)."""
    return [(policy, i, record_run(ctx, policy, i)[0]) for policy, i in work]


def record_runs(ctx: SimContext, policies: Sequence[str], runs: int, jobs: int | None = None,
                executor: str | None = None) -> Iterator[tuple[str, int, bytes]]:
    """Record runs ``0 .. runs-1`` of every policy: ``(policy, index, MCAP bytes)`` in completion order
    (each file's bytes depend only on the context, the policy and the index)."""
    from hrc.compile.executors import make_executor

    work = [[(p, i) for i in range(start, min(runs, start + 5))] for p in policies for start in range(0, runs, 5)]
    with make_executor(executor, jobs) as ex:
        for batch in ex.map_chunks(_chunk, ctx, None, work):
            yield from batch



def check_record_folder(folder: str, out: str) -> None:
    """``--record DIR`` is replaced whole: it must be new, empty or an earlier recording (``*.mcap`` files
    only), and neither inside ``--out`` nor holding it. Raises `InputError` saying which."""
    from pathlib import Path

    from hrc.errors import InputError

    path, out_path = Path(folder).resolve(), Path(out).resolve()
    if path == out_path or out_path in path.parents or path in out_path.parents:
        raise InputError(folder, "--record", f"--record and --out {out} must not hold one another (each is "
                                             "replaced whole)")
    if path.exists() and not path.is_dir():
        raise InputError(folder, "--record", "exists and is not a folder")
    if path.is_dir() and any(p.suffix != ".mcap" or not p.is_file() for p in path.iterdir()):
        raise InputError(folder, "--record", "refusing to replace a folder that holds anything but .mcap files "
                                             "(not an earlier hrc simulate --record output)")


def write_recordings(ctx: SimContext, policies: Sequence[str], runs: int, folder: str, jobs: int | None = None,
                     executor: str | None = None) -> int:
    """Record runs ``0 .. runs-1`` of each policy into `folder` (`file_name` each), replacing it whole and
    atomically (`hrc.io.atomic.atomic_dir`); the bytes written."""
    from hrc.io.atomic import atomic_dir

    total = 0
    with atomic_dir(folder) as stage:
        for policy, index, data in record_runs(ctx, policies, runs, jobs, executor):
            (stage / file_name(policy, index)).write_bytes(data)
            total += len(data)
    return total
