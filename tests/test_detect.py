"""The human action detector from motion (hrc.detect, issue 28) against hand-made traces whose truth is
known by construction: a person who walks to a shelf, picks, walks on and waits at the table for the
robot; one who turns back; one who stands at a junction; two actions at one place. Every trace is made
of the compile's own routes walked at a constant pace, with seeded Gaussian noise; every event is
checked against the times the trace was built with."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from hrc.compile.compiler import compile_task
from hrc.detect import DetectingDispatcher, DetectParams, detector_model
from hrc.detect.changepoint import hinge
from hrc.detect.field import geodesic_map
from hrc.detect.filter import split
from hrc.detect.sensor import Sensor, SensorModel
from hrc.dispatch import Observation
from hrc.errors import DetectError, DispatchError
from hrc.io.task_file import load_task

WORKSHOP = ROOT / "tasks" / "cube_stacking.yaml"
SPEED = 1.1  # m/s: the person's pace in the hand-made traces (their top speed is 1.2)
MATCH = 1.0  # s: an event is right when its time is within this of the truth (the measure)


@pytest.fixture(scope="module")
def workshop():
    task = load_task(WORKSHOP)
    return compile_task(task, seed=0, jobs=1)


class Trace:
    """A person's positions, built leg by leg, with the truth of what they did."""

    def __init__(self, cps, start: str, rate: float = 10.0, sigma: float = 0.05, seed: int = 0) -> None:
        self.cps = cps
        self.locations = cps.paths.locations
        self.rate = rate
        self.sigma = sigma
        self.rng = np.random.default_rng(seed)
        self.t = 0.0
        self.at = self.locations[start]
        self.samples: list[tuple[float, float, float]] = []
        self.truth: list[tuple[float, str, str, str]] = []
        self._next = 0.0

    def _emit_until(self, t_end: float, where) -> None:
        while self._next <= t_end + 1e-9:
            x, y = where(self._next)
            nx, ny = self.rng.normal(0.0, self.sigma, 2)
            self.samples.append((round(self._next, 3), float(x + nx), float(y + ny)))
            self._next = round(self._next + 1 / self.rate, 6)

    def stand(self, seconds: float) -> None:
        p = self.at
        self._emit_until(self.t + seconds, lambda _: p)
        self.t += seconds

    def walk(self, points) -> None:
        pts = np.array(points, dtype=float)
        seg = np.hypot(*np.diff(pts, axis=0).T)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        t0 = self.t

        def where(t):
            s = min(max((t - t0) * SPEED, 0.0), cum[-1])
            k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
            f = 0.0 if seg[k] == 0 else (s - cum[k]) / seg[k]
            return pts[k] + f * (pts[k + 1] - pts[k])

        self._emit_until(t0 + cum[-1] / SPEED, where)
        self.t = t0 + cum[-1] / SPEED
        self.at = tuple(pts[-1])

    def route(self, origin: str, target: str):
        return self.cps.paths.get("human", origin, target).points

    def length(self, origin: str, target: str) -> float:
        return float(np.hypot(*np.diff(np.array(self.route(origin, target)), axis=0).T).sum())

    def leg(self, action: str, phase: str, origin: str, target: str, work: float, wait: float = 0.0) -> None:
        """Walk from origin to target, wait, work: the truth of depart, arrive, start, end."""
        self.truth.append((self.t, "depart", action, phase))
        if origin != target:
            self.walk(self.route(origin, target))
        self.truth.append((self.t, "arrive", action, phase))
        self.stand(wait)
        self.truth.append((self.t, "start", action, phase))
        self.stand(work)
        self.truth.append((self.t, "end", action, phase))


def run(d: DetectingDispatcher, samples, robot=()) -> list[tuple[float, float, str, str, str]]:
    """Feed the positions (and the robot's events, by time): (given at, estimated t, event, action, phase)
    of each event given and not withdrawn."""
    robot = sorted(robot, key=lambda r: r[0])  # stable: events at one time stay in their order
    out = []
    k = 0
    for t, x, y in samples:
        while k < len(robot) and robot[k][0] <= t:
            rt, event, action, phase = robot[k]
            d.observe(Observation(max(rt, d.now), event, "robot", action, phase))
            k += 1
        given, refused = d.position(t, x, y)
        assert not refused, refused
        for ev, _ in given:
            if ev.event == "undo":  # the detector withdrew its last event (a departure for the wrong place)
                out.pop()
                continue
            out.append((t, ev.t, ev.event, ev.action, ev.phase))
    return out


