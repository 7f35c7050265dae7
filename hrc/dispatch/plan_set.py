"""The compiled plan set as the dispatcher reads it: the compile's dispatch form, and each plan's STNU and
events on demand.

Loaded from an `hrc compile` output folder (`load_plan_set`: ``dispatch/``, the form the compile wrote,
checked against ``compiled.json``'s header; ``input/`` for the task; nothing compiled again) or made from
an in-memory `hrc.compile.compiler.CompiledPlanSet` (`plan_set_from_compiled`: the simulator). Either way
the dispatcher works on the same arrays (`hrc.compile.dispatch_form.DispatchForm`), and builds no Python
object per plan: set validation and set ranking read the arrays; a plan's `PlanEntry` (its STNU as an
`STNU` value, its legs and the event each timepoint stands for) is made only for the plans a decision or
a caller looks at (`PlanSet.entry`), and a few are kept.

An output written before the form existed (no ``dispatch_form`` in ``compiled.json``) is read the old
way, its GraphML files parsed and the form built from them in memory: slower, the same answers.

The timepoint of ``AGENT``'s ``EVENT`` on ``ACTION.PHASE`` is ``tool_name("AGENT.PHASE.ACTION.EVENT")``
(`hrc.compile.temporal_net_creator` names it, `hrc.temporal.graphml.tool_name` writes it), present for
depart, arrive, start and end, and for park/unpark where the plan stops at a waiting place.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, overload

import numpy as np

from hrc.compile.dispatch_form import DispatchForm, build_form, plan_record, read_form
from hrc.compile.temporal_net_creator import ORIGIN
from hrc.errors import InputError
from hrc.io.folder_use import FolderUse
from hrc.model import Plan, Task
from hrc.plans import agent_legs
from hrc.temporal import STNU
from hrc.temporal.graphml import read_graphml, read_network, tool_name
from hrc.temporal.limits import MAX_FILE_BYTES

from .messages import LEG_EVENTS

__all__ = ["PlanEntry", "PlanSet", "content_digest", "load_plan_set", "plan_entry", "plan_set_from_compiled"]

LegKey = tuple[str, str, str]  # (agent, action, phase)
EventKey = tuple[str, str, str, str]  # (agent, action, phase, event)

_CLASSES = ("DC", "consistent", "inconsistent")
_ENTRIES_KEPT = 64  # PlanEntry values kept (a decision looks at one or two plans a message)


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
    blocked: bool = False

    @property
    def id(self) -> str:
        return self.plan.id


_OWN_LEG = ("depart", "arrive", "start", "end")
"""The timepoints a leg of an agent's own action has, in order (a joint action's lead's leg too).

Compared by name: atheris 2.3.0's instrumentation (the fuzz targets, docs/fuzzing.md) miscompiles
``x != (a if c else [1, 2, 3])`` on Python 3.11: the comparison returns ``a`` when ``c`` holds."""
_SHARED_LEG = ("depart", "arrive")
"""The timepoints of another taker's leg of a joint action: its phase starts and ends on the lead's."""


def plan_entry(task: Task, plan: Plan, rank: int, compiled_class: str, preference: float | None, stnu: STNU,
               where: str, blocked: bool = False) -> PlanEntry:
    """A `PlanEntry` of `plan` with its `stnu` (timepoints named as its GraphML file names them). Raises
    `InputError` naming `where` when the STNU lacks a leg's timepoints."""
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
            # a joint action's phase starts and ends once, on its lead's leg (`hrc.model.Task.lead`): the
            # other agents' legs of it have a departure and an arrival only
            shared = task.has_joint and task.action(leg.action).joint and plan.agent_of(leg.action) != agent.id
            expected = _SHARED_LEG if shared else _OWN_LEG  # (a name, not a literal: see _OWN_LEG)
            if tuple(e for e, _ in found if e in _OWN_LEG) != expected:
                raise InputError(where, "", f"the STNU lacks the timepoints of {agent.id}'s "
                                            f"{leg.action}.{leg.phase} (not compiled from this task?)")
            points[(agent.id, leg.action, leg.phase)] = tuple(found)
    return PlanEntry(plan, rank, compiled_class, preference, stnu, legs, points, events, blocked)


