"""Controllability under observation delay: the robot learns each contingent timepoint late.

Dynamic controllability (`hrc.temporal.dc`) assumes that the agent learns a contingent timepoint the
instant it happens. Delay controllability (N. Bhargava, C. Muise, T. Vaquero & B. Williams, "Delay
controllability: multi-agent coordination under communication delay", 2018) gives each contingent
timepoint ``C`` an observation delay: ``C`` happening at ``T(C)`` is learnt at ``T(C) + gamma(C)``;
``gamma = 0`` is DC, ``gamma = inf`` (never learnt) is strong controllability (Vidal & Fargier 1999).
Variable-delay controllability (N. Bhargava, C. Muise & B. Williams, IJCAI 2018) lets the delay be any
``delta`` in ``[lo, hi]``, chosen by nature, and the agent learns *that* ``C`` happened, not when.

The papers' text was not available here (the public material searched holds neither); the semantics and
the reductions below are derived in this module, and each is tested against an independent brute-force
game over information sets (`hrc.temporal.oracle.oracle_is_delay_controllable`), an LP for strong
controllability and the DC check at delay 0 (tests/test_temporal_delay.py).

**Semantics** (integer ticks, as the rest of the core). Contingent link ``(A, C, l, u)``, delay
``[lo, hi]`` (``lo == hi``: a fixed delay). Nature ends ``C`` at ``c`` in ``[T(A) + l, T(A) + u]`` and
delivers the observation at ``o`` in ``[c + lo, c + hi]``; at tick ``t`` the agent's decisions may depend
on the observations delivered at or before ``t`` (at delay 0 this is the instantaneous reaction of
`hrc.temporal.oracle`). An observation says that ``C`` happened; with a fixed delay it also says when
(``c = o - gamma``). The network is *delay controllable* if some strategy of the agent meets every link
for every choice of nature.

**Reduction to DC** (this module's own derivation; it is the shape of the papers' results: one
transformation, then the O(n^3) DC check). For each contingent timepoint ``C`` with delay ``[lo, hi]``:

1. *Uninformative*: ``hi = inf``, or ``hi > lo`` and ``hi - lo >= u - l``. Nature can deliver the
   observation at the one tick ``T(A) + u + lo`` whatever ``c`` is, so observing ``C`` tells the agent
   nothing it could not predict: ``C`` is as good as never observed. It is *substituted*
   (Vidal & Fargier's reduction): ``T(C) = T(A) + omega`` with ``omega`` in ``[l, u]``, so a link
   ``T(Y) - T(C) <= w`` must hold for every ``omega`` and becomes ``T(Y) - T(A) <= w + l`` (and
   ``T(C) - T(X) <= w`` becomes ``T(A) - T(X) <= w - u``), along a chain of substituted links to its
   first timepoint that is not substituted. A link whose two ends reduce to one timepoint is a
   condition on nature alone: broken, the network is not controllable at any strategy.
2. *Observed*: ``C`` is replaced by its *observation point* ``C'`` (named ``C@seen`` unless the delay is
   0), a contingent timepoint the agent observes at once: ``T(C') - T(A)`` in ``[l + hi, u + lo]``.
   ``C'`` is the tick from which the agent knows ``c`` to within ``[T(C') - hi, T(C') - lo]``: the
   observation's tick ``o`` clipped to ``[T(A) + l + hi, T(A) + u + lo]`` (before ``T(A) + l + hi`` it
   learns no more than ``c >= T(A) + l``, after ``T(A) + u + lo`` it knows from the clock alone that
   ``c > T(A) + u + lo - hi``). Every link at ``C`` must hold for each ``c`` in that interval:
   ``T(Y) - T(C) <= w`` becomes ``T(Y) - T(C') <= w - hi`` and ``T(C) - T(X) <= w`` becomes
   ``T(C') - T(X) <= w + lo``. With a fixed delay ``gamma`` this is exact renaming, ``C' = C + gamma``.

   Equivalence: an agent winning the reduced DC game wins the delayed game (it acts on ``C'`` as
   defined, which it can compute; the true ``c`` lies in the interval every reduced link covers);
   conversely nature can deliver every ``C'`` of the reduced game as an observation at that tick and then
   pick ``c`` anywhere in ``[T(C') - hi, T(C') - lo]`` (within ``[l, u]`` of ``T(A)``), unknown to the
   agent, so a strategy for the delayed game is one for the reduced game.

A contingent link whose activation is a contingent timepoint (a chain) is handled when the activation is
substituted (then so must be the link: one that is observed would reveal the activation's ``omega``) or
observed with a fixed delay ``g`` and the link's reduced lower bound ``l + hi - g`` is non-negative; other
chains raise `DelayError` (none of the project's plans nor the shared benchmark instances has a chain).

Hence delay 0 everywhere gives back the network itself (the verdict is `check_dc`'s), and a delay beyond
every bound of the network substitutes every contingent timepoint or makes its observation point useless:
strong controllability. Cost: O(links) for the reduction, then one DC check (the C core when built):
the DC check's class.

**Execution** (`delay_window`): the agent runs the reduced network's real-time strategy
(`hrc.temporal.execution`), fed with the observation points it can compute from what it has learnt:
``C'`` is executed at ``max(o, T(A) + l + hi)`` once that tick has come (``o`` the tick the observation
arrived), or at ``T(A) + u + lo`` when that tick has come without an observation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import compress

from hrc.temporal.dc import DEFAULT_ALGORITHM, DCResult, Verdict, check_dc
from hrc.temporal.execution import ExecutionWindow, MustWait, real_time_state
from hrc.temporal.graph import Edge
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink
from hrc.temporal.rul import core_verdict, edge_arrays

__all__ = ["NEVER", "SEEN_SUFFIX", "ZERO", "DelayError", "DelayedNetwork", "ObservationDelay", "check_delay",
           "delay_window", "delayed_network", "observation_points", "strong_network"]

SEEN_SUFFIX = "@seen"
"""Appended to a contingent timepoint's name for its observation point (delay not 0)."""


