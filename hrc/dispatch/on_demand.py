"""Compile on demand (issue 35): when the person leaves every compiled plan, answer at once with the safe
fallback and compile plans that extend what was seen, in the background, into the dispatcher's set.

A searched compile (`hrc.compile.search`) holds the best plans and one for each of the person's first
choices, not every plan; a person who chooses otherwise later leaves them all. Then:

1. **At once**: the dispatcher (`Dispatcher.fallback` set) accepts what was seen (a fact, not a request)
   and answers from the fallback (`hrc.dispatch.fallback`: the robot continues its leg under way, or
   waits), marked ``"fallback"``, with no plan and no class.
2. **In the background**: `wanted` names what the new plans must extend, each agent's actions seen in
   order (`hrc.compile.extend.Prefix`), and `OnDemand` compiles them in a worker process
   (`hrc.compile.extend.extend_plans`: the search compile on the subtree of plans that extend the
   prefix, within a budget in families compiled). The answers meanwhile keep coming from the fallback.
3. **Adopted between two messages**: once the plans have come, before the next message is answered,
   their record goes into the run's log (``{"plans": {...}}``: the message count it follows, the prefix,
   the ids, the SHA-256 of their dispatch form records), synced, and only then the dispatcher takes them
   (`Dispatcher.adopt`: the set grows, the plans already there keep their indices). The next answer that
   accepts a message says ``"new_plans": N``.

**Deterministic replay.** What is compiled is a function of the prefix, the task, the compile's seed and
options and the budget (in families, never seconds): `extend_plans` reads no clock for it. When a run
ends is the only thing the background decides, and the log records it. A replay (``hrc dispatch
--replay``, `replay_run`) and a resume compile the same prefixes again at the same places, check the
ids and the digest against the log's, and so answer byte for byte. The log's header names the on-demand
settings (`OnDemandSettings`): a log replays only with them.

At most one compile runs at a time; when the plans that come do not agree with the history any more
(the person went on meanwhile), the next one is asked for the history then.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
from collections.abc import Iterable, Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hrc.compile.dispatch_form import build_form, concat_forms
from hrc.compile.extend import EXTEND_FAMILIES, EXTEND_K, Prefix, extend_plans
from hrc.errors import HrcError
from hrc.model import Plan, Task

from .dispatcher import Dispatcher
from .logfile import LogContents
from .plan_set import PlanSet
from .protocol import answer, check_header, is_accepted

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan, CompileOptions

__all__ = ["Added", "OnDemand", "OnDemandSettings", "PlanRows", "Replay", "adopt", "announce", "compile_rows",
           "enable", "extended_set", "plan_rows", "rows_digest", "wanted"]

PlanRows = tuple[tuple[str, str, float | None, Plan, bytes], ...]
"""Plans as `hrc.compile.dispatch_form.build_form` takes them: (id, class, preference, plan, form record)."""


def plan_rows(plans: Iterable[CompiledPlan]) -> PlanRows:
    """Compiled plans (`hrc.compile.extend.extend_plans`') as `PlanRows`."""
    return tuple((cp.plan.id, cp.plan_class.value, cp.preference, cp.plan, bytes(cp.form)) for cp in plans)


@dataclass(frozen=True, slots=True)
class OnDemandSettings:
    """The budget of one compile on demand: `plans` asked for, `families` compiled at most; and the
    compile's `seed` and `options` (the motions: the same plans in every process)."""

    plans: int = EXTEND_K
    families: int = EXTEND_FAMILIES
    seed: int = 0
    human_waits: bool = True
    rank_by: str = "worst"

    def header(self) -> dict[str, Any]:
        """What the log's header says of them (a log replays only with the same)."""
        return {"plans": self.plans, "families": self.families}

    @property
    def options(self) -> CompileOptions:
        from hrc.compile.compiler import CompileOptions

        return CompileOptions(self.human_waits, self.rank_by)

    @classmethod
    def of_folder(cls, folder: str, plans: int = EXTEND_K, families: int = EXTEND_FAMILIES) -> OnDemandSettings:
        """With the seed and options of the compile in `folder` (its ``compiled.json``)."""
        from hrc.compile.output import read_header

        header = read_header(folder)
        found = header.get("options")
        options: dict[str, Any] = found if isinstance(found, dict) else {}
        return cls(plans, families, int(header.get("seed", 0)), bool(options.get("human_waits", True)),
                   str(options.get("rank_by", "worst")))


def enable(dispatcher: Dispatcher, settings: OnDemandSettings) -> None:
    """Make `dispatcher` answer with the fallback where it would refuse a message no plan allows, and say
    so in its log's header (`hrc.dispatch.protocol.log_header`)."""
    dispatcher.fallback = True
    dispatcher.on_demand = settings  # type: ignore[attr-defined]


def wanted(dispatcher: Dispatcher) -> Prefix | None:
    """What plans compiled now must extend: None while some plan agrees with what was seen; else each
    agent's actions seen in order, and the one it announced next (`Observation.next`). A joint action in an
    agent's prefix says the agent is in its crew (issue 37): where the crew is a choice of the plan,
    `hrc.compile.extend.extend_plans` keeps only the crews holding every agent seen on it."""
    if len(dispatcher.remaining):
        return None
    history = dispatcher.seen
    seqs = []
    for agent in dispatcher.task.agent_ids:
        seq = history.actions_seen(agent)
        nxt = history.announced.get(agent)
        seqs.append((agent, seq + ((nxt,) if nxt is not None and nxt not in seq else ())))
    return Prefix(tuple(seqs))


class _Compiler:
    """The task, its paths and bounds (made once), compiling prefixes (`compile_rows`)."""

    def __init__(self, task: Task, settings: OnDemandSettings) -> None:
        from hrc.compile.bounds import NodeBounds
        from hrc.motion import plan_paths

        self.task, self.settings = task, settings
        self.paths = plan_paths(task, seed=settings.seed)
        self.bounds = NodeBounds(task, self.paths, settings.rank_by)

    def rows(self, prefix: Prefix) -> PlanRows:
        s = self.settings
        ext = extend_plans(self.task, self.paths, prefix, k=s.plans, families=s.families, options=s.options,
                           bounds=self.bounds)
        return plan_rows(ext.plans)


_WORKER: _Compiler | None = None


def _start_worker(task: Task, settings: OnDemandSettings) -> None:
    global _WORKER
    _WORKER = _Compiler(task, settings)


def _work(prefix: Prefix) -> PlanRows:
    assert _WORKER is not None
    return _WORKER.rows(prefix)


def compile_rows(task: Task, settings: OnDemandSettings, prefix: Prefix) -> PlanRows:
    """The plans compiled on demand for `prefix`, here and now (what the worker does; for a replay)."""
    return _Compiler(task, settings).rows(prefix)


def rows_digest(rows: PlanRows) -> str:
    h = hashlib.sha256()
    for plan_id, cls, pref, _, record in rows:
        h.update(json.dumps([plan_id, cls, pref]).encode())
        h.update(record)
    return h.hexdigest()[:16]


def extended_set(plan_set: PlanSet, rows: PlanRows) -> tuple[PlanSet, int]:
    """`plan_set` with the plans of `rows` it does not hold yet after its own, and how many were new. The
    new set keeps the old one alive (`base`): its folder stays held while the dispatcher runs."""
    have = {plan_set.id(p) for p in range(len(plan_set))} if rows else set()
    new = [r for r in rows if r[0] not in have]
    if not new:
        return plan_set, 0
    form = concat_forms(plan_set.form, build_form(plan_set.task, plan_set.rank_by, new, plan_set.source))
    out = PlanSet(form, plan_set.source)
    out.base = plan_set  # type: ignore[attr-defined]
    return out, len(new)


@dataclass(frozen=True, slots=True)
class Added:
    """Plans compiled on demand, adopted after `after` messages: the log's ``{"plans": ...}`` record."""

    after: int
    prefix: Prefix
    ids: tuple[str, ...]
    digest: str

    def record(self) -> dict[str, Any]:
        return {"plans": {"after": self.after, "for": self.prefix.to_json(), "ids": list(self.ids),
                          "sha256": self.digest}}

    @classmethod
    def from_record(cls, task: Task, rec: Mapping[str, Any]) -> Added:
        """From a log record's value; `ValueError` when it is not one."""
        after, ids, digest = rec.get("after"), rec.get("ids"), rec.get("sha256")
        if isinstance(after, bool) or not isinstance(after, int) or not isinstance(ids, list) or \
                not all(isinstance(i, str) for i in ids) or not isinstance(digest, str):
            raise ValueError("a plans record has after (a count), ids and sha256")
        return cls(after, Prefix.from_json(task, rec.get("for")), tuple(ids), digest)


def adopt(dispatcher: Dispatcher, rows: PlanRows) -> tuple[Dispatcher, int]:
    """A fork of `dispatcher` that has taken `rows` (`Dispatcher.adopt`), and how many plans were new."""
    plan_set, n = extended_set(dispatcher.plan_set, rows)
    work = dispatcher.fork()
    work.adopt(plan_set)  # with no new plan too: one already here may agree (set aside for its route)
    return work, n


def announce(line: str, n: int) -> str:
    """An accepted answer with ``"new_plans": n`` added (the first accepted answer after plans came)."""
    out = json.loads(line)
    out["new_plans"] = n
    return json.dumps(out, ensure_ascii=False, allow_nan=False)


class OnDemand:
    """The background compile of one run: one worker process (spawned: it shares nothing with the
    dispatcher's threads), its task's paths made once when it starts. `ask` a prefix (ignored while a
    compile runs or when that prefix was compiled already), `done` gives the finished one."""

    def __init__(self, task: Task, settings: OnDemandSettings, background: bool = True) -> None:
        self.task, self.settings = task, settings
        self._pool: ProcessPoolExecutor | None = None
        self._local: _Compiler | None = None
        if background:
            self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_start_worker, initargs=(task, settings))
        self._running: tuple[Prefix, Future[PlanRows]] | None = None
        self._asked: set[Prefix] = set()
        self.compiled = 0

    def ask(self, prefix: Prefix | None) -> None:
        if prefix is None or self._running is not None or prefix in self._asked:
            return
        self._asked.add(prefix)
        if self._pool is None:  # in the caller's process (tests without a pool)
            self._local = self._local or _Compiler(self.task, self.settings)
            fut: Future[PlanRows] = Future()
            fut.set_result(self._local.rows(prefix))
        else:
            fut = self._pool.submit(_work, prefix)
        self._running = (prefix, fut)

    def done(self, wait: bool = False) -> tuple[Prefix, PlanRows] | None:
        """The compile that finished (once), or None; `wait`: until it finishes. Raises `HrcError` when
        it failed."""
        if self._running is None:
            return None
        prefix, fut = self._running
        if not wait and not fut.done():
            return None
        self._running = None
        try:
            rows = fut.result()
        except Exception as err:  # noqa: BLE001 - a worker's failure is said, the run goes on with the fallback
            raise HrcError(f"compile on demand for {prefix.to_json()} failed: {type(err).__name__}: {err}") from err
        self.compiled += 1
        return prefix, rows

    @property
    def running(self) -> bool:
        return self._running is not None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None


