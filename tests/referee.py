"""An independent referee for the spatial side of the classes: space-time search and replayed runs.

Nothing here uses the compiler's conflict model (`hrc.motion.conflicts`) or its passing orders; it works
from the task, the plan and the planned paths alone, on a time grid:

- `schedule_exists` / `earliest_completion`: is there any way for the team to carry the plan out,
  every agent moving along its shortest routes at full speed and waiting only at its locations (before
  leaving, or after arriving), the human's and the robot's manipulations at their shortest, the task
  graph kept, the two discs never closer than ``reach + tolerance`` at any instant of the grid, and
  (optionally) everything done by the deadline? A breadth-first search over joint states, one boolean
  matrix (robot position index x human position index) per time step.
- `dispatch`, `closest_approach`, `broken_constraints`: a run of a plan's STNU under its real-time
  execution strategy, with nature's durations given; both discs moved along the plan's routes as the
  run's times say (the robot at its speed, the human at any pace profile that fits the run's travel
  times); the smallest distance between them; every task constraint the times break.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrc.model import Plan, Task
from hrc.motion import PathLibrary
from hrc.plans import agent_legs
from hrc.temporal import STNU
from hrc.temporal.graphml import tool_name


@dataclass
class _Track:
    """One agent's itinerary on the time grid: a position per cell, whether it may wait in a cell, and
    the cells where each phase's manipulation starts and ends."""

    xy: np.ndarray  # (cells, 2); NaN once the agent is done
    can_wait: np.ndarray  # (cells,) bool
    work_start: dict[tuple[str, str], int]  # (action, phase) -> first cell of its manipulation
    work_end: dict[tuple[str, str], int]  # (action, phase) -> the cell right after it
    done_from: int = 0  # the first cell after the last phase's "standing there" cell (clearing, then gone)


def _track(task: Task, plan: Plan, paths: PathLibrary, agent_id: str, dt: float) -> _Track:
    agent = task.agent(agent_id)
    xy: list[tuple[float, float]] = []
    wait: list[bool] = []
    starts: dict[tuple[str, str], int] = {}
    ends: dict[tuple[str, str], int] = {}
    here = task.workspace.location(agent.start).xy
    legs = agent_legs(task, plan, agent_id)
    if not legs:
        return _Track(np.full((1, 2), np.nan), np.array([True]), {}, {})
    xy.append(here)
    wait.append(True)
    for leg in legs:
        path = paths.get(agent_id, leg.origin, leg.location)
        pts = np.asarray(path.points, dtype=float)
        if path.length > 0:
            seg = np.hypot(*(pts[1:] - pts[:-1]).T)
            cum = np.concatenate([[0.0], np.cumsum(seg)])
            steps = max(1, math.ceil(path.duration / dt))
            for k in range(1, steps + 1):
                s = min(k * dt * agent.speed, path.length)
                xy.append((float(np.interp(s, cum, pts[:, 0])), float(np.interp(s, cum, pts[:, 1]))))
                wait.append(False)
            wait[-1] = True  # arrived: may wait before starting
        here = task.workspace.location(leg.location).xy
        work = max(1, math.ceil(task.action(leg.action).phase(leg.phase).duration(agent_id).lb / dt))
        starts[(leg.action, leg.phase)] = len(xy)
        for _ in range(work):
            xy.append(here)
            wait.append(False)
        ends[(leg.action, leg.phase)] = len(xy)
        xy.append(here)  # done with this phase, standing there: may wait before leaving
        wait.append(True)
    # then it clears the spot (it needs reach / speed to be out of reach of it: hrc.motion.conflicts) and
    # steps out of the way
    reach = sum(a.radius for a in task.agents) + task.safety_margin
    done_from = len(xy)
    for _ in range(math.ceil(reach / agent.speed / dt - 1e-9)):
        xy.append(here)
        wait.append(False)
    xy.append((math.nan, math.nan))
    wait.append(True)
    return _Track(np.array(xy), np.array(wait), starts, ends, done_from)