class DelayError(NetworkError):
    """A delay the reduction does not cover (a chain of contingent links with variable delays), or a
    delay that is not one (negative, ``lo > hi``, not integer ticks, an unknown timepoint)."""


@dataclass(frozen=True, slots=True)
class ObservationDelay:
    """A contingent timepoint is learnt between ``lo`` and ``hi`` ticks after it happens (``hi`` None:
    never). ``lo == hi``: a fixed delay, and the observation tells when it happened."""

    lo: int
    hi: int | None

    def __post_init__(self) -> None:
        for value in (self.lo, self.hi):
            if value is not None and (type(value) is not int or value < 0):
                raise DelayError(f"an observation delay must be a non-negative integer number of ticks, got "
                                 f"{value!r}")
        if self.hi is not None and self.lo > self.hi:
            raise DelayError(f"observation delay [{self.lo}, {self.hi}]: lo > hi")

    @property
    def fixed(self) -> bool:
        return self.hi == self.lo

    def informative(self, lb: int, ub: int) -> bool:
        """Does observing a contingent link of duration ``[lb, ub]`` under this delay tell the agent
        anything (module docstring, case 2)?"""
        return self.hi is not None and (self.hi == self.lo or self.hi - self.lo < ub - lb)

    def __str__(self) -> str:
        hi = "inf" if self.hi is None else str(self.hi)
        return hi if self.hi == self.lo or (self.hi is None and self.lo == 0) else f"[{self.lo}, {hi}]"


ZERO = ObservationDelay(0, 0)
NEVER = ObservationDelay(0, None)

Delays = ObservationDelay | Mapping[str, ObservationDelay]
"""One delay for every contingent timepoint, or one per contingent timepoint (missing ones: 0)."""


