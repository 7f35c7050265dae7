"""The protective separation distance (ISO/TS 15066, 5.5.4) and the task's `safety:` section.

The numbers are worked by hand from the standard's equation 1 with constant speeds (the module's
docstring); bad sections end `hrc show` with one line naming the key and exit status 2.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest
from conftest import MIN_MAP, MIN_TASK, WORKSHOP_TASK, dump

from hrc.cli import main
from hrc.errors import TaskFileError
from hrc.io.task_file import dump_task, load_task
from hrc.model import Safety
from hrc.motion import separation
from hrc.motion.separation import protective_separation, stopping

SAFETY: dict[str, Any] = {"reaction_time": "0.1 s", "stopping": {"deceleration": "1.0 m/s^2"},
                          "intrusion": "0.2 m", "sensor_uncertainty": "50 mm", "robot_uncertainty": "2 cm"}


@pytest.mark.parametrize(("v", "s_h", "s_r", "s_s"), [
    # S_h = 1.6 (0.1 + v / 1), S_r = 0.1 v, S_s = v^2 / 2
    (0.0, 0.16, 0.0, 0.0),
    (0.3, 0.64, 0.03, 0.045),
    (0.6, 1.12, 0.06, 0.18),
    (1.0, 1.76, 0.1, 0.5),
])
def test_terms_at_constant_deceleration(v: float, s_h: float, s_r: float, s_s: float) -> None:
    safety = Safety(reaction_time=0.1, deceleration=1.0, intrusion=0.2, sensor_uncertainty=0.05,
                    robot_uncertainty=0.02)
    t = protective_separation(safety, v)
    assert (t.human, t.robot, t.stopping) == pytest.approx((s_h, s_r, s_s), abs=1e-12)
    assert (t.intrusion, t.sensor, t.robot_position) == (0.2, 0.05, 0.02)
    assert t.total == pytest.approx(s_h + s_r + s_s + 0.27, abs=1e-12)


def test_measured_stops_interpolate_and_stop_at_the_fastest() -> None:
    safety = Safety(reaction_time=0.2, stops=((0.4, 0.5, 0.1), (0.8, 0.8, 0.35)), human_speed=2.0)
    assert stopping(safety, 0.2) == pytest.approx((0.25, 0.05))  # halfway to the first stop, from (0, 0, 0)
    assert stopping(safety, 0.6) == pytest.approx((0.65, 0.225))  # halfway between the two
    assert stopping(safety, 0.8) == pytest.approx((0.8, 0.35))
    # S_p(0.6) = 2.0 (0.2 + 0.65) + 0.6 * 0.2 + 0.225
    assert protective_separation(safety, 0.6).total == pytest.approx(1.7 + 0.12 + 0.225)
    with pytest.raises(ValueError, match="beyond the fastest measured stop"):
        stopping(safety, 0.81)


def _write(tmp_path: Path, safety: Any) -> Path:
    task = copy.deepcopy(MIN_TASK)
    task["safety"] = safety
    (tmp_path / "map.yaml").write_text(dump(MIN_MAP), encoding="utf-8")
    path = tmp_path / "task.yaml"
    path.write_text(dump(task), encoding="utf-8")
    return path


def test_section_read_round_trips_and_reach(tmp_path: Path) -> None:
    task = load_task(_write(tmp_path, SAFETY))
    assert task.safety == Safety(reaction_time=0.1, deceleration=1.0, intrusion=0.2, sensor_uncertainty=0.05,
                                 robot_uncertainty=0.02)
    dump_task(task, tmp_path / "again.yaml")
    assert load_task(tmp_path / "again.yaml") == task
    # reach = r_h + r_r + S_p(v): 0.65 + (1.12 + 0.06 + 0.18 + 0.27) at 0.6 m/s, 0.65 + 0.16 + 0.27 standing
    assert separation.reach(task, 0.6) == pytest.approx(0.65 + 1.63)
    assert separation.reach(task, 0.0) == pytest.approx(0.65 + 0.43)


def test_without_safety_the_margin_stays() -> None:
    task = load_task(WORKSHOP_TASK)
    assert task.safety is None
    human, robot = task.agent("human"), task.agent("robot")
    assert separation.reach(task, robot.speed) == human.radius + robot.radius + task.safety_margin
    assert separation.reach(task, 0.0) == human.radius + robot.radius + task.safety_margin


def _with(key: str, value: Any) -> dict[str, Any]:
    out = copy.deepcopy(SAFETY)
    *parents, last = key.split(".")
    node: Any = out
    for p in parents:
        node = node[int(p) if p.isdigit() else p]
    if value is _DROP:
        del node[last]
    else:
        node[int(last) if last.isdigit() else last] = value
    return out


_DROP = object()
_STOPS = [{"speed": "0.3 m/s", "time": "0.3 s", "distance": "0.06 m"},
          {"speed": "0.6 m/s", "time": "0.5 s", "distance": "0.2 m"}]


def _stops(i: int, key: str, value: str) -> dict[str, Any]:
    stops = copy.deepcopy(_STOPS)
    stops[i][key] = value
    return _with("stopping", stops)


BAD = [
    ("negative-time", _with("reaction_time", "-0.1 s"), "safety.reaction_time", "non-negative"),
    ("unit-missing", _with("reaction_time", 0.1), "safety.reaction_time", "the unit is missing"),
    ("unit-missing-text", _with("intrusion", "0.2"), "safety.intrusion", "the unit is missing"),
    ("wrong-unit", _with("intrusion", "0.2 s"), "safety.intrusion", "expected a length in m, cm, mm"),
    ("not-a-number", _with("intrusion", "far m"), "safety.intrusion", "expected a length with its unit"),
    ("unknown-key", _with("colour", "red"), "safety.colour", "unknown key"),
    ("missing-stopping", _with("stopping", _DROP), "safety.stopping", "missing"),
    ("zero-deceleration", _with("stopping.deceleration", "0 m/s^2"), "safety.stopping.deceleration", "positive"),
    ("zero-approach", _with("human_speed", "0 m/s"), "safety.human_speed", "positive"),
    ("distance-falls", _stops(1, "distance", "0.05 m"), "safety.stopping[1].distance",
     "stopping distance falls as the speed rises"),
    ("time-falls", _stops(1, "time", "0.2 s"), "safety.stopping[1].time", "stopping time falls"),
    ("speed-not-rising", _stops(1, "speed", "0.3 m/s"), "safety.stopping[1].speed", "rising speed"),
    ("stops-too-slow", _with("stopping", _STOPS[:1]), "safety.stopping", "fastest measured stop is at 0.3 m/s"),
    ("reduced-not-slower", _with("reduced_speed", "0.6 m/s"), "safety.reduced_speed", "below the robot's speed"),
    ("huge-time", _with("reaction_time", "1e9 s"), "safety.reaction_time", "at most 60 s"),
]


@pytest.mark.parametrize(("safety", "key", "fragment"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_section_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], safety: Any, key: str,
                                     fragment: str) -> None:
    path = _write(tmp_path, safety)
    with pytest.raises(TaskFileError):
        load_task(path)
    assert main(["show", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert re.fullmatch(rf"error: {re.escape(str(path))}:\d+: {re.escape(key)}: [^\n]*{re.escape(fragment)}[^\n]*\n",
                        err), err


def test_measured_stops_read(tmp_path: Path) -> None:
    task = load_task(_write(tmp_path, _with("stopping", _STOPS)))
    assert task.safety is not None
    assert task.safety.stops == ((0.3, 0.3, 0.06), (0.6, 0.5, 0.2))
    assert task.safety.deceleration is None


CORRIDOR = Path(__file__).parent / "data" / "separation" / "crossing_iso.yaml"


def test_corridor_crossing_separation_turns_dc_into_consistent() -> None:
    """One corridor (y < 1.8 m) and one side passage crossing into it at x = 5 m (tests/data/separation).

    The person walks the corridor from H (0.5, 0.9) to B (5, 0.9), 4.5 m at 1.2 m/s: [3.75, 4.6875] s,
    then works [1, 5] s; the robot drives down the passage from R (5, 5.5) to X (5, 2.4), 3.1 m at 0.6 m/s:
    5.1667 s, then works 1 s. Deadline 9.8 s. X is 1.5 m from B and from the corridor's centre line.

    - 0.1 m margin: reach 0.75 m < 1.5 m, no conflict: makespan [max(4.75, 6.17), max(9.69, 6.17)] = [6.17,
      9.69] s, DC.
    - ISO/TS 15066 (T_r 0.1 s, 1 m/s^2): S_p(0.6) = 1.6 (0.1 + 0.6) + 0.06 + 0.18 = 1.36 m, reach 2.01 m
      driving; S_p(0) = 0.16 m, reach 0.81 m standing (so the robot at X and the person at B do not
      conflict, nor does the person walking past X). The robot's drive enters reach of B at s = 3.1 - 0.51 m.
      Robot first: the person arrives at B after the robot is at X (5.167 s after it leaves), and leaves
      H no earlier than 5.167 - 3.162 / 1.2 = 2.532 s after it (3.162 m: where the corridor comes within
      2.01 m of X), plus the sampling's 25 ms: the person's worst case 2.557 + 4.6875 + 5 = 12.24 s > 9.8.
      Person first: the robot may enter after the person has finished at B and walked 2.01 m away, so its
      end is at least 9.69 + 2.01 / 1.2 - 2.59 / 0.6 + 5.167 + 1 > 9.8 in the worst case. Either order
      fits the deadline when the person is quick: consistent, not DC.
    """
    from dataclasses import replace

    from hrc.compile.classify import PlanClass
    from hrc.compile.motion_pattern import choose_pattern
    from hrc.motion import plan_paths
    from hrc.plans import generate_plans

    iso = load_task(CORRIDOR)
    margin = replace(iso, safety=None)
    (plan,) = list(generate_plans(iso))
    paths = plan_paths(iso, seed=0)
    before = choose_pattern(margin, plan, paths)
    assert before.classification.plan_class is PlanClass.DC
    assert before.pattern.orders == ()
    assert before.classification.makespan == pytest.approx((5.1667 + 1, 4.6875 + 5), abs=2e-3)
    after = choose_pattern(iso, plan, paths)
    assert after.classification.plan_class is PlanClass.CONSISTENT
    gaps = sorted((o.first, o.separation.gap) for o in after.pattern.orders)
    assert gaps == [("robot", pytest.approx(2.532 + 0.025, abs=0.02)), ("robot", pytest.approx(3.1 / 0.6, abs=1e-6))]
    early, worst = after.classification.makespan
    assert early == pytest.approx(2.557 + 3.75 + 1, abs=0.02)
    assert worst == pytest.approx(2.557 + 4.6875 + 5, abs=0.02)


def test_reduced_speed_zone_makes_the_crossing_dc() -> None:
    """The corridor crossing with a deadline of 12 s: both orders still break it in the person's worst
    case (12.24 s robot first; person first the robot ends at 9.69 + 1.675 - 4.317 + 5.167 + 1 = 13.2 s),
    so the plan is consistent. Allowed a reduced speed of 0.3 m/s, the robot's protective separation falls
    to 1.6 (0.1 + 0.3) + 0.03 + 0.045 = 0.715 m, reach 1.365 m < 1.5 m: no conflict left, and its slower
    drive (3.1 / 0.3 = 10.33 s, then 1 s of work) fits: DC, makespan 11.33 s both ways."""
    from dataclasses import replace

    from hrc.compile.classify import PlanClass
    from hrc.compile.motion_pattern import choose_pattern
    from hrc.motion import plan_paths
    from hrc.plans import generate_plans

    iso = replace(load_task(CORRIDOR), deadline=12.0)
    assert iso.safety is not None
    (plan,) = list(generate_plans(iso))
    paths = plan_paths(iso, seed=0)
    assert choose_pattern(iso, plan, paths).classification.plan_class is PlanClass.CONSISTENT
    slow = replace(iso, safety=replace(iso.safety, reduced_speed=0.3))
    choice = choose_pattern(slow, plan, paths)
    assert choice.classification.plan_class is PlanClass.DC
    assert choice.pattern.orders == ()
    (robot_leg,) = [m for m in choice.pattern.motions if m.agent == "robot"]
    assert robot_leg.speed == 0.3
    assert robot_leg.time == pytest.approx(3.1 / 0.3, abs=1e-3)
    assert choice.classification.makespan == pytest.approx((3.1 / 0.3 + 1, 3.1 / 0.3 + 1), abs=2e-3)


def test_report_says_the_model_and_what_the_separation_costs(tmp_path: Path) -> None:
    """`hrc compile` of the crossing: the report names the model term by term and shows the plan's class
    going from DC (margin) to consistent (separation), with the worst case 9.7 -> 12.3 s; a task without
    safety: says it kept the margin, and its compiled.json has no trace of the new model."""
    out = tmp_path / "iso"
    assert main(["compile", str(CORRIDOR), "--out", str(out), "-q", "--jobs", "1"]) == 0
    md = (out / "report.md").read_text(encoding="utf-8")
    assert ("S_p = S_h 1.120 + S_r 0.060 + S_s 0.180 + C 0 + Z_d 0 + Z_r 0 = 1.360 m, standing 0.160 m; "
            "no reduced-speed zone") in md
    assert "plans per class with the margin: DC 1, consistent 0, inconsistent 0." in md
    row = next(line for line in md.splitlines() if line.startswith("| 1 | `0a7c3d0747`"))
    assert row == ("| 1 | `0a7c3d0747` | DC \u2192 consistent | 9.7 "
                   "\u2192 12.3 | +2.6 | 0 \u2192 0 | 0 \u2192 2 | 0 |")
    assert "What the protective separation costs" in (out / "report.html").read_text(encoding="utf-8")
    plain = tmp_path / "plain"
    margin_task = tmp_path / "margin.yaml"
    margin_task.write_text(CORRIDOR.read_text().split("safety:")[0], encoding="utf-8")
    (tmp_path / "corridor.yaml").write_text((CORRIDOR.parent / "corridor.yaml").read_text(), encoding="utf-8")
    assert main(["compile", str(margin_task), "--out", str(plain), "-q", "--jobs", "1"]) == 0
    md = (plain / "report.md").read_text(encoding="utf-8")
    assert "the fixed safety margin, 0.1 m between the two discs (the task has no safety: section)" in md
    assert "What the protective separation costs" not in md
    assert "safety\"" not in (plain / "compiled.json").read_text(encoding="utf-8")


def _floor(v: float, reduced: float | None = None):  # noqa: ANN202
    """The corridor's floor with the person standing at (1, 0.9) and the robot at (9, 0.9) driving at `v`
    straight at them (to (1.7, 0.9), nearer than any protective separation lets it)."""
    from dataclasses import replace

    from hrc.sim.floor import Floor

    task = load_task(CORRIDOR)
    assert task.safety is not None
    task = replace(task, safety=replace(task.safety, reduced_speed=reduced))
    floor = Floor(task)
    floor.place(floor.human, (1.0, 0.9))
    floor.place(floor.robot, (9.0, 0.9))
    floor.robot.set_route(((9.0, 0.9), (1.7, 0.9)), v)
    return task, floor


def _drive(floor, until: float) -> list[tuple[float, float]]:  # noqa: ANN001
    """Advance `floor` to time `until` (s) in its own steps; the robot's x after each step, with the time."""
    t, xs = 0.0, []
    while t < until - 1e-9:
        h = min(floor.safe_step(), until - t)
        floor.advance(h)
        t += h
        xs.append((t, floor.robot.xy[0]))
    return xs