class Replay:
    """`hrc.dispatch.protocol.replay` for a run that may have adopted plans compiled on demand: iterate
    for each message's answer with the logged one. Before each message, the plans the log says were
    adopted there are compiled again (here, synchronously) and checked against the log's ids and digest
    (`HrcError` if they differ: another hrc, or a compile that is not deterministic), then adopted.
    After the iteration `dispatcher` is the run's state and `pending` the ``new_plans`` not yet said."""

    def __init__(self, dispatcher: Dispatcher, contents: LogContents, path: str = "log") -> None:
        check_header(dispatcher, contents, path)
        self.dispatcher, self.contents, self.path = dispatcher, contents, path
        self.pending = 0
        self.compiler: _Compiler | None = None

    def _add(self, value: Mapping[str, Any]) -> None:
        settings = getattr(self.dispatcher, "on_demand", None)
        if not isinstance(settings, OnDemandSettings):
            raise HrcError(f"{self.path}: the log adds plans compiled on demand, and this dispatcher does not "
                           "compile on demand")
        try:
            rec = Added.from_record(self.dispatcher.task, value)
        except ValueError as err:
            raise HrcError(f"{self.path}: a plans record is damaged ({err})") from None
        self.compiler = self.compiler or _Compiler(self.dispatcher.task, settings)
        rows = self.compiler.rows(rec.prefix)
        if tuple(r[0] for r in rows) != rec.ids or rows_digest(rows) != rec.digest:
            raise HrcError(f"{self.path}: the plans compiled on demand for {rec.prefix.to_json()} differ from the "
                           "logged ones (another hrc, or the compile is not deterministic)")
        self.dispatcher, n = adopt(self.dispatcher, rows)
        self.pending = n or self.pending

    def __iter__(self) -> Iterator[tuple[str, str]]:
        added = list(self.contents.added)
        for number, message in enumerate(self.contents.messages):
            while added and added[0][0] <= number:
                self._add(added.pop(0)[1])
            line = answer(self.dispatcher, message.data)
            if self.pending and is_accepted(line):
                line, self.pending = announce(line, self.pending), 0
            yield line, message.answer
        for _, value in added:  # plans adopted after the last message
            self._add(value)