@dataclass(frozen=True)
class DelayedNetwork:
    """`original` as the agent can act on it under `delays` (module docstring): `network` has an
    observation point for each observed contingent timepoint (`seen` maps the contingent timepoint to
    it) and none of the `substituted` ones. `broken`: links between one timepoint and itself that the
    substitution left and nature can break (each as the pair of edges of its negative cycle); the network
    is then not controllable."""

    original: STNU
    network: STNU
    delays: Mapping[str, ObservationDelay]
    seen: Mapping[str, str]
    substituted: frozenset[str]
    broken: tuple[tuple[Edge, ...], ...] = ()
    activation: Mapping[str, ContingentLink] = field(default_factory=dict)


def _per_point(stnu: STNU, delays: Delays) -> dict[str, ObservationDelay]:
    if isinstance(delays, ObservationDelay):
        return {c.target: delays for c in stnu.contingents}
    contingent = stnu.contingent_timepoints
    for name, d in delays.items():
        if name not in contingent:
            raise DelayError(f"observation delay for {name!r}, which is not a contingent timepoint")
        if not isinstance(d, ObservationDelay):
            raise DelayError(f"observation delay for {name!r} must be an ObservationDelay, got {d!r}")
    return {c.target: delays.get(c.target, ZERO) for c in stnu.contingents}


def _unique(name: str, taken: set[str]) -> str:
    while name in taken:
        name += "'"
    taken.add(name)
    return name


class _Reduction:
    """The reduction's bookkeeping: how each timepoint reads in the reduced network."""

    def __init__(self, stnu: STNU, delays: Mapping[str, ObservationDelay]) -> None:
        self.link = {c.target: c for c in stnu.contingents}
        link = self.link
        substituted = {c for c, d in delays.items() if not d.informative(link[c].lb, link[c].ub)}
        for c in link:
            a = link[c].source
            if a in substituted and c not in substituted:
                raise DelayError(f"contingent timepoint {c!r} is observed but its activation {a!r} is never "
                                 f"(usefully) observed: not supported")
        self.substituted = frozenset(substituted)
        # root and path (links from the root) of every timepoint after substitution
        self.root: dict[str, str] = {}
        self.path: dict[str, tuple[str, ...]] = {}
        for v in stnu.timepoints:
            chain: list[str] = []
            x = v
            while x in substituted:
                chain.append(x)
                x = link[x].source
            self.root[v] = x
            self.path[v] = tuple(reversed(chain))
        self.delays = delays
        observed = [c for c in link if c not in substituted]
        for c in observed:
            a = link[c].source
            if a in link:  # a chain: the activation is observed too (else c would be substituted)
                da, dc_ = delays[a], delays[c]
                if not da.fixed or link[c].lb + (dc_.hi or 0) - (da.hi or 0) < 0:
                    raise DelayError(f"contingent timepoint {c!r} follows contingent {a!r}: with these delays "
                                     f"({dc_} after {da}) the reduction does not apply")

    def shift(self, v: str) -> tuple[int, int]:
        """(lo, hi) of the observed or executable timepoint `v`: ``T(v)`` lies in ``[T(v') - hi, T(v') - lo]``."""
        d = self.delays.get(v)
        if d is None:
            return 0, 0
        return d.lo, d.hi or 0

    def bounds(self, s: str, t: str, lb: int | None, ub: int | None) -> tuple[str, str, int | None, int | None]:
        """The link ``lb <= T(t) - T(s) <= ub`` after substitution and shift: ``(s', t', lb', ub')``."""
        rs, rt = self.root[s], self.root[t]
        ps, pt = self.path[s], self.path[t]
        if ps or pt:
            common = 0
            while common < min(len(ps), len(pt)) and ps[common] == pt[common]:
                common += 1
            only_s, only_t = ps[common:], pt[common:]
            link = self.link
            if ub is not None:
                ub = ub - sum(link[c].ub for c in only_t) + sum(link[c].lb for c in only_s)
            if lb is not None:
                lb = lb + sum(link[c].ub for c in only_s) - sum(link[c].lb for c in only_t)
        s_lo, s_hi = self.shift(rs)
        t_lo, t_hi = self.shift(rt)
        if ub is not None:
            ub = ub + t_lo - s_hi
        if lb is not None:
            lb = lb + t_hi - s_lo
        return rs, rt, lb, ub


