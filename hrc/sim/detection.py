"""How a motion detector did in a simulated run: its events against what the person did.

The simulator knows the truth (the person's leg events on the floor, `hrc.sim.run`); the detector gives
events with estimated times, each at a moment of the run (`hrc.detect.online`). `detection_of` matches
them one to one, greedily in time order: a given event matches a true one of the same kind (event,
action, phase) whose time it estimates within `MATCH` seconds. Precision is matched / given, recall
matched / true; the delay of a match is when it was given minus when it happened. For every leg the
person walked (depart and arrive apart), `lead` is how long before the arrival the detector had given
its departure, which names the action they were heading for (negative: after). A departure the
detector withdrew (an ``undo``: it named the wrong place) is not among the events given, and is counted
(`withdrawn`). `aggregate_detection`
sums runs up for ``simulation.json``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["MATCH", "Detection", "aggregate_detection", "detection_of"]

MATCH = 1.0
"""s: a given event matches a true one of the same kind whose time it estimates within this."""

Given = tuple[float, float, str, str, str]  # (given at, estimated t, event, action, phase)


@dataclass(frozen=True, slots=True)
class Detection:
    """One run: true events, events given, matched; the matches' delays (s); per walked leg the lead of
    its departure before its arrival (s; None: never given); events the dispatcher refused."""

    truth: int
    given: int
    matched: int
    delays: tuple[float, ...]
    leads: tuple[float | None, ...]
    refused: tuple[str, ...] = ()
    withdrawn: int = 0

    def to_json(self) -> dict:
        d = np.array(self.delays) if self.delays else None
        known = [x for x in self.leads if x is not None]
        return {"truth": self.truth, "given": self.given, "matched": self.matched,
                "delay_median": None if d is None else round(float(np.median(d)), 3),
                "delay_max": None if d is None else round(float(d.max()), 3),
                "legs": len(self.leads), "next_before_arrival": sum(1 for x in known if x > 0),
                "refused": list(self.refused), "withdrawn": self.withdrawn}


def detection_of(truth: Sequence[tuple[float, str, str, str]], given: Sequence[Given],
                 refused: tuple[str, ...] = (), withdrawn: int = 0) -> Detection:
    """Match `given` events to `truth` ``(t, event, action, phase)`` (see the module docstring)."""
    used: set[int] = set()
    delays: list[float] = []
    for t, event, action, phase in sorted(truth):
        best = None
        for k, (_, est, e, a, p) in enumerate(given):
            if k in used or (e, a, p) != (event, action, phase) or abs(est - t) > MATCH + 1e-9:
                continue
            if best is None or abs(est - t) < abs(given[best][1] - t):
                best = k
        if best is not None:
            used.add(best)
            delays.append(given[best][0] - t)
    departs = {(a, p): t for t, e, a, p in truth if e == "depart"}
    leads: list[float | None] = []
    for t, e, a, p in truth:
        if e != "arrive" or (a, p) not in departs or t - departs[(a, p)] < 0.05:
            continue
        when = next((at for at, _, ge, ga, gp in given if (ge, ga, gp) == ("depart", a, p)), None)
        leads.append(None if when is None else round(t - when, 3))
    return Detection(len(truth), len(given), len(used), tuple(round(x, 3) for x in delays), tuple(leads), refused,
                     withdrawn)


def aggregate_detection(runs: Sequence[Detection | None]) -> dict | None:
    """Over runs: precision, recall, delay median / p90, the share of walked legs whose action was known
    before the arrival and the median lead; events refused by the dispatcher. None: no motion detector."""
    dets = [d for d in runs if d is not None]
    if not dets:
        return None
    given = sum(d.given for d in dets)
    truth = sum(d.truth for d in dets)
    matched = sum(d.matched for d in dets)
    delays = [x for d in dets for x in d.delays]
    leads = [x for d in dets for x in d.leads]
    known = [x for x in leads if x is not None]

    def r(x: float) -> float | None:
        return None if not math.isfinite(x) else round(float(x), 4)

    return {"events_true": truth, "events_given": given, "events_matched": matched,
            "precision": r(matched / given) if given else None, "recall": r(matched / truth) if truth else None,
            "delay_median": r(float(np.median(delays))) if delays else None,
            "delay_p90": r(float(np.percentile(delays, 90))) if delays else None,
            "legs_walked": len(leads), "next_before_arrival": sum(1 for x in known if x > 0),
            "next_before_arrival_rate": r(sum(1 for x in known if x > 0) / len(leads)) if leads else None,
            "next_lead_median": r(float(np.median(known))) if known else None,
            "refused": sum(len(d.refused) for d in dets), "withdrawn": sum(d.withdrawn for d in dets)}