def schedule_exists(task: Task, plan: Plan, paths: PathLibrary, *, dt: float = 0.02, tolerance: float = 0.05,
                    deadline: bool = True) -> bool:
    """Whether the team can carry out `plan` with the discs apart (see the module docstring)."""
    done = earliest_completion(task, plan, paths, dt=dt, tolerance=tolerance)
    return done is not None and (not deadline or task.deadline is None or done <= task.deadline + 1e-9)


def earliest_completion(task: Task, plan: Plan, paths: PathLibrary, *, dt: float = 0.02,
                        tolerance: float = 0.05) -> float | None:
    """The earliest time (s, on the grid) at which the team can have carried out `plan` with the discs
    apart, or None if no way exists (see `schedule_exists`)."""
    human = next(a for a in task.agents if a.is_human)
    robot = next(a for a in task.agents if not a.is_human)
    reach = human.radius + robot.radius + task.safety_margin + tolerance
    tr = _track(task, plan, paths, robot.id, dt)
    th = _track(task, plan, paths, human.id, dt)
    nr, nh = len(tr.xy), len(th.xy)
    d = np.hypot(tr.xy[:, None, 0] - th.xy[None, :, 0], tr.xy[:, None, 1] - th.xy[None, :, 1])
    free = ~(d < reach)  # NaN (an agent that is done) compares False: free
    # the task graph: a manipulation may start (its first cell be entered) only once its predecessors ended
    gate_r = np.ones((nr, nh), dtype=bool)  # robot may move from cell i to i + 1 given human at j
    gate_h = np.ones((nr, nh), dtype=bool)
    owner = dict(plan.allocation)
    for p in task.precedence:
        before, after = (p.before.action, p.before.phase), (p.after.action, p.after.phase)
        if owner[after[0]] == owner[before[0]]:
            continue  # the agent's own sequence keeps that order
        if owner[after[0]] == robot.id:
            i = tr.work_start[after] - 1
            gate_r[i, : th.work_end[before]] = False
        else:
            j = th.work_start[after] - 1
            gate_h[: tr.work_end[before], j] = False
    now = np.zeros((nr, nh), dtype=bool)
    now[0, 0] = free[0, 0]
    wr, wh = tr.can_wait[:, None], th.can_wait[None, :]
    for step in range(4 * (nr + nh) + 1):
        if now[tr.done_from:, th.done_from:].any():
            # past its last "standing there" cell each agent is clearing the spot or gone: the work ended
            # one cell earlier
            return (step - 1) * dt
        nxt = now & wr & wh  # both wait
        nxt[1:, :] |= (now & gate_r & wh)[:-1, :]  # the robot moves on, the human waits
        nxt[:, 1:] |= (now & gate_h & wr)[:, :-1]  # the human moves on, the robot waits
        nxt[1:, 1:] |= (now & gate_r & gate_h)[:-1, :-1]  # both move on
        nxt &= free
        if not nxt.any():
            return None
        now = nxt
    return None


# ---------------------------------------------------------------------------------------------------------
# Replayed runs: the robot (and the human's waits, which the paper's model lets the robot's strategy time)
# follow the STNU's real-time execution strategy; nature picks the human's durations.