def delayed_network(stnu: STNU, delays: Delays) -> DelayedNetwork:
    """The reduction of the module docstring, as an STNU. O(links) (times the length of chains of
    substituted contingent links, 1 on plan networks). Raises `DelayError` (see there)."""
    per = _per_point(stnu, delays)
    red = _Reduction(stnu, per)
    taken = set(stnu.timepoints)
    seen: dict[str, str] = {}
    for c in stnu.contingents:
        if c.target not in red.substituted:
            d = per[c.target]
            seen[c.target] = c.target if d == ZERO else _unique(c.target + SEEN_SUFFIX, taken)
    name = {v: seen.get(v, v) for v in stnu.timepoints if v not in red.substituted}
    reqs: list[RequirementLink] = []
    broken: list[tuple[Edge, ...]] = []
    for r in stnu.requirements:
        s, t, lb, ub = red.bounds(r.source, r.target, r.lb, r.ub)
        s, t = name[s], name[t]
        crossed = lb is not None and ub is not None and lb > ub
        if s == t or crossed:
            if crossed or (ub is not None and ub < 0) or (lb is not None and lb > 0):
                # the negative cycle: both edges of a crossed link; of a link to itself, the edge that is
                # negative on its own (the other, a loop of weight >= 0, is no part of it)
                pair = (Edge(s, t, ub) if ub is not None else None, Edge(t, s, -lb) if lb is not None else None)
                broken.append(tuple(e for e in pair if e is not None and (s != t or e.value < 0)))
            continue  # a condition on nature alone, or a link nature breaks (in `broken`)
        reqs.append(RequirementLink(s, t, lb, ub))
    conts: list[ContingentLink] = []
    activation: dict[str, ContingentLink] = {}
    for c in stnu.contingents:
        if c.target in red.substituted:
            continue
        d = per[c.target]
        g = red.shift(c.source)[1]  # the activation's fixed delay (0 for an executable one)
        new = ContingentLink(name[c.source], name[c.target], c.lb + (d.hi or 0) - g, c.ub + d.lo - g)
        conts.append(new)
        activation[name[c.target]] = c
    timepoints = tuple(name[v] for v in stnu.timepoints if v in name)
    net = STNU(timepoints, tuple(reqs), tuple(conts), stnu.name)
    return DelayedNetwork(stnu, net, per, seen, red.substituted, tuple(broken), activation)


def strong_network(stnu: STNU) -> DelayedNetwork:
    """Strong controllability as a network: every contingent timepoint never observed (Vidal & Fargier's
    reduction, module docstring case 1). The STN left is consistent iff `stnu` is strongly controllable."""
    return delayed_network(stnu, NEVER)


def check_delay(stnu: STNU, delays: Delays, algorithm: str = DEFAULT_ALGORITHM) -> DCResult:
    """Is `stnu` controllable when each contingent timepoint is learnt with `delays` (ticks)?

    The verdict reads as `check_dc`'s: ``DC`` (controllable under these delays), ``not DC`` (consistent,
    but no strategy meets every link whatever nature does, given what the agent learns and when) or
    ``inconsistent`` (the network's STN). The cycle explains a ``not DC`` on the reduced network
    (`delayed_network`: observation points ``C@seen``, substituted links on their roots): a
    semi-reducible negative cycle, a negative cycle of the reduced STN, or a link nature alone breaks.
    Delay 0 is `check_dc`; O(links) plus one DC check. Raises `DelayError` (see there).
    """
    per = _per_point(stnu, delays)
    if all(d == ZERO for d in per.values()):
        return check_dc(stnu, algorithm)
    verdict = _fast_verdict(stnu, per) if algorithm == DEFAULT_ALGORITHM else None
    if verdict is None:
        reduced = delayed_network(stnu, per)
        if not reduced.broken:
            result = check_dc(reduced.network, algorithm)
            if result.verdict is not Verdict.INCONSISTENT:
                return result
        # the reduced network is inconsistent, or has a link nature breaks: is the network itself consistent?
        verdict = "not DC" if check_dc(stnu.as_stn(), algorithm).consistent else "inconsistent"
    if verdict == "DC":
        return DCResult(Verdict.DC, True, (), lambda: check_dc(delayed_network(stnu, per).network, algorithm).added)
    if verdict == "inconsistent":
        return DCResult(Verdict.INCONSISTENT, False, lambda: check_dc(stnu.as_stn(), algorithm).cycle)
    return DCResult(Verdict.NOT_DC, True, lambda: _explain(stnu, per, algorithm))


