"""The robot's speed and separation monitoring on the floor (ISO/TS 15066:2016, 5.5.4), and what it measured.

A task with a `safety:` section puts the simulated robot under the rule a certified safety controller
enforces: while it drives *towards* the person at speed ``v``, the free distance between the two discs
never falls below the protective separation distance ``S_p(v)`` (`hrc.motion.separation`). The robot
drives at its commanded speed while ``S_p`` at that speed leaves room, else at the task's reduced speed
(a reduced-speed zone, when the task allows one) while ``S_p`` at that speed does, else it makes a
*protective stop*; each step at a speed ``v`` ends exactly where the free distance reaches ``S_p(v)``
(`hrc.sim.floor.Floor`), so on a straight approach the robot stops exactly where the standard says, at
``S_p`` of the speed it drove. It resumes by itself as soon as the separation allows again (5.5.4.2.3:
the robot system may resume motion automatically). Driving away from the person it is not limited (the
standard's speeds are those towards each other). The floor moves the discs kinematically: the reaction
and the braking are not simulated but budgeted, as the standard does, in ``S_p`` (``S_r``, ``S_s`` and
the person's approach meanwhile, ``S_h``). Motion acquisition assumes the same rule
(`hrc.motion.conflicts`: reach ``r_h + r_r + S_p(v)``), so a plan the compile kept apart is not
interrupted by it; a plan that ignores it is.

`SsmTally` counts, per run: protective stops (the robot wanted to drive and the rule held it at 0) and
the seconds they held it, the seconds lost to slowing, the smallest free distance while the robot was
driving towards the person and, separately, while it stood (stopped or at a place) and the person
walked up to it, and *breaches*: steps at whose end the robot, having driven towards the person, was
closer than the protective separation at the speed it drove (0 by construction; measured, not assumed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hrc.model import Safety
from hrc.motion.separation import protective_separation

__all__ = ["ROOM", "SsmMeasures", "SsmTally", "combined", "ssm_limit", "ssm_speed"]


ROOM = 1e-9
"""m: the room beyond ``S_p(v)`` a step at ``v`` needs (a robot standing exactly at ``S_p(v)`` is stopped)."""


def ssm_speed(safety: Safety, free: float, top: float) -> float:
    """The speed (m/s) the robot may drive towards the person at from free distance `free` (m): `top` while
    ``S_p(top) < free``, else the task's reduced speed while ``S_p`` at it is, else 0 (a protective stop).
    O(stops)."""
    if protective_separation(safety, top).total < free - ROOM:
        return top
    slow = safety.reduced_speed
    if slow is not None and slow < top and protective_separation(safety, slow).total < free - ROOM:
        return slow
    return 0.0


def ssm_limit(safety: Safety, before: float, top: float, closing: bool, margin: float) -> tuple[float, float]:
    """One robot step against one person at free distance `before` (m): ``(allowed, keep)``, the speed the
    rule allows (`ssm_speed` when the robot drives towards the person, `closing`; else its `top`) and the
    free distance the step must keep from them (``S_p(allowed)`` driving towards them, else `margin`, the
    standing separation ``S_p(0)``, or `before` when they already came closer). The one pair's floor and
    the team's (`hrc.sim.team_floor`, each robot against each person) take the same rule from here."""
    keep = min(margin, before)
    if not closing:
        return top, keep
    allowed = ssm_speed(safety, before, top)
    if allowed > 0:
        keep = protective_separation(safety, allowed).total
    return allowed, keep


@dataclass(frozen=True, slots=True)
class SsmMeasures:
    """What speed and separation monitoring did in one run (s, m; None: no such moment)."""

    protective_stops: int
    stop_time: float
    slow_time: float
    min_free_robot_approaching: float | None
    min_free_person_approaching: float | None
    breaches: int

    def to_json(self) -> dict:
        def r(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else round(x, 3)

        return {"protective_stops": self.protective_stops, "stop_time": r(self.stop_time),
                "slow_time": r(self.slow_time), "min_free_robot_approaching": r(self.min_free_robot_approaching),
                "min_free_person_approaching": r(self.min_free_person_approaching), "breaches": self.breaches}


class SsmTally:
    """The counters of one run (mutable: the floor adds to them each step)."""

    def __init__(self, safety: Safety) -> None:
        self.safety = safety
        self.stops = 0
        self.stop_time = 0.0
        self.slow_time = 0.0
        self.min_robot = math.inf
        self.min_person = math.inf
        self.breaches = 0
        self.stopped = False  # held at 0 by the rule at the last step

    def robot_step(self, h: float, top: float, allowed: float, closing: bool, moved: float, free_after: float) -> None:
        """After the robot's step of `h` s: it wanted `top` m/s, the rule `allowed` it (towards the person
        when `closing`), it moved `moved` m, and the discs are `free_after` apart."""
        if allowed <= 0 and top > 0:
            if not self.stopped:
                self.stops += 1
            self.stopped = True
            self.stop_time += h
        else:
            self.stopped = False
            if allowed < top:
                self.slow_time += h * (1 - allowed / top)
        if closing and moved > 0:
            self.min_robot = min(self.min_robot, free_after)
            speed = moved / h if h > 0 else 0.0
            if free_after < protective_separation(self.safety, speed).total - 1e-6:
                self.breaches += 1

    def person_step(self, robot_standing: bool, free_before: float, free_after: float) -> None:
        """After the person's step: the robot stood (stopped, or at a place) and the person came closer."""
        if robot_standing and free_after < free_before:
            self.min_person = min(self.min_person, free_after)

    def measures(self) -> SsmMeasures:
        return SsmMeasures(self.stops, self.stop_time, self.slow_time,
                           None if math.isinf(self.min_robot) else self.min_robot,
                           None if math.isinf(self.min_person) else self.min_person, self.breaches)


def combined(measures: Sequence[SsmMeasures]) -> SsmMeasures:
    """A team's robots' measures as one (issue 37: `hrc.sim.team_floor` keeps one tally per robot): stops,
    their time, the slowing and breaches added up, the closest approaches the smallest of any robot."""
    def least(xs: list[float | None]) -> float | None:
        found = [x for x in xs if x is not None]
        return min(found) if found else None

    return SsmMeasures(sum(m.protective_stops for m in measures), sum(m.stop_time for m in measures),
                       sum(m.slow_time for m in measures), least([m.min_free_robot_approaching for m in measures]),
                       least([m.min_free_person_approaching for m in measures]), sum(m.breaches for m in measures))