class PlanSet:
    """Every plan of a compile, in compile rank order (index 0 the best), as its dispatch `form`; with the
    task, the compile's ``rank_by`` and where it came from. ``len`` is the plan count; `entry` (and the
    `plans` view) make a plan's `PlanEntry` when asked for one."""

    def __init__(self, form: DispatchForm, source: str = "", content: str | None = None,
                 use: FolderUse | None = None, compiled: BinaryIO | None = None,
                 settings: Mapping[str, Any] | None = None) -> None:
        self.form = form
        self.task: Task = form.task
        self.rank_by: str = form.rank_by
        self.source = source or form.source
        self.use = use
        """The output folder held while this set lives (`hrc.io.folder_use`: no compile replaces it)."""
        self.compiled = compiled
        """That folder's file of the plans' lines (``compiled.json``, or ``plans.jsonl`` beside a large
        one), open: read from at the form's offsets (a plan's motions), whatever is at its path later."""
        self._content = content
        self._settings = settings  # the compile's seed and options, where `content` is a folder's (`named_by`)
        self._index: dict[str, int] | None = None
        self._entries: OrderedDict[int, tuple[PlanEntry, dict[str, int]]] = OrderedDict()
        self._digest: str | None = None

    def __len__(self) -> int:
        return len(self.form)

    def close(self) -> None:
        """Close ``compiled.json`` and let the folder go (a compile may replace it then); also when the set
        is collected."""
        compiled, self.compiled = getattr(self, "compiled", None), None
        if compiled is not None:
            compiled.close()
        use = getattr(self, "use", None)
        if use is not None:
            use.release()

    def __del__(self) -> None:
        self.close()

    def id(self, p: int) -> str:
        return self.form.plan_id(p)

    def index(self, plan_id: str) -> int:
        """The index of the plan with this id; `KeyError` if there is none."""
        if self._index is None:
            self._index = {raw.decode("ascii").rstrip(): p for p, raw in enumerate(self.form.plans["id"].tolist())}
        return self._index[plan_id]

    @property
    def digest(self) -> str:
        """What a log names the set by: SHA-256 of the task's digest, every plan id in rank order and the
        set's content (`content_digest`: every plan's STNU, class, preference, and the compile's seed and
        options, which determine every motion), so that a log of another compile of the same task (another
        seed) is refused as such when it is opened, not at its first answer that differs."""
        if self._digest is None:
            content = self._content if self._content is not None else content_digest(self.form)
            self._digest = self._name(content)
        return self._digest

    def _name(self, content: str) -> str:
        from hrc.io.task_file import task_digest

        ids = ",".join(raw.decode("ascii").rstrip() for raw in self.form.plans["id"].tolist())
        return hashlib.sha256(f"{task_digest(self.task)}:{ids}:{content}".encode()).hexdigest()[:16]

    def named_by(self, digest: object) -> bool:
        """Whether a log naming its set by `digest` was written for this set: `digest`, or for a set read
        from a folder's dispatch form (whose `digest` hashes ``form.json``, at no cost), the digest the same
        compile has in memory (`content_digest` of the arrays, as ``hrc simulate --keep-logs`` names its
        runs' logs): compared only when the first is not it, O(size of the form)."""
        if digest == self.digest:
            return True
        return self._settings is not None and digest == self._name(content_digest(self.form, self._settings))

    def entry(self, p: int) -> PlanEntry:
        """Plan `p`'s `PlanEntry`, its STNU made from the form's arrays (a few are kept)."""
        return self._entry(p)[0]

    def node_index(self, p: int) -> dict[str, int]:
        """Plan `p`'s timepoints by name: their index in the form's arrays (and in its entry's STNU)."""
        return self._entry(p)[1]

    def _entry(self, p: int) -> tuple[PlanEntry, dict[str, int]]:
        found = self._entries.get(p)
        if found is not None:
            self._entries.move_to_end(p)
            return found
        form = self.form
        row = form.plans[p]
        pref = float(row["preference"])
        entry = plan_entry(self.task, form.plan(p), int(row["rank"]), _CLASSES[int(row["cls"])],
                           None if pref != pref else pref, form.stnu(p), f"{self.source}: plan {form.plan_id(p)}",
                           bool(row["blocked"]))
        found = self._entries[p] = (entry, {name: i for i, name in enumerate(entry.stnu.timepoints)})
        if len(self._entries) > _ENTRIES_KEPT:
            self._entries.popitem(last=False)
        return found

    @property
    def plans(self) -> _Entries:
        """Every plan's `PlanEntry`, made as they are read (a sequence view: index it, or iterate)."""
        return _Entries(self)


