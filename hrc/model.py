"""The core data model: task, workspace, agents, actions, phases, constraints, plans.

Everything here is an immutable value (frozen dataclass with tuple fields); the model imports nothing
from the rest of `hrc`. Times are seconds and lengths metres (floats) at this level; the temporal core
converts them to exact integer ticks in one place (`hrc.temporal.ticks`).

Vocabulary (../shared/DESIGN.md): an *action* is a unit of the task made of *phases*, each done at one
location; an *allocation* maps actions to agents; a *sequence* is one agent's order of actions; a *plan*
is an allocation plus one sequence per agent.
"""

from __future__ import annotations

import enum
import functools
import hashlib
import itertools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

__all__ = [
    "DEFAULT_TRAVEL_SLACK",
    "Action",
    "Agent",
    "AgentKind",
    "Event",
    "Interval",
    "Location",
    "Obstacle",
    "Phase",
    "PhaseRef",
    "Plan",
    "Precedence",
    "Preference",
    "PreferenceKind",
    "SENSING_PATHS",
    "Safety",
    "Sensing",
    "Task",
    "TemporalConstraint",
    "Workspace",
    "is_acyclic",
]


DEFAULT_TRAVEL_SLACK = 1.25
"""A person may take up to 25 % longer than at top speed on a route (see `Agent`)."""


class AgentKind(enum.Enum):
    """Who controls an agent's durations: the robot's are controllable, the human's contingent."""

    HUMAN = "human"
    ROBOT = "robot"


@dataclass(frozen=True, slots=True)
class Interval:
    """A closed interval ``[lb, ub]`` in seconds; ``ub`` may be ``inf``."""

    lb: float
    ub: float

    def __iter__(self):  # allows ``lb, ub = interval``
        yield self.lb
        yield self.ub

    def contains(self, value: float) -> bool:
        return self.lb <= value <= self.ub


@dataclass(frozen=True, slots=True)
class Location:
    """A named point on the map (m)."""

    id: str
    x: float
    y: float

    @property
    def xy(self) -> tuple[float, float]:
        return (self.x, self.y)


@dataclass(frozen=True, slots=True)
class Obstacle:
    """A simple polygon (counter-clockwise or not) the agents may not enter."""

    id: str
    polygon: tuple[tuple[float, float], ...]


@dataclass(frozen=True, slots=True)
class Workspace:
    """The shop floor: rectangular bounds ``(xmin, ymin, xmax, ymax)``, obstacles and named locations.

    `obstacles` includes those read from the optional DXF floor plan (`floorplan`, as written in the
    map file, relative to it); `source` is the map file's path as given to the loader.
    """

    name: str
    bounds: tuple[float, float, float, float]
    obstacles: tuple[Obstacle, ...]
    locations: tuple[Location, ...]
    floorplan: str | None = None
    source: str = field(default="", compare=False)

    def location(self, loc_id: str) -> Location:
        for loc in self.locations:
            if loc.id == loc_id:
                return loc
        raise KeyError(loc_id)

    @property
    def location_ids(self) -> tuple[str, ...]:
        return tuple(loc.id for loc in self.locations)


@dataclass(frozen=True, slots=True)
class Agent:
    """A co-worker: a disc of `radius` (m) moving at up to `speed` (m/s), starting at location `start`.

    `travel_slack` (>= 1) bounds how much longer than at top speed a human's travel may take: a
    person's pace varies, so their travel is a contingent duration ``[t, t * travel_slack]``. A robot
    drives as commanded; its slack is kept but not used.
    """

    id: str
    kind: AgentKind
    radius: float
    speed: float
    start: str
    travel_slack: float = DEFAULT_TRAVEL_SLACK

    @property
    def is_human(self) -> bool:
        return self.kind is AgentKind.HUMAN


@dataclass(frozen=True, slots=True)
class Phase:
    """A part of an action done at one location; `durations` maps agent id -> manipulation time bounds."""

    id: str
    location: str
    durations: tuple[tuple[str, Interval], ...]

    def duration(self, agent_id: str) -> Interval:
        for aid, interval in self.durations:
            if aid == agent_id:
                return interval
        raise KeyError(agent_id)