@pytest.mark.parametrize("v", [0.2, 0.4, 0.6, 0.9])
def test_controller_stops_where_the_standard_says(v: float) -> None:
    """A straight approach at `v` to a standing person: the robot drives at `v` all the way (no earlier
    slowing) and makes one protective stop with the free distance exactly S_p(v) = 1.6 (0.1 + v) + 0.1 v
    + v^2 / 2 (T_r 0.1 s, 1 m/s^2), i.e. its centre at x = 1 + 0.65 + S_p(v); it stays stopped while the
    person stands, and no step ever ends closer than S_p at the speed it drove."""
    task, floor = _floor(v)
    s_p = 1.6 * (0.1 + v) + 0.1 * v + v * v / 2
    stop_x = 1.0 + 0.65 + s_p
    xs = _drive(floor, (9.0 - stop_x) / v + 3.0)
    assert floor.robot.xy[0] == pytest.approx(stop_x, abs=1e-9)
    assert floor.free() == pytest.approx(s_p, abs=1e-9)
    arrived = next(t for t, x in xs if abs(x - stop_x) < 1e-9)
    assert arrived == pytest.approx((9.0 - stop_x) / v, abs=0.5 + 1e-9)  # within the step that reached it
    for t, x in xs:  # never behind the constant-speed schedule (no slowing before the stop)
        assert x <= max(stop_x, 9.0 - v * t) + 1e-9
    m = floor.ssm.measures()
    assert (m.protective_stops, m.breaches) == (1, 0)
    assert m.stop_time == pytest.approx(3.0, abs=0.5)
    assert m.min_free_robot_approaching == pytest.approx(s_p, abs=1e-9)