def dispatch(stnu: STNU, durations: dict[str, int], pick: Callable[[int, int | None], int],
             origin: str = "Z") -> dict[str, int]:
    """Execute `stnu` online from its `origin` at tick 0 (the task's start): each contingent timepoint C
    occurs `durations[C]` ticks after its activation;
    every other timepoint goes at a tick `pick(earliest, latest)` of its window (`hrc.temporal.execution`),
    kept while it stays in the window and chosen again when not; after every event (an observation or
    an execution) the windows are asked again. Returns the time of every timepoint; AssertionError if the
    strategy gets stuck or the rest stops being DC."""
    from hrc.temporal import Verdict
    from hrc.temporal.execution import ExecutionWindow, real_time_state

    activation = {c.target: c.source for c in stnu.contingents}
    executed: dict[str, int] = {origin: 0}
    planned: dict[str, int] = {}
    now = 0
    for _ in range(20 * len(stnu.timepoints) + 20):
        for c, a in activation.items():  # nature first: what happens now is seen before deciding
            if c not in executed and a in executed and executed[a] + durations[c] <= now:
                executed[c] = executed[a] + durations[c]
        if len(executed) == len(stnu.timepoints):
            return executed
        state = real_time_state(stnu, executed, now)
        assert state.verdict is Verdict.DC, (now, state.verdict, executed)
        for x in stnu.timepoints:
            if x in executed or x in activation:
                continue
            step = state.step(x)
            if isinstance(step, ExecutionWindow):
                hi = step.latest
                if x not in planned or not (step.earliest <= planned[x] and (hi is None or planned[x] <= hi)):
                    planned[x] = pick(step.earliest, hi)
            else:
                planned.pop(x, None)
        due = [executed[a] + durations[c] for c, a in activation.items() if c not in executed and a in executed]
        assert planned or due, f"stuck at {now} with {sorted(set(stnu.timepoints) - set(executed))}"
        next_go = min(planned.values(), default=None)
        if due and (next_go is None or min(due) <= next_go):
            now = min(due)  # an observation first
            continue
        assert next_go is not None
        now = next_go
        x = min(x for x, t in planned.items() if t == now)
        executed[x] = now
        planned.pop(x)
    raise AssertionError("dispatch did not finish")


def sampled_run(stnu: STNU, rng: random.Random, pick: Callable[[int, int | None], int]) -> dict[str, float]:
    """One run of `stnu` by `dispatch`: nature's durations each at a bound or random (from `rng`), every
    other timepoint where `pick` puts it in its window; every timepoint's time in seconds."""
    durations = {c.target: rng.choice([c.lb, c.ub, rng.randint(c.lb, c.ub)]) for c in stnu.contingents}
    return {k: v / 1000 for k, v in dispatch(stnu, durations, pick).items()}


def _position(points: np.ndarray, cum: np.ndarray, s: float) -> tuple[float, float]:
    return float(np.interp(s, cum, points[:, 0])), float(np.interp(s, cum, points[:, 1]))


def trajectory(task: Task, plan: Plan, motions, times: dict[str, float], agent_id: str,  # noqa: ANN001
               pace: str = "even") -> Callable[[float], tuple[float, float] | None]:
    """The agent's position at time t (None once it is done): standing at its locations, moving along each
    leg's route between the leg's depart and arrive (and park / unpark) times; the robot at its speed, the
    human at the `pace` ("even", "rush": full speed then standing at the end, "dawdle": standing first)."""
    agent = task.agent(agent_id)
    legs = agent_legs(task, plan, agent_id)
    pieces: list[tuple[float, float, np.ndarray, np.ndarray]] = []  # (t0, t1, points, cumulative length)
    stands: list[tuple[float, float, tuple[float, float]]] = []
    here = task.workspace.location(agent.start).xy
    last = 0.0
    by_leg = {m.leg: m for m in motions if m.agent == agent_id}
    end_time = 0.0
    for leg in legs:
        m = by_leg[leg.index]
        name = f"{agent_id}.{leg.phase}.{leg.action}"
        dep, arr = times[tool_name(f"{name}.depart")], times[tool_name(f"{name}.arrive")]
        stands.append((last, dep, here))
        pts = np.asarray(m.points if m.points else (here,), dtype=float)
        if m.park:
            park, unpark = times[tool_name(f"{name}.park")], times[tool_name(f"{name}.unpark")]
            xy = task.workspace.location(m.park).xy
            k = int(np.argmin(np.hypot(pts[:, 0] - xy[0], pts[:, 1] - xy[1])))
            first, second = pts[:k + 1], pts[k:]
            pieces.append((dep, park, first, _cum(first)))
            stands.append((park, unpark, xy))
            pieces.append((unpark, arr, second, _cum(second)))
        elif len(pts) > 1:
            pieces.append((dep, arr, pts, _cum(pts)))
        here = task.workspace.location(leg.location).xy
        last = arr
        end_time = times[tool_name(f"{name}.end")]
    stands.append((last, end_time, here))
    speed = agent.speed

    def at(t: float) -> tuple[float, float] | None:
        if not legs or t > end_time + 1e-9:
            return None
        for t0, t1, pts, cum in pieces:
            if t0 <= t <= t1:
                total = cum[-1]
                if total == 0 or t1 <= t0:
                    return _position(pts, cum, 0.0 if t < t1 else total)
                if agent.is_human and pace != "even":
                    need = total / speed
                    spare = max(0.0, (t1 - t0) - need)
                    tau = t - t0 - (spare if pace == "dawdle" else 0.0)
                    s = min(total, max(0.0, tau * speed))
                else:
                    s = total * (t - t0) / (t1 - t0)
                return _position(pts, cum, s)
        for t0, t1, xy in stands:
            if t0 - 1e-9 <= t <= t1 + 1e-9:
                return xy
        return here

    return at