@dataclass(frozen=True, slots=True)
class Action:
    """A unit of the task, done by exactly one of `agents`, its phases in the given order.

    A *joint* action (`roles` not empty: Strassmair & Taylor 2014, section IV, "support the pile", left
    there for future work) is done by a *crew* at once: `roles` holds each role's name and its candidates
    (the agents that may play it, task order; the candidates of different roles are disjoint), `needed`
    how many roles a crew fills (all of them, or any `needed` of them for ``agents: [...]`` with
    ``agents_needed: k``, whose roles are named after their one agent each), and `agents` every candidate
    (task order). Each phase's `durations` are by agent (the duration of the agent's role). Which crew
    does it is a choice of the plan (`Task.crew`: the agents whose sequences hold it); each phase starts
    when every agent of the crew is at its location and ends for all at once
    (`hrc.compile.temporal_net_creator`, "joint actions").
    """

    id: str
    name: str
    agents: tuple[str, ...]
    phases: tuple[Phase, ...]
    roles: tuple[tuple[str, tuple[str, ...]], ...] = ()  # (role, candidates), in the task file's order
    needed: int = 0  # the crew's size: len(roles) (0 says so), or fewer for "any k of these agents"; 1 alone

    def __post_init__(self) -> None:
        # a role given as (role, agent) has that one candidate; `needed` 0: every role, 1 for a lone agent
        if any(isinstance(c, str) for _, c in self.roles):
            object.__setattr__(self, "roles", tuple((r, (c,) if isinstance(c, str) else tuple(c))
                                                    for r, c in self.roles))
        if self.needed == 0:
            object.__setattr__(self, "needed", len(self.roles) if self.roles else 1)

    @property
    def joint(self) -> bool:
        """Whether the action is done by a crew of agents at once (a joint action)."""
        return bool(self.roles)

    @property
    def crews(self) -> tuple[tuple[str, ...], ...]:
        """Every crew that may do a joint action, each as its agents in the order of `agents` (task
        order): `needed` of its roles (in role order) times one candidate each. Candidates of different
        roles are disjoint, so no crew comes twice: a crew is counted once. () for a one-agent action."""
        if not self.roles:
            return ()
        order = {ag: i for i, ag in enumerate(self.agents)}
        out = []
        for chosen in itertools.combinations(self.roles, self.needed):
            for pick in itertools.product(*(cands for _, cands in chosen)):
                out.append(tuple(sorted(pick, key=order.__getitem__)))
        return tuple(out)

    @property
    def crew_choice(self) -> bool:
        """Whether a joint action may be done by more than one crew (a choice of the plan)."""
        return bool(self.roles) and (self.needed < len(self.roles) or any(len(c) > 1 for _, c in self.roles))

    def role_of(self, agent_id: str) -> str:
        """The role `agent_id` plays when it takes part in a joint action."""
        for role, cands in self.roles:
            if agent_id in cands:
                return role
        raise KeyError(agent_id)

    def phase(self, phase_id: str) -> Phase:
        for ph in self.phases:
            if ph.id == phase_id:
                return ph
        raise KeyError(phase_id)


@dataclass(frozen=True, slots=True)
class PhaseRef:
    """``ACTION.PHASE``: one phase of one action."""

    action: str
    phase: str

    def __str__(self) -> str:
        return f"{self.action}.{self.phase}"


@dataclass(frozen=True, slots=True)
class Event:
    """``ACTION.PHASE.start`` or ``ACTION.PHASE.end``: the start or end of a phase's manipulation."""

    action: str
    phase: str
    boundary: str  # "start" | "end"

    def __str__(self) -> str:
        return f"{self.action}.{self.phase}.{self.boundary}"


@dataclass(frozen=True, slots=True)
class Precedence:
    """A task-graph edge: phase `after` starts no earlier than phase `before` ends."""

    before: PhaseRef
    after: PhaseRef


@dataclass(frozen=True, slots=True)
class TemporalConstraint:
    """``bounds.lb <= T(target) - T(source) <= bounds.ub`` between two events (s)."""

    source: Event
    target: Event
    bounds: Interval


class PreferenceKind(enum.Enum):
    """APA preference function shapes (Wilcox, Nikolaidis & Shah 2012, section IV)."""

    CONSTANT = "constant"
    LINEAR = "linear"
    QUADRATIC = "quadratic"


@dataclass(frozen=True, slots=True)
class Preference:
    """A soft constraint on ``d = T(target) - T(source)`` over `domain`: value ``sum(c_i * d**i)``.

    `coefficients` are ``(c0,)``, ``(c0, c1)`` or ``(c0, c1, c2)`` for constant, linear and quadratic
    preferences; quadratic ones must be concave (``c2 <= 0``) so that APA's QP stays convex.
    """

    source: Event
    target: Event
    domain: Interval
    kind: PreferenceKind
    coefficients: tuple[float, ...]

    def value(self, d: float) -> float:
        return sum(c * d**i for i, c in enumerate(self.coefficients))