def _explain(stnu: STNU, per: Mapping[str, ObservationDelay], algorithm: str) -> tuple[Edge, ...]:
    """Why `stnu` is consistent but not controllable under `per`: a link nature breaks after substitution,
    or the reduced network's semi-reducible negative cycle, or its STN's negative cycle."""
    reduced = delayed_network(stnu, per)
    if reduced.broken:
        return reduced.broken[0]
    return check_dc(reduced.network, algorithm).cycle


def _fast_verdict(stnu: STNU, per: Mapping[str, ObservationDelay]) -> str | None:
    """`check_delay`'s verdict from the C core on index arrays (no `STNU` built) for networks without
    chains of contingent links: "DC", "not DC", "inconsistent", or None (no core, or a case left to
    `delayed_network`: a chain, a link whose two ends a substitution makes one)."""
    src, dst, wt, act, ctg, xs, ys = edge_arrays(stnu)
    names = stnu.timepoints
    n = len(names)
    contingent = set(ctg)
    if not contingent.isdisjoint(act):
        return None  # a chain: the general path
    hit = bytearray(n)
    for c in ctg:
        hit[c] = 1
    first = per[names[ctg[0]]] if ctg else ZERO
    if first.hi is not None and all(d is first or d == first for d in per.values()) and (
            first.fixed or all(y - x > first.hi - first.lo for x, y in zip(xs, ys, strict=True))):
        return _fast_uniform(n, src, dst, wt, act, ctg, xs, ys, hit, first.lo, first.hi)
    lo = [0] * n  # observed C: T(C) in [T(C') - hi, T(C') - lo]
    hi = [0] * n
    into = [0] * n  # substituted C: an edge into C moves to its activation, minus the link's upper bound
    out_of = [0] * n  # ... an edge out of C, plus its lower bound
    root = list(range(n))
    kept: list[int] = []
    for j in range(len(ctg)):
        c = ctg[j]
        d = per[names[c]]
        if d.informative(xs[j], ys[j]):
            lo[c], hi[c] = d.lo, d.hi or 0
            kept.append(j)
        else:
            root[c], into[c], out_of[c] = act[j], -ys[j], xs[j]
    if len(kept) < len(ctg):
        src2, dst2 = list(map(root.__getitem__, src)), list(map(root.__getitem__, dst))
        if any(map(int.__eq__, src2, dst2)):
            return None
    else:
        src2, dst2 = src, dst
    # T(v) - T(u) <= w becomes T(v') - T(u') <= w + lo(v) - hi(u) (observed) / + into(v) + out_of(u); only
    # the edges at a contingent timepoint change, found at C speed (compress / map)
    shift_in = [a + b for a, b in zip(lo, into, strict=True)]
    shift_out = [b - a for a, b in zip(hi, out_of, strict=True)]
    wt2 = list(wt)
    for i in compress(range(len(src)), map(hit.__getitem__, src)):
        wt2[i] += shift_out[src[i]]
    for i in compress(range(len(dst)), map(hit.__getitem__, dst)):
        wt2[i] += shift_in[dst[i]]
    act2, ctg2 = [act[j] for j in kept], [ctg[j] for j in kept]
    xs2 = [xs[j] + hi[ctg[j]] for j in kept]
    ys2 = [ys[j] + lo[ctg[j]] for j in kept]
    return _settled(core_verdict(n, src2, dst2, wt2, act2, ctg2, xs2, ys2), n, src, dst, wt, act, ctg, xs, ys)