def check(given, truth, keys=None) -> None:
    """Every true event given once, within MATCH seconds; nothing else given."""
    keys = keys or {(e, a, p) for _, e, a, p in truth}
    want = [x for x in truth if (x[1], x[2], x[3]) in keys]
    got = [g for g in given if (g[2], g[3], g[4]) in keys]
    assert [(e, a, p) for _, e, a, p in want] == [(g[2], g[3], g[4]) for g in got], (want, got)
    for (t, e, a, p), g in zip(want, got, strict=True):
        assert abs(g[1] - t) <= MATCH, f"{e} {a}.{p}: estimated {g[1]:.2f} s, truly {t:.2f} s"


def detector(cps, **params) -> DetectingDispatcher:
    d = DetectingDispatcher.from_compiled(cps, threads=1, params=DetectParams(**params))
    assert isinstance(d, DetectingDispatcher)
    return d


# ---------------------------------------------------------------------------------------------------------

def test_a_person_walks_to_a_shelf_picks_walks_on_and_waits_for_the_robot_at_the_table(workshop):
    """The workshop's best plan: the person fetches and puts cube 1, fetches cube 3, and at the table waits
    for the robot's cube 2 to be put (the task graph) before putting cube 3."""
    tr = Trace(workshop, "H")
    tr.stand(1.0)
    tr.leg("cube1", "fetch", "H", "S1", work=3.0)
    tr.leg("cube1", "put", "S1", "T", work=2.5)
    tr.leg("cube3", "fetch", "T", "S3", work=3.2)
    walk = tr.length("S3", "T") / SPEED
    robot_end = tr.t + walk + 2.0  # the person reaches the table 2 s before the robot has put cube 2
    tr.leg("cube3", "put", "S3", "T", work=3.0, wait=2.0)
    tr.stand(1.0)
    put = robot_end - 4.5
    robot = [(0.5, "depart", "cube2", "fetch"), (15.0, "arrive", "cube2", "fetch"), (15.0, "start", "cube2", "fetch"),
             (20.0, "end", "cube2", "fetch"), (20.0, "depart", "cube2", "put"), (put, "arrive", "cube2", "put"),
             (put, "start", "cube2", "put"), (robot_end, "end", "cube2", "put")]
    d = detector(workshop)
    given = run(d, tr.samples, robot)
    cube3_put_start = next(t for t, e, a, p in tr.truth if (e, a, p) == ("start", "cube3", "put"))
    assert abs(cube3_put_start - robot_end) < 1e-6  # the trace is what the test says
    check(given, tr.truth[:-1])  # all but the last end (the person has not left the table yet)
    start = next(g for g in given if g[2:] == ("start", "cube3", "put"))
    assert start[1] == pytest.approx(robot_end, abs=0.15)  # when the robot's put ended: the task graph


def test_each_event_is_given_soon_after_it_happens_and_the_destination_before_arrival(workshop):
    tr = Trace(workshop, "H", seed=3)
    tr.stand(0.5)
    tr.leg("cube1", "fetch", "H", "S1", work=3.0)
    tr.leg("cube1", "put", "S1", "T", work=2.5)
    tr.walk(tr.route("T", "H"))
    given = run(detector(workshop), tr.samples)
    check(given, tr.truth)
    for t, e, a, p in tr.truth:
        at = next(g[0] for g in given if g[2:] == (e, a, p))
        # a new action's departure waits for its destination (from H the ways part late); the rest at once
        limit = 3.0 if (e, p) == ("depart", "fetch") else 0.8
        assert at - t <= limit, f"{e} {a}.{p} given {at - t:.2f} s after it happened"
    arrive = next(t for t, e, a, p in tr.truth if (e, a, p) == ("arrive", "cube1", "put"))
    depart = next(g[0] for g in given if g[2:] == ("depart", "cube1", "put"))
    assert arrive - depart > 3.0  # the walk's destination known long before the arrival