class _Entries(Sequence[PlanEntry]):
    def __init__(self, plan_set: PlanSet) -> None:
        self._set = plan_set

    def __len__(self) -> int:
        return len(self._set)

    @overload
    def __getitem__(self, i: int) -> PlanEntry: ...
    @overload
    def __getitem__(self, i: slice) -> list[PlanEntry]: ...

    def __getitem__(self, i: int | slice) -> PlanEntry | list[PlanEntry]:
        if isinstance(i, slice):
            return [self._set.entry(k) for k in range(len(self._set))[i]]
        if not -len(self._set) <= i < len(self._set):
            raise IndexError(i)
        return self._set.entry(i % len(self._set))

    def __iter__(self) -> Iterator[PlanEntry]:
        return (self._set.entry(k) for k in range(len(self._set)))


def content_digest(form: DispatchForm, header: Mapping[str, Any] | None = None) -> str:
    """SHA-256 of what the form's arrays hold (every plan's row but where its line lies in
    ``compiled.json``, its sequences, timepoints, edges and contingent links, integers as 64 bits) and of
    the compile's seed and options in `header` (``compiled.json``'s, or the in-memory set's): the
    motions are a function of the task, the seed and the options (the compile is deterministic).
    O(size of the form)."""
    h = hashlib.sha256(json.dumps({k: (header or {}).get(k) for k in ("seed", "options")}, sort_keys=True).encode())
    rows = form.plans
    for name in ("id", "rank", "cls", "blocked", "preference", "n", "shape"):
        h.update(np.ascontiguousarray(rows[name]).tobytes())
    for name in ("seq", "nodes", "edges_ptr", "edges_u", "edges_v", "edges_w", "conts_ptr", "conts_a", "conts_c",
                 "conts_lb", "conts_ub"):
        h.update(np.ascontiguousarray(getattr(form, name), dtype=np.int64).tobytes())
    return h.hexdigest()