def _fast_uniform(n: int, src: list[int], dst: list[int], wt: list[int], act: list[int], ctg: list[int],
                  xs: list[int], ys: list[int], hit: bytearray, lo: int, hi: int) -> str | None:
    """`_fast_verdict` for one delay ``[lo, hi]`` observed usefully at every contingent timepoint (`hit`
    marks them): an edge out of C loses hi, one into C gains lo (a fixed delay: the renaming C' = C + g)."""
    wt2 = list(wt)
    for i in compress(range(len(src)), map(hit.__getitem__, src)):
        wt2[i] -= hi
    for i in compress(range(len(dst)), map(hit.__getitem__, dst)):
        wt2[i] += lo
    verdict = core_verdict(n, src, dst, wt2, act, ctg, [x + hi for x in xs], [y + lo for y in ys])
    return _settled(verdict, n, src, dst, wt, act, ctg, xs, ys)


def _settled(verdict: str | None, n: int, src: list[int], dst: list[int], wt: list[int], act: list[int],
             ctg: list[int], xs: list[int], ys: list[int]) -> str | None:
    """The reduced network's verdict as `check_delay`'s: when it is inconsistent, so is the network
    itself, or the delay alone makes it uncontrollable (the network's STN, checked here, tells which)."""
    if verdict != "inconsistent":
        return verdict
    stn = core_verdict(n, src + act + ctg, dst + ctg + act, wt + ys + [-x for x in xs], [], [], [], [])
    return None if stn is None else "inconsistent" if stn == "inconsistent" else "not DC"


def observation_points(reduced: DelayedNetwork, learnt: Mapping[str, int], now: int) -> dict[str, int]:
    """The executed timepoints of `reduced.network` at tick `now`: executable timepoints as `learnt`
    gives them (their execution ticks), and the observation point of each observed contingent timepoint
    whose tick has come (module docstring, Execution). `learnt` maps a contingent timepoint to the tick
    its observation *arrived* (not when it happened); substituted ones are ignored."""
    out = {v: t for v, t in learnt.items() if v not in reduced.substituted and v not in reduced.seen}
    links = {c.target: c for c in reduced.original.contingents}
    for c, point in reduced.seen.items():
        link, d = links[c], reduced.delays[c]
        a = link.source
        if a in reduced.seen:  # an observed activation (fixed delay): its own tick
            a_time = learnt[a] - (reduced.delays[a].hi or 0) if a in learnt else None
        else:
            a_time = learnt.get(a)
        if a_time is None:
            continue
        first, last = a_time + link.lb + (d.hi or 0), a_time + link.ub + d.lo
        tick = min(max(learnt[c], first), last) if c in learnt else last
        if tick <= now:
            out[point] = tick
    return out


def delay_window(stnu: STNU, delays: Delays, learnt: Mapping[str, int], now: int,
                 timepoint: str) -> ExecutionWindow | MustWait:
    """When may the agent execute the executable `timepoint`, at tick `now`, having learnt `learnt`
    (executable timepoints: their execution ticks; contingent ones: the tick their observation arrived)?

    The reduced network's real-time window (`hrc.temporal.execution.RealTimeState.step`), its
    observation points computed as the module docstring says; a `MustWait` names contingent timepoints
    by their own names. Meaningful when `check_delay` says DC: executing inside the windows then meets
    every link whatever nature does. Raises `DelayError` / `NetworkError` on misuse."""
    reduced = delayed_network(stnu, delays)
    executed = observation_points(reduced, learnt, now)
    step = real_time_state(reduced.network, executed, now).step(timepoint)
    back = {point: c for c, point in reduced.seen.items()}
    if isinstance(step, MustWait):
        return MustWait(step.timepoint, tuple(back.get(v, v) for v in step.until))
    return ExecutionWindow(step.timepoint, step.earliest, step.latest, tuple(back.get(v, v) for v in step.waits_on))

