"""The compiler's files: ``compiled.json`` (schema below, versioned) and ``stnu/PLAN_ID.graphml``.

Schema version 2 (times in seconds, rounded to the millisecond; plans in rank order)::

    {"schema_version": 2, "generator": "hrc X.Y.Z", "seed": N,
     "options": {"human_waits": bool, "rank_by": "worst" | "earliest" | "nominal"},
     "task": {"name", "digest", "deadline", "agents": {ID: KIND}},
     "counts": {"DC": n, "consistent": n, "inconsistent": n},
     "plans": [{"id", "rank" (1 = best), "class": "DC" | "consistent" | "inconsistent",
                "allocation": {ACTION: AGENT}, "sequences": {AGENT: [ACTION, ...]},
                "makespan": [earliest, worst case] | null, "nominal_makespan": s | null, "idle": {AGENT: s},
                "preference": value | null (APA's optimal global preference value, `hrc.compile.preferences`),
                "stnu": "stnu/ID.graphml" | null, "stnu_size": {"timepoints", "requirement_links", "contingent_links"},
                "explanation": str | null,
                "motions": [{"agent", "leg", "from", "to", "action", "phase", "free_time", "time",
                             "detour": null | {"round": str, "points": [[x, y], ...]},
                             "park": null | {"at": LOC, "time": s}}],
                "passing": [{"robot": OCCUPANCY, "human": OCCUPANCY, "first": "robot" | "human",
                             "how": "forced" | "chosen", "point": [x, y],
                             "constraint": {"from": TIMEPOINT, "to": TIMEPOINT, "min": s}}],
                "pattern": {"conflicts": n, "implied": n, "candidates": n, "exhaustive": bool}}]}

An OCCUPANCY is ``{"kind": "travel", "leg": i, "from": LOC, "to": LOC}`` or ``{"kind": "stay", "leg": i,
"at": LOC}`` (leg indices as in `hrc.plans.agent_legs`, -1 for the start location), with ``"agent": ID``
first when the task has more than two agents (issue 37: "robot" is then the robot of the pair, "human"
the person or, for two robots, the second robot in task order; ``first`` names the slot). ``passing`` lists
the passing orders the plan's STNU carries (``T(to) - T(from) >= min``, timepoints named as the node ids
of the written STNU file: `hrc.temporal.graphml.tool_name` of `hrc.compile.temporal_net_creator`'s
names); orders the plan implies anyway are only counted (``implied``).
A ``time`` above ``free_time`` is a detour's, or a stop at a waiting place (``park``: the agent goes
to LOC, its start, in ``park.time`` of its moving time, waits there as the plan needs, then goes on; its
STNU has the timepoints ``...park`` and ``...unpark``); the robot drives a route in exactly its time.

Optional keys (schema version 2 still: readers of the keys above need no change), present only when
they say something: ``"sensing": {"path", "observation_delay": [lo, hi | null], "dated", "checked_delay",
"classes"}`` with a ``"class_at_delay_0"`` per plan (the task states how the human's events reach the robot:
every class is the class under that sensing, `hrc.compile.sensing`; a compile without it has neither key);
``"stnu_files": "archive"`` with ``"stnu_archive": "stnu.zip"`` (the STNUs are the
zip file's members named by each plan's ``stnu``, not files beside it) or ``"stnu_files": "none"`` (no
STNU written, every ``stnu`` is null): `hrc compile --stnu`; ``"partial": true`` with
``"plans_expected": N`` (the run was interrupted: ``plans`` holds the plans compiled by then, ranked
among themselves, and ``counts`` counts them); ``"identical_actions": [[ACTION, ...], ...]`` (`hrc compile
--symmetry`: of the plans that differ only by swapping the actions of a group, only the one in which
they come in this order, by agent then position, was compiled); ``"people_meet": [{"first": OCCUPANCY,
"second": OCCUPANCY, "point": [x, y]}, ...]`` per plan of a task with two or more people (where two of
them may meet on the plan's routes, whatever the timing: people give way to each other, so these are
reported, never constrained; `hrc.motion.conflicts.people_meetings`).

The file is written streaming by `hrc.compile.stream` (header, then one plan per line in rank order,
so that it diffs plan by plan); it is one JSON document for `json.load`.

**Large compiles: schema version 3.** When the plans' lines would total more than `INLINE_MAX_BYTES`
(16 MiB: kitting's 2,880 plans are 46 MB, kitting_7picks' 40,320 are 656 MB, mostly passing orders),
each line goes instead to ``plans.jsonl`` (`PLAN_LINES`) beside it, one per line in rank order (line k
is rank k), byte for byte the line schema 2 puts in ``plans`` (JSON lines: `grep`, `head` and `jq -c`
read it a plan at a time; the dispatch form's ``line_at``/``line_len`` point into it, so one plan is
read without reading the rest: `read_plan`). ``compiled.json`` then says ``"schema_version": 3`` and
``"plan_lines": {"path": "plans.jsonl", "bytes": N}`` (the file's size), ``"ranking_summary"`` (per
class: plans, plans without a schedule, quantiles of the earliest and worst-case makespans), and its ``plans``
holds one short row per plan (about 200 bytes; the first `ROWS_MAX` plans, ``"plans_listed": n``
when that is fewer than all)::

    {"id", "rank", "class", "sequences": {AGENT: [ACTION, ...]}, "makespan": [earliest, worst] | null,
     "preference": value | null}

each value as the plan's full line has it. Why a threshold and not always: a small compile's single
file (the workshop's 300 kB) is what people and tools open, and it stays the same bytes as before;
why JSON lines and not a columnar or compressed file: the lines are already written as text by the
workers (`hrc.compile.spool`) and only copied into place in rank order (no encoding, no new
dependency), and every line stays a JSON document a tool reads alone. `iter_plans` reads every full
entry of either layout.

The file is deterministic for a given task and seed: no timestamps, no host names, sorted keys where
order carries no meaning.

Beside it, ``input/`` holds the task as compiled (``input/task.yaml``, ``input/map.yaml`` and the map's
DXF floor plan if it has one), so that an output folder stands on its own: the dispatcher and the
console load the task from there (`load_compiled_task`) and check it against ``task.digest``.
"""

