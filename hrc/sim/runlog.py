"""A simulated run's exchanges with its controller, caught as they happen, and written as a dispatcher
log (``hrc simulate --keep-logs``, `hrc.dispatch.logfile`'s format) or an MCAP recording (`hrc.record.sim`).

`catching` wraps the run's controller so that every observation it is given, and what it answered, is
also put into a list (the run itself is unchanged: the same run ``simulation.json`` holds). For the
dispatcher's policies each observation is the protocol's message (`hrc.dispatch.Observation.to_json`)
and its answer the decision (or the refusal) the dispatcher gave; for ``fixed`` (no dispatcher) the
answer is the robot's order from the fixed plan. `log_bytes` makes a log of them whose header names
the compiled plan set (as ``hrc dispatch --log`` does) and the task (its digest), so that ``hrc learn``
reads a simulated run as it reads a run on the floor.

A team's run (issue 37, `hrc.sim.team_run`) is caught the same way (`catching` over
`hrc.sim.team_policies.make_team_controller`): each answer is the team's (`Decision.to_json`: ``robots``,
``people``, ``away``; for ``fixed`` each robot's order), and the header names the team as ``hrc dispatch
--log`` does (``"team"``), so that ``hrc dispatch --replay`` over the same compile gives the same answers.
Each message carries the ``delay`` the dispatcher was told (late buttons), and the header the stated
maximum (``max_observation_delay``, a compile with ``sensing:``), as ``hrc dispatch --log`` writes them.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any

from hrc.sim.detector import Happening
from hrc.sim.policies import DispatchedController, Policy
from hrc.sim.run import SimContext, make_controller
from hrc.sim.team_policies import TeamDispatched, TeamFixed

__all__ = ["Exchange", "catching", "log_bytes", "log_name"]

Exchange = tuple[float, bytes, str]
"""(run time, the message's bytes, the answer's line)."""


def log_name(policy: str, index: int) -> str:
    """``POLICY-NNNN.jsonl``: the log of run `index` of `policy` (sorted as the runs are)."""
    return f"{policy}-{index:04d}.jsonl"


def _answer(ctl: Any, before: int, t: float) -> dict[str, Any]:
    """What the controller answered to the observation it has just been given."""
    if len(ctl.refused) > before:
        return {"t": t, "ok": False, "error": ctl.refused[-1].split(": ", 1)[-1]}
    if hasattr(ctl, "d"):  # the dispatcher's answer (one pair's or a team's)
        return dict(ctl.d.decision.to_json())
    if isinstance(ctl, TeamFixed):  # a team's fixed plan: each robot's order
        robots = {r.id: _order(ctl.order(r.id)) for r in ctl.task.agents if not r.is_human}
        people = {p.id: None for p in ctl.task.agents if p.is_human}
        return {"t": t, "ok": True, "plan": ctl.plan_id, "class": ctl.plan_class, "candidates": {},
                "robots": robots, "people": people, "away": [], "stopped": False, "policy": "fixed"}
    robot = _order(ctl.order())  # the fixed plan: its order for the robot
    return {"t": t, "ok": True, "plan": ctl.plan_id, "class": ctl.plan_class, "candidates": {}, "robot": robot,
            "human": None, "human_away": False, "stopped": False, "policy": "fixed"}


def _order(order: Any) -> dict[str, Any] | None:
    return None if order is None else {"action": order.action, "phase": order.phase, "event": order.event,
                                       "earliest": round(order.earliest, 3),
                                       "latest": None if order.latest is None else round(order.latest, 3)}


def catching(exchanges: list[Exchange], make: Callable[[SimContext, Policy], Any] = make_controller) -> Any:
    """A controller factory for `hrc.sim.run.simulate_run` (or, with `make` =
    `hrc.sim.team_policies.make_team_controller`, `hrc.sim.team_run.simulate_team_run`) whose controllers
    also put every observation and its answer into `exchanges` (the controller itself is unchanged)."""

    def factory(ctx: SimContext, policy: Policy) -> Any:
        ctl = make(ctx, policy)
        inner = ctl.observe

        def observe(h: Happening) -> None:
            before = len(ctl.refused)
            inner(h)
            t = round(h.t, 3)
            message = {"t": t, "agent": h.agent or None, "action": h.action, "phase": h.phase, "event": h.event,
                       "delay": h.delay}
            line = json.dumps({k: v for k, v in message.items() if v is not None})
            exchanges.append((t, line.encode("utf-8"), json.dumps(_answer(ctl, before, t))))

        ctl.observe = observe  # type: ignore[method-assign]  # this instance only: what the run loop calls
        if isinstance(ctl, DispatchedController | TeamDispatched) and hasattr(ctl.d, "answer_position"):
            _catch_positions(ctl.d, exchanges)
        return ctl

    return factory


def _catch_positions(d: Any, exchanges: list[Exchange]) -> None:
    """With a motion detector in front (`hrc.detect.online.DetectingDispatcher`): each tracked position it
    is given, and the answer the protocol would give (`answer_position`: the decision, the events given
    with the time each was stamped, the belief), into `exchanges`; the dispatcher itself is unchanged."""
    from hrc.errors import DispatchError

    inner = d.position
    team = len(d.people) > 1  # a team's positions name their person (issue 37); the one person's never did

    def position(t: float, x: float, y: float, person: str | None = None) -> Any:
        person = d.model.human if person is None else person
        message = {"t": t, "agent": person, "event": "position", "x": x, "y": y} if team else \
            {"t": t, "event": "position", "x": x, "y": y}
        line = json.dumps(message).encode("utf-8")
        try:
            given, refused = inner(t, x, y, person)
        except DispatchError as err:
            exchanges.append((t, line, json.dumps({"t": t, "ok": False, "error": " ".join(str(err).split())[:500]})))
            raise
        exchanges.append((t, line, json.dumps(d.position_answer(person, t, given, refused))))
        return given, refused

    d.position = position


def _plan_set_digest(ctx: SimContext, policy: Policy) -> tuple[str, int]:
    """The digest and size of the policy's compiled plan set as a dispatcher names it (per process)."""
    key = ("plan_set_digest", policy.compile)
    got = ctx.cache.get(key)
    if got is None:
        from hrc.dispatch.plan_set import plan_set_from_compiled

        ps = plan_set_from_compiled(ctx.compiles[policy.compile])
        got = ctx.cache[key] = (ps.digest, len(ps))
    return got


