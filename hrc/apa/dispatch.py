"""STPPdispatch (Wilcox, Nikolaidis & Shah 2012, Fig. 8): dispatch the DO form online, recompile on
new preferences or on a deviation from the optimal policy, and keep the hard constraints meanwhile.

`STPPDispatcher` is a pure state machine, as every dispatcher in `hrc` is: time comes in with the
messages (``observe(event, seconds)``), never from a clock, so a replay gives the same answers.

* **Function 1** (standard STP dispatch, Muscettola et al. 1998): an event is *enabled* when every event
  that must come before it (a negative edge of the DO form's APSP) has been executed; its *window* is
  tightened by one-step propagation of each execution (`hrc.temporal.propagate_execution`'s rule,
  vectorised over the APSP rows: ``hi <= t + D[e, :]``, ``lo >= t - D[:, e]``).
* **Function 2**: an observation outside its DO window but inside the hard constraints is a
  *deviation*; so is a call to `set_preferences`. Either recompiles the plan with the past replaced by
  rigid links (Fig. 8 line 7, `STPP.with_commitments`; events yet to come no earlier than now).
* **Shadow dispatch** (Fig. 8 line 3): the original STP's windows are propagated alongside, always.
  A recompile is taken to last `recompile_latency` seconds; until it is done the dispatcher answers
  from the shadow STP (hard constraints only, no optimality). **When a recompile is slower than the
  next event**, that event is checked against the shadow windows and committed; when the recompiled
  DO form arrives it is accepted only if every commitment made meanwhile lies inside it, and
  otherwise the dispatcher recompiles again with those commitments rigid.
* An observation outside the hard windows is a *violation*: it is recorded (it happened), the state
  says so, and no DO form is claimed any more.
* Both are answered **at once**, for every event still to come, not only the one observed: an
  observation (or `advance`, time passing) after which some event yet to happen has no time left in
  its DO window (its window passed, or the observation emptied it: an event out of order) is a
  deviation, recompiled now; with no time left in its hard window, a violation now.
* Bad messages (unknown or repeated events, time going backwards) raise `DispatchError` and change
  nothing.

Worker types (section VI) ride on top: with several named preference sets (each added to the STPP's
own preferences, which every worker shares), after each observation of
a watched event the dispatcher asks `hrc.apa.workers.best_worker_type` which set achieves the larger
global preference value given what has been observed, and switches (and recompiles) when another set
does strictly better.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hrc.apa.compile import TICKS_PER_SECOND, CompileResult, compile_stpp, do_apsp, stpp_network
from hrc.apa.model import STPP, Constraint
from hrc.apa.workers import best_worker_type
from hrc.errors import DispatchError
from hrc.temporal.stn import all_pairs_shortest_paths
from hrc.temporal.ticks import to_ticks

__all__ = ["Step", "STPPDispatcher"]


@dataclass(frozen=True, slots=True)
class Step:
    """The dispatcher's answer to one message.

    `status`: ``on_policy`` (inside the DO window), ``recompiled`` (a deviation or new preferences: a
    new DO form is active), ``switched`` (another worker type's preferences are active), ``shadow``
    (a recompile is under way: windows are the hard constraints'), ``violation`` (a hard constraint is
    broken). `windows` lists the enabled, unexecuted events with their windows (s, None = open).
    """

    status: str
    event: str | None
    time: float | None
    windows: tuple[tuple[str, float | None, float | None], ...]
    worker_type: str | None = None
    value: float | None = None


class STPPDispatcher:
    """Fig. 8 for one STPP; see the module docstring. Times in seconds; the reference event (the
    STPP's first) is due at time 0 until something is executed."""

    def __init__(self, stpp: STPP, *, solver: str = "piqp", ticks_per_second: int = TICKS_PER_SECOND,
                 recompile_latency: float = 0.0, preference_sets: Mapping[str, Sequence[Constraint]] | None = None,
                 worker_type: str | None = None, watch: Iterable[str] | None = None) -> None:
        self.solver = solver
        self.tps = ticks_per_second
        self.latency = to_ticks(recompile_latency, ticks_per_second)
        shared = stpp.preferred  # every worker type's preferences include the STPP's own
        self.sets = {k: (*shared, *v) for k, v in (preference_sets or {}).items()}
        if self.sets and worker_type not in self.sets:
            raise DispatchError(f"worker type {worker_type!r} is not one of {', '.join(self.sets)}")
        self.worker_type = worker_type if self.sets else None
        self.hard = stpp.without_preferences()
        self.plan = self.hard.with_preferences(self.sets[worker_type]) if self.sets and worker_type else stpp
        self.watch = frozenset(stpp.events if watch is None else watch)
        self.events = stpp.events
        self.index = {e: i for i, e in enumerate(self.events)}
        n = len(self.events)
        self.executed: dict[str, int] = {}
        self.now = 0
        self.violated = False
        d0 = np.asarray(all_pairs_shortest_paths(stpp_network(self.hard, self.tps)), dtype=float)
        self.d0 = d0
        self.lo0, self.hi0 = -d0[:, 0].copy(), d0[0, :].copy()
        self.result: CompileResult | None = None
        self.d = d0
        self.lo, self.hi = np.full(n, -math.inf), np.full(n, math.inf)
        self.pending: tuple[int, CompileResult, np.ndarray] | None = None
        self._install(self._compile(self.plan))

    # -- compilation -------------------------------------------------------------------------
    def _compile(self, plan: STPP) -> tuple[CompileResult, np.ndarray] | None:
        now = self.now / self.tps if self.executed else None
        committed = plan.with_commitments({e: t / self.tps for e, t in self.executed.items()}, now)
        result = compile_stpp(committed, solver=self.solver, ticks_per_second=self.tps)
        if not result.consistent:
            return None
        return result, np.asarray(do_apsp(result), dtype=float)

    def _windows_for(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not self.executed:
            return -d[:, 0].copy(), d[0, :].copy()
        lo, hi = np.full(len(self.events), -math.inf), np.full(len(self.events), math.inf)
        for e, t in self.executed.items():
            k = self.index[e]
            lo = np.maximum(lo, t - d[:, k])
            hi = np.minimum(hi, t + d[k, :])
        return lo, hi

    def _install(self, compiled: tuple[CompileResult, np.ndarray] | None) -> bool:
        if compiled is None:
            self.violated = True
            self.result = None
            return False
        self.result, self.d = compiled
        self.lo, self.hi = self._windows_for(self.d)
        return True

    def _recompile(self) -> str:
        """Recompile now; active at once, or after the latency (shadow dispatch meanwhile)."""
        compiled = self._compile(self.plan)
        if compiled is None:
            self.violated = True
            self.result = None
            return "violation"
        if self.latency <= 0:
            self._install(compiled)
            return "recompiled"
        self.pending = (self.now + self.latency, *compiled)
        self.result = None
        return "shadow"

    def _settle(self, time: int) -> str | None:
        """Activate a pending recompile whose time has come, if the commitments made while it ran
        fit it; otherwise recompile again with them."""
        if self.pending is None or time < self.pending[0]:
            return None
        _, result, d = self.pending
        self.pending = None
        lo, hi = self._windows_for(d)
        fits = all(lo[self.index[e]] <= t <= hi[self.index[e]] for e, t in self.executed.items())
        if fits:
            self.result, self.d, self.lo, self.hi = result, d, lo, hi
            return "recompiled"
        return self._recompile()

    # -- messages ----------------------------------------------------------------------------
    def observe(self, event: str, seconds: float) -> Step:
        """`event` happened at `seconds`. Raises `DispatchError` (state unchanged) for an unknown or
        repeated event or a time before the last one (and leaves a pending recompile pending)."""
        if event not in self.index:
            raise DispatchError(f"unknown event {event!r}")
        if event in self.executed:
            raise DispatchError(f"event {event!r} was already executed at {self.executed[event] / self.tps:g} s")
        if not math.isfinite(seconds):
            raise DispatchError(f"time must be a finite number of seconds, found {seconds!r}")
        t = to_ticks(seconds, self.tps)
        if self.executed and t < self.now:
            raise DispatchError(f"time {seconds:g} s is before the last observation ({self.now / self.tps:g} s)")
        k = self.index[event]
        self.now = t  # a recompile started by _settle starts now
        self._settle(t)
        inside_hard = self.lo0[k] <= t <= self.hi0[k]
        in_policy = self.result is not None and self.lo[k] <= t <= self.hi[k]
        self.executed[event] = t
        self.lo0 = np.maximum(self.lo0, t - self.d0[:, k])
        self.hi0 = np.minimum(self.hi0, t + self.d0[k, :])
        if not inside_hard or self.violated:
            self.violated = True
            self.result = None
            return self._step("violation", event, seconds)
        if self._hard_broken(t):  # an event still to come can no longer keep the hard constraints
            self.violated = True
            self.result = None
            return self._step("violation", event, seconds)
        if self.result is not None:
            self.lo = np.maximum(self.lo, t - self.d[:, k])
            self.hi = np.minimum(self.hi, t + self.d[k, :])
            in_policy = in_policy and not self._policy_broken(t)
        status = "on_policy" if in_policy else ("shadow" if self.pending is not None else "deviation")
        if self.sets and event in self.watch:
            best = best_worker_type(self.hard, self.sets, {e: v / self.tps for e, v in self.executed.items()},
                                    self.now / self.tps, current=self.worker_type, solver=self.solver,
                                    ticks_per_second=self.tps)
            if best != self.worker_type:
                self.worker_type = best
                self.plan = self.hard.with_preferences(self.sets[best])
                status = self._recompile()
                return self._step("switched" if status == "recompiled" else status, event, seconds)
        if status == "deviation":
            status = self._recompile()
        return self._step(status, event, seconds)

    def set_preferences(self, preferences: Sequence[Constraint], seconds: float | None = None) -> Step:
        """New preferences (Fig. 8 line 5): recompile with them, the past rigid."""
        if seconds is not None:
            t = to_ticks(seconds, self.tps)
            if self.executed and t < self.now:
                raise DispatchError(f"time {seconds:g} s is before the last observation ({self.now / self.tps:g} s)")
            self.now = t
        self.plan = self.hard.with_preferences(preferences)
        return self._step(self._recompile(), None, seconds)

    def advance(self, seconds: float) -> Step:
        """Time passes without an event (a pending recompile may become active). Raises
        `DispatchError` for a time before the last observation."""
        if not math.isfinite(seconds):
            raise DispatchError(f"time must be a finite number of seconds, found {seconds!r}")
        t = to_ticks(seconds, self.tps)
        if self.executed and t < self.now:
            raise DispatchError(f"time {seconds:g} s is before the last observation ({self.now / self.tps:g} s)")
        if self.executed:
            self.now = t
        status = self._settle(t) or ("shadow" if self.pending else "on_policy")
        if self.executed and not self.violated:
            if self._hard_broken(t):
                self.violated = True
                self.result = None
                status = "violation"
            elif self.result is not None and self._policy_broken(t):
                status = self._recompile()  # a deviation: the DO deadline of an event still to come passed
        return self._step(status, None, seconds)

    def _waiting(self) -> np.ndarray:
        return np.array([k for k, e in enumerate(self.events) if e not in self.executed], dtype=np.intp)

    def _hard_broken(self, t: int) -> bool:
        """Whether an event still to come has no time left in its hard window at time `t` (its window
        passed, or emptied by what was observed): a violation, now rather than at its own observation."""
        k = self._waiting()
        return bool(len(k)) and bool(np.any((self.hi0[k] < t) | (self.lo0[k] > self.hi0[k])))

    def _policy_broken(self, t: int) -> bool:
        """The same for the active DO windows: a deviation from the policy (Fig. 8, function 2)."""
        k = self._waiting()
        return bool(len(k)) and bool(np.any((self.hi[k] < t) | (self.lo[k] > self.hi[k])))

    # -- views -------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return len(self.executed) == len(self.events)

    def _current(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.result is None:
            return self.d0, self.lo0, self.hi0
        return self.d, self.lo, self.hi

    def enabled(self) -> tuple[str, ...]:
        """Unexecuted events all of whose required predecessors have been executed."""
        d, _, _ = self._current()
        out = []
        for e in self.events:
            if e in self.executed:
                continue
            k = self.index[e]
            before = np.nonzero(d[k, :] < 0)[0]
            if all(self.events[j] in self.executed for j in before):
                out.append(e)
        return tuple(out)

    def window(self, event: str) -> tuple[float | None, float | None]:
        """`event`'s current window (s) in the active DO form (the shadow STP while recompiling)."""
        _, lo, hi = self._current()
        k = self.index[event]
        return (None if math.isinf(lo[k]) else float(lo[k]) / self.tps,
                None if math.isinf(hi[k]) else float(hi[k]) / self.tps)

    def _step(self, status: str, event: str | None, seconds: float | None) -> Step:
        wins = tuple((e, *self.window(e)) for e in self.enabled())
        value = None if self.result is None else self.result.value
        return Step(status, event, seconds, wins, self.worker_type, value)

    def next_events(self) -> Step:
        """The enabled events and their windows, without a message."""
        return self._step("shadow" if self.pending else ("violation" if self.violated else "on_policy"), None, None)