from __future__ import annotations

import functools
import json
import math
import os
import shutil
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hrc import __version__
from hrc.compile.compiler import CompiledPlan, CompiledPlanSet, CompileOptions
from hrc.compile.defaults import STNU_ARCHIVE, STNU_MODES  # here too, as before
from hrc.compile.dispatch_form import FORM_FOLDER, FormWriter, plan_sequences
from hrc.compile.motion_pattern import MotionPattern, PassingOrder
from hrc.compile.sensing import sensing_dict
from hrc.compile.temporal_net_creator import ref_namer
from hrc.errors import InputError
from hrc.io.map_file import workspace_to_dict
from hrc.io.task_file import load_task, task_digest, task_to_dict
from hrc.model import Plan, Task
from hrc.motion import Conflict, Motion, Occupancy, TimeRef
from hrc.plans import Leg, agent_legs
from hrc.temporal.graphml import tool_name

__all__ = ["FORM_PLACEHOLDER", "INLINE_MAX_BYTES", "JSON_TAIL", "PLAN_LINES", "ROWS_MAX", "SCHEMA_VERSION",
           "SPLIT_SCHEMA_VERSION", "STNU_ARCHIVE", "STNU_MODES", "compiled_json", "compiled_to_dict", "header_dict",
           "iter_plans", "json_head", "line_head", "line_places", "lines_path", "load_compiled_task", "plan_dict",
           "plan_line", "plan_row", "ranking_summary", "read_header", "read_plan", "split_lines", "write_compiled",
           "write_form", "write_input"]

SCHEMA_VERSION = 2
SPLIT_SCHEMA_VERSION = 3
"""``compiled.json`` with its plans' lines in `PLAN_LINES` and a short row per plan (module docstring)."""

PLAN_LINES = "plans.jsonl"
INLINE_MAX_BYTES = 16 << 20
"""Plan lines (bytes, all together) ``compiled.json`` holds itself; above, they go to `PLAN_LINES`."""

ROWS_MAX = 50_000
"""Rows ``compiled.json`` lists at most in the split layout (about 10 MB; the rest only in `PLAN_LINES`)."""



def _s(x: float) -> float:
    return round(float(x), 3)


def _occupancy(o: Occupancy, named: bool = False) -> dict[str, Any]:
    """An occupancy's entry; `named` (a task of more than two agents) adds whose it is, first."""
    who = {"agent": o.agent} if named else {}
    if o.kind == "travel":
        return who | {"kind": "travel", "leg": o.leg, "from": o.origin, "to": o.location}
    return who | {"kind": "stay", "leg": o.leg, "at": o.location}