SENSING_PATHS: dict[str, tuple[tuple[float, float | None], bool]] = {
    "buttons": ((0.0, 0.5), False),
    "motion": ((0.0, 7.0), True),
}
"""The known ways human events reach the robot, with their default observation delay ``[lo, hi]`` (s) and
whether an observation carries the time the event happened (``dated``). Buttons: pressed after the fact,
within 0.5 s (issue 32's "buttons 0.5 s late"), stamped when pressed. The motion detector
(`hrc.detect`): events dated back to when they happened, most within 2 s (docs/detect.md, "Measured"),
but some only when the person walks away: a first departure from a standstill 2.7-3.1 s after it, and
two actions done at one place without a step between them (kitting's inspect and label) 5.5-5.7 s after
the first ends. 7 s covers the p95 of every run's latest observation under both sensors of issue 32's
measure (docs/simulate.md, "The promise at the compile's sensing"); the classes of the workshop and of
kitting are the same at 7 s as at 0."""


@dataclass(frozen=True, slots=True)
class Sensing:
    """How the human's events reach the robot: `path` (a key of `SENSING_PATHS`, or "stated": given on the
    command line), the observation `delay` ``(lo, hi)`` in seconds (``hi`` None: never) and `dated`
    (the observation says when the event happened, so only ``hi`` matters: `hrc.temporal.delay`)."""

    path: str
    delay: tuple[float, float | None]
    dated: bool = False

    def __str__(self) -> str:
        lo, hi = self.delay
        span = f"{lo:g} s" if lo == hi else f"[{lo:g}, {'inf' if hi is None else format(hi, 'g')}] s"
        return f"{self.path} (observation delay {span}{', events dated' if self.dated else ''})"


@dataclass(frozen=True, slots=True)
class Safety:
    """Speed and separation monitoring (ISO/TS 15066:2016, 5.5.4): what the protective separation distance
    of `hrc.motion.separation` is made of. Seconds, metres, m/s, m/s^2.

    `reaction_time` T_r (sensing to the stop command); the robot's stopping either at a constant
    `deceleration` or as measured `stops` ``(speed, time, distance)`` rising with speed (ISO 10218-1,
    annex B); `human_speed` v_h (ISO 13855: 1.6 m/s); `intrusion` C; `sensor_uncertainty` Z_d and
    `robot_uncertainty` Z_r; `reduced_speed` the robot's speed in a reduced-speed zone near the person,
    None when the task allows none.
    """

    reaction_time: float
    deceleration: float | None = None
    stops: tuple[tuple[float, float, float], ...] = ()
    human_speed: float = 1.6
    intrusion: float = 0.0
    sensor_uncertainty: float = 0.0
    robot_uncertainty: float = 0.0
    reduced_speed: float | None = None


