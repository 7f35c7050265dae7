"""The compiled plan set as the dispatcher reads it: each plan with its STNU and the names of its events.

Loaded from an `hrc compile` output folder (``compiled.json``, ``stnu/*.graphml``, ``input/``: no
re-compile) or taken from an in-memory `hrc.compile.compiler.CompiledPlanSet`. For each plan the
dispatcher needs its allocation and sequences (set validation), its STNU (set ranking, decisions) and
which timepoint of that STNU each observable event is: the timepoint of ``AGENT``'s ``EVENT`` on
``ACTION.PHASE`` is ``tool_name("AGENT.PHASE.ACTION.EVENT")`` (`hrc.compile.temporal_net_creator`
names it, `hrc.temporal.graphml.tool_name` writes it), present for depart, arrive, start and end, and
for park/unpark where the plan stops at a waiting place.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hrc.compile.temporal_net_creator import ORIGIN
from hrc.errors import InputError
from hrc.model import Plan, Task
from hrc.plans import agent_legs
from hrc.temporal import STNU
from hrc.temporal.graphml import read_graphml, read_network, tool_name
from hrc.temporal.limits import MAX_FILE_BYTES

from .fastnet import PlanNet
from .messages import LEG_EVENTS

__all__ = ["PlanEntry", "PlanSet", "load_plan_set", "plan_set_from_compiled"]

LegKey = tuple[str, str, str]  # (agent, action, phase)
EventKey = tuple[str, str, str, str]  # (agent, action, phase, event)


@dataclass(frozen=True, slots=True)
class PlanEntry:
    """One compiled plan: `plan`, its compile-time `rank` and `compiled_class`, APA `preference` value,
    its `stnu`, each agent's legs as ``(action, phase)`` in order (`legs`), each leg's timepoints in the
    order they happen (`leg_points`: ``(event, timepoint)``), and the event each timepoint stands for
    (`events`). `blocked`: the compile found no motion pattern at all for it ("the co-workers would block
    each other"), so its STNU carries none of its passing orders and a check of it says nothing about the
    plan: it stays inconsistent whatever the check says (`hrc.dispatch.ranking`)."""

    plan: Plan
    rank: int
    compiled_class: str
    preference: float | None
    stnu: STNU
    legs: Mapping[str, tuple[tuple[str, str], ...]]
    leg_points: Mapping[LegKey, tuple[tuple[str, str], ...]]
    events: Mapping[str, EventKey]
    net: PlanNet  # the same network as index arrays, for re-checking it at every message
    blocked: bool = False

    @property
    def id(self) -> str:
        return self.plan.id


@dataclass(frozen=True, slots=True)
class PlanSet:
    """Every plan of a compile, in compile rank order, with the task and the compile's ``rank_by``."""

    task: Task
    plans: tuple[PlanEntry, ...]
    rank_by: str = "worst"
    source: str = ""


def _entry(task: Task, plan: Plan, rank: int, compiled_class: str, preference: float | None,
           stnu: STNU, where: str, blocked: bool = False) -> PlanEntry:
    known = set(stnu.timepoints)
    if ORIGIN not in known:
        raise InputError(where, "", f"the STNU has no origin timepoint {ORIGIN!r}")
    legs: dict[str, tuple[tuple[str, str], ...]] = {}
    points: dict[LegKey, tuple[tuple[str, str], ...]] = {}
    events: dict[str, EventKey] = {}
    for agent in task.agents:
        seq = agent_legs(task, plan, agent.id)
        legs[agent.id] = tuple((leg.action, leg.phase) for leg in seq)
        for leg in seq:
            found = []
            for event in LEG_EVENTS:
                node = tool_name(f"{agent.id}.{leg.phase}.{leg.action}.{event}")
                if node in known:
                    found.append((event, node))
                    events[node] = (agent.id, leg.action, leg.phase, event)
            if [e for e, _ in found if e in ("depart", "arrive", "start", "end")] != ["depart", "arrive", "start",
                                                                                     "end"]:
                raise InputError(where, "", f"the STNU lacks the timepoints of {agent.id}'s "
                                            f"{leg.action}.{leg.phase} (not compiled from this task?)")
            points[(agent.id, leg.action, leg.phase)] = tuple(found)
    index = {v: i for i, v in enumerate(stnu.timepoints)}
    net_legs: dict[str, list[tuple[int, int, int, int, int, int]]] = {}
    for (agent_id, _action, _phase), found_points in points.items():
        at = dict(found_points)
        net_legs.setdefault(agent_id, []).append(tuple(  # type: ignore[arg-type]
            index[at[e]] if e in at else -1 for e in ("depart", "arrive", "park", "unpark", "start", "end")))
    for agent_id in legs:  # in each agent's order (points were filled agent by agent)
        net_legs.setdefault(agent_id, [])
    net = PlanNet(stnu.timepoints, stnu.requirements, stnu.contingents, ORIGIN, net_legs)
    return PlanEntry(plan, rank, compiled_class, preference, stnu, legs, points, events, net, blocked)


def plan_set_from_compiled(cps: Any) -> PlanSet:
    """The plan set of an in-memory `hrc.compile.compiler.CompiledPlanSet` (its GraphML text is read
    back, so the dispatcher sees exactly what the folder would hold)."""
    entries = []
    for cp in cps.plans:
        where = f"<compiled plan {cp.plan.id}>"
        stnu = read_graphml(cp.graphml.encode(), where)
        entries.append(_entry(cps.task, cp.plan, cp.rank, cp.plan_class.value, cp.preference, stnu, where,
                              blocked=cp.pattern.candidates == 0))
    return PlanSet(cps.task, tuple(entries), cps.options.rank_by, "<memory>")


def _need(obj: Any, key: str, kind: type | tuple[type, ...], file: str, path: str) -> Any:
    if not isinstance(obj, dict) or key not in obj or not isinstance(obj[key], kind):
        raise InputError(file, f"{path}.{key}" if path else key, "missing or of the wrong type")
    return obj[key]


class _Archive:
    """``stnu.zip`` of a compile made with ``--stnu archive``: each plan's GraphML is a member named as
    the plan's ``stnu`` path (`hrc.compile.sink.PlanSink`)."""

    def __init__(self, folder: Path, file: str, name: str) -> None:
        self.path = folder / name
        self.file = file
        if folder.resolve() not in self.path.resolve().parents:
            raise InputError(file, "stnu_archive", "must name a file inside the output folder")
        try:
            self.zip = zipfile.ZipFile(self.path)
        except (OSError, zipfile.BadZipFile) as err:
            raise InputError(str(self.path), "", f"cannot read the STNU archive: {err}") from err

    def read(self, member: str, where: str) -> STNU:
        try:
            info = self.zip.getinfo(member)
        except KeyError:
            raise InputError(self.file, where, f"{member!r} is not in {self.path.name}") from None
        if info.file_size > MAX_FILE_BYTES:
            raise InputError(str(self.path), member, f"larger than {MAX_FILE_BYTES} bytes")
        try:
            data = self.zip.read(info)
        except (OSError, zipfile.BadZipFile, ValueError) as err:
            raise InputError(str(self.path), member, f"cannot read: {err}") from err
        return read_graphml(data, f"{self.path}:{member}")


def load_plan_set(out_dir: str | os.PathLike[str]) -> PlanSet:
    """Read an `hrc compile` output folder. Raises `InputError` naming the file and key at fault."""
    from hrc.compile.output import STNU_ARCHIVE, load_compiled_task  # the compiler's own reader of input/

    folder = Path(out_dir)
    if not folder.is_dir():
        raise InputError(str(folder), "", "not a folder (give the --out folder of hrc compile)")
    file = str(folder / "compiled.json")
    task = load_compiled_task(folder)
    try:
        data = json.loads((folder / "compiled.json").read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise InputError(file, "", f"cannot read: {err}") from err
    options = data.get("options") if isinstance(data, dict) else None
    rank_by = options.get("rank_by", "worst") if isinstance(options, dict) else "worst"
    plans = _need(data, "plans", list, file, "")
    mode = data.get("stnu_files", "graphml")
    if mode == "none":
        raise InputError(file, "stnu_files", "compiled with --stnu none: no STNUs to dispatch with (compile "
                                             "again with --stnu graphml or --stnu archive)")
    archive = _Archive(folder, file, str(data.get("stnu_archive", STNU_ARCHIVE))) if mode == "archive" else None
    agents = {a.id for a in task.agents}
    entries = []
    for i, p in enumerate(plans):
        path = f"plans[{i}]"
        allocation = _need(p, "allocation", dict, file, path)
        sequences = _need(p, "sequences", dict, file, path)
        stnu_rel = _need(p, "stnu", str, file, path)
        try:
            plan = Plan(tuple((a.id, allocation[a.id]) for a in task.actions),
                        tuple((ag.id, tuple(sequences[ag.id])) for ag in task.agents))
        except (KeyError, TypeError) as err:
            raise InputError(file, path, f"allocation or sequences do not fit the task ({err})") from err
        if plan.id != p.get("id") or set(allocation.values()) - agents:
            raise InputError(file, f"{path}.id", f"{p.get('id')!r} is not the id of its allocation and sequences")
        stnu_path = (folder / stnu_rel).resolve()
        if folder.resolve() not in stnu_path.parents:
            raise InputError(file, f"{path}.stnu", "must name a file inside the output folder")
        stnu = archive.read(stnu_rel, f"{path}.stnu") if archive is not None else read_network(stnu_path)
        pref = p.get("preference")
        pattern = p.get("pattern")
        blocked = isinstance(pattern, dict) and pattern.get("candidates") == 0  # no motion pattern was found
        entries.append(_entry(task, plan, int(p.get("rank", i + 1)), str(_need(p, "class", str, file, path)),
                              float(pref) if isinstance(pref, int | float) else None, stnu, str(stnu_path), blocked))
    if not entries:
        raise InputError(file, "plans", "no plans: nothing to dispatch")
    return PlanSet(task, tuple(entries), rank_by if isinstance(rank_by, str) else "worst", str(folder))