def _named(task: Task) -> bool:
    """Whether `compiled.json` names the agent of each occupancy: with more than one person or robot (issue
    37), "robot" and "human" no longer say whose it is; a 1+1 task's files stay as they were."""
    return len(task.agents) > 2


def _xy(p: tuple[float, float]) -> list[float]:
    return [round(p[0], 3), round(p[1], 3)]


_ORDER_TEXTS: dict[tuple[int, str, str, bool], tuple[Conflict, tuple[str, str]]] = {}
_ORDER_TEXTS_CAP = 50_000  # entries kept per process (a few hundred bytes each, and their conflicts)


def _order_text(o: PassingOrder, named: bool = False) -> tuple[str, str]:
    """A passing order's ``compiled.json`` entry as JSON text before and after its constraint's two
    timepoint names (the rest names no action). Kept per conflict, by identity (the entry holds the
    conflict, so its id is not reused while it is here): conflicts come from `hrc.motion.find_conflicts`'
    per-process cache, so the same few thousand recur across the plans of a task."""
    key = (id(o.conflict), o.first, o.how, named)
    hit = _ORDER_TEXTS.get(key)
    if hit is not None and hit[0] is o.conflict:
        return hit[1]
    robot, human, point, gap = _order_values(o, named)
    text = (f'{{"robot":{_json(robot)},"human":{_json(human)},"first":{_json(o.first)},"how":{_json(o.how)},'
            f'"point":{_json(point)},"constraint":{{"from":', f',"min":{_json(gap)}}}}}')
    if len(_ORDER_TEXTS) >= _ORDER_TEXTS_CAP:
        _ORDER_TEXTS.clear()
    _ORDER_TEXTS[key] = (o.conflict, text)
    return text


def _order_values(o: PassingOrder, named: bool = False) -> tuple[dict, dict, list[float], float]:
    """The parts of a passing order's entry that name no action: its occupancies, point and gap."""
    return (_occupancy(o.conflict.robot, named), _occupancy(o.conflict.human, named), _xy(o.conflict.point),
            _s(o.separation.gap))


_Parts = tuple[list[tuple[str, str]], list[TimeRef], list[tuple[int, int]]]
_PARTS: list[tuple[MotionPattern, _Parts]] = []


def _pattern_parts(pattern: MotionPattern, named: bool = False) -> _Parts:
    """Per passing order of `pattern` (not implied): its `_order_text`; the distinct timepoints of their
    constraints (as references, which each plan names), and per order the positions of its constraint's
    two among them (a few dozen timepoints for a hundred or more orders: each plan names each once). A
    family's plans share one pattern (`hrc.compile.compiler.compile_family`), so these are gathered once,
    for the last pattern seen."""
    entry = _PARTS[0] if _PARTS else None  # read once: another thread may replace it meanwhile
    if entry is None or entry[0] is not pattern:
        orders = pattern.constrained
        at: dict[tuple[str, int, str], int] = {}
        refs: list[TimeRef] = []

        def slot(ref: TimeRef) -> int:
            k = (ref.agent, ref.leg, ref.what)
            if k not in at:
                at[k] = len(refs)
                refs.append(ref)
            return at[k]

        pairs = [(slot(o.separation.earlier), slot(o.separation.later)) for o in orders]
        entry = (pattern, ([_order_text(o, named) for o in orders], refs, pairs))
        _PARTS[:] = [entry]
    return entry[1]


_json = json.JSONEncoder(separators=(",", ":")).encode  # as json.dumps(value, separators=...), one encoder


@functools.lru_cache(maxsize=1 << 12)
def _json_tool_name(name: str) -> str:
    """A timepoint's GraphML node id (`tool_name`) as JSON (a compile writes a few hundred distinct
    ones, each thousands of times)."""
    return _json(tool_name(name))


def _constraint_names(task: Task, cp: CompiledPlan, refs: list[TimeRef]) -> list[str]:
    """The plan's names of timepoints `refs` (`_pattern_parts`), as the GraphML names them, as JSON strings."""
    name = ref_namer(task, cp.plan)
    return [_json_tool_name(name(r)) for r in refs]