def _cum(pts: np.ndarray) -> np.ndarray:
    if len(pts) < 2:
        return np.zeros(len(pts))
    return np.concatenate([[0.0], np.cumsum(np.hypot(*(pts[1:] - pts[:-1]).T))])


def closest_approach(task: Task, plan: Plan, motions, times: dict[str, float], pace: str = "even",  # noqa: ANN001
                     dt: float = 0.005) -> tuple[float, float]:
    """The smallest distance between the two agents' centres over the run, and when (every `dt` s)."""
    human = next(a for a in task.agents if a.is_human)
    robot = next(a for a in task.agents if not a.is_human)
    h = trajectory(task, plan, motions, times, human.id, pace)
    r = trajectory(task, plan, motions, times, robot.id)
    horizon = max(times.values())
    best, when = math.inf, 0.0
    for k in range(int(horizon / dt) + 2):
        t = k * dt
        a, b = h(t), r(t)
        if a is not None and b is not None:
            d = math.dist(a, b)
            if d < best:
                best, when = d, t
    return best, when


def broken_constraints(task: Task, plan: Plan, times: dict[str, float], tol: float = 0.002) -> list[str]:
    """The task's own rules a run's times break: durations outside their bounds (robot), the task graph,
    temporal constraints and the deadline (from the task, not from any STNU)."""
    out = []
    owner = dict(plan.allocation)

    def tp(action: str, phase: str, what: str) -> float:
        return times[tool_name(f"{owner[action]}.{phase}.{action}.{what}")]

    for action in task.actions:
        for phase in action.phases:
            iv = phase.duration(owner[action.id])
            d = tp(action.id, phase.id, "end") - tp(action.id, phase.id, "start")
            if task.agent(owner[action.id]).is_human:
                continue  # nature's
            if not iv.lb - tol <= d <= iv.ub + tol:
                out.append(f"{action.id}.{phase.id} took {d:.3f} s outside [{iv.lb}, {iv.ub}]")
    for p in task.precedence:
        if tp(p.after.action, p.after.phase, "start") < tp(p.before.action, p.before.phase, "end") - tol:
            out.append(f"task graph: {p.after} before {p.before} ended")
    for c in task.constraints:
        d = tp(c.target.action, c.target.phase, c.target.boundary) - tp(c.source.action, c.source.phase,
                                                                          c.source.boundary)
        if not c.bounds.lb - tol <= d <= c.bounds.ub + tol:
            out.append(f"constraint {c.target} - {c.source} = {d:.3f} s outside {tuple(c.bounds)}")
    if task.deadline is not None:
        last = max(tp(a.id, ph.id, "end") for a in task.actions for ph in a.phases)
        if last > task.deadline + tol:
            out.append(f"deadline {task.deadline} s missed: {last:.3f} s")
    return out