def test_a_person_who_turns_back_is_never_reported_going_where_they_turned_from(workshop):
    """After cube 1 the person takes a step or two east, toward cube 4, turns back to the table, stands,
    then fetches cube 3. No cube 4 event is ever given; cube 3's departure is the second leave."""
    tr = Trace(workshop, "H", seed=1)
    tr.stand(0.5)
    tr.leg("cube1", "fetch", "H", "S1", work=3.0)
    tr.leg("cube1", "put", "S1", "T", work=2.5)
    east = tr.route("T", "S4")
    partial = [east[0], (east[0][0] + 0.8, east[0][1])]  # 0.8 m toward S4, and back
    tr.walk(partial)
    tr.walk(partial[::-1])
    tr.stand(2.0)
    tr.leg("cube3", "fetch", "T", "S3", work=3.0)
    d = detector(workshop)
    given = run(d, tr.samples)
    assert not [g for g in given if g[3] == "cube4"], given
    check(given, tr.truth[:-1])  # the last end: they stay at the shelf
    assert [o.action for o in d.history if o.event == "depart"] == ["cube1", "cube1", "cube3"]


def test_a_person_standing_at_a_junction_is_not_named_until_their_way_shows(workshop):
    """From H the ways to S1, S2 and S3 share the passage: a person who stops before it leaves them
    tied. Without the plan's head start (prior 0) the detector gives no departure while they stand there;
    the one given once they walk on is the right one, at the time they left."""
    tr = Trace(workshop, "H", seed=2)
    tr.stand(0.5)
    way = tr.route("H", "S2")
    pts = np.array(way)
    cut = next(k for k in range(1, len(pts)) if pts[k][1] > 3.6)  # the passage is at y 5.0-5.8
    junction = [tuple(p) for p in pts[:cut]]
    depart = tr.t
    tr.walk(junction)
    tr.stand(5.0)
    standing = (tr.t - 5.0, tr.t)
    tr.walk([tr.at, *[tuple(p) for p in pts[cut:]]])
    tr.truth = [(depart, "depart", "cube2", "fetch"), (tr.t, "arrive", "cube2", "fetch")]
    tr.stand(1.0)
    d = detector(workshop, prior=0.0)
    given = run(d, tr.samples)
    assert not [g for g in given if standing[0] <= g[0] <= standing[1]], given
    check(given, tr.truth, {("depart", "cube2", "fetch"), ("arrive", "cube2", "fetch")})
    assert all(g[3] == "cube2" for g in given)


def test_a_person_who_follows_the_plan_is_named_before_the_ways_part(workshop):
    """With the plan's head start (the default), a person who heads where the best plan sends them (cube 1)
    is named as soon as the other places are ruled out, long before the passage where the ways part."""
    tr = Trace(workshop, "H", seed=4)
    tr.stand(0.5)
    tr.leg("cube1", "fetch", "H", "S1", work=3.0)
    given = run(detector(workshop), tr.samples)
    check(given, tr.truth[:-1])
    named = next(g[0] for g in given if g[2:] == ("depart", "cube1", "fetch"))
    assert named < 4.0


_PART_AT_THE_TABLE = """
map: {map}
safety_margin: 0.1
deadline: 120
agents:
  - {{id: human, kind: human, radius: 0.30, speed: 1.2, start: H}}
  - {{id: robot, kind: robot, radius: 0.35, speed: 0.6, start: R}}
actions:
  - id: part
    name: bring the part to the table
    agents: [human]
    phases:
      - {{id: fetch, location: S5, duration: {{human: [2, 4]}}}}
      - {{id: put, location: T, duration: {{human: [2, 4]}}}}
"""  # the start of both small tasks below: a person brings a part from S5 to the table T

TWO_AT_ONE_PLACE = "name: two_at_one_place" + _PART_AT_THE_TABLE + """\
  - id: check
    name: check the part on the table
    agents: [human]
    phases:
      - {{id: look, location: T, duration: {{human: [4, 6]}}}}
  - id: cube
    name: fetch cube 4
    agents: [human, robot]
    phases:
      - {{id: fetch, location: S4, duration: {{human: [2, 4], robot: [5, 6]}}}}
precedence:
  - [part, check]
"""


