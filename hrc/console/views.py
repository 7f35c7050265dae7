"""The engineer's views, as JSON-ready data the page draws: the map with both agents' planned routes,
and the Gantt bars (planned and actual) of a plan.

The map and every plan's routes are fixed for a run, so they are computed once: the free-space paths
are planned again with the seed of ``compiled.json`` (`hrc.motion.plan_paths` is deterministic for a
task and seed, so these are the paths the compiler used), and a detour's points come from the plan's
``motions`` in ``compiled.json``. Gantt bars come from the dispatcher's `planned_times` (observed times
where observed, else the plan's earliest schedule given what happened) and from its history.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, Protocol

from hrc.model import Task

__all__ = ["gantt_bars", "map_view", "under_way"]

# (agent, action, phase, event) -> run seconds, as `Dispatcher.planned_times` gives them
Times = Mapping[tuple[str, str, str, str], float]

# A bar from event to event, per kind; "wait" is a stop at a waiting place (park .. unpark).
_BAR_EVENTS = (("travel", "depart", "arrive"), ("wait", "park", "unpark"), ("work", "start", "end"))


class _Observed(Protocol):  # read-only, as `hrc.dispatch.Observation` (frozen) has them
    @property
    def t(self) -> float: ...
    @property
    def event(self) -> str: ...
    @property
    def agent(self) -> str | None: ...
    @property
    def action(self) -> str | None: ...
    @property
    def phase(self) -> str | None: ...


def _xy(p: Iterable[float]) -> list[float]:
    x, y = p
    return [round(float(x), 3), round(float(y), 3)]


def map_view(task: Task) -> dict[str, Any]:
    """The shop floor: bounds, obstacle polygons, named locations and each agent's disc and start."""
    ws = task.workspace
    return {
        "bounds": list(ws.bounds),
        "obstacles": [{"id": o.id, "points": [_xy(p) for p in o.polygon]} for o in ws.obstacles],
        "locations": {loc.id: _xy(loc.xy) for loc in ws.locations},
        "agents": {a.id: {"kind": a.kind.value, "radius": a.radius, "start": a.start} for a in task.agents},
    }


def gantt_bars(planned: Times, history: Iterable[_Observed], now: float,
               joint: Mapping[str, tuple[str, ...]] | None = None) -> dict[str, list[dict[str, Any]]]:
    """Planned and actual bars: ``{"planned": [...], "actual": [...]}``, each bar
    ``{"agent", "action", "phase", "kind": "travel" | "wait" | "work", "from": s, "to": s}``.

    A planned bar joins two events of `planned`; an actual bar joins two observed events, and an event
    begun but not yet ended is drawn up to `now` (``"open": true``). A `joint` action (action -> its agents,
    issue 37) has one start and one end, its lead's: its work bar is drawn for each of its agents.
    """
    if joint:
        planned = _shared(planned, joint)
    planned_bars = []
    keys = sorted({(a, act, ph) for (a, act, ph, _e) in planned})
    for agent, action, phase in keys:
        for kind, first, last in _BAR_EVENTS:
            t0 = planned.get((agent, action, phase, first))
            t1 = planned.get((agent, action, phase, last))
            if t0 is not None and t1 is not None:
                planned_bars.append({"agent": agent, "action": action, "phase": phase, "kind": kind,
                                     "from": round(t0, 3), "to": round(t1, 3)})
    seen: dict[tuple[str, str, str, str], float] = {}
    for o in history:
        if o.agent and o.action and o.phase:
            seen[(o.agent, o.action, o.phase, o.event)] = o.t
    if joint:
        seen = _shared(seen, joint)
    actual = []
    for (agent, action, phase, event), t0 in sorted(seen.items(), key=lambda kv: kv[1]):
        for kind, first, last in _BAR_EVENTS:
            if event == first:
                t1 = seen.get((agent, action, phase, last))
                actual.append({"agent": agent, "action": action, "phase": phase, "kind": kind, "from": t0,
                               "to": now if t1 is None else t1, "open": t1 is None})
    return {"planned": planned_bars, "actual": actual}


def _shared(times: Times, joint: Mapping[str, tuple[str, ...]]) -> dict[tuple[str, str, str, str], float]:
    """`times` with a joint action's start and end (its lead's) given to each of its agents too."""
    out = dict(times)
    for (_, action, phase, event), t in times.items():
        if action in joint and event in ("start", "end"):
            for other in joint[action]:
                out.setdefault((other, action, phase, event), t)
    return out


def under_way(history: Iterable[_Observed], agent: str,
              joint: Mapping[str, tuple[str, ...]] | None = None) -> list[tuple[str, str]]:
    """The `agent`'s phases started and not yet ended, as (action, phase), oldest first (a `joint` action of
    the agent's: started and ended by its lead)."""
    started: dict[tuple[str, str], None] = {}
    joint = joint or {}
    for o in history:
        if o.action and o.phase and (o.agent == agent or agent in joint.get(o.action, ())):
            if o.event == "start":
                started[(o.action, o.phase)] = None
            elif o.event == "end":
                started.pop((o.action, o.phase), None)
    return list(started)
