"""Classes under a stated sensing: each plan's class when the robot learns the human's events late.

The task's ``sensing:`` (or ``hrc compile --observation-delay``) says how the human's events reach the
robot (`hrc.model.Sensing`: buttons, the motion detector, or a delay stated on the command line). Each plan
is first compiled as before (its motion pattern chosen, its STNU classed by the DC check, which assumes the
robot learns every event the instant it happens); then a plan that is DC at delay 0 is checked for
controllability under the sensing's observation delay (`hrc.temporal.delay.check_delay`: Bhargava et al.
2018). One that fails is classed *consistent* under the sensing, its explanation naming the limits and
passing orders the robot can no longer guarantee and the human events it learns too late; its class at
delay 0 stays on record (`Classification.class_at_delay_0`). A plan consistent or inconsistent at delay 0
keeps its class: more delay never makes a plan DC, and the delay changes no schedule (consistency).

A dated observation (the detector dates each event back to when it happened) with a delay in
``[lo, hi]`` is as good as one of exactly ``hi`` (the robot can hold each one until ``hi`` after its
date; nature can always send it that late), so it is checked as the fixed delay ``hi``; an undated one
(a button pressed late, stamped when pressed) as the variable delay ``[lo, hi]``.

The motion pattern (passing orders, detours, waiting places) is the one chosen at delay 0: a pattern that
would be DC under the sensing where the chosen one is not is not searched for (see docs/temporal.md).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from hrc.compile.classify import Classification, PlanClass
from hrc.compile.temporal_net_creator import TICKS_PER_SECOND, PlanNetwork
from hrc.model import Sensing
from hrc.temporal.delay import SEEN_SUFFIX, ObservationDelay, check_delay
from hrc.temporal.ticks import to_ticks

__all__ = ["explain_delay", "sensing_delay", "sensing_dict", "under_sensing"]


def sensing_delay(sensing: Sensing) -> ObservationDelay:
    """The observation delay the check uses for `sensing`, in the compile's ticks (module docstring)."""
    lo, hi = sensing.delay
    if hi is None:
        return ObservationDelay(0, None)
    if sensing.dated:
        lo = hi
    return ObservationDelay(to_ticks(lo, TICKS_PER_SECOND), to_ticks(hi, TICKS_PER_SECOND))


def under_sensing(sensing: Sensing | None, net: PlanNetwork, c: Classification,
                  verdict_dc: bool | None = None) -> Classification:
    """`c` (a plan's classification at delay 0, of `net`) under `sensing` (None: `c` unchanged, byte for
    byte). `verdict_dc`: the delay check's verdict, when known (a relabelling of a checked plan has the
    same); else it is run."""
    if sensing is None:
        return c
    if c.plan_class is not PlanClass.DC:
        return replace(c, class_at_delay_0=c.plan_class)
    if verdict_dc is None:
        result = check_delay(net.stnu, sensing_delay(sensing))
        if result.is_dc:
            return replace(c, class_at_delay_0=PlanClass.DC)
        cycle = result.cycle
    elif verdict_dc:
        return replace(c, class_at_delay_0=PlanClass.DC)
    else:
        cycle = check_delay(net.stnu, sensing_delay(sensing)).cycle
    return replace(c, plan_class=PlanClass.CONSISTENT, explanation=explain_delay(net, cycle, sensing),
                   class_at_delay_0=PlanClass.DC)


def explain_delay(net: PlanNetwork, cycle: tuple, sensing: Sensing) -> str:
    """Say in words what the delay check's negative cycle runs through: the limits and passing orders the
    robot cannot guarantee, and the human steps whose end it learns too late (observation points
    ``C@seen`` read as ``C``; links of the reduced network read as the plan's links they come from)."""
    meaning = dict(net.meaning)
    position = {t: i for i, t in enumerate(net.stnu.timepoints)}

    def plain(name: str) -> str:
        return name[: -len(SEEN_SUFFIX)] if name.endswith(SEEN_SUFFIX) and name[: -len(SEEN_SUFFIX)] in position \
            else name

    seen: dict[str, set[tuple[int, str]]] = {}
    for edge in cycle:
        a, b = plain(edge.source), plain(edge.target)
        key = (a, b) if (a, b) in meaning else (b, a)
        if key in meaning and key[0] in position and key[1] in position:
            kind, text = meaning[key]
            seen.setdefault(kind, set()).add((min(position[key[0]], position[key[1]]), text))
    found = {kind: list(dict.fromkeys(text for _, text in sorted(items))) for kind, items in seen.items()}
    limits = "; ".join(found.get("limit", []) + found.get("space", []) + found.get("order", [])) \
        or "the plan's ordering"
    late = "; ".join(found.get("human", [])) or "the human's events"
    return (f"under {sensing}: {limits} cannot be guaranteed by the robot alone, which learns late of: "
            f"{late} (DC at delay 0)")


def sensing_dict(sensing: Sensing) -> dict[str, Any]:
    """``compiled.json``'s and the dispatch form's record of the sensing the classes assume: as stated
    (seconds), and the delay checked (`sensing_delay`, seconds)."""
    lo, hi = sensing.delay
    checked = sensing_delay(sensing)
    return {"path": sensing.path, "observation_delay": [lo, hi], "dated": sensing.dated,
            "checked_delay": [checked.lo / TICKS_PER_SECOND,
                              None if checked.hi is None else checked.hi / TICKS_PER_SECOND],
            "classes": "DC: controllable when the robot learns each human event checked_delay late "
                       "(hrc.temporal.delay); each plan's class_at_delay_0: assuming it learns them at once"}