@pytest.fixture(scope="module")
def one_place(tmp_path_factory):
    path = tmp_path_factory.mktemp("detect") / "two_at_one_place.yaml"
    path.write_text(TWO_AT_ONE_PLACE.format(map=ROOT / "maps" / "workshop.yaml"), encoding="utf-8")
    return compile_task(load_task(path), seed=0, jobs=1)


@pytest.mark.parametrize("check_first", [True, False])
def test_two_actions_at_one_place_are_told_apart_by_the_time_spent_there(one_place, check_first):
    """The person puts the part at T, then either checks it there (5 s more) before fetching cube 4, or
    fetches cube 4 first. Position alone cannot tell a put from a check at the same place; the time spent
    at T can (a put alone takes 2-4 s): the legs at T are given when the person leaves, timed by it."""
    tr = Trace(one_place, "H", seed=5)
    tr.stand(0.5)
    tr.leg("part", "fetch", "H", "S5", work=3.0)
    tr.leg("part", "put", "S5", "T", work=3.0)
    if check_first:
        tr.leg("check", "look", "T", "T", work=5.0)
        tr.leg("cube", "fetch", "T", "S4", work=3.0)
    else:
        tr.leg("cube", "fetch", "T", "S4", work=3.0)
        tr.leg("check", "look", "S4", "T", work=5.0)
    tr.stand(1.0)
    given = run(detector(one_place), tr.samples)
    want = [x for x in tr.truth if x[1:] != ("end", *tr.truth[-1][2:])]  # the last end: they stay
    check(given, want)


WAITS_FOR_THE_ROBOT = "name: waits_for_the_robot" + _PART_AT_THE_TABLE + """\
  - id: cube
    name: fetch cube 4
    agents: [human, robot]
    phases:
      - {{id: fetch, location: S4, duration: {{human: [2, 4], robot: [5, 6]}}}}
  - id: check
    name: check the part and the cube on the table
    agents: [human]
    phases:
      - {{id: look, location: T, duration: {{human: [1, 2]}}}}
  - id: tidy
    name: put the tray back
    agents: [human]
    phases:
      - {{id: fetch, location: S3, duration: {{human: [2, 4]}}}}
precedence:
  - [part, check]
  - [cube, check]
  - [check, tidy]
"""


def test_leaving_before_the_next_legs_here_could_start_ends_the_leg_at_once(tmp_path):
    """The person puts the part at T (3 s) and leaves for cube 4. In the plans where the robot fetches the
    cube, the person's next legs are the check at T (1-2 s), then the tray: the stay (3 s) fits the put and
    the check, but the check cannot have started (the robot's cube is not done), so the put ended when
    they left, and is given at once, not after the walk names their destination (1 m or more)."""
    path = tmp_path / "waits_for_the_robot.yaml"
    path.write_text(WAITS_FOR_THE_ROBOT.format(map=ROOT / "maps" / "workshop.yaml"), encoding="utf-8")
    cps = compile_task(load_task(path), seed=0, jobs=1)
    tr = Trace(cps, "H", seed=3)
    tr.stand(0.5)
    tr.leg("part", "fetch", "H", "S5", work=3.0)
    tr.leg("part", "put", "S5", "T", work=3.0)
    tr.leg("cube", "fetch", "T", "S4", work=3.0)
    tr.stand(1.0)
    given = run(detector(cps), tr.samples)
    check(given, tr.truth[:-1])  # the last end: they stay
    put_end = next(t for t, e, a, p in tr.truth if (e, a, p) == ("end", "part", "put"))
    at = next(g[0] for g in given if g[2:] == ("end", "part", "put"))
    depart = next(g[0] for g in given if g[2:] == ("depart", "cube", "fetch"))
    assert at - put_end < 0.6 and at < depart, (at - put_end, depart - put_end)


# ---------------------------------------------------------------------------------------------------------

def test_the_walking_distance_fields_agree_with_the_compiles_routes(workshop):
    task = workshop.task
    geo = geodesic_map(task.workspace, task.agent("human").radius)
    for a in ("H", "T", "S1", "S4"):
        for b in ("S2", "S3", "S5"):
            route = np.array(workshop.paths.get("human", a, b).points)
            length = float(np.hypot(*np.diff(route, axis=0).T).sum())
            x, y = workshop.paths.locations[a]
            assert geo.distance(geo.index(b), x, y) == pytest.approx(length, rel=0.05), (a, b)
    x, y = workshop.paths.locations["T"]
    assert geo.distance(geo.index("T"), x, y) < 0.1