def test_controller_slows_in_the_reduced_speed_zone_then_stops_and_resumes() -> None:
    """At 0.6 m/s with a reduced speed of 0.3 m/s allowed: full speed until the free distance is S_p(0.6) =
    1.36 m, then 0.3 m/s until S_p(0.3) = 0.715 m, where it stops. The person steps 1 m back: the robot
    resumes (at full speed, then reduced) and stops again 0.715 m from them; the person then walks up to
    the stopped robot, and stops 2 cm short of it (`hrc.sim.floor.CONTACT`), which is counted apart."""
    task, floor = _floor(0.6, reduced=0.3)
    _drive(floor, 15.0)
    assert floor.free() == pytest.approx(0.715, abs=1e-9)
    m = floor.ssm.measures()
    assert m.protective_stops == 1
    # slowed for (1.36 - 0.715) / 0.3 s at half speed: half of that time lost
    assert m.slow_time == pytest.approx((1.36 - 0.715) / 0.3 / 2, abs=0.02)
    floor.human.set_route(((1.0, 0.9), (0.5, 0.9)), 1.2)
    _drive(floor, 10.0)
    assert floor.free() == pytest.approx(0.715, abs=1e-9)
    assert floor.robot.xy[0] == pytest.approx(0.5 + 0.65 + 0.715, abs=1e-9)
    assert floor.ssm.measures().protective_stops == 2
    assert floor.ssm.measures().min_free_person_approaching is None
    x = floor.robot.xy[0]
    floor.human.set_route(((0.5, 0.9), (3.0, 0.9)), 1.2)
    _drive(floor, 5.0)
    m = floor.ssm.measures()
    assert m.min_free_person_approaching == pytest.approx(0.02, abs=1e-6)
    assert m.breaches == 0
    assert floor.robot.xy[0] >= x - 1e-9  # it does not drive into them; it may back off


