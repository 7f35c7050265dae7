"""The human action detector's filter: noisy positions in, the person's leg events out.

Strassmair & Taylor 2014, section V.B: "Implicit communication could be realized by applying a
Hidden-Markov-Model, using the human position as observation and representing the human action as
hidden state." The hidden state here is where the person is in the task, as the dispatcher's remaining
plans allow it (`hrc.detect.situation`): standing at a place (waiting, working, or idle between
legs), or walking to one of the places the remaining plans send them next. Two parts:

- **where they are going**: a forward filter over the discrete destination. A person walks to their
  destination on a near-shortest route, so that the walking distance to it falls by as much as they
  walk (Ziebart et al. 2009, maximum-entropy goal-directed motion; the posterior over goals telescopes
  to ``P(G | walk from S to Q) ∝ P(G) exp(beta (D_G(S) - D_G(Q)))``, Dragan & Srinivasa 2013, eq. 8).
  The prior favours the best plan's next leg (`DetectParams.prior`). The departure is given out once
  one destination holds `DetectParams.commit` of the posterior, or the person has reached one: the
  detector holds an event back while unsure rather than guess.
- **when**: change points on the positions kept (`DetectParams.window`). The person left a place when
  the average of the last `smooth` seconds of positions lies farther from it than the noise allows, and
  arrived when it lies within it; the time is the break point of a hinge fitted by least squares to the
  positions (standing, then walking at a constant pace: `hrc.detect.changepoint`), so a departure or
  arrival is given out with the time it happened, not the time it was seen.

What position cannot tell is taken from the plans: a start is given at the arrival, or when the task
graph (the end of a predecessor) or the dispatcher's hint to the person lets it, whichever is later; an
end when the person leaves (the manipulation is over), or, while they stay, once its upper duration
bound has passed (at the middle of its bounds: the time is a guess, the event is not); legs at the
place where the person stands (two actions at one place) when the plans leave no other choice, or when
the person leaves for a place that only they lead to (the stay split among them by their bounds:
`split`; which of them were done there told by the time spent: `_likeliest`); a departure for the
wrong place (the plan's head start named it) withdrawn once the person stops at another (`_wrong_way`).

The state (`Track`) is immutable and replaced whole on each position, and nothing here reads a clock:
a run replays from its log. Cost per position: O(W) for W positions kept, plus O(G) walking-distance
reads for G candidate destinations (a few hundred microseconds; scripts/bench_detect.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .changepoint import arrived_at, arrived_span, left_at, left_span
from .model import DetectorModel
from .situation import Future, Situation

__all__ = ["MAX_SAMPLES", "Belief", "Detected", "Track", "decide", "ingest", "split"]

Leg = tuple[str, str]


def _late(model: DetectorModel) -> float:
    """s past a manipulation's upper bound before a person who stays is taken to have ended it, and within
    which one who leaves is taken to have left as they ended: the start the detector has may be early by a
    noisy arrival, and a leaving is seen a little late."""
    return 0.25 + 2.0 * model.params.sigma


@dataclass(frozen=True, slots=True)
class Detected:
    """An event given out: the person's `event` of `action`.`phase` at `t` (its estimated time, s); or
    ``undo`` (no action, phase): the person's last event, a departure for the wrong place, withdrawn.
    `span`: where a departure or an arrival timed by a change point may truly have happened,
    ``(earliest, latest)`` (`hrc.detect.changepoint.hinge_span`); None for the events timed otherwise."""

    t: float
    event: str
    action: str
    phase: str
    span: tuple[float, float] | None = None

    def to_json(self, agent: str = "human") -> dict[str, object]:
        if self.event == "undo":
            return {"t": self.t, "event": "undo"}
        return {"t": self.t, "agent": agent, "action": self.action, "phase": self.phase, "event": self.event}


@dataclass(frozen=True, slots=True)
class Belief:
    """The detector's belief now: what the person is `doing` ("walk", "wait", "work", "idle"), on which
    leg (`action`, `phase`; None while idle), and its probability `p`; `next`: the action the person is
    heading for (while walking: the destination's, once one leads) and its probability."""

    doing: str
    action: str | None = None
    phase: str | None = None
    p: float = 1.0
    next: str | None = None
    p_next: float = 0.0

    def to_json(self) -> dict[str, object]:
        return {"doing": self.doing, "action": self.action, "phase": self.phase, "p": round(self.p, 3),
                "next": self.next, "p_next": round(self.p_next, 3)}


@dataclass(frozen=True, slots=True)
class Track:
    """The filter's state: the positions kept ``(t, x, y)``, oldest first; `left`: the place the person
    has left and when (while their destination is unsure); `prior`: where the best plan had them go next
    while they worked (what the console showed them; the plan may change once their end is known);
    `last`: the time of the last event given out (events never go back in time) and `given_at` the time
    of the position with which it was given (for the record); `stuck`: the time of a departure already
    withdrawn once (or whose withdrawal was refused: it is not tried again); the `belief`."""

    samples: tuple[tuple[float, float, float], ...] = ()
    left: tuple[str, float] | None = None
    prior: str | None = None
    last: float = 0.0
    given_at: float = 0.0
    stuck: float | None = None
    belief: Belief = Belief("idle")
    left_span: tuple[float, float] | None = None  # where the departure in `left` may truly be (`Detected.span`)
    arrived_span: tuple[float, float] | None = None  # where the last arrival given may truly be (`Detected.span`)

    @property
    def t(self) -> float | None:
        return self.samples[-1][0] if self.samples else None


MAX_SAMPLES = 2048
"""Positions kept at most (the newest): a tracker at 100 Hz fills a 4 s window with 400. Positions that
all carry one ``t`` never leave the window; without this bound each one made the next cost more and the
memory grow without end (issue 34). The change-point fits cost O(samples) each, so a position costs at
most a bounded amount."""


def ingest(model: DetectorModel, track: Track, t: float, x: float, y: float) -> Track:
    """`track` with the position (x, y) seen at `t` (s, not before the last one); older ones than the
    window dropped, and all but the newest `MAX_SAMPLES`."""
    keep = t - model.params.window
    samples = tuple(s for s in track.samples[-(MAX_SAMPLES - 1):] if s[0] >= keep) + ((t, x, y),)
    return replace(track, samples=samples)


def _recent(model: DetectorModel, track: Track) -> tuple[float, float, int]:
    """The mean position of the last `smooth` seconds (at least the last two positions) and their count."""
    samples = track.samples
    t = samples[-1][0]
    n = 0
    sx = sy = 0.0
    for s in reversed(samples):
        if n >= 2 and s[0] < t - model.params.smooth:
            break
        sx += s[1]
        sy += s[2]
        n += 1
    return sx / n, sy / n, n


def _radii(model: DetectorModel, n: int) -> tuple[float, float]:
    """(here, gone): the mean of `n` positions within `here` of a place is there; beyond `gone`, it left."""
    p = model.params
    noise = p.sigma / math.sqrt(n)
    here = p.stand + 3.0 * noise
    return here, here + noise


_STANDING = 0.1  # s: an arrival is taken once its hinge lies this far before the last position


def _at(t: float, track: Track, sit: Situation) -> float:
    """An event's estimated time: never before the last one given out, never after the last position. (The
    dispatcher may pin it later, never earlier than its last message: `hrc.detect.online`.)"""
    del sit
    return round(min(max(t, track.last), track.samples[-1][0]), 3)


def _start_time(model: DetectorModel, sit: Situation, leg: Leg, arrived: float,
                doubt: float | None = None) -> float | None:
    """When the person starts `leg` after arriving at `arrived`: at once, or when the task graph lets them,
    or when the dispatcher's hint asks them to (None: not yet known: a predecessor has not ended, or the
    hint tells them to wait for the robot). `doubt`: the latest the arrival may truly have happened as the
    dispatcher reads it (`Dispatcher._windows`: a hint's earliest holds for every time within the
    estimate's tolerance or stated span); a hint's earliest up to it is that doubt, not a wait asked of
    the person, who started on arriving (issue 32's windows had the detector date every start after an
    arrival up to 0.8 s late, and an end timed from it past its match)."""
    ready = sit.ready(leg)
    if ready is None:
        return None
    t = max(arrived, ready)
    if isinstance(sit.hint, tuple) and sit.hint[:2] == leg and sit.hint[2] in ("start", "depart") \
            and sit.hint[3] > max(sit.now, doubt or 0.0) + 0.05:  # the plan asks them to wait (not "from now on")
        t = max(t, sit.hint[3])
    elif isinstance(sit.hint, str) and sit.hint.startswith("robot.") and sit.leg == leg:
        return None
    return t


def decide(model: DetectorModel, track: Track, sit: Situation) -> tuple[Track, list[Detected]]:
    """The events the positions in `track` show under `sit` (possibly none), and the new track. Call
    again with the situation the events lead to until it gives none (`hrc.detect.online` does)."""
    if not track.samples or sit.away:
        return replace(track, belief=Belief("idle")), []
    t = track.samples[-1][0]
    if 0 < track.last < sit.since:  # the dispatcher pinned the last event later (its clock moved on): ours
        sit = sit.with_since(track.last)
    x, y, n = _recent(model, track)
    here, gone = _radii(model, n)
    leg = sit.leg
    if leg is not None:
        place = model.place[leg]
        dist = math.hypot(x - model.xy[place][0], y - model.xy[place][1])
        if sit.last in ("depart", "park", "unpark"):  # walking to the leg's place
            if dist <= here and sit.allows(*leg, "arrive"):
                arrived = arrived_at(model, track.samples, sit.since)
                if arrived <= t - _STANDING:  # standing, not still coming
                    span = arrived_span(model, track.samples, sit.since, arrived)
                    return replace(track, arrived_span=span), [Detected(_at(arrived, track, sit), "arrive", *leg, span)]
            wrong = _wrong_way(model, track, sit, place, x, y, here)
            if wrong is not None:
                return wrong
            return replace(track, belief=Belief("walk", *leg, 1.0, leg[0], 1.0)), []
        if sit.last == "arrive":  # at the place, not started
            doubt = sit.since + model.tolerance
            if track.arrived_span is not None:
                doubt = max(doubt, track.arrived_span[1])
            start = _start_time(model, sit, leg, sit.since, doubt)
            if start is not None and start <= t and sit.allows(*leg, "start"):
                return track, [Detected(_at(start, track, sit), "start", *leg)]
            if dist > gone and track.left is None:  # left without starting: it started and ended meanwhile
                lb, _ = model.durations.get(leg, (0.0, 0.0))
                left = left_at(model, track.samples, place, sit.since)
                if left - sit.since >= lb and sit.allows(*leg, "start"):
                    return track, [Detected(_at(sit.since, track, sit), "start", *leg)]
            return replace(track, belief=Belief("wait", *leg, 1.0)), []
        # working
        assert sit.start is not None
        lb, ub = model.durations.get(leg, (0.0, 0.0))
        if dist > gone or (track.left is not None and track.left[0] == place):
            if track.left is None or track.left[0] != place:
                left = left_at(model, track.samples, place, sit.start)
                track = replace(track, left=(place, left), prior=_next_place(sit),
                                left_span=left_span(model, track.samples, place, sit.start, left))
            assert track.left is not None
            left = track.left[1]
            if any(len(f.legs) > 1 and _could_stay(model, sit, leg, f, left) for f in sit.futures):
                return _leaving(model, track, sit, x, y, here, leg)  # legs here first in some plan: the walk says
            # as they ended (no plan has them do more here in the time they stayed), unless well past the bound
            end = sit.start + model.mid(leg) if left - sit.start > ub + _late(model) else left
            end = min(end, left)
            return track, [Detected(_at(end, track, sit), "end", *leg)]
        best = sit.futures[0] if sit.futures else None  # the dispatcher's best plan's
        going_on = best is not None and len(best.legs) > 1 and sit.ready(best.legs[0]) is not None
        if t - sit.start >= ub + _late(model) and dist <= here and not going_on:
            # past its bound: over, at a time position cannot tell (unless the best plan has the person go
            # on here with work that is ready: then the walk away times them all)
            track = replace(track, prior=_next_place(sit))
            return track, [Detected(_at(sit.start + model.mid(leg), track, sit), "end", *leg)]
        return replace(track, belief=Belief("work", *leg, 1.0)), []
    return _idle(model, track, sit, t, x, y, here, gone)


def _idle(model: DetectorModel, track: Track, sit: Situation, t: float, x: float, y: float, here: float,
          gone: float) -> tuple[Track, list[Detected]]:
    """No leg under way: the person stands where they last were, or has left it for a destination."""
    place = sit.place
    px, py = model.xy[place]
    dist = math.hypot(x - px, y - py)
    futures = [f for f in sit.futures if sit.allows(*f.legs[0], "depart")]
    if track.left is None or track.left[0] != place:
        if dist <= gone:
            track = replace(track, left=None)
            staying = [f for f in futures if f.legs and model.place[f.legs[0]] == place]
            if futures and len(staying) == len(futures) and len({f.legs[0] for f in futures}) == 1:
                first = futures[0].legs[0]  # every plan has the person go on here: it is certain what
                start = _start_time(model, sit, first, sit.since)
                if start is not None and start <= t:
                    at = _at(start, track, sit)
                    return track, [Detected(at, "depart", *first), Detected(at, "arrive", *first)] + \
                        ([] if first[0] in model.joint else [Detected(at, "start", *first)])  # (a joint
                    # action's start is its lead robot's: issue 37)
            return replace(track, belief=Belief("idle")), []
        left = left_at(model, track.samples, place, sit.since)
        track = replace(track, left=(place, left), prior=track.prior or _next_place(sit),
                        left_span=left_span(model, track.samples, place, sit.since, left))
    elif dist <= here:  # back where they were: no walk after all
        return replace(track, left=None, prior=None, belief=Belief("idle")), []
    return _leaving(model, track, sit, x, y, here, None)


def _likeliest(model: DetectorModel, sit: Situation, futures: list[Future], working: Leg | None,
              left_t: float) -> Future:
    """Of futures that all lead to one place (two actions at one place: the person may or may not have
    done the other before leaving), the one whose legs here fit the time the person stayed (their duration
    bounds summed: too short a stay rules a leg out, a longer one may be waiting), then the best ranked."""
    begin = sit.start if working is not None and sit.start is not None else sit.since
    stay = left_t - begin

    def misfit(f: Future) -> float:
        legs = ([working] if working is not None else []) + list(f.legs[:-1] if f.destination else f.legs)
        lo = sum(model.durations.get(leg, (0.0, 0.0))[0] for leg in legs)
        hi = sum(model.durations.get(leg, (0.0, 0.0))[1] for leg in legs)
        return max(0.0, lo - stay) + max(0.0, stay - hi - _late(model))

    return min(futures, key=lambda f: (round(misfit(f), 1), f.rank))


def _stopped_at(model: DetectorModel, track: Track, dests: list[str], x: float, y: float, here: float,
                since: float) -> str | None:
    """The candidate place the person has stopped at (within `here` of it, and standing: the arrival hinge
    lies before the last position), or None. A place on the way to another (S2 on the way to S1) is
    walked through, not stopped at."""
    t = track.samples[-1][0]
    for g in dests:
        gx, gy = model.xy[g]
        if math.hypot(x - gx, y - gy) <= here and arrived_at(model, track.samples, since) <= t - _STANDING:
            return g
    return None


_WRONG = 1.0  # s standing at another place before a departure given for one is withdrawn


def _wrong_way(model: DetectorModel, track: Track, sit: Situation, goal: str, x: float, y: float,
               here: float) -> tuple[Track, list[Detected]] | None:
    """The person, said to be walking to `goal`, has stopped at another place where the task has work
    (the plan's head start named the wrong one): withdraw the departure (an ``undo``, which the
    dispatcher allows while it is the person's last event and at most `UNDO_SECONDS` old) and decide
    again from where they left. None when that is not the case, or the undo was refused before."""
    if sit.last != "depart" or track.stuck == sit.since:
        return None
    t = track.samples[-1][0]
    for loc in sorted(set(model.place.values()) - {goal, sit.place}):
        lx, ly = model.xy[loc]
        if math.hypot(x - lx, y - ly) <= here and arrived_at(model, track.samples, sit.since) <= t - _WRONG:
            track = replace(track, left=(sit.place, sit.since), prior=None, stuck=sit.since, left_span=None)
            return track, [Detected(round(t, 3), "undo", "", "")]
    return None


def split(model: DetectorModel, legs: Sequence[Leg], total: float) -> list[float]:
    """Durations of `legs`, done one after the other at one place in `total` seconds: each at the middle of
    its bounds, and what the stay is longer or shorter shared out in proportion to each one's variance
    (the squared half-width of its bounds: the most probable split under symmetric priors of those
    widths, a long uncertain check taking more of it than a short sure take), clipped to the bounds where
    it can be. O(k) for k legs. Kitting's check (8-15 s) and label (2-4 s) in 16 s: 12.58 and 3.42 s.
    """
    mids = [model.mid(leg) for leg in legs]
    var = [((model.durations.get(leg, (0.0, 0.0))[1] - model.durations.get(leg, (0.0, 0.0))[0]) / 2) ** 2
           for leg in legs]
    excess = total - sum(mids)
    if sum(var) <= 0:
        return [m + excess / len(legs) for m in mids] if legs else []
    out = [m + excess * v / sum(var) for m, v in zip(mids, var, strict=True)]
    lo = [model.durations.get(leg, (0.0, 0.0))[0] for leg in legs]
    hi = [model.durations.get(leg, (0.0, 0.0))[1] for leg in legs]
    clipped = [min(max(x, a), b) for x, a, b in zip(out, lo, hi, strict=True)]
    rest = total - sum(clipped)  # what the bounds could not take: shared by them all, as they are
    return [x + rest * (x / sum(clipped) if sum(clipped) > 0 else 1 / len(legs)) for x in clipped]


def _could_stay(model: DetectorModel, sit: Situation, working: Leg, future: Future, left: float) -> bool:
    """Whether the person, working on `working` since ``sit.start``, could also have done `future`'s legs at
    this place before leaving at `left`: the first of them ready by then (its predecessors in the task
    graph ended, the robot's included: a plan in which the person takes the kit once the robot's picks are
    done cannot have them take it while a pick is under way) and the lower bounds fitting in the time
    from when it could start."""
    stays = future.legs[:-1] if future.destination is not None else future.legs
    if not stays:
        return False
    ready = sit.ready(stays[0])
    if ready is None:
        return False
    assert sit.start is not None
    begin = max(sit.start + model.durations.get(working, (0.0, 0.0))[0], ready)
    return begin + sum(model.durations.get(leg, (0.0, 0.0))[0] for leg in stays) <= left + _late(model)


def _next_place(sit: Situation) -> str | None:
    """Where the best plan sends the person next (its next leg elsewhere), or None."""
    return sit.futures[0].destination if sit.futures else None


def _leaving(model: DetectorModel, track: Track, sit: Situation, x: float, y: float, here: float,
             working: Leg | None) -> tuple[Track, list[Detected]]:
    """The person has left `track.left`'s place (ending `working`, the leg under way, if any): where to?
    Once one destination is clear (or reached), the events: the end of `working`, the legs at the place
    that lead there, and the departure; the legs' times split [start, left] in proportion to the middle
    of their duration bounds."""
    assert track.left is not None
    place, left_t = track.left
    px, py = model.xy[place]
    if math.hypot(x - px, y - py) <= here:  # back where they were: no walk after all
        belief = Belief("work", *working) if working else Belief("idle")
        return replace(track, left=None, belief=belief), []
    futures = sit.futures if working is not None else \
        [f for f in sit.futures if sit.allows(*f.legs[0], "depart")]
    moving = [f for f in futures if f.destination is not None]
    if not moving:  # every leg left is here: leaving, the person is through with them
        if not futures:
            return replace(track, belief=Belief("walk")), []
        future = futures[0]
    else:
        dests = sorted({f.destination for f in moving if f.destination is not None})
        best = track.prior if track.prior in dests else moving[0].destination
        p = model.params
        logw = np.array([(p.prior if g == best else 0.0)
                         + p.beta * (model.distance(g, px, py) - model.distance(g, x, y)) for g in dests])
        post = np.exp(logw - logw.max())
        post /= post.sum()
        k = int(np.argmax(post))
        goal = dests[k]
        stopped = _stopped_at(model, track, dests, x, y, here, left_t)  # a place on the way to another
        if stopped is not None:
            goal = stopped
        future = _likeliest(model, sit, [f for f in moving if f.destination == goal], working, left_t)
        walked = math.hypot(x - px, y - py)
        if stopped is None and (post[k] < p.commit or (len(dests) > 1 and walked < p.min_walk)):
            return replace(track, belief=Belief("walk", *future.legs[-1], float(post[k]), future.legs[-1][0],
                                                float(post[k]))), []
    # the destination is clear: the end of the leg under way, the legs here on the way, then the departure
    events: list[Detected] = []
    stays = future.legs[:-1] if future.destination is not None else future.legs
    if working is not None:
        begin = sit.start if sit.start is not None else sit.since
        spans = [working, *stays]
    else:
        begin = sit.since
        if stays:
            ready = _start_time(model, sit, stays[0], sit.since)
            begin = sit.since if ready is None else min(ready, left_t)
        spans = list(stays)
    if spans:
        at = begin
        for leg, d in zip(spans, split(model, spans, max(left_t - begin, 0.0)), strict=True):
            if leg != working:
                s = _at(at, track, sit)
                events += [Detected(s, "depart", *leg), Detected(s, "arrive", *leg), Detected(s, "start", *leg)]
            at += d
            events.append(Detected(_at(at, track, sit), "end", *leg))
    if future.destination is not None:
        events.append(Detected(_at(left_t, track, sit), "depart", *future.legs[-1], track.left_span))
    return replace(track, left=None, prior=None), events
