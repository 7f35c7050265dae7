"""The engineer's views, as JSON-ready data the page draws: the map with both agents' planned routes,
and the Gantt bars (planned and actual) of a plan.

The map and every plan's routes are fixed for a run, so they are computed once: the free-space paths
are planned again with the seed of ``compiled.json`` (`hrc.motion.plan_paths` is deterministic for a
task and seed, so these are the paths the compiler used), and a detour's points come from the plan's
``motions`` in ``compiled.json``. Gantt bars come from the dispatcher's `planned_times` (observed times
where observed, else the plan's earliest schedule given what happened) and from its history.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol

from hrc.model import Task
from hrc.motion import PathLibrary

__all__ = ["PlanRoutes", "gantt_bars", "map_view", "under_way"]

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


class PlanRoutes:
    """Each plan's routes, one polyline per agent leg: ``routes(plan_id) -> {agent: [leg, ...]}``, a leg
    being ``{"action", "phase", "from", "to", "points": [[x, y], ...], "detour": str | None}`` (and
    ``"speed"`` for a leg the robot drives at a reduced speed).

    `motions` gives a plan's ``motions`` from ``compiled.json`` by its id (None: no such plan;
    `hrc.console.run.plan_motions` reads one line of the file); `paths` the free-space paths for its
    seed. Cost: one pass over a plan's motions on first use, the last `KEPT` plans cached.
    """

    KEPT = 64

    def __init__(self, motions: Callable[[str], list[dict[str, Any]] | None], paths: PathLibrary) -> None:
        self._motions = motions
        self._paths = paths
        self._cache: dict[str, dict[str, list[dict[str, Any]]]] = {}

    def routes(self, plan_id: str | None) -> dict[str, list[dict[str, Any]]]:
        if plan_id is None:
            return {}
        if plan_id not in self._cache:
            found = self._motions(plan_id)
            if found is None:
                return {}
            if len(self._cache) >= self.KEPT:
                self._cache.pop(next(iter(self._cache)))
            out: dict[str, list[dict[str, Any]]] = {}
            for m in found:
                if m["detour"]:
                    points = m["detour"]["points"]
                elif m["from"] == m["to"]:
                    points = []
                else:
                    points = [_xy(p) for p in self._paths.get(m["agent"], m["from"], m["to"]).points]
                out.setdefault(m["agent"], []).append({
                    "action": m["action"], "phase": m["phase"], "from": m["from"], "to": m["to"],
                    "points": points, "detour": m["detour"]["round"] if m["detour"] else None,
                    "park": m["park"]["at"] if m["park"] else None}
                    | ({"speed": m["speed"]} if m.get("speed") else {}))  # a reduced-speed leg only
            self._cache[plan_id] = out
        return self._cache[plan_id]


def gantt_bars(planned: Times, history: Iterable[_Observed], now: float) -> dict[str, list[dict[str, Any]]]:
    """Planned and actual bars: ``{"planned": [...], "actual": [...]}``, each bar
    ``{"agent", "action", "phase", "kind": "travel" | "wait" | "work", "from": s, "to": s}``.

    A planned bar joins two events of `planned`; an actual bar joins two observed events, and an event
    begun but not yet ended is drawn up to `now` (``"open": true``).
    """
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
    actual = []
    for (agent, action, phase, event), t0 in sorted(seen.items(), key=lambda kv: kv[1]):
        for kind, first, last in _BAR_EVENTS:
            if event == first:
                t1 = seen.get((agent, action, phase, last))
                actual.append({"agent": agent, "action": action, "phase": phase, "kind": kind, "from": t0,
                               "to": now if t1 is None else t1, "open": t1 is None})
    return {"planned": planned_bars, "actual": actual}


def under_way(history: Iterable[_Observed], agent: str) -> list[tuple[str, str]]:
    """The `agent`'s phases started and not yet ended, as (action, phase), oldest first."""
    started: dict[tuple[str, str], None] = {}
    for o in history:
        if o.agent == agent and o.action and o.phase:
            if o.event == "start":
                started[(o.action, o.phase)] = None
            elif o.event == "end":
                started.pop((o.action, o.phase), None)
    return list(started)