def test_robot_steps_carry_the_limits_their_plan_assumed() -> None:
    """Each robot step of the crossing's answers says the limits its plan assumed: 0.6 m/s, S_p 1.36 m
    driving and 0.16 m standing (and the reduced speed's 0.715 m when allowed); the same task without
    safety: answers without the field, as before."""
    from dataclasses import replace

    from hrc.compile.compiler import compile_task
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.messages import Observation, RobotStep

    iso = load_task(CORRIDOR)
    assert iso.safety is not None
    slow = replace(iso, safety=replace(iso.safety, reduced_speed=0.3))
    d = Dispatcher.from_compiled(compile_task(slow, jobs=1))
    step = d.decision.robot
    assert isinstance(step, RobotStep)
    assert step.to_json()["separation"] == {"speed": 0.6, "separation": 1.36, "standing": 0.16, "reduced_speed": 0.3,
                                            "reduced_separation": 0.715}
    after = d.observe(Observation(0.0, "depart", "robot", "cross", "work")).robot
    if isinstance(after, RobotStep):
        assert after.separation == step.separation
    plain = Dispatcher.from_compiled(compile_task(replace(iso, safety=None), jobs=1))
    assert isinstance(plain.decision.robot, RobotStep)
    assert "separation" not in plain.decision.to_json()["robot"]


