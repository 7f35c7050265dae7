"""What the report says, as plain values: the ranked rows, the featured plans, why a class is empty.

The Markdown and HTML writers render the same `ReportData`, so the two reports cannot disagree. No
plotting here (figures live in `gantt`, `maps` and `figures`). Building it is O(plans x actions).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hrc.compile.temporal_net_creator import ref_timepoint
from hrc.motion.separation import describe as model_words
from hrc.plans import agent_legs
from hrc.report.separation import SeparationCost, separation_costs

if TYPE_CHECKING:
    from hrc.compile.classify import Classification
    from hrc.compile.compiler import ClassStats, CompiledPlan, CompiledPlanSet
    from hrc.compile.motion_pattern import MotionPattern, PassingOrder
    from hrc.model import Plan, Task

__all__ = ["CLASS_MEANING", "DetourNote", "FEATURED_TOP", "INLINE_LINKS", "MIN_WAIT", "MODEL_ASSUMPTIONS",
           "PASSING_HOW", "PREFERENCE_HEADER", "PREFERENCE_MEANING", "PassingNote", "ReportData", "Row",
           "STATS_HEADER", "agent_letters", "allocation_legend", "binding_orders", "build_report_data",
           "empty_class_reason", "featured_plans", "fmt_detour", "fmt_idle", "fmt_makespan", "fmt_motion_marks",
           "fmt_passing", "fmt_preference", "fmt_sequence", "fmt_stnu", "meeting_words", "motion_notes",
           "occupancy_words", "passing_words", "plan_motion_notes", "sensing_sentences", "split_explanation",
           "stats_rows", "table_scope"]

PREFERENCE_HEADER = "Preference (higher is better)"
"""The ranked table's preference column: APA's value has no unit (a sum of the task's preference functions)."""
PREFERENCE_MEANING = ("the worker's best achievable global preference value in the plan (APA: the sum of the "
                      "task's preference functions at their best, no unit; higher is better, and it breaks ties "
                      "between plans that finish in the same second).")

MIN_WAIT = 0.05
"""Seconds: a wait shorter than this is neither drawn (`hrc.report.gantt`) nor listed: it is rounding, not
somebody standing still."""

INLINE_LINKS = 3
"""A "why consistent" naming at most this many human durations says them in its sentence, not in a list."""

CLASS_MEANING = (
    ("DC", "dynamically controllable: the robot alone meets every constraint (the deadline, the temporal "
           "constraints and the passing orders that keep the two apart) whatever the human's durations "
           "within their bounds, deciding as it sees them."),
    ("consistent", "some timing of the team meets every constraint, but the robot cannot guarantee it alone; "
                   "the explanation names the human durations that matter."),
    ("inconsistent", "no timing meets every constraint even with every duration at its best; the plan is "
                     "kept, ranked last, as the instruction for finishing late."),
)
"""What each class promises, in the words both reports use."""

MODEL_ASSUMPTIONS = (
    "The model behind the classes: the human's walking and manipulation durations are uncertain within "
    "their bounds (walking up to the travel slack slower than at full speed, at any pace along the way); "
    "as in the paper, the robot's strategy decides when the human leaves for and starts each step "
    "(`hrc compile --human-waits no` takes that away: the human then never waits for the robot's sake); "
    "both wait only at the plan's locations, never in an aisle; the robot drives each route without "
    "stopping; an agent with nothing left to do steps out of the way; and wherever their routes or places "
    "come within reach of each other, one of them goes first, in the order the plan fixes (a detour is the "
    "robot's way round instead)."
)
"""The assumptions the classes rest on, in one paragraph."""

FEATURED_TOP = 3
"""The best plans given a section of their own (plus the best of each class)."""


@dataclass(frozen=True, slots=True)
class Row:
    """One line of the ranked table; times in seconds, None where the plan has no schedule."""

    rank: int
    plan_id: str
    plan_class: str
    allocation: str  # one letter per action, task order: "H H R R H"
    sequences: tuple[tuple[str, tuple[str, ...]], ...]
    makespan: tuple[float, float] | None
    idle: tuple[tuple[str, float], ...]
    stnu_size: tuple[int, int, int]
    stnu_link: str
    featured: bool
    detours: int = 0  # robot travels that take a detour
    passing: int = 0  # passing orders in the STNU (the plan does not imply them)
    preference: float | None = None  # APA's optimal preference value


@dataclass(frozen=True, slots=True)
class DetourNote:
    """The robot's travel `origin -> target` (to do `step`) goes round `round`: `time` instead of `free_time`."""

    agent: str
    step: str
    origin: str
    target: str
    free_time: float
    time: float
    round: str


@dataclass(frozen=True, slots=True)
class PassingNote:
    """A passing order that makes `waiting` stand still for `wait` seconds in the earliest schedule."""

    waiting: str
    first: str  # the co-worker's occupancy that goes first, in words
    step: str  # what the waiting agent then goes on to do
    wait: float
    point: tuple[float, float]
    how: str


@dataclass(frozen=True, slots=True)
class ReportData:
    """Everything both report formats show, in display order."""

    title: str
    task_name: str
    digest: str
    seed: int
    deadline: float | None
    agents: tuple[str, ...]
    actions: tuple[str, ...]
    letters: tuple[tuple[str, str], ...]  # agent -> allocation letter
    counts: tuple[tuple[str, int], ...]  # class -> plans, best class first
    empty_reasons: tuple[tuple[str, str], ...]  # class -> why no plan is in it
    rows: tuple[Row, ...]
    featured: tuple[str, ...]  # plan ids, rank order
    notes: tuple[tuple[str, tuple[tuple[DetourNote, ...], tuple[PassingNote, ...]]], ...]  # featured id -> notes
    explanations: tuple[tuple[str, str], ...]  # featured plan id -> explanation ("" for DC)
    options: tuple[tuple[str, str], ...] = ()  # compile options in words
    preferences: bool = False  # the task has preferences: the table shows each plan's value
    total: int = 0  # plans compiled; more than the rows when the table holds only the best (a large set)
    stats: tuple[ClassStats, ...] = ()  # makespans per class over all plans (only then)
    sensing: tuple[str, ...] = ()  # what the classes assume of how human events reach the robot, in sentences
    sensing_moves: tuple[tuple[int, str, str, str, str], ...] = ()  # (rank, plan, at delay 0, now, why)
    separation: tuple[SeparationCost, ...] = ()  # per plan, against the fixed margin (a task with safety:)
    margin_counts: tuple[tuple[str, int], ...] = ()  # class -> plans with the fixed margin (likewise)
    meetings: tuple[tuple[str, tuple[str, ...]], ...] = ()  # featured id -> where two people may meet (issue 37)

    @property
    def truncated(self) -> bool:
        """The ranked table shows only the best plans and the best of each class (`stats` says the rest)."""
        return self.total > len(self.rows)


def agent_letters(agents: tuple[str, ...]) -> dict[str, str]:
    """One upper-case letter per agent (its id's first), or the whole id when two would share one."""
    firsts = [a[:1].upper() for a in agents]
    return {a: (f if firsts.count(f) == 1 else a) for a, f in zip(agents, firsts, strict=True)}


def featured_plans(cps: CompiledPlanSet, top: int = FEATURED_TOP) -> tuple[CompiledPlan, ...]:
    """The `top` best plans plus the best plan of each class, in rank order (plans are ranked already)."""
    chosen = {cp.plan.id: cp for cp in cps.plans[:top]}
    seen: set[str] = set()
    for cp in cps.plans:
        cls = cp.plan_class.value
        if cls not in seen:
            seen.add(cls)
            chosen.setdefault(cp.plan.id, cp)
    return tuple(sorted(chosen.values(), key=lambda cp: cp.rank))


def _fmt(s: float) -> str:
    return f"{s:g}"


def empty_class_reason(cls: str, cps: CompiledPlanSet) -> str:
    """One sentence saying why no plan of `cps` is in class `cls` (a `PlanClass` value)."""
    plans = cps.plans
    deadline = cps.task.deadline
    counts = cps.counts()
    if not plans:
        return f"no plan is {cls}: the task has no valid plan."
    if cls == "DC":
        best = plans[0]
        verdict, key, _ = split_explanation(best.classification.explanation)
        detail = verdict + (f" \u2014 {'; '.join(key)}" if key else "")
        return (f"no plan is DC: in every plan the robot depends on the human's timing (the best plan, "
                f"{best.plan.id}: {detail}).")
    if cls == "consistent":
        n_dc = counts["DC"]
        if n_dc == cps.total:
            return ("no plan is merely consistent: every plan is DC, the robot alone can meet every "
                    "constraint whatever the human's timing within its bounds.")
        if n_dc == 0:
            return "no plan is consistent: not even human and robot together can meet every constraint."
        return ("no plan is merely consistent: where the team can meet every constraint, the robot can "
                "do so alone, whatever the human's timing.")
    if cls == "inconsistent":
        timed = [(p.classification.makespan[0], p.rank, p.plan.id) for p in plans
                 if p.classification.makespan is not None]
        if cps.summary is not None:  # the plans held are the best only: the summary knows the slowest
            timed = [(cps.summary.slowest[0], 0, cps.summary.slowest[1])] if cps.summary.slowest else []
        if deadline is not None and timed:
            slowest_ms, _, slowest_id = max(timed)
            return (f"no plan is inconsistent: even the slowest allocation ({slowest_id}, earliest "
                    f"makespan {slowest_ms:.1f} s) meets the {_fmt(deadline)} s deadline and every other "
                    "constraint.")
        return "no plan is inconsistent: every plan has a schedule that meets every constraint."
    return f"no plan is {cls}."


def _step(action: str, phase: str) -> str:
    return f"{action} {phase}"


def binding_orders(task: Task, plan: Plan, pattern: MotionPattern,
                   classification: Classification) -> tuple[PassingOrder, ...]:
    """The passing orders that are tight in the earliest schedule: where one agent waits for the other."""
    times = dict(classification.schedule)
    out = []
    for o in pattern.constrained:
        sep = o.separation
        a, b = ref_timepoint(task, plan, sep.earlier), ref_timepoint(task, plan, sep.later)
        if a in times and b in times and times[b] - times[a] - sep.gap <= 0.002:
            out.append(o)
    return tuple(out)


def _wait_before(task: Task, plan: Plan, times: dict[str, float], agent: str, leg_index: int, what: str) -> float:
    """How long `agent` stands still just before its leg's `what` event in the schedule `times`."""
    legs = agent_legs(task, plan, agent)
    leg = legs[leg_index]
    base = f"{agent}.{leg.phase}.{leg.action}"
    if what == "start":
        return times[f"{base}.start"] - times[f"{base}.arrive"]
    before = 0.0
    if leg_index > 0:
        prev = legs[leg_index - 1]
        before = times[f"{agent}.{prev.phase}.{prev.action}.end"]
    wait = times[f"{base}.depart"] - before
    if f"{base}.park" in times and f"{base}.unpark" in times:  # it waits at a waiting place on its way
        wait += times[f"{base}.unpark"] - times[f"{base}.park"]
    return wait


def motion_notes(cps: CompiledPlanSet, cp: CompiledPlan) -> tuple[tuple[DetourNote, ...], tuple[PassingNote, ...]]:
    """The plan's detours, and the passing orders that make an agent wait in the earliest schedule (at
    least `MIN_WAIT`: an order that is tight but makes nobody stand still is not listed;
    a wait at a waiting place on the way counts)."""
    return plan_motion_notes(cps.task, cp)


def plan_motion_notes(task: Task, cp: CompiledPlan) -> tuple[tuple[DetourNote, ...], tuple[PassingNote, ...]]:
    """`motion_notes` of `cp`, a plan of `task` (what the map figures need: no plan set)."""
    plan = cp.plan
    legs = {(leg.agent, leg.index): leg for a in task.agents for leg in agent_legs(task, plan, a.id)}
    detours = tuple(
        DetourNote(m.agent, _step(legs[(m.agent, m.leg)].action, legs[(m.agent, m.leg)].phase), m.origin, m.target,
                   float(m.free_time), float(m.time), m.via)
        for m in sorted(cp.motions, key=lambda m: (task.agent_ids.index(m.agent), m.leg)) if m.via)
    times = dict(cp.classification.schedule)
    passing = []
    if times:
        for o in binding_orders(task, plan, cp.pattern, cp.classification):
            ref = o.separation.later
            waiting, other = (o.conflict.robot, o.conflict.human) if o.first == "human" else (o.conflict.human,
                                                                                               o.conflict.robot)
            leg = legs[(ref.agent, ref.leg)]
            what = "start" if ref.what == "start" else "depart"
            wait = _wait_before(task, plan, times, ref.agent, ref.leg, what)
            if wait < MIN_WAIT:  # tight, but nobody stands still for it: not a wait to list
                continue
            passing.append(PassingNote(waiting.agent, other.describe(), _step(leg.action, leg.phase), wait,
                                       o.conflict.point, o.how))
    return detours, tuple(passing)


def _stnu_link(cps: CompiledPlanSet, plan_id: str) -> str:
    """Where the plan's STNU is: its GraphML file, the archive that holds it, or "" (none written)."""
    return {"graphml": f"stnu/{plan_id}.graphml", "archive": "stnu.zip", "none": ""}[cps.stnu_files]


def build_report_data(cps: CompiledPlanSet, margin: CompiledPlanSet | None = None) -> ReportData:
    """Collect what the reports show (see the module docstring); `margin`: the same task compiled with the
    fixed safety margin in place of its protective separation (`hrc.report.separation`)."""
    task = cps.task
    letters = agent_letters(task.agent_ids)
    featured = featured_plans(cps)
    featured_ids = {cp.plan.id for cp in featured}
    counts = cps.counts()
    rows = tuple(
        Row(rank=cp.rank, plan_id=cp.plan.id, plan_class=cp.plan_class.value,
            allocation=" ".join(letters[agent] for _, agent in cp.plan.allocation),
            sequences=cp.plan.sequences, makespan=cp.classification.makespan, idle=cp.classification.idle,
            stnu_size=cp.stnu_size, stnu_link=_stnu_link(cps, cp.plan.id), featured=cp.plan.id in featured_ids,
            detours=len(cp.pattern.detours), passing=len(cp.pattern.constrained), preference=cp.preference)
        for cp in cps.plans)
    return ReportData(
        title=f"Compiled schedules for {task.name}",
        task_name=task.name,
        digest=cps.digest,
        seed=cps.seed,
        deadline=task.deadline,
        agents=task.agent_ids,
        actions=task.action_ids,
        letters=tuple(letters.items()),
        counts=tuple(counts.items()),
        empty_reasons=tuple((c, empty_class_reason(c, cps)) for c, n in counts.items() if n == 0),
        rows=rows,
        featured=tuple(cp.plan.id for cp in featured),
        notes=tuple((cp.plan.id, motion_notes(cps, cp)) for cp in featured),
        explanations=tuple((cp.plan.id, cp.classification.explanation) for cp in featured),
        options=(("human waits", "yes (the robot's strategy times the human's steps)" if cps.options.human_waits
                  else "no (the human never waits for the robot's sake)"),
                 ("rank within a class by", f"{cps.options.rank_by} makespan"
                  + (" to the second, then the preference value" if task.preferences else "")),
                 ("separation", model_words(task)))
        + (() if cps.summary is None or cps.summary.best is None else
           (("plans kept", f"the best {cps.summary.best[0]} of each allocation: {cps.total:,} of the "
                           f"{cps.summary.best[1]:,} plans compiled (--best-per-allocation)"),))
        + ((("plans searched", f"{cps.total:,} plans compiled by the search compile (docs/search.md); "
                               f"{cps.search}"),) if cps.search else ()),
        preferences=bool(task.preferences),
        total=cps.total,
        stats=cps.summary.stats if cps.summary is not None and cps.total > len(rows) else (),
        sensing=sensing_sentences(cps),
        sensing_moves=tuple((cp.rank, cp.plan.id, cp.classification.class_at_delay_0.value, cp.plan_class.value,
                             cp.classification.explanation) for cp in cps.plans
                            if cp.classification.class_at_delay_0 not in (None, cp.plan_class)),
        separation=() if margin is None else separation_costs(cps, margin),
        margin_counts=() if margin is None else tuple(margin.counts().items()),
        meetings=tuple((cp.plan.id, meeting_words(cp)) for cp in featured if cp.pattern.meetings),
    )


def meeting_words(cp: CompiledPlan) -> tuple[str, ...]:
    """Where two people may meet in the plan (`hrc.motion.conflicts.people_meetings`), one line each,
    each place once: "alice K->C and bob at K, near (6.0, 4.6)"."""
    return tuple(dict.fromkeys(f"{m.robot.describe()} and {m.human.describe()}, near ({m.point[0]:.1f}, "
                               f"{m.point[1]:.1f})" for m in cp.pattern.meetings))


def sensing_sentences(cps: CompiledPlanSet) -> tuple[str, ...]:
    """What the classes assume of how the human's events reach the robot (`hrc.compile.sensing`), and how
    the classes moved from delay 0 to the stated delay."""
    sensing = cps.task.sensing
    if sensing is None:
        return ("No sensing stated (the task has no sensing:): every class assumes that the robot learns each "
                "of the human's events the instant it happens. Buttons pressed late or a motion detector "
                "learn them later: state it (sensing: in the task, or hrc compile --observation-delay) to "
                "class the plans for it.",)
    held = [cp for cp in cps.plans if cp.classification.class_at_delay_0 is not None]
    before: dict[str, int] = {}
    for cp in held:
        key = cp.classification.class_at_delay_0.value  # type: ignore[union-attr]
        before[key] = before.get(key, 0) + 1
    after: dict[str, int] = {}
    for cp in held:
        after[cp.plan_class.value] = after.get(cp.plan_class.value, 0) + 1
    order = [c for c in ("DC", "consistent", "inconsistent")]
    lost = sum(1 for cp in held if cp.classification.class_at_delay_0 is not cp.plan_class)
    return (f"Sensing: {sensing}. Every class is the class for a robot that learns each human event that late "
            "(delay controllability, Bhargava et al. 2018; a dated observation is checked at the delay's upper "
            "end, an undated one over the whole range). The motion pattern is the one chosen at delay 0.",
            "Classes at delay 0 → under this sensing"
            + (" (the plans listed)" if len(held) < cps.total else "") + ": "
            + ", ".join(f"{c} {before.get(c, 0)} → {after.get(c, 0)}" for c in order)
            + f"; {lost} plan(s) lose DC" + (":" if lost else "."))



# Text shared by both formats (plain Unicode; the writers escape it for their own syntax).

def table_scope(data: ReportData) -> str:
    """What the ranked table holds when it does not hold every plan."""
    return (f"The {len(data.rows):,} best of the {data.total:,} plans (and the best plan of each class); "
            "every plan is in compiled.json. Makespans over all plans are summarised below the table.")


def stats_rows(data: ReportData) -> list[list[str]]:
    """The all-plans statistics table: class, plans, without a schedule, earliest and worst-case makespan
    (min / quartiles / max, s)."""
    def q(v: tuple[float, ...] | None) -> str:
        return "\u2014" if v is None else " / ".join(f"{x:.1f}" for x in v)
    return [[st.plan_class, f"{st.plans:,}", f"{st.no_schedule:,}", q(st.earliest), q(st.worst)]
            for st in data.stats]


STATS_HEADER = ["Class", "Plans", "No schedule", "Earliest makespan (s): min / 25 % / median / 75 % / max",
                "Worst-case makespan (s): min / 25 % / median / 75 % / max"]

def fmt_makespan(makespan: tuple[float, float] | None) -> str:
    """``52.3–61.0`` (earliest–worst case, s), or ``—`` when the plan has no schedule."""
    return "\u2014" if makespan is None else f"{makespan[0]:.1f}\u2013{makespan[1]:.1f}"


def fmt_idle(idle: tuple[tuple[str, float], ...]) -> str:
    """Idle seconds per agent in task order: ``3.2 / 10.1``."""
    return " / ".join(f"{s:.1f}" for _, s in idle) if idle else "\u2014"


def fmt_sequence(seq: tuple[str, ...]) -> str:
    return " \u2192 ".join(seq) if seq else "\u2014"


def fmt_stnu(size: tuple[int, int, int]) -> str:
    """Timepoints / requirement links / contingent links."""
    return " / ".join(str(n) for n in size)


def fmt_preference(value: float | None) -> str:
    """APA's optimal preference value, or ``—``."""
    return "\u2014" if value is None else f"{value:.2f}"


def fmt_motion_marks(row: Row) -> str:
    """``↷1 ⇄6``: detours taken and passing orders carried, or ``—``."""
    marks = ([f"\u21b7{row.detours}"] if row.detours else []) + ([f"\u21c4{row.passing}"] if row.passing else [])
    return " ".join(marks) or "\u2014"


def fmt_detour(note: DetourNote) -> str:
    """``robot R → S2 (cube2 fetch) goes round human at T: 14.2 s instead of 9.5 s``."""
    return (f"{note.agent} {note.origin} \u2192 {note.target} ({note.step}) goes round {note.round}: "
            f"{note.time:.1f} s instead of {note.free_time:.1f} s")


def fmt_passing(note: PassingNote) -> str:
    """``robot waits 3.1 s before cube3 fetch: human S2 → T goes first at (5.0, 5.4)``."""
    first = note.first.replace("->", " \u2192 ")
    return (f"{note.waiting} waits {note.wait:.1f} s before {note.step}: {first} goes first at "
            f"({note.point[0]:.1f}, {note.point[1]:.1f}) ({note.how})")


def allocation_legend(data: ReportData) -> str:
    letters = ", ".join(f"{letter} = {agent}" for agent, letter in data.letters)
    return f"one letter per action in task order ({' '.join(data.actions)}): {letters}"


def split_explanation(text: str) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """``(verdict, constraints, links)`` of a classification's explanation.

    The compiler writes ``"VERDICT: link; link; ..."``, the links of the cycle that breaks the plan in
    words. The few that are task constraints rather than steps of the plan (the makespan deadline, a
    temporal constraint, a task-graph edge) are the ones a reader wants first; all links go into a
    collapsed list. Text without that shape is returned whole as the verdict.
    """
    head, sep, rest = text.partition(": ")
    if not sep:
        return text, (), ()
    links = tuple(part.strip() for part in rest.split("; ") if part.strip())
    key = tuple(part for part in links if "deadline" in part or part.startswith(("constraint", "task graph")))
    return head, key, links


def occupancy_words(occ: Any, end: bool) -> str:
    """When an agent's occupancy (`hrc.motion.conflicts.Occupancy`) ends (`end`) or begins, in words:
    ``the robot has left T`` / ``the human arrives at T``, ``the robot sets off R → S1``, ..."""
    a, loc, origin = f"the {occ.agent}", occ.location, occ.origin
    if occ.kind == "travel":
        if occ.part == 1:
            return f"{a} has reached its waiting place" if end else f"{a} sets off {origin} \u2192 its waiting place"
        if occ.part == 2:
            return f"{a} has arrived at {loc}" if end else f"{a} leaves its waiting place for {loc}"
        return f"{a} has arrived at {loc}" if end else f"{a} sets off {origin} \u2192 {loc}"
    if occ.part == 1:
        return f"{a} has left its waiting place" if end else f"{a} reaches its waiting place"
    if occ.leg == -1:
        return f"{a} has left its start {loc}" if end else f"{a} is at its start {loc}"
    return f"{a} has left {loc}" if end else f"{a} arrives at {loc}"


PASSING_HOW = {"chosen": "chosen by the compile", "forced": "forced by those (the other way round cannot be kept)",
               "implied": "implied by the plan"}
"""What each `passing_words` kind means, as a heading."""


def passing_words(orders: Sequence[Any]) -> tuple[tuple[str, str, tuple[tuple[float, float], ...]], ...]:
    """Each passing order once, in words: ``(how, text, places)`` with `how` ``chosen`` (by the compile),
    ``forced`` (the other way round cannot be kept) or ``implied``, and `text` like ``the robot has left T
    before the human arrives at T``. Orders that read the same (one conflict in several places, or the same
    moves on several legs) are one; the compile's choices first, then what they force, each in order of
    first appearance."""
    groups: dict[str, list[Any]] = {}
    for o in orders:
        c = o.conflict
        first, second = (c.robot, c.human) if o.first == "robot" else (c.human, c.robot)
        groups.setdefault(f"{occupancy_words(first, True)} before {occupancy_words(second, False)}", []).append(o)
    out = []
    for text, group in sorted(groups.items(), key=lambda kv: all(o.how != "chosen" for o in kv[1])):
        points = tuple(dict.fromkeys((round(o.conflict.point[0], 1), round(o.conflict.point[1], 1))
                                     for o in group))
        how = "chosen" if any(o.how == "chosen" for o in group) else group[0].how
        out.append((how, f"{text}, at {_points(points)}", points))
    return tuple(out)

def _points(points: Sequence[tuple[float, float]]) -> str:
    return ", ".join(f"({x:.1f}, {y:.1f})" for x, y in points)