def log_bytes(ctx: SimContext, policy: Policy, exchanges: Sequence[Exchange]) -> bytes:
    """The run's exchanges as a dispatcher log (`hrc.dispatch.logfile`, version 2), header first."""
    from hrc.dispatch.logfile import LOG_VERSION, encode_answer, encode_header, encode_input
    from hrc.io.task_file import task_digest

    digest, plans = _plan_set_digest(ctx, policy)
    key = ("task_digest",)
    if key not in ctx.cache:
        ctx.cache[key] = task_digest(ctx.task)
    header: dict[str, Any] = {"hrc_dispatch_log": LOG_VERSION, "compiled": digest, "plans": plans,
                              "task": ctx.cache[key], "policy": policy.name}
    kinds = {a.id: a.kind.value for a in ctx.task.agents}
    if sorted(kinds.values()) != ["human", "robot"]:  # a team (issue 37): as `hrc.dispatch.protocol.log_header`
        header["team"] = kinds
    made: tuple[Any, ...] = ("team-dispatcher", policy.name, "motion") if "team" in header else \
        ("dispatcher", policy.name, True)  # (`make_team_controller`'s and `make_controller`'s cache keys)
    detect = ctx.cache.get(made) if ctx.settings.motion and policy.dispatched else None
    if detect is not None:  # as `hrc.dispatch.protocol.log_header`: a replay needs the same detector
        header["detect"] = dict(detect.detect_settings())
    if policy.dispatched and ctx.task.sensing is not None and ctx.task.sensing.delay[1] is not None:
        header["max_observation_delay"] = ctx.task.sensing.delay[1]  # the dispatcher's default (its replay's)
    parts = [encode_header(header)]
    for _, data, answer in exchanges:
        parts += [encode_input(data), encode_answer(answer)]
    return b"".join(parts)
