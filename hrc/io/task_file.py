"""Load and write task files (YAML); the format is documented in docs/task-format.md.

`load_task` is the only way from a task file to a `Task`: it validates everything it can without
planning (ids, bounds, the task graph, locations against the map and each agent's radius) and raises
`TaskFileError` / `MapFileError` naming file, line and key path. `dump_task` writes the model back;
``load_task(dump_task(t)) == t`` (tested).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from typing import Any

import yaml

from hrc.errors import TaskFileError
from hrc.io.atomic import write_text_atomic
from hrc.io.map_file import clearance, load_workspace, workspace_to_dict
from hrc.io.safety_section import read_safety, safety_to_dict
from hrc.io.yamldoc import Doc, read_yaml
from hrc.model import (
    DEFAULT_TRAVEL_SLACK,
    SENSING_PATHS,
    Action,
    Agent,
    AgentKind,
    Event,
    Interval,
    Phase,
    PhaseRef,
    Precedence,
    Preference,
    PreferenceKind,
    Sensing,
    Task,
    TemporalConstraint,
    Workspace,
    is_acyclic,
)

__all__ = ["dump_task", "load_task", "task_digest", "task_to_dict"]

MAX_SECONDS = 1e6
"""Largest duration, deadline or constraint bound (s, about 11.6 days): schedules are exact to the
millisecond, and sums of such numbers must stay far inside what the temporal core handles exactly."""
MIN_SPEED = 0.01
"""Slowest agent speed (m/s): slower, a travel across a shop floor would outlast `MAX_SECONDS`."""
MAX_TRAVEL_SLACK = 100.0

_TOP_REQUIRED = ("name", "map", "agents", "actions")
_TOP_OPTIONAL = ("precedence", "constraints", "deadline", "preferences", "preference_sets", "safety_margin",
                 "sensing", "safety")
_COEFFS = {PreferenceKind.CONSTANT: 1, PreferenceKind.LINEAR: 2, PreferenceKind.QUADRATIC: 3}


def load_task(path: str | os.PathLike[str]) -> Task:
    """Read and validate a task file and the map it names."""
    doc = read_yaml(path, TaskFileError)
    top = doc.mapping(doc.value, (), required=_TOP_REQUIRED, optional=_TOP_OPTIONAL)
    name = doc.ident(top["name"], ("name",))
    map_path = doc.text(top["map"], ("map",))
    map_file = os.path.normpath(os.path.join(os.path.dirname(doc.file), map_path))
    if not os.path.isfile(map_file):
        doc.fail(("map",), f"map file '{map_file}' does not exist")
    workspace = load_workspace(map_file)
    margin = doc.number(top.get("safety_margin", 0.1), ("safety_margin",), minimum=0)

    agents = _agents(doc, top["agents"], workspace, margin)
    raw_actions = doc.sequence(top["actions"], ("actions",), min_len=1)
    actions = [_action(doc, raw, ("actions", i), agents, workspace, margin)
               for i, raw in enumerate(raw_actions)]
    doc.unique([a.id for a in actions], ("actions",), "action")
    _check_reachable(doc, agents, actions, workspace, margin)
    by_id = {a.id: a for a in actions}

    precedence = [_precedence(doc, raw, ("precedence", i), by_id)
                  for i, raw in enumerate(doc.sequence(top.get("precedence", []), ("precedence",)))]
    _check_acyclic(doc, actions, precedence)
    constraints = [_constraint(doc, raw, ("constraints", i), by_id)
                   for i, raw in enumerate(doc.sequence(top.get("constraints", []), ("constraints",)))]
    deadline = None
    if top.get("deadline") is not None:
        deadline = doc.number(top["deadline"], ("deadline",), positive=True, maximum=MAX_SECONDS, unit=" s")
    preferences = [_preference(doc, raw, ("preferences", i), by_id)
                   for i, raw in enumerate(doc.sequence(top.get("preferences", []), ("preferences",)))]
    sets = []
    raw_sets = top.get("preference_sets", {})
    if not isinstance(raw_sets, dict):
        doc.fail(("preference_sets",), "expected a mapping of set name -> list of preferences")
    for set_name, raw_set in raw_sets.items():
        doc.ident(set_name, ("preference_sets", set_name))
        items = doc.sequence(raw_set, ("preference_sets", set_name), min_len=1)
        sets.append((set_name, tuple(_preference(doc, raw, ("preference_sets", set_name, i), by_id)
                                     for i, raw in enumerate(items))))
    safety = None
    if top.get("safety") is not None:
        robots = [a for a in agents if not a.is_human]
        if not robots:
            doc.fail(("safety",), "speed and separation monitoring keeps a robot away from people: the task has no "
                                  "robot")
        for robot in robots:  # the same section, checked against every robot's speed
            safety = read_safety(doc, top["safety"], robot)
    sensing = _sensing(doc, top["sensing"]) if top.get("sensing") is not None else None
    return Task(name=name, agents=tuple(agents), actions=tuple(actions), precedence=tuple(precedence),
                constraints=tuple(constraints), deadline=deadline, preferences=tuple(preferences),
                map_path=map_path, workspace=workspace, safety_margin=margin, preference_sets=tuple(sets),
                source=doc.file, sensing=sensing, safety=safety)


def _sensing(doc: Doc, raw: Any) -> Sensing:
    """``sensing: {path: buttons | motion | stated, delay: [lo, hi]}`` (delay in seconds, optional but for
    ``stated``: the path's default, `hrc.model.SENSING_PATHS`; ``hi`` may be ``.inf``: never observed)."""
    m = doc.mapping(raw, ("sensing",), required=("path",), optional=("delay",))
    path = m["path"]
    if path not in SENSING_PATHS and path != "stated":
        doc.fail(("sensing", "path"), f"expected one of {', '.join(SENSING_PATHS)} or stated, found {path!r}")
    default, dated = SENSING_PATHS.get(path, (None, False))
    if m.get("delay") is None:
        if default is None:
            doc.fail(("sensing", "delay"), "path stated needs a delay [lo, hi] in seconds")
        return Sensing(path, default, dated)
    pair = doc.sequence(m["delay"], ("sensing", "delay"))
    if len(pair) != 2:
        doc.fail(("sensing", "delay"), f"expected [lo, hi] in seconds, found {len(pair)} value(s)")
    lo = doc.number(pair[0], ("sensing", "delay", 0), minimum=0, maximum=MAX_SECONDS, unit=" s")
    hi = doc.number(pair[1], ("sensing", "delay", 1), minimum=0, maximum=MAX_SECONDS, unit=" s", allow_inf=True)
    if lo > hi:
        doc.fail(("sensing", "delay"), f"lo {lo:g} s exceeds hi {hi:g} s")
    return Sensing(path, (lo, None if math.isinf(hi) else hi), dated)


def _agents(doc: Doc, raw: Any, ws: Workspace, margin: float) -> list[Agent]:
    items = doc.sequence(raw, ("agents",), min_len=1)
    agents = []
    for i, item in enumerate(items):
        path = ("agents", i)
        m = doc.mapping(item, path, required=("id", "kind", "radius", "speed", "start"),
                        optional=("travel_slack",))
        aid = doc.ident(m["id"], path + ("id",))
        kinds = [k.value for k in AgentKind]
        if m["kind"] not in kinds:
            doc.fail(path + ("kind",), f"expected one of {', '.join(kinds)}, found {m['kind']!r}")
        radius = doc.number(m["radius"], path + ("radius",), positive=True)
        speed = doc.number(m["speed"], path + ("speed",), positive=True, minimum=MIN_SPEED, unit=" m/s")
        start = doc.ident(m["start"], path + ("start",))
        slack = doc.number(m.get("travel_slack", DEFAULT_TRAVEL_SLACK), path + ("travel_slack",), minimum=1,
                           maximum=MAX_TRAVEL_SLACK)
        agent = Agent(id=aid, kind=AgentKind(m["kind"]), radius=radius, speed=speed, start=start,
                      travel_slack=slack)
        _check_location(doc, path + ("start",), start, agent, ws, margin)
        agents.append(agent)
    doc.unique([a.id for a in agents], ("agents",), "agent")  # any number of people and robots, at least one
    return agents


def _check_location(doc: Doc, path: tuple, loc_id: str, agent: Agent, ws: Workspace, margin: float) -> None:
    if loc_id not in ws.location_ids:
        doc.fail(path, f"unknown location '{loc_id}' (map {ws.source} has: {', '.join(ws.location_ids)})")
    loc = ws.location(loc_id)
    dist, what = clearance(ws, loc.x, loc.y)
    need = agent.radius + margin
    if dist < need + 1e-6:  # the motion planner keeps 1 um more than the clearance: reject ties here
        doc.fail(path, f"{agent.id} at location '{loc_id}' overlaps {what}: clearance {dist:.3f} m < "
                       f"radius {agent.radius:g} + safety margin {margin:g} m")


def _check_reachable(doc: Doc, agents: list[Agent], actions: list[Action], ws: Workspace, margin: float) -> None:
    """Every phase location an agent may be given lies in the part of the floor its disc can reach from
    its start: free space (the bounds minus the obstacles, each grown by the agent's radius + safety
    margin) split into its connected parts (shapely). Without this, `hrc show` would count plans that
    path planning then refuses. O(obstacles log obstacles) per agent."""
    import shapely
    from shapely.geometry import Point, Polygon, box

    xmin, ymin, xmax, ymax = ws.bounds
    obstacles = shapely.union_all([Polygon(o.polygon) for o in ws.obstacles]) if ws.obstacles else None
    for agent in agents:
        need = agent.radius + margin
        if 2 * need >= min(xmax - xmin, ymax - ymin):
            continue  # _check_location has said what is wrong, or will
        free = box(xmin + need, ymin + need, xmax - need, ymax - need)
        if obstacles is not None:
            free = free.difference(obstacles.buffer(need, quad_segs=16))
        start = ws.location(agent.start)
        parts = list(getattr(free, "geoms", [free]))
        home = next((g.buffer(1e-6) for g in parts if g.buffer(1e-6).covers(Point(start.x, start.y))), None)
        if home is None:
            continue
        for i, action in enumerate(actions):
            if agent.id not in action.agents:
                continue
            for j, phase in enumerate(action.phases):
                loc = ws.location(phase.location)
                if not home.covers(Point(loc.x, loc.y)):
                    doc.fail(("actions", i, "phases", j, "location"),
                             f"{agent.id} cannot reach location '{phase.location}' from its start "
                             f"'{agent.start}': no way through keeps its clearance of {need:g} m (radius + "
                             f"safety margin); take {agent.id} out of {action.id}'s agents, or move the location")


def _action(doc: Doc, raw: Any, path: tuple, agents: list[Agent], ws: Workspace, margin: float) -> Action:
    m = doc.mapping(raw, path, required=("id", "phases"), optional=("name", "agents", "agents_needed", "roles"))
    aid = doc.ident(m["id"], path + ("id",))
    name = doc.text(m.get("name", aid), path + ("name",))
    known = {a.id: a for a in agents}
    roles: list[tuple[str, tuple[str, ...]]] = []  # (role, candidates in task order)
    needed = 1
    if "roles" in m:
        for key in ("agents", "agents_needed"):
            if key in m:
                doc.fail(path + (key,), "give either roles or agents (with agents_needed), not both")
        rm = m["roles"]
        if not isinstance(rm, dict):
            doc.fail(path + ("roles",), "expected a mapping role: agent (e.g. {holder: human, stacker: robot}) "
                                        "or role: {agents: [candidates]}")
        played: dict[str, str] = {}  # agent -> the role it may play
        for role, ag in rm.items():
            doc.ident(role, path + ("roles", str(role)))
            rpath = path + ("roles", role)
            if isinstance(ag, dict):  # role: {agents: [alice, bob]}: any one of them plays it (the plan chooses)
                cm = doc.mapping(ag, rpath, required=("agents",))
                raw = doc.sequence(cm["agents"], rpath + ("agents",), min_len=1)
                named = [(doc.ident(c, rpath + ("agents", j)), rpath + ("agents", j)) for j, c in enumerate(raw)]
            else:
                named = [(doc.ident(ag, rpath), rpath)]
            for cand, cpath in named:
                if cand not in known:
                    doc.fail(cpath, f"unknown agent '{cand}' (known: {', '.join(known)})")
                if cand in played:
                    doc.fail(cpath, f"'{cand}' already plays role '{played[cand]}': one agent, one role")
                played[cand] = role
            roles.append((role, tuple(x for x in known if x in {c for c, _ in named})))
        needed = len(roles)
        who = [ag for ag in known if ag in played]  # task order
    else:
        if "agents" not in m:
            doc.fail(path + ("agents",), "missing (required key; or roles, for a joint action)")
        who = doc.sequence(m["agents"], path + ("agents",))
        if not who:
            doc.fail(path + ("agents",), f"no agent can do action '{aid}'")
        for j, ag in enumerate(who):
            if doc.ident(ag, path + ("agents", j)) not in known:
                doc.fail(path + ("agents", j), f"unknown agent '{ag}' (known: {', '.join(known)})")
        doc.unique(list(who), path + ("agents",), "agent", key="")
        if "agents_needed" in m:
            needed = m["agents_needed"]
            if isinstance(needed, bool) or not isinstance(needed, int) or needed < 1:
                doc.fail(path + ("agents_needed",), f"expected a whole number >= 1, found {needed!r}")
            if needed > len(who):
                doc.fail(path + ("agents_needed",), f"{needed} agents needed out of {len(who)}: at most "
                                                    f"{len(who)} (its agents: {', '.join(who)})")
            if needed > 1:  # any `needed` of them: a role per agent, named after it, `needed` roles filled
                roles = [(ag, (ag,)) for ag in known if ag in who]
            else:
                needed = 1
    if roles:
        if len(roles) < 2 or needed < 2:
            doc.fail(path + ("roles",), f"a joint action needs two or more roles, found {len(roles)}")
        if all(known[ag].is_human for _, cands in roles for ag in cands):
            doc.fail(path + ("roles",), "a joint action needs a robot among its agents: the robot starts it")
        people = [(role, next(c for c in cands if known[c].is_human)) for role, cands in roles
                  if any(known[c].is_human for c in cands)]
        if len(people) >= needed:  # `needed` roles a person may play: a crew without a robot
            where = path + (("roles",) if "roles" in m else ("agents_needed",))
            crew = ", ".join(ag for _, ag in people[:needed])
            doc.fail(where, f"a crew of people only ({crew}) could do it: a joint action needs a robot in "
                            f"every crew, the robot starts it")
    by_key = ({role: cands for role, cands in roles} if "roles" in m else {ag: (ag,) for ag in who})
    keys = list(by_key)
    what = "role" if "roles" in m else "agent"
    phases = []
    for j, raw_phase in enumerate(doc.sequence(m["phases"], path + ("phases",), min_len=1)):
        ppath = path + ("phases", j)
        pm = doc.mapping(raw_phase, ppath, required=("id", "location", "duration"))
        pid = doc.ident(pm["id"], ppath + ("id",))
        loc = doc.ident(pm["location"], ppath + ("location",))
        if isinstance(pm["duration"], dict):
            for key in pm["duration"]:
                if key not in by_key:
                    if what == "role":
                        doc.fail(ppath + ("duration", key), f"no role '{key}' in action '{aid}' "
                                                            f"(its roles: {', '.join(keys)})")
                    doc.fail(ppath + ("duration", key), f"agent '{key}' may not do action '{aid}' "
                                                        f"(its agents: {', '.join(who)})")
        dm = doc.mapping(pm["duration"], ppath + ("duration",), required=keys)
        got = {}
        for key in keys:
            lb, ub = doc.interval(dm[key], ppath + ("duration", key), maximum=MAX_SECONDS, unit=" s")
            for ag in by_key[key]:
                got[ag] = Interval(lb, ub)
                _check_location(doc, ppath + ("location",), loc, known[ag], ws, margin)
        durations = [(ag, got[ag]) for ag in who]
        phases.append(Phase(id=pid, location=loc, durations=tuple(durations)))
    doc.unique([p.id for p in phases], path + ("phases",), "phase")
    return Action(id=aid, name=name, agents=tuple(who), phases=tuple(phases), roles=tuple(roles),
                  needed=needed if roles else 1)


def _phase_ref(doc: Doc, raw: Any, path: tuple, actions: dict[str, Action], first: bool) -> PhaseRef:
    """``ACTION.PHASE``, or ``ACTION`` alone (its first phase after, its last phase before)."""
    text = doc.text(raw, path)
    parts = text.split(".")
    if len(parts) > 2:
        doc.fail(path, f"expected ACTION or ACTION.PHASE, found '{text}'")
    if parts[0] not in actions:
        doc.fail(path, f"unknown action '{parts[0]}' (known: {', '.join(actions)})")
    action = actions[parts[0]]
    if len(parts) == 1:
        return PhaseRef(action.id, action.phases[0 if first else -1].id)
    if parts[1] not in [p.id for p in action.phases]:
        doc.fail(path, f"action '{action.id}' has no phase '{parts[1]}'")
    return PhaseRef(action.id, parts[1])


def _event(doc: Doc, raw: Any, path: tuple, actions: dict[str, Action]) -> Event:
    text = doc.text(raw, path)
    parts = text.split(".")
    if len(parts) != 3 or parts[2] not in ("start", "end"):
        doc.fail(path, f"expected ACTION.PHASE.start or ACTION.PHASE.end, found '{text}'")
    ref = _phase_ref(doc, ".".join(parts[:2]), path, actions, first=True)
    return Event(ref.action, ref.phase, parts[2])


def _precedence(doc: Doc, raw: Any, path: tuple, actions: dict[str, Action]) -> Precedence:
    if isinstance(raw, list):
        if len(raw) != 2:
            doc.fail(path, f"expected [before, after], found a list of {len(raw)}")
        before_raw, after_raw, bpath, apath = raw[0], raw[1], path + (0,), path + (1,)
    else:
        m = doc.mapping(raw, path, required=("before", "after"))
        before_raw, after_raw, bpath, apath = m["before"], m["after"], path + ("before",), path + ("after",)
    before = _phase_ref(doc, before_raw, bpath, actions, first=False)
    after = _phase_ref(doc, after_raw, apath, actions, first=True)
    if before.action == after.action:
        doc.fail(path, f"precedence within one action ('{before.action}'): phases already run in order")
    return Precedence(before=before, after=after)


def _check_acyclic(doc: Doc, actions: list[Action], precedence: list[Precedence]) -> None:
    edges = [(str(PhaseRef(a.id, p.id)), str(PhaseRef(a.id, q.id)))
             for a in actions for p, q in zip(a.phases, a.phases[1:], strict=False)]
    edges += [(str(pr.before), str(pr.after)) for pr in precedence]
    succ: dict[str, list[str]] = {}
    for u, v in edges:
        succ.setdefault(u, []).append(v)
        succ.setdefault(v, [])
    if is_acyclic(succ):
        return
    import networkx as nx  # only to name a cycle (as before): reading a task does not import it (issue 38)

    g: nx.DiGraph = nx.DiGraph()
    g.add_edges_from(edges)
    try:
        cycle = nx.find_cycle(g)
    except nx.NetworkXNoCycle:
        return
    names = [u for u, _ in cycle] + [cycle[0][0]]
    doc.fail(("precedence",), f"the task graph has a cycle: {' -> '.join(names)}")


def _constraint(doc: Doc, raw: Any, path: tuple, actions: dict[str, Action]) -> TemporalConstraint:
    m = doc.mapping(raw, path, required=("from", "to", "bounds"))
    source = _event(doc, m["from"], path + ("from",), actions)
    target = _event(doc, m["to"], path + ("to",), actions)
    lb, ub = _signed_interval(doc, m["bounds"], path + ("bounds",))
    return TemporalConstraint(source=source, target=target, bounds=Interval(lb, ub))


def _signed_interval(doc: Doc, raw: Any, path: tuple) -> tuple[float, float]:
    """``[lb, ub]`` for ``lb <= T(to) - T(from) <= ub``: either may be negative, ``ub`` may be .inf."""
    seq = doc.sequence(raw, path)
    if len(seq) != 2:
        doc.fail(path, f"expected [lb, ub], found a list of {len(seq)}")
    lb = doc.number(seq[0], path + (0,), maximum=MAX_SECONDS, unit=" s")
    ub = doc.number(seq[1], path + (1,), allow_inf=True, maximum=MAX_SECONDS, unit=" s")
    if lb > ub:
        doc.fail(path, f"lb {lb:g} > ub {ub:g}")
    return lb, ub


def _preference(doc: Doc, raw: Any, path: tuple, actions: dict[str, Action]) -> Preference:
    m = doc.mapping(raw, path, required=("from", "to", "domain", "kind", "coefficients"))
    source = _event(doc, m["from"], path + ("from",), actions)
    target = _event(doc, m["to"], path + ("to",), actions)
    lb, ub = _signed_interval(doc, m["domain"], path + ("domain",))
    if math.isinf(ub):
        doc.fail(path + ("domain",), "a preference needs a finite domain")
    kinds = [k.value for k in PreferenceKind]
    if m["kind"] not in kinds:
        doc.fail(path + ("kind",), f"expected one of {', '.join(kinds)}, found {m['kind']!r}")
    kind = PreferenceKind(m["kind"])
    coeffs = doc.sequence(m["coefficients"], path + ("coefficients",))
    if len(coeffs) != _COEFFS[kind]:
        doc.fail(path + ("coefficients",), f"a {kind.value} preference takes {_COEFFS[kind]} "
                                           f"coefficient(s) [c0, c1, c2 ...], found {len(coeffs)}")
    values = tuple(doc.number(c, path + ("coefficients", i)) for i, c in enumerate(coeffs))
    if kind is PreferenceKind.QUADRATIC and values[2] > 0:
        doc.fail(path + ("coefficients", 2), f"quadratic preference must be concave (c2 <= 0), "
                                             f"found {values[2]:g}")
    return Preference(source=source, target=target, domain=Interval(lb, ub), kind=kind,
                      coefficients=values)


def task_to_dict(task: Task, map_path: str | None = None) -> dict[str, Any]:
    """The YAML-ready form of `task` (map path as in the task unless `map_path` is given)."""
    out: dict[str, Any] = {"name": task.name, "map": map_path or task.map_path,
                           "safety_margin": task.safety_margin}
    if task.deadline is not None:
        out["deadline"] = task.deadline
    out["agents"] = [{"id": a.id, "kind": a.kind.value, "radius": a.radius, "speed": a.speed, "start": a.start}
                     | ({} if a.travel_slack == DEFAULT_TRAVEL_SLACK else {"travel_slack": a.travel_slack})
                     for a in task.agents]
    out["actions"] = [_action_dict(a) for a in task.actions]
    out["precedence"] = [[str(p.before), str(p.after)] for p in task.precedence]
    out["constraints"] = [{"from": str(c.source), "to": str(c.target), "bounds": [c.bounds.lb, c.bounds.ub]}
                          for c in task.constraints]
    out["preferences"] = [_preference_dict(p) for p in task.preferences]
    if task.preference_sets:  # written only when present: older files round-trip unchanged
        out["preference_sets"] = {name: [_preference_dict(p) for p in prefs] for name, prefs in task.preference_sets}
    if task.sensing is not None:  # likewise
        lo, hi = task.sensing.delay
        out["sensing"] = {"path": task.sensing.path, "delay": [lo, math.inf if hi is None else hi]}
    if task.safety is not None:  # likewise
        out["safety"] = safety_to_dict(task.safety)
    return out


def _action_dict(a: Action) -> dict[str, Any]:
    """An action's YAML form; a joint action's (written only for one: older files round-trip unchanged)
    with its roles, and each phase's durations by role."""
    if not a.joint:
        return {"id": a.id, "name": a.name, "agents": list(a.agents), "phases": [
            {"id": p.id, "location": p.location, "duration": {ag: [iv.lb, iv.ub] for ag, iv in p.durations}}
            for p in a.phases]}
    if a.needed < len(a.roles):  # any `needed` of its agents: roles named after them, durations by agent
        return {"id": a.id, "name": a.name, "agents": list(a.agents), "agents_needed": a.needed, "phases": [
            {"id": p.id, "location": p.location, "duration": {ag: [iv.lb, iv.ub] for ag, iv in p.durations}}
            for p in a.phases]}
    return {"id": a.id, "name": a.name,
            "roles": {role: (cands[0] if len(cands) == 1 else {"agents": list(cands)}) for role, cands in a.roles},
            "phases": [{"id": p.id, "location": p.location,
                        "duration": {role: [p.duration(cands[0]).lb, p.duration(cands[0]).ub]
                                     for role, cands in a.roles}} for p in a.phases]}


def task_digest(task: Task) -> str:
    """SHA-256 of the task and its map as loaded (not of the files' bytes: comments do not count)."""
    payload = {"task": task_to_dict(task, map_path="-"), "map": workspace_to_dict(task.workspace)}
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _preference_dict(p: Preference) -> dict[str, Any]:
    return {"from": str(p.source), "to": str(p.target), "domain": [p.domain.lb, p.domain.ub],
            "kind": p.kind.value, "coefficients": list(p.coefficients)}


def dump_task(task: Task, path: str | os.PathLike[str]) -> None:
    """Write `task` to `path` atomically, its `map` made relative to the new file's folder."""
    target = os.fspath(path)
    map_path = task.map_path
    if task.workspace.source:
        map_path = os.path.relpath(os.path.abspath(task.workspace.source),
                                   os.path.dirname(os.path.abspath(target)))
    write_text_atomic(target, yaml.safe_dump(task_to_dict(task, map_path), sort_keys=False))