def _folder_content(header: Mapping[str, Any]) -> str:
    """`content_digest`'s counterpart for a form read from a folder, at no cost: the SHA-256 of its
    ``form.json`` (checked against the SHA-256 of every array file when the form was read) with the seed
    and options."""
    form = header.get("dispatch_form")
    sha = form.get("sha256") if isinstance(form, dict) else None
    text = json.dumps({"form": sha, **{k: header.get(k) for k in ("seed", "options")}}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def plan_set_from_compiled(cps: Any) -> PlanSet:
    """The plan set of an in-memory `hrc.compile.compiler.CompiledPlanSet` (its plans' dispatch form
    records, or where a plan has none, its GraphML text read back: the same arrays the folder would
    hold)."""
    task = cps.task

    def record(cp: Any) -> bytes:
        if cp.form:
            return bytes(cp.form)
        where = f"<compiled plan {cp.plan.id}>"
        return plan_record(task, cp.plan, read_graphml(cp.graphml.encode(), where), cp.pattern.candidates == 0,
                           graphml_names=True, where=where)

    entries = ((cp.plan.id, cp.plan_class.value, cp.preference, cp.plan, record(cp)) for cp in cps.plans)
    form = build_form(task, cps.options.rank_by, entries, "<memory>")
    header = {"seed": cps.seed, "options": {"human_waits": cps.options.human_waits, "rank_by": cps.options.rank_by}}
    return PlanSet(form, "<memory>", content_digest(form, header))


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


def load_plan_set(out_dir: str | os.PathLike[str], *, allow_partial: bool = False) -> PlanSet:
    """Read an `hrc compile` output folder. Raises `InputError` naming the file and key at fault: not such
    a folder, compiled with ``--stnu none``, a partial output (interrupted; unless `allow_partial`), a
    dispatch form that does not match ``compiled.json`` (truncated, swapped, from another compile).

    The set holds the folder as long as it lives (`PlanSet.use`, `hrc.io.folder_use`), taken before
    anything in it is read: a compile into it is refused meanwhile, and the file of the plans' lines
    (``compiled.json``, or ``plans.jsonl`` beside a large one: `hrc.compile.output.lines_path`) stays open
    (`PlanSet.compiled`) for what is read from it later."""
    from hrc.compile.output import lines_path, read_header

    folder = Path(out_dir)
    if not folder.is_dir():
        raise InputError(str(folder), "", "not a folder (give the --out folder of hrc compile)")
    use = FolderUse(folder).acquire()
    try:
        plan_set = _load(folder, allow_partial)
        name = lines_path(folder, read_header(folder)).name
        try:
            plan_set.compiled = use.open(name)
        except OSError as err:
            raise InputError(str(folder / name), "", f"cannot read: {err.strerror or err}") from err
    except BaseException:
        use.release()
        raise
    plan_set.use = use
    return plan_set


def _load(folder: Path, allow_partial: bool) -> PlanSet:
    from hrc.compile.output import load_compiled_task, read_header

    file = str(folder / "compiled.json")
    header = read_header(folder)
    task = load_compiled_task(folder)
    options = header.get("options")
    rank_by = options.get("rank_by", "worst") if isinstance(options, dict) else "worst"
    rank_by = rank_by if rank_by in ("worst", "earliest", "nominal") else "worst"
    if header.get("partial") and not allow_partial:
        raise InputError(file, "partial", "a partial output (the compile was interrupted): finish it with hrc "
                                          "compile --resume, or dispatch what it holds with --allow-partial")
    mode = header.get("stnu_files", "graphml")
    if mode == "none":
        raise InputError(file, "stnu_files", "compiled with --stnu none: no STNUs to dispatch with (compile "
                                             "again with --stnu graphml or --stnu archive)")
    meta = header.get("dispatch_form")
    if isinstance(meta, dict):
        form = read_form(folder, task, rank_by, expected=str(meta.get("sha256")))
        if len(form) == 0:
            raise InputError(file, "plans", "no plans: nothing to dispatch")
        return PlanSet(form, str(folder), _folder_content(header), settings=header)
    return _from_graphml(folder, task, rank_by, header)


def _from_graphml(folder: Path, task: Task, rank_by: str, header: Mapping[str, Any]) -> PlanSet:
    """An output without a dispatch form (written before there was one): ``compiled.json`` and every
    STNU file read, and the form built from them in memory."""
    from hrc.compile.output import STNU_ARCHIVE, iter_plans, lines_path

    file = str(lines_path(folder, dict(header)))
    try:
        plans = list(iter_plans(folder))
    except OSError as err:
        raise InputError(file, "", f"cannot read: {err}") from err
    mode = header.get("stnu_files", "graphml")
    archive = _Archive(folder, file, str(header.get("stnu_archive", STNU_ARCHIVE))) if mode == "archive" else None
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
        cls = str(_need(p, "class", str, file, path))
        if cls not in _CLASSES:
            raise InputError(file, f"{path}.class", f"{cls!r} is not one of {', '.join(_CLASSES)}")
        pref = p.get("preference")
        pattern = p.get("pattern")
        blocked = isinstance(pattern, dict) and pattern.get("candidates") == 0  # no motion pattern was found
        record = plan_record(task, plan, stnu, blocked, graphml_names=True, where=str(stnu_path))
        entries.append((plan.id, cls, float(pref) if isinstance(pref, int | float) else None, plan, record))
    if not entries:
        raise InputError(file, "plans", "no plans: nothing to dispatch")
    form = build_form(task, rank_by, entries, str(folder))
    return PlanSet(form, str(folder), content_digest(form, header))
