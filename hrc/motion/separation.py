"""The protective separation distance of speed and separation monitoring (ISO/TS 15066:2016, 5.5.4).

A robot beside people under speed and separation monitoring (SSM) is slowed and stopped by its safety
controller whenever the person comes closer than the *protective separation distance*

    S_p(v_r) = S_h + S_r + S_s + C + Z_d + Z_r                       (ISO/TS 15066, 5.5.4.2.3, eq. 1)

taken here with constant speeds over the reaction and stopping time (the standard's eq. 2-4 integrate
the speeds; with them constant, and the person walking straight at the robot, the integrals are
products):

- ``S_h = v_h (T_r + T_s)``: the person's approach while the robot reacts and stops, at the approach
  speed of ISO 13855 (``v_h`` = 1.6 m/s, the task may say otherwise);
- ``S_r = v_r T_r``: the robot's own travel during its reaction time ``T_r``;
- ``S_s``: the robot's stopping distance from `v_r`, and ``T_s`` its stopping time: ``v_r / a`` and
  ``v_r^2 / (2 a)`` at a constant deceleration `a`, else interpolated linearly in speed between the
  task's measured stops (ISO 10218-1, annex B) and ``(0, 0, 0)``: a chord lies above a convex curve, so
  for a stopping distance convex in speed (as under a constant deceleration) this errs on the safe side;
- ``C``: the intrusion distance (ISO 13855: how far a body part may reach beyond what the sensor sees);
- ``Z_d``, ``Z_r``: the position uncertainty of the person (the sensor) and of the robot.

The distance is *free* distance, between the two discs (`hrc.model.Agent.radius`), which stand for the
person's and the robot's outline; so motion acquisition's reach, the centre distance under which two
occupancies conflict, is ``r_h + r_r + S_p(v_r)`` (`reach`), and a task without `safety` keeps its fixed
``safety_margin`` in place of S_p. A standing robot (``v_r = 0``) still keeps ``v_h T_r + C + Z_d + Z_r``:
the person's approach while its controller reacts, so it never starts moving into them. O(stops) per call.

Joint actions (issue 37) are the one place where the distance is not kept: the standing robot and the
person who works beside it at a joint action's spot (`hrc.motion.conflicts._coworking`: the robot's stay
there against the person's walk up, stay and walk away). The robot's drives keep `reach` at their speed,
there too, so it arrives before the person and leaves after them (docs/motion.md, "Joint actions").

>>> from hrc.model import Safety
>>> terms = protective_separation(Safety(reaction_time=0.1, deceleration=1.0), 0.6)
>>> round(terms.human, 3), round(terms.robot, 3), round(terms.stopping, 3), round(terms.total, 3)
(1.12, 0.06, 0.18, 1.36)
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

from hrc.model import Agent, Safety, Task

__all__ = ["SeparationTerms", "describe", "limits", "protective_separation", "reach", "stopping"]


@dataclass(frozen=True, slots=True)
class SeparationTerms:
    """S_p at robot speed `speed` (m/s), term by term (m), with the stopping time `stop_time` (s)."""

    speed: float
    human: float  # S_h
    robot: float  # S_r
    stopping: float  # S_s
    intrusion: float  # C
    sensor: float  # Z_d
    robot_position: float  # Z_r
    stop_time: float  # T_s

    @property
    def total(self) -> float:
        """S_p (m)."""
        return self.human + self.robot + self.stopping + self.intrusion + self.sensor + self.robot_position


def stopping(safety: Safety, speed: float) -> tuple[float, float]:
    """``(T_s, S_s)``: the robot's stopping time (s) and distance (m) from `speed` (m/s).

    Raises `ValueError` for a speed beyond the fastest measured stop (nothing is known there; the task
    file's loader refuses a robot faster than that)."""
    if speed <= 0:
        return 0.0, 0.0
    if safety.deceleration is not None:
        return speed / safety.deceleration, speed * speed / (2 * safety.deceleration)
    stops = ((0.0, 0.0, 0.0), *safety.stops)
    if speed > stops[-1][0] + 1e-12:
        raise ValueError(f"speed {speed:g} m/s is beyond the fastest measured stop ({stops[-1][0]:g} m/s)")
    i = min(bisect.bisect_left([s[0] for s in stops], speed), len(stops) - 1)
    (v0, t0, d0), (v1, t1, d1) = stops[i - 1], stops[i]
    f = (speed - v0) / (v1 - v0) if v1 > v0 else 1.0
    return t0 + f * (t1 - t0), d0 + f * (d1 - d0)


def protective_separation(safety: Safety, speed: float) -> SeparationTerms:
    """S_p (ISO/TS 15066, eq. 1) at robot speed `speed`, term by term (see the module docstring)."""
    t_s, s_s = stopping(safety, speed)
    return SeparationTerms(speed=speed, human=safety.human_speed * (safety.reaction_time + t_s),
                           robot=speed * safety.reaction_time, stopping=s_s, intrusion=safety.intrusion,
                           sensor=safety.sensor_uncertainty, robot_position=safety.robot_uncertainty, stop_time=t_s)


def reach(task: Task, speed: float, human: Agent | None = None, robot: Agent | None = None) -> float:
    """The centre distance (m) under which the person and the robot driving at `speed` conflict:
    ``r_h + r_r + S_p(speed)``, or ``r_h + r_r + safety_margin`` for a task without `safety`. `human` and
    `robot` name the pair (default: the task's first of each); for two robots, or two people, the
    protective separation does not apply (it keeps a robot from a person): ``r_a + r_b + safety_margin``."""
    human = human or next(a for a in task.agents if a.is_human)
    robot = robot or next(a for a in task.agents if not a.is_human)
    if task.safety is None or human.is_human == robot.is_human:
        return human.radius + robot.radius + task.safety_margin  # as it always was, to the last bit
    return human.radius + robot.radius + protective_separation(task.safety, speed).total


def describe(task: Task) -> str:
    """Which co-worker model `task` gives motion acquisition, in one line (the reports, `hrc show`); a team's
    robots of another speed than the first's are named with their own S_p."""
    robot = next(a for a in task.agents if not a.is_human)
    if task.safety is None:
        return (f"the fixed safety margin, {task.safety_margin:g} m between the two discs (the task has no "
                "safety: section)")
    moving, standing = protective_separation(task.safety, robot.speed), protective_separation(task.safety, 0.0)
    terms = (f"S_h {moving.human:.3f} + S_r {moving.robot:.3f} + S_s {moving.stopping:.3f} + C {moving.intrusion:g} "
             f"+ Z_d {moving.sensor:g} + Z_r {moving.robot_position:g}")
    slow = task.safety.reduced_speed
    zone = "; no reduced-speed zone"
    if slow:
        zone = (f"; a reduced-speed zone at {slow:g} m/s allowed: "
                f"S_p {protective_separation(task.safety, slow).total:.3f} m")
    others = "".join(f"; {r.id} at its {r.speed:g} m/s: S_p {protective_separation(task.safety, r.speed).total:.3f} m"
                     for r in task.agents if not r.is_human and r.speed != robot.speed)  # a team's other speeds
    return (f"the protective separation of ISO/TS 15066 (speed and separation monitoring): at the robot's "
            f"{robot.speed:g} m/s S_p = {terms} = {moving.total:.3f} m, standing {standing.total:.3f} m{zone}{others}")


def limits(task: Task, robot: Agent | None = None) -> dict[str, float] | None:
    """What a plan of `task` assumed of `robot`'s safety controller (default: the task's first robot), for
    the robot to be told with each step (`hrc.dispatch`): its top ``speed`` (m/s) and the protective
    ``separation`` at it, the separation ``standing`` (m), and the ``reduced_speed`` and its
    ``reduced_separation`` when the task allows a reduced-speed zone; None for a task without `safety` (its
    answers stay as they were). A team's robots are told each their own (issue 37: S_p at its own speed)."""
    if task.safety is None:
        return None
    robot = robot or next(a for a in task.agents if not a.is_human)
    out = {"speed": robot.speed, "separation": round(protective_separation(task.safety, robot.speed).total, 6),
           "standing": round(protective_separation(task.safety, 0.0).total, 6)}
    slow = task.safety.reduced_speed
    if slow is not None:
        out |= {"reduced_speed": slow, "reduced_separation": round(protective_separation(task.safety, slow).total, 6)}
    return out