_PASSING = "\x00hrc: the passing orders\x00"  # a stand-in no field of a plan's entry can hold
_PASSING_JSON = _json(_PASSING)


def plan_line(task: Task, cp: CompiledPlan, stnu: str | None = "graphml") -> str:
    """``json.dumps(plan_dict(task, cp, stnu), separators=(",", ":"))``, the plan's ``compiled.json``
    line (tested equal), built faster: the passing orders, nine tenths of a line, are spliced in from
    their text parts (`_pattern_parts`) with this plan's names, not built as dicts and encoded."""
    texts, refs, pairs = _pattern_parts(cp.pattern, _named(task))
    names = _constraint_names(task, cp, refs)
    entries = [f"{before}{names[a]},\"to\":{names[b]}{after}"
               for (before, after), (a, b) in zip(texts, pairs, strict=True)]
    text = _json(_plan_fields(task, cp, stnu, _PASSING, len(entries), _MOTIONS))
    if text.count(_PASSING_JSON) != 1 or text.count(_MOTIONS_JSON) != 1:  # pragma: no cover - the stand-ins
        return _json(plan_dict(task, cp, stnu))                           # hold a NUL, which no id or name may
    legs = _legs(task, cp.plan)
    motions = "[" + ",".join(_motion_text(m, legs[(m.agent, m.leg)]) for m in cp.motions) + "]"
    return text.replace(_MOTIONS_JSON, motions).replace(_PASSING_JSON, "[" + ",".join(entries) + "]")


_MOTIONS = "\x00hrc: the motions\x00"
_MOTIONS_JSON = _json(_MOTIONS)
_MOTION_TEXTS: dict[tuple[int, str, str], tuple[Motion, str]] = {}


def _motion_text(m: Motion, leg: Leg) -> str:
    """A motion's ``compiled.json`` entry as JSON text, kept per motion, by identity (the entry holds the
    motion): a leg's motion along its shortest route is one object for every plan that has that leg
    (`hrc.motion.plan_motions`), with the step the plan does there."""
    key = (id(m), leg.action, leg.phase)
    hit = _MOTION_TEXTS.get(key)
    if hit is not None and hit[0] is m:
        return hit[1]
    text = _json(_motion_dict(m, leg))
    if len(_MOTION_TEXTS) >= _ORDER_TEXTS_CAP:
        _MOTION_TEXTS.clear()
    _MOTION_TEXTS[key] = (m, text)
    return text


def plan_dict(task: Task, cp: CompiledPlan, stnu: str | None = "graphml") -> dict[str, Any]:
    """One plan's entry of ``compiled.json`` (``stnu``: the `STNU_MODES` value; None writes ``"stnu": null``)."""
    name = ref_namer(task, cp.plan)
    passing = []
    for o in cp.pattern.constrained:
        robot, human, point, gap = _order_values(o, _named(task))
        passing.append({"robot": robot, "human": human, "first": o.first, "how": o.how, "point": point,
                        "constraint": {"from": tool_name(name(o.separation.earlier)),
                                       "to": tool_name(name(o.separation.later)), "min": gap}})
    return _plan_fields(task, cp, stnu, passing, len(passing))


def _legs(task: Task, plan: Plan) -> dict[tuple[str, int], Leg]:
    return {(leg.agent, leg.index): leg for a in task.agents for leg in agent_legs(task, plan, a.id)}


def _motion_dict(m: Motion, leg: Leg) -> dict[str, Any]:
    return {
        "agent": m.agent, "leg": m.leg, "from": m.origin, "to": m.target,
        "action": leg.action, "phase": leg.phase,
        "free_time": _s(m.free_time), "time": _s(m.time),
        "detour": {"round": m.via, "points": [_xy(p) for p in m.points]} if m.via else None,
        "park": {"at": m.park, "time": _s(m.park_time)} if m.park else None,
    } | ({"speed": m.speed} if m.speed else {})  # a reduced speed only: files without one stay as they were