def test_the_hinge_finds_a_departure_and_an_arrival_in_noise():
    rng = np.random.default_rng(0)
    ts = np.arange(0.0, 4.0, 0.1)
    xs = 2.0 + 1.1 * np.maximum(0.0, ts - 1.5) + rng.normal(0, 0.1, len(ts))
    ys = 3.0 + rng.normal(0, 0.1, len(ts))
    assert hinge(ts, xs, ys, True, 0.0, 4.0, (0.8, 1.3)) == pytest.approx(1.5, abs=0.2)
    xs = 2.0 + 1.1 * np.maximum(0.0, 2.5 - ts) + rng.normal(0, 0.1, len(ts))
    assert hinge(ts, xs, ys, False, 0.0, 4.5, (0.8, 1.3)) == pytest.approx(2.5, abs=0.2)


def test_a_stay_is_split_among_legs_at_one_place_by_their_bounds(one_place):
    model = detector_model(one_place.task)
    legs = [("part", "put"), ("check", "look")]  # 2-4 s and 4-6 s: the same width
    assert split(model, legs, 8.0) == pytest.approx([3.0, 5.0])  # the middles
    assert split(model, legs, 9.0) == pytest.approx([3.5, 5.5])  # the excess shared by their variances
    longer = split(model, [("part", "fetch"), ("check", "look")], 13.0)  # far past both upper bounds
    assert sum(longer) == pytest.approx(13.0) and longer[1] > longer[0]
    assert split(model, [], 3.0) == []


@pytest.mark.parametrize("bad", [dict(sigma=-0.1), dict(commit=1.0), dict(commit=0.3), dict(beta=math.inf),
                                 dict(window=0.5), dict(smooth=5.0), dict(sigma=True)])
def test_impossible_detector_settings_are_refused(bad):
    with pytest.raises(DetectError):
        DetectParams(**bad)


@pytest.mark.parametrize("bad", [dict(sigma=-1.0), dict(rate=0.0), dict(dropout=1.0), dict(latency=-0.5),
                                 dict(rate=math.nan)])
def test_impossible_sensor_models_are_refused(bad):
    with pytest.raises(DetectError):
        SensorModel(**bad)


def test_the_sensor_drops_and_delays_as_told():
    sensor = Sensor(SensorModel(sigma=0.0, rate=10.0, dropout=0.5, latency=0.3), np.random.default_rng(0))
    for _ in range(1000):
        sensor.measure(sensor.next_time, (1.0, 2.0))
    kept = len(sensor.queue)
    assert 400 < kept < 600
    assert sensor.due(0.29) == []
    first = sensor.due(0.31 + sensor.queue[0][1])
    assert first and first[0][1:] == (1.0, 2.0)


def test_a_position_going_back_in_time_is_refused_and_changes_nothing(workshop):
    d = detector(workshop)
    d.position(1.0, 1.0, 1.0)
    track = d.track
    with pytest.raises(DispatchError, match="backwards"):
        d.position(0.5, 1.0, 1.0)
    assert d.track is track


def test_the_detector_model_needs_a_human(workshop):
    from dataclasses import replace

    task = workshop.task
    robots = tuple(a for a in task.agents if not a.is_human)
    with pytest.raises(DetectError, match="no human"):
        detector_model(replace(task, agents=robots))


def test_a_detector_state_is_a_function_of_its_messages(workshop):
    """Two detectors fed the same positions are in the same state, and a fork goes its own way."""
    tr = Trace(workshop, "H", seed=7)
    tr.stand(0.5)
    tr.leg("cube1", "fetch", "H", "S1", work=3.0)
    a, b = detector(workshop), detector(workshop)
    half = len(tr.samples) // 2
    run(a, tr.samples[:half])
    fork = a.fork()
    run(b, tr.samples[:half])
    assert a.track == b.track and a.history == b.history
    assert isinstance(fork, DetectingDispatcher)
    run(fork, tr.samples[half:])
    assert a.track != fork.track and len(fork.history) > len(a.history)


def _unused(path: Path) -> None:  # pragma: no cover - keeps the import list honest for type checkers
    del path