def test_simulation_under_the_controller_reports_its_measures() -> None:
    """The crossing simulated under speed and separation monitoring: every run carries the controller's
    counts, the robot never drives closer than S_p at its speed, the DC plans are measured against their
    compiled worst case, and hrc is compared with motion-blind on the same seeds."""
    import json

    from hrc.sim.montecarlo import simulate, simulation_json

    task = load_task(CORRIDOR)
    sim = simulate(task, 3, 0, ("hrc", "motion-blind"), jobs=1)
    doc = json.loads(simulation_json(sim))
    for name in ("hrc", "motion-blind"):
        ssm = doc["policies"][name]["aggregate"]["ssm"]
        assert ssm["runs_closer_than_separation"] == 0
        assert all("ssm" in run for run in doc["policies"][name]["runs"])
        robot = ssm["min_free_robot_approaching"]
        assert robot is None or robot >= 0.16 - 1e-9  # S_p(0): it never drives nearer
    assert set(doc["separation"]["policies"]) == {"hrc", "motion-blind"}
    assert doc["separation"]["policies"]["hrc"]["over_compiled_worst_case"] == 0
    assert "hrc_vs_motion_blind" in doc["separation"]


@pytest.mark.slow  # a node process and DDS discovery: tens of seconds
def test_ros2_node_publishes_the_drive_limits(tmp_path: Path) -> None:
    """hrc ros2 on the crossing: with the robot's first drive it publishes on robot/separation what the
    plan assumed (0.6 m/s, S_p 1.36 m driving, 0.16 m standing), the drive's own speed and separation."""
    import json

    from conftest import compiled_folder
    from ros2_client import Client, NodeProcess, ros_env

    folder = compiled_folder(tmp_path / "out", CORRIDOR)
    env = ros_env(tmp_path)
    node = NodeProcess(folder, env, "--log", str(tmp_path / "ros.log"))
    client = None
    try:
        client = Client(env)
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        got: list[str] = []
        latest = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        client.node.create_subscription(client.String, "robot/separation", lambda m: got.append(m.data), latest)
        client.wait_matched()
        answer = json.loads(client.send('{"t": 0, "event": "tick"}'))
        assert answer["robot"]["event"] == "depart"
        client.spin_until(lambda: got, 20, "a message on robot/separation")
        msg = json.loads(got[-1])
        assert msg == {"t": 0.0, "action": "cross", "phase": "work", "event": "depart", "speed": 0.6,
                       "separation": 1.36, "standing": 0.16, "drive_speed": 0.6, "drive_separation": 1.36}
    finally:
        if client is not None:
            client.close()
        node.stop()
        node.kill()
