"""Each plan's routes as the console, the recorder and the ROS 2 node draw and drive them, read from an
`hrc compile` output folder: a plan's ``motions`` from ``compiled.json`` (`plan_motions`: its one line,
where the plan set's dispatch form says it lies) and each agent leg's polyline (`PlanRoutes`: the
free-space paths planned again with the compile's seed, a detour's points from the plan's ``motions``).

They belong to the compiled plan set the dispatcher loads (`hrc.dispatch.plan_set`), below every front
end that shows or drives a run (console, record, ros2).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from typing import Any

from hrc.dispatch.plan_set import PlanSet
from hrc.errors import InputError
from hrc.motion import PathLibrary

__all__ = ["PlanRoutes", "plan_motions"]


def _xy(p: Iterable[float]) -> list[float]:
    x, y = p
    return [round(float(x), 3), round(float(y), 3)]


def plan_motions(out_dir: str | os.PathLike[str], plan_set: PlanSet) -> Callable[[str], list[dict[str, Any]] | None]:
    """A plan's ``motions`` from ``compiled.json`` (or ``plans.jsonl`` beside a large one), by plan id
    (None: no such plan), read when asked for: its one line, where the dispatch form says it lies (a
    large compile's lines are gigabytes); for an output without a form, the file is read once. Read from
    the file the plan set holds open (`PlanSet.compiled`: the one its form was checked with, whatever a
    later compile puts at its path; one opened now for a set that holds none)."""
    from hrc.compile.output import iter_plans, lines_path

    path = lines_path(out_dir)
    rows = plan_set.form.plans
    everything: dict[str, Any] | None = None
    held = plan_set.compiled
    if held is None:
        try:
            held = plan_set.compiled = open(path, "rb")  # noqa: SIM115 - kept open with the set
        except OSError as err:
            raise InputError(str(path), "", f"cannot read: {err.strerror or err}") from err
    fd = held.fileno()

    def motions(plan_id: str) -> list[dict[str, Any]] | None:
        nonlocal everything
        try:
            p = plan_set.index(plan_id)
        except KeyError:
            return None
        at, size = int(rows["line_at"][p]), int(rows["line_len"][p])
        try:
            if size:
                line = json.loads(os.pread(fd, size, at))
                if isinstance(line, dict) and line.get("id") == plan_id:
                    return list(line.get("motions", []))
                raise ValueError(f"plan {plan_id}'s line is not where the dispatch form says")
            if everything is None:
                everything = {p["id"]: p for p in iter_plans(out_dir)}
            return list(everything[plan_id]["motions"]) if plan_id in everything else None
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise InputError(str(path), "", f"cannot read plan {plan_id}'s motions ({err})") from err

    return motions


class PlanRoutes:
    """Each plan's routes, one polyline per agent leg: ``routes(plan_id) -> {agent: [leg, ...]}``, a leg
    being ``{"action", "phase", "from", "to", "points": [[x, y], ...], "detour": str | None}`` (and
    ``"speed"`` for a leg the robot drives at a reduced speed).

    `motions` gives a plan's ``motions`` from ``compiled.json`` by its id (None: no such plan;
    `plan_motions` reads one line of the file); `paths` the free-space paths for its
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

    def way(self, agent: str, origin: str, target: str) -> list[list[float]]:
        """The planned free-space way of `agent` between two locations, as a leg's points (mm): a robot's
        way home after its last phase (`hrc.ros2.drive.home_drive`), the path the simulator drives it.
        Raises KeyError for a pair the compile never planned."""
        return [_xy(p) for p in self._paths.get(agent, origin, target).points]