def _plan_fields(task: Task, cp: CompiledPlan, stnu: str | None, passing: Any, n_passing: int,
                 motions: Any = None) -> dict[str, Any]:
    """A plan's entry (`passing` and `motions`: the values of those keys, or stand-ins spliced over
    later, `plan_line`; `motions` None: the motions' entries)."""
    plan, c = cp.plan, cp.classification
    if motions is None:
        legs = _legs(task, plan)
        motions = [_motion_dict(m, legs[(m.agent, m.leg)]) for m in cp.motions]
    pattern = cp.pattern
    return {
        "id": plan.id,
        "rank": cp.rank,
        "class": c.plan_class.value,
        "allocation": dict(plan.allocation),
        "sequences": {agent: list(seq) for agent, seq in plan.sequences},
        "makespan": None if c.makespan is None else [_s(c.makespan[0]), _s(c.makespan[1])],
        "nominal_makespan": None if c.nominal is None else _s(c.nominal),
        "idle": {agent: _s(t) for agent, t in c.idle},
        "preference": None if cp.preference is None else round(cp.preference, 6),
        "stnu": f"stnu/{plan.id}.graphml" if stnu not in (None, "none") else None,
        "stnu_size": dict(zip(("timepoints", "requirement_links", "contingent_links"), cp.stnu_size, strict=True)),
        "explanation": c.explanation or None,
        **({} if c.class_at_delay_0 is None else {"class_at_delay_0": c.class_at_delay_0.value}),
        "motions": motions,
        "passing": passing,
        "pattern": {"conflicts": len(pattern.orders), "implied": len(pattern.orders) - n_passing,
                    "candidates": pattern.candidates, "exhaustive": pattern.exhaustive},
    } | ({"people_meet": [{"first": _occupancy(c.robot, True), "second": _occupancy(c.human, True),
                           "point": _xy(c.point)} for c in pattern.meetings]} if _people(task) > 1 else {})


def _people(task: Task) -> int:
    return sum(a.is_human for a in task.agents)


def header_dict(task: Task, seed: int, digest: str, options: CompileOptions, counts: dict[str, int],
                stnu: str = "graphml", partial: tuple[int, int] | None = None,
                symmetric: tuple[tuple[str, ...], ...] = (), best: tuple[int, int] | None = None,
                form: str | None = None, extra: dict[str, Any] | None = None,
                lines: tuple[int, int] | None = None, summary: dict[str, Any] | None = None) -> dict[str, Any]:
    """``compiled.json`` without its plans. The optional keys appear only when they say something:
    ``stnu_files`` ("none" or "archive") and ``stnu_archive`` when the STNUs are not one GraphML file per
    plan; ``partial`` and ``plans_expected`` when the run was interrupted (`partial`: plans written, plans
    expected, the latter possibly an upper bound); ``identical_actions`` when only one plan per
    relabelling of identical actions was compiled (``hrc compile --symmetry``); ``best_per_allocation`` and
    ``plans_compiled`` when only the best plans of each allocation are listed (`best`: how many, and the
    plans compiled; ``hrc compile --best-per-allocation``); ``dispatch_form`` when the dispatch form was
    written (`form`: the SHA-256 of its ``form.json``, `hrc.compile.dispatch_form`); ``plan_lines`` (and
    ``"schema_version": 3``) when the plans' lines are in `PLAN_LINES` (`lines`: its size in bytes and the
    rows ``compiled.json`` lists, ``plans_listed`` when fewer than the plans; `summary`: the ranking at a
    glance, per class its plans and makespan quantiles, `ranking_summary`); `extra`'s entries last (a
    search compile's ``search``: what it guarantees, `hrc.compile.search.SearchOutcome.header`)."""
    out: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION if lines is None else SPLIT_SCHEMA_VERSION,
        "generator": f"hrc {__version__}",
        "seed": seed,
        "options": {"human_waits": options.human_waits, "rank_by": options.rank_by},
        "task": {"name": task.name, "digest": digest, "deadline": task.deadline,
                 "agents": {a.id: a.kind.value for a in task.agents}},
        "counts": counts,
    }
    if task.sensing is not None:
        out["sensing"] = sensing_dict(task.sensing)
    if stnu != "graphml":
        out["stnu_files"] = stnu
        if stnu == "archive":
            out["stnu_archive"] = STNU_ARCHIVE
    if symmetric:
        out["identical_actions"] = [list(g) for g in symmetric]
    if best is not None:
        out["best_per_allocation"] = best[0]
        out["plans_compiled"] = best[1]
    if partial is not None:
        out["partial"] = True
        out["plans_expected"] = partial[1]
    if lines is not None:
        out["plan_lines"] = {"path": PLAN_LINES, "bytes": lines[0]}
        if lines[1] < sum(counts.values()):
            out["plans_listed"] = lines[1]
        if summary is not None:
            out["ranking_summary"] = summary
    if form is not None:
        out["dispatch_form"] = {"path": FORM_FOLDER, "sha256": form}
    if extra:
        out.update(extra)
    return out