@dataclass(frozen=True, slots=True)
class Task:
    """A collaborative task on a workspace.

    `map_path` is the map's path as written in the task file (relative to it); `workspace` is that
    map, loaded. `deadline` bounds the makespan (s) from the task's start to the end of its last phase.
    `safety_margin` (m) is added to every agent's radius for clearance from obstacles and the co-worker.
    `preference_sets` are named extra preferences, one set per *worker type* (APA, section VI: group A
    places all fasteners then torques, group B torques each in turn); `preferences` hold for everyone.
    `safety`: speed and separation monitoring, whose protective separation replaces `safety_margin` between
    the co-workers (`hrc.motion.separation`); None keeps the margin.
    """

    name: str
    agents: tuple[Agent, ...]
    actions: tuple[Action, ...]
    precedence: tuple[Precedence, ...]
    constraints: tuple[TemporalConstraint, ...]
    deadline: float | None
    preferences: tuple[Preference, ...]
    map_path: str
    workspace: Workspace
    safety_margin: float = 0.1
    preference_sets: tuple[tuple[str, tuple[Preference, ...]], ...] = ()
    source: str = field(default="", compare=False)
    sensing: Sensing | None = None  # how the human's events reach the robot; None: at once (DC)
    safety: Safety | None = None
    has_joint: bool = field(init=False, repr=False, compare=False)
    """Whether some action is joint (`Action.roles`): asked per leg on hot paths, so computed once."""
    has_crew_choice: bool = field(init=False, repr=False, compare=False)
    """Whether some joint action may be done by more than one crew (`Action.crew_choice`)."""
    agent_ids: tuple[str, ...] = field(init=False, repr=False, compare=False)
    """The agents' ids in task order (computed once: asked per action when a plan is read from its code)."""
    action_ids: tuple[str, ...] = field(init=False, repr=False, compare=False)
    """The actions' ids in task order (computed once, as `agent_ids`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "has_joint", any(a.joint for a in self.actions))
        object.__setattr__(self, "has_crew_choice", any(a.crew_choice for a in self.actions))
        object.__setattr__(self, "agent_ids", tuple(a.id for a in self.agents))
        object.__setattr__(self, "action_ids", tuple(a.id for a in self.actions))

    def preference_set(self, name: str) -> tuple[Preference, ...]:
        """The named set's preferences (raises `KeyError` for an unknown name)."""
        for set_name, prefs in self.preference_sets:
            if set_name == name:
                return prefs
        raise KeyError(name)

    def agent(self, agent_id: str) -> Agent:
        for ag in self.agents:
            if ag.id == agent_id:
                return ag
        raise KeyError(agent_id)

    def action(self, action_id: str) -> Action:
        for ac in self.actions:
            if ac.id == action_id:
                return ac
        raise KeyError(action_id)

    def crew(self, action_id: str, plan: Plan) -> tuple[str, ...]:
        """The agents (task order) that do `action_id` in `plan`: those whose sequences hold it (for a
        joint action, the crew the plan chose among `Action.crews`; otherwise its one agent)."""
        return tuple(ag for ag, seq in plan.sequences if action_id in seq)

    def lead(self, action_id: str, plan: Plan | None = None) -> str:
        """Who starts a joint action (the first robot of its crew, in task order): the one whose
        controllable timepoint is the action's start, and the agent a plan's allocation names for it.
        Without `plan`, the crew is the action's only one (raises `KeyError` when the plan chooses it,
        `Action.crew_choice`). For any other action, its one agent is chosen by the plan, so this raises
        `KeyError`."""
        action = self.action(action_id)
        if not action.joint or (plan is None and action.crew_choice):
            raise KeyError(action_id)
        crew = action.agents if plan is None else self.crew(action_id, plan)
        lead = self.crew_lead(crew)
        assert lead is not None  # a joint action's every crew holds a robot (`hrc.io.task_file`)
        return lead

    def crew_lead(self, crew: Iterable[str]) -> str | None:
        """The lead of a crew (agent ids): its first robot in task order (`lead`), None without one (a crew
        the run has only partly seen)."""
        members = set(crew)
        return next((a.id for a in self.agents if a.id in members and not a.is_human), None)

    def action_precedence(self) -> tuple[tuple[str, str], ...]:
        """Distinct action pairs ``(a, b)`` such that some phase of `b` must follow some phase of `a`."""
        pairs = {(p.before.action, p.after.action) for p in self.precedence}
        return tuple(sorted(pairs))


@functools.lru_cache(maxsize=4096)
def _plan_id(sequences: tuple[tuple[str, tuple[str, ...]], ...]) -> str:
    """`Plan.id`, remembered for the plans of the moment: a compile asks for a plan's id a dozen times
    (its records, files, caches), and a SHA-256 costs more than looking up the sequences."""
    text = ";".join(f"{agent}:{','.join(seq)}" for agent, seq in sequences)
    return hashlib.sha256(text.encode()).hexdigest()[:10]


@dataclass(frozen=True, slots=True)
class Plan:
    """An allocation (action -> agent) and one sequence of actions per agent.

    A joint action is in the sequence of every agent taking part; the allocation names its lead
    (`Task.lead`), the agent that starts it.

    Both are stored in a canonical order (task order of actions, task order of agents), so equal plans
    compare equal and `id` depends only on what the plan is, not on when it was enumerated.
    """

    allocation: tuple[tuple[str, str], ...]
    sequences: tuple[tuple[str, tuple[str, ...]], ...]

    @property
    def id(self) -> str:
        """A stable 10-hex-digit id, derived from the allocation and the sequences."""
        return _plan_id(self.sequences)

    def agent_of(self, action_id: str) -> str:
        for action, agent in self.allocation:
            if action == action_id:
                return agent
        raise KeyError(action_id)

    def sequence(self, agent_id: str) -> tuple[str, ...]:
        for agent, seq in self.sequences:
            if agent == agent_id:
                return seq
        raise KeyError(agent_id)


def is_acyclic(g: Mapping[str, Sequence[str]]) -> bool:
    """Whether the graph `g` (each node's successors; every node a key) has no directed cycle (Kahn's
    algorithm: every node can be taken in a topological order; O(nodes + edges)). The task reader's
    precedence check and plan generation's validity check (`hrc.plans`) both ask it."""
    indegree = dict.fromkeys(g, 0)
    for succ in g.values():
        for v in succ:
            indegree[v] += 1
    ready = [u for u, d in indegree.items() if d == 0]
    taken = 0
    while ready:
        u = ready.pop()
        taken += 1
        for v in g[u]:
            indegree[v] -= 1
            if indegree[v] == 0:
                ready.append(v)
    return taken == len(g)