def compiled_to_dict(cps: CompiledPlanSet) -> dict[str, Any]:
    data = header_dict(cps.task, cps.seed, cps.digest, cps.options, cps.counts())
    data["plans"] = [plan_dict(cps.task, cp) for cp in cps.plans]
    return data


def write_input(task: Task, out_dir: Path) -> None:
    """Copy the task as compiled into ``out_dir/input/``: task.yaml, map.yaml and the DXF floor plan."""
    folder = out_dir / "input"
    folder.mkdir(parents=True, exist_ok=True)
    ws = task.workspace
    floorplan = None
    if ws.floorplan is not None:
        floorplan = os.path.basename(ws.floorplan)
        shutil.copyfile(os.path.join(os.path.dirname(ws.source), ws.floorplan), folder / floorplan)
    (folder / "map.yaml").write_text(yaml.safe_dump(workspace_to_dict(ws, floorplan), sort_keys=False),
                                     encoding="utf-8")
    (folder / "task.yaml").write_text(yaml.safe_dump(task_to_dict(task, "map.yaml"), sort_keys=False),
                                      encoding="utf-8")


_HEADER_END = ',\n "plans": [\n'
_HEADER_MAX = 1 << 22  # bytes: a header is a few hundred bytes (identical_actions may add a few kB)


def read_header(out_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """``compiled.json``'s header (everything but its plans, `header_dict`) without reading its plans: a
    large compile's file is gigabytes. Raises `InputError` naming the file when it is not an hrc compile
    output."""
    compiled = Path(out_dir) / "compiled.json"
    try:
        with open(compiled, "rb") as f:
            head = f.read(_HEADER_MAX)
        at = head.find(_HEADER_END.encode())
        if at < 0:
            raise ValueError("no plans list after the header")
        data = json.loads(head[:at].decode("utf-8") + "\n}")
        if not isinstance(data, dict):
            raise ValueError("not a JSON object")
        data["task"]["digest"]  # noqa: B018 - every compile output has it
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise InputError(str(compiled), "", f"not an hrc compile output ({type(err).__name__}: {err})") from err
    return data


def load_compiled_task(out_dir: str | os.PathLike[str]) -> Task:
    """The task of an `hrc compile` output folder, checked against the digest in its ``compiled.json``.

    Raises `InputError` (naming the file) when the folder is not such an output or the copy was edited.
    """
    folder = Path(out_dir)
    digest = read_header(folder)["task"]["digest"]
    task = load_task(folder / "input" / "task.yaml")
    if task_digest(task) != digest:
        raise InputError(str(folder / "input" / "task.yaml"), "",
                         "the task differs from the one compiled (task.digest in compiled.json)")
    return task


def write_compiled(cps: CompiledPlanSet, out_dir: Path, inline_max: int = INLINE_MAX_BYTES) -> None:
    """Write ``compiled.json``, the STNUs, the dispatch form and ``input/`` into `out_dir` (a staging
    folder: `atomic_dir`): the same bytes as a streamed compile of the same plans. The plans' lines go
    to `PLAN_LINES` when they total more than `inline_max` bytes (the module docstring)."""
    write_input(cps.task, out_dir)
    (out_dir / "stnu").mkdir(parents=True, exist_ok=True)
    for cp in cps.plans:
        (out_dir / "stnu" / f"{cp.plan.id}.graphml").write_text(cp.graphml, encoding="utf-8")
    data = compiled_to_dict(cps)
    lines = [json.dumps(p, separators=(",", ":")).encode("utf-8") for p in data.pop("plans")]
    split = split_lines([len(x) for x in lines], inline_max)
    rows = None if split is None else [plan_row(cp.plan.id, cp.rank, cp.plan_class.value, cp.plan.sequences,
                                                cp.classification.makespan, cp.preference)
                                       for cp in cps.plans[:ROWS_MAX]]
    summary = None
    if split is not None:
        spans = [cp.classification.makespan or (math.inf, math.inf) for cp in cps.plans]
        summary = ranking_summary(np.array([cp.plan_class.order for cp in cps.plans]),
                                  np.array([round(a, 6) for a, _ in spans]), np.array([round(b, 6) for _, b in spans]))
    data = header_dict(cps.task, cps.seed, cps.digest, cps.options, cps.counts(), form=FORM_PLACEHOLDER,
                       lines=None if split is None else (split[0], len(rows or ())), summary=summary)
    places = line_places(data, (len(x) for x in lines)) if split is None else split[1]
    data["dispatch_form"]["sha256"] = write_form(out_dir, cps, places)
    if rows is not None:
        (out_dir / PLAN_LINES).write_bytes(b"".join(x + b"\n" for x in lines))
        lines = [r.encode("utf-8") for r in rows]
    (out_dir / "compiled.json").write_bytes(json_head(data).encode("utf-8") + b",\n".join(lines)
                                            + JSON_TAIL.encode("utf-8"))


def ranking_summary(cls: np.ndarray, early: np.ndarray, worst: np.ndarray) -> dict[str, Any]:
    """A split ``compiled.json``'s ``ranking_summary`` from every listed plan's class order (0 DC, 1
    consistent, 2 inconsistent) and makespans (rounded to 6 decimals as `hrc.compile.compiler.rank_key`
    keeps them; infinite: no schedule): per class its plans, those without a schedule, and the quantiles
    (min, 25 %, median, 75 %, max) of the earliest and worst-case makespans (None without any)."""
    out: dict[str, Any] = {}
    for order, name in enumerate(("DC", "consistent", "inconsistent")):
        mine = cls == order
        ok = mine & np.isfinite(worst)
        q = (0, 25, 50, 75, 100)
        out[name] = {"plans": int(mine.sum()), "no_schedule": int((mine & ~np.isfinite(worst)).sum()),
                     "earliest": [round(float(x), 3) for x in np.percentile(early[ok], q)] if ok.any() else None,
                     "worst": [round(float(x), 3) for x in np.percentile(worst[ok], q)] if ok.any() else None}
    return out


def split_lines(sizes: Sequence[int], inline_max: int) -> tuple[int, list[tuple[int, int]]] | None:
    """None when plan lines of `sizes` bytes (rank order) stay in ``compiled.json`` (together, with the
    ``,\n`` between them, at most `inline_max` bytes); else the size of `PLAN_LINES` holding them and the
    ``(offset, length)`` of each line in it (each line followed by a newline)."""
    if sum(sizes) + 2 * max(len(sizes) - 1, 0) <= inline_max:
        return None
    places, at = [], 0
    for size in sizes:
        places.append((at, size))
        at += size + 1
    return at, places


def plan_row(plan_id: str, rank: int, cls: str, sequences: Iterable[tuple[str, Sequence[str]]],
             makespan: tuple[float, float] | None, preference: float | None) -> str:
    """A plan's row in a split ``compiled.json`` (schema version 3, the module docstring): its id, rank,
    class, sequences, makespan and preference, each as its full line has it."""
    return _json({"id": plan_id, "rank": rank, "class": cls,
                  "sequences": {agent: list(seq) for agent, seq in sequences},
                  "makespan": None if makespan is None else [_s(makespan[0]), _s(makespan[1])],
                  "preference": None if preference is None else round(preference, 6)})


def lines_path(out_dir: str | os.PathLike[str], header: dict[str, Any] | None = None) -> Path:
    """The file holding the plans' full lines of an output folder: `PLAN_LINES` when its
    ``compiled.json`` (`header`, read if not given) names it, else ``compiled.json`` itself."""
    header = read_header(out_dir) if header is None else header
    named = header.get("plan_lines")
    return Path(out_dir) / (PLAN_LINES if isinstance(named, dict) else "compiled.json")


def iter_plans(out_dir: str | os.PathLike[str]) -> Iterator[dict[str, Any]]:
    """Every plan's full entry (schema version 2's, `plan_dict`) of an output folder in rank order, from
    ``compiled.json`` or `PLAN_LINES`, one line at a time. Raises `InputError` naming the file when a
    line is not JSON."""
    path = lines_path(out_dir)
    with open(path, "rb") as f:
        for number, line in enumerate(f, 1):
            if line.startswith(b'{"id":'):
                try:
                    yield json.loads(line.rstrip(b",\n"))
                except ValueError as err:
                    raise InputError(str(path), f"line {number}", f"not a plan's entry ({err})") from err


def read_plan(out_dir: str | os.PathLike[str], plan_id: str) -> dict[str, Any] | None:
    """One plan's full entry (`plan_dict`) by id, None when the output has no such plan: read at the
    place the dispatch form gives (its ``plans.npy`` memory-mapped, one line read: milliseconds at 40,320
    plans), or found line by line in an output without a form (``--stnu none``). Raises `InputError`
    naming the file when the output or the line is not what it should be."""
    folder = Path(out_dir)
    header = read_header(folder)
    path = lines_path(folder, header)
    where: tuple[int, int] | None = None
    form = folder / FORM_FOLDER / "plans.npy"
    if isinstance(header.get("dispatch_form"), dict) and form.is_file():
        try:
            rows = np.load(form, mmap_mode="r", allow_pickle=False)
            hit = np.flatnonzero(rows["id"] == plan_id.encode("ascii", "replace"))
        except (OSError, ValueError) as err:
            raise InputError(str(form), "", f"cannot read it ({err})") from err
        if not len(hit):
            return None
        where = int(rows["line_at"][hit[0]]), int(rows["line_len"][hit[0]])
    try:
        if where is not None and where[1]:
            with open(path, "rb") as f:
                f.seek(where[0])
                line = json.loads(f.read(where[1]))
            if not isinstance(line, dict) or line.get("id") != plan_id:
                raise ValueError(f"plan {plan_id}'s line is not where the dispatch form says")
            return line
    except (OSError, ValueError) as err:
        raise InputError(str(path), "", f"cannot read plan {plan_id} ({err})") from err
    return next((p for p in iter_plans(folder) if p.get("id") == plan_id), None)


def write_form(out_dir: Path, cps: CompiledPlanSet, places: Sequence[tuple[int, int]]) -> str:
    """The dispatch form of `cps`' plans (rank order) in ``out_dir/dispatch/``, each plan's line at
    `places` in ``compiled.json``; returns the SHA-256 of its ``form.json``."""
    for wide in (False, True):
        writer = FormWriter(out_dir, cps.task, cps.options.rank_by, wide)
        try:
            for cp, (at, size) in zip(cps.plans, places, strict=True):
                writer.add(cp.plan.id, cp.plan_class.value, cp.preference, plan_sequences(cps.task, cp.plan), cp.form,
                           at, size)
        except OverflowError:
            writer.abandon()
            if wide:  # pragma: no cover - every bound of the temporal core fits 64 bits
                raise
            continue
        return writer.close()
    raise AssertionError("unreachable")  # pragma: no cover


def compiled_json(cps: CompiledPlanSet) -> str:
    """``compiled.json``'s text without its dispatch form (`write_compiled` writes both): the header
    indented, then one plan per line (C-speed encoding; a 2,880-plan file takes 0.3 s instead of 3 s with
    `indent` everywhere, and still diffs plan by plan)."""
    data = compiled_to_dict(cps)
    plans = data.pop("plans")
    body = ",\n".join(json.dumps(p, separators=(",", ":")) for p in plans)
    return json_head(data) + body + JSON_TAIL


def json_head(header: dict[str, Any]) -> str:
    """``compiled.json``'s text up to its first plan line (`header_dict` indented, then ``"plans": [``)."""
    return json.dumps(header, indent=1)[:-2] + _HEADER_END


JSON_TAIL = "\n ]\n}\n"
"""``compiled.json``'s text after its last plan line."""


FORM_PLACEHOLDER = "0" * 64
"""A dispatch form digest's length: `header_dict` with it is as long as with the real one, so the places of
the plan lines (`line_places`) are known before the form that records them is written."""


def line_places(header: dict[str, Any], sizes: Iterable[int]) -> list[tuple[int, int]]:
    """``(offset, length)`` in bytes of each plan line of ``compiled.json`` whose header is `header` and
    whose lines are `sizes` bytes long (without the ``,\n`` between them), in order."""
    at = len(json_head(header).encode("utf-8"))
    out = []
    for k, size in enumerate(sizes):
        at += 2 if k else 0
        out.append((at, size))
        at += size
    return out


def line_head(plan_id: str, rank: int) -> str:
    """The start of a plan's ``compiled.json`` line, up to its rank and the comma after it: the rest (its
    tail) is the same wherever the plan ranks, so the compile writes it once and copies it."""
    return f'{{"id":{json.dumps(plan_id)},"rank":{rank},'
