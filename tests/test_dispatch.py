"""The dispatcher (issue 9): driven by a client that plays the human and the robot controller.

On the workshop compile: (a) a human who follows the first best plan's allocation and order, timed as the
dispatcher's hints say, ends with every constraint of the plan that was carried out kept (that plan DC at
every step); (b) whatever order the human picks, every action is done exactly once by one agent and every
robot event falls in the window it was last given; (c) a human who leaves for good: the robot finishes.
Replay is byte-identical; malformed or impossible messages are refused and change nothing.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, compiled_folder
from dispatch_client import Run, broken_links

from hrc.cli import main
from hrc.dispatch import Dispatcher, Observation, RobotStep, WaitFor
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import handle_line
from hrc.errors import DispatchError
from hrc.io.task_file import load_task

WORKSHOP = ROOT / "tasks" / "cube_stacking.yaml"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return compiled_folder(tmp_path_factory.mktemp("dispatch") / "ws")


@pytest.fixture(scope="module")
def plan_set(folder):
    return load_plan_set(folder)


def _in_process(plan_set, **options):
    d = Dispatcher(plan_set, **options)
    return d, (lambda line: handle_line(d, line))


def _all_done(task, out) -> None:
    for action in task.actions:
        for phase in action.phases:
            agent = out.doer[action.id]
            assert (agent, action.id, phase.id, "end") in out.times, f"{action.id}.{phase.id} never ended"
    for key in out.times:  # no action by two agents
        assert out.doer[key[1]] == key[0], key


@pytest.mark.parametrize("seed", range(6))
def test_a_human_who_follows_the_first_plan_gets_its_promise(plan_set, seed):
    d, send = _in_process(plan_set)
    out = Run(plan_set, send, seed, human_choice="plan", timing="hinted").play()
    assert out.first["class"] == "DC"
    assert not out.refused, out.refused
    final = out.answers[-1]["plan"]
    assert all(a["class"] == "DC" for a in out.answers), [a["class"] for a in out.answers]
    entry = next(e for e in plan_set.plans if e.id == final)
    assert broken_links(entry.stnu, out.times) == []
    human = dict(entry.plan.sequences)["human"]
    assert human == dict(next(e for e in plan_set.plans if e.id == out.first["plan"]).plan.sequences)["human"]
    _all_done(plan_set.task, out)


@pytest.mark.parametrize("seed", range(10))
def test_any_order_the_human_picks_ends_with_every_action_done_once(plan_set, seed):
    d, send = _in_process(plan_set)
    out = Run(plan_set, send, seed, human_choice="random", timing="eager").play()
    _all_done(plan_set.task, out)
    for t, lo, hi in out.windows:
        assert lo - 1e-9 <= t and (hi is None or t <= hi + 1e-9), (t, lo, hi)
    assert out.answers[-1]["robot"] is None


@pytest.mark.parametrize("seed", range(4))
def test_a_human_who_leaves_for_good_leaves_the_robot_to_finish(plan_set, seed):
    d, send = _in_process(plan_set)
    out = Run(plan_set, send, seed, human_choice="random", timing="eager", away_after=1).play()
    _all_done(plan_set.task, out)
    left = [a for a in out.answers if a["human_away"]]
    assert left and left[-1]["robot"] is None
    human_actions = {a for a, agent in out.doer.items() if agent == "human"}
    assert len(human_actions) == 1


def test_through_the_cli_with_a_log_that_replays_byte_for_byte(plan_set, folder, tmp_path):
    log = tmp_path / "run.log"
    with subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(folder), "--log", str(log)],
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          bufsize=1) as proc:
        assert proc.stdin and proc.stdout and proc.stderr

        def send(line: str) -> str:
            proc.stdin.write(line + "\n")
            proc.stdin.flush()
            return proc.stdout.readline().rstrip("\n")

        out = Run(plan_set, send, 3, human_choice="plan", timing="hinted").play()
        for bad in ("{", "[]", '{"t": 1e99, "event": "tick"}', '{"t": 5, "agent": "human", "event": "start"}'):
            answer = json.loads(send(bad))
            assert answer["ok"] is False and "\n" not in answer["error"]
        proc.stdin.close()
        assert proc.wait(timeout=60) == 0
        assert proc.stderr.read() == ""
    _all_done(plan_set.task, out)
    replayed = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), "--replay", str(log)],
                              capture_output=True, text=True, timeout=120)
    assert replayed.returncode == 0, replayed.stderr
    logged = [json.loads(line)["out"] for line in log.read_text().splitlines() if '"out"' in line[:8]]
    assert replayed.stdout.splitlines() == logged
    assert len(logged) == len(out.answers) + len(out.refused) + 4


def _snapshot(d: Dispatcher):
    return (d.decision, d.history, d.candidates, d.now, d.human_options())


BAD = [
    ("not json", "not JSON"),
    ('{"t": -1, "event": "tick"}', "'t' must be"),
    ('{"t": "soon", "event": "tick"}', "'t' must be"),
    ('{"t": 1, "event": "jump"}', "'event' must be one of"),
    ('{"t": 1, "event": "start", "agent": "human", "action": "cube1"}', "needs phase"),
    ('{"t": 1, "event": "start", "agent": "dog", "action": "cube1", "phase": "fetch"}', "unknown agent"),
    ('{"t": 1, "event": "start", "agent": "human", "action": "cube9", "phase": "fetch"}', "unknown action"),
    ('{"t": 1, "event": "start", "agent": "human", "action": "cube1", "phase": "lift"}', "has no phase"),
    ('{"t": 1, "event": "end", "agent": "robot", "action": "cube2", "phase": "fetch"}', "without a start"),
    ('{"t": 1, "event": "start", "agent": "robot", "action": "cube2", "phase": "put"}', "comes first"),
    ('{"t": 1, "event": "start", "agent": "human", "action": "cube2", "phase": "fetch"}', "not ended cube1.fetch"),
    ('{"t": 1, "event": "depart", "agent": "human", "action": "cube1", "phase": "fetch"}', "comes after its start"),
    ('{"t": 1, "event": "start", "agent": "robot", "action": "cube1", "phase": "fetch"}', "being done by the human"),
    ('{"t": 1.5, "event": "start", "agent": "human", "action": "cube1", "phase": "fetch"}', "duplicate"),
    ('{"t": 0.5, "event": "tick"}', "time goes backwards"),
    ('{"t": 1, "event": "back", "agent": "human"}', "not away"),
    ('{"t": 1, "event": "tick", "action": "cube1"}', "takes no action"),
    ('{"t": 1, "event": "tick", "extra": 1}', "unknown key"),
    ('{"t": 30, "event": "undo"}', "too late to undo"),
]


def test_every_bad_message_is_refused_and_changes_nothing(plan_set):
    d, send = _in_process(plan_set)
    assert json.loads(send('{"t": 1, "event": "start", "agent": "human", "action": "cube1", "phase": "fetch"}'))["ok"]
    for line, reason in BAD:
        before = _snapshot(d)
        answer = json.loads(send(line))
        assert answer["ok"] is False and reason in answer["error"], (line, answer)
        assert _snapshot(d) == before, line


def test_an_event_no_remaining_plan_allows_is_refused(plan_set):
    """The workshop's pile: cube 3 cannot be put before cube 2, whoever does it."""
    d, send = _in_process(plan_set)
    for line in ('{"t": 0, "agent": "human", "action": "cube3", "phase": "fetch", "event": "start"}',
                 '{"t": 5, "agent": "human", "action": "cube3", "phase": "fetch", "event": "end"}'):
        assert json.loads(send(line))["ok"]
    answer = json.loads(send('{"t": 9, "agent": "human", "action": "cube3", "phase": "put", "event": "start"}'))
    assert not answer["ok"] and "task graph" in answer["error"]
    # the robot has cube1 in every remaining plan where the human does cube3 first and then ...
    with pytest.raises(DispatchError, match="no remaining plan allows"):
        d.observe(Observation(9, "start", "human", "triangle", "fetch"))


def test_undo_withdraws_the_last_human_observation(plan_set):
    d, _ = _in_process(plan_set)
    first = d.decision
    d.observe(Observation(1.0, "start", "human", "cube1", "fetch"))
    assert len(d.candidates) < 32
    d.observe(Observation(3.0, "undo"))
    assert d.history == () and len(d.candidates) == 32 and d.now == 3.0
    assert d.decision.plan == first.plan
    with pytest.raises(DispatchError, match="nothing to undo"):
        d.observe(Observation(3.5, "undo"))
    d.observe(Observation(4.0, "start", "human", "cube1", "fetch"))
    step = d.decision.robot
    assert isinstance(step, RobotStep)
    d.observe(Observation(max(4.0, step.earliest), step.event, "robot", step.action, step.phase))
    with pytest.raises(DispatchError, match="nothing to undo"):  # the robot has acted on it since
        d.observe(Observation(d.now + 1, "undo"))


def test_overrun_and_missed_deadline_still_give_a_decision(plan_set):
    """A human who takes far longer than the bounds: the plan is never dropped for its timing, the set is
    still ranked and the robot still told what to do, past the deadline too."""
    d, _ = _in_process(plan_set)
    d.observe(Observation(0.0, "start", "human", "cube1", "fetch"))
    dec = d.observe(Observation(200.0, "tick"))  # the fetch has overrun its bound by far
    assert sum(dec.candidates.values()) == len(d.candidates) > 0 and dec.robot is not None
    dec = d.observe(Observation(201.0, "end", "human", "cube1", "fetch"))
    assert dec.plan is not None and dec.robot is not None
    assert dec.plan_class in ("DC", "consistent", "inconsistent")


def test_feasible_only_stops_when_nothing_feasible_is_left(plan_set):
    d, _ = _in_process(plan_set, feasible_only=True)
    assert d.decision.candidates["inconsistent"] == 0
    d.observe(Observation(0.0, "start", "human", "cube1", "fetch"))
    dec = d.observe(Observation(500.0, "tick"))
    assert dec.stopped and dec.robot is None and dec.plan is None


def test_human_options_are_what_the_dispatcher_accepts(plan_set):
    d, _ = _in_process(plan_set)
    options = d.human_options()
    assert options and all(o.event in ("depart", "start") for o in options)
    for o in options:
        Dispatcher(plan_set).observe(Observation(0.0, o.event, "human", o.action, o.phase))  # accepted
    actions = {o.action for o in options}
    for action in plan_set.task.action_ids:
        if action not in actions:
            with pytest.raises(DispatchError):
                Dispatcher(plan_set).observe(Observation(0.0, "start", "human", action, "fetch"))


@pytest.mark.parametrize("argv, message", [
    (["dispatch", "/nonexistent/out"], "not a folder"),
    (["dispatch", str(ROOT / "tasks")], "not an hrc compile output"),
    (["dispatch", "FOLDER", "--replay", str(ROOT / "README.md")], "not an hrc dispatch log"),
    (["dispatch", "FOLDER", "--replay", "LOG", "--log", "LOG"], "cannot be used together"),
    (["dispatch", "FOLDER", "--log", "/"], "must be a regular file"),
])
def test_cli_errors_are_one_line_and_exit_2(folder, tmp_path, capsys, argv, message):
    argv = [str(folder) if a == "FOLDER" else str(tmp_path / "x.log") if a == "LOG" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err


def test_preferences_narrow_the_robot_window_to_apas(tmp_path):
    """The spar assembly (APA's demo: each fastener placed soon after its sealant): with the task's
    preferences the robot's first window is APA's DO window inside the class's window, narrower; the
    same run with --no-preferences gets the class's window."""
    out = tmp_path / "spar"
    assert main(["compile", str(ROOT / "tasks" / "spar_assembly.yaml"), "--out", str(out), "--no-report",
                 "-q"]) == 0
    plan_set = load_plan_set(out)
    pref = Dispatcher(plan_set).decision.robot
    plain = Dispatcher(plan_set, use_preferences=False).decision.robot
    assert pref is not None and plain is not None and pref.event == plain.event == "depart"
    assert plain.earliest <= pref.earliest and pref.latest is not None and plain.latest is not None
    assert pref.latest < plain.latest - 1.0


def test_a_fork_is_independent(plan_set):
    d = Dispatcher(plan_set)
    f = d.fork()
    f.observe(Observation(1.0, "start", "human", "cube1", "fetch"))
    assert d.history == () and len(d.candidates) == 32 and f.history != ()


def test_a_plan_the_compile_found_blocked_is_never_promised():
    """Found by `hrc simulate` on kitting: a plan for which motion acquisition found no pattern ("the
    co-workers would block each other") was written with an STNU that carried none of its conflicts, and
    a check of that STNU alone said DC; the dispatcher used to start every kitting run on one. It must
    rank such a plan inconsistent, after every other plan (its file now carries the block, so its check
    says inconsistent too). With the
    person never waiting for the robot's sake (``human_waits=False``, no waiting place for the person),
    a person whose inspect and deliver at Q enclose the robot's label there blocks it in most plans."""
    from dataclasses import replace as dc_replace

    from hrc.compile.compiler import CompiledPlanSet, CompileOptions, compile_plan, rank_key
    from hrc.dispatch.ranking import CLASS_ORDER, reference_evaluate
    from hrc.dispatch.validation import History, seen_arrays
    from hrc.io.task_file import task_digest
    from hrc.motion import plan_paths
    from hrc.plans import generate_plans
    from hrc.temporal import check_dc

    task = load_task(ROOT / "tasks" / "kitting.yaml")
    paths = plan_paths(task, seed=0)
    options = CompileOptions(human_waits=False)
    compiled = sorted((compile_plan(task, p, paths, options) for p in list(generate_plans(task))[::45]), key=rank_key)
    cps = CompiledPlanSet(task=task, seed=0, digest=task_digest(task), paths=paths,
                          plans=tuple(dc_replace(cp, rank=i + 1) for i, cp in enumerate(compiled)), options=options)
    d = Dispatcher.from_compiled(cps)
    blocked = [e for e in d.plan_set.plans if e.blocked]
    assert blocked and all(e.compiled_class == "inconsistent" for e in blocked)
    # the compiled plan's flag (what hrc.sim.run reads) is the form's, and does not hang on wording
    assert {cp.plan.id for cp in compiled if cp.blocked} == {e.id for e in blocked}
    reworded = [dc_replace(cp, classification=dc_replace(cp.classification, explanation="(in other words)"))
                for cp in compiled]
    assert [cp.blocked for cp in reworded] == [cp.blocked for cp in compiled]
    assert all(cp.plan_class.value == "inconsistent" for cp in compiled if cp.blocked)
    assert not any(check_dc(e.stnu).consistent for e in blocked)  # its file carries the block (issue 27)
    seen, legs_seen = seen_arrays(History.start(task), d.plan_set.form.nodes.shape[2])
    for e in blocked:
        cls, _, _ = d.ranker.evaluate(np.array([d.plan_set.index(e.id)]), seen, legs_seen, 0)
        assert CLASS_ORDER[int(cls[0])] == reference_evaluate(e, {}, 0).plan_class == "inconsistent"
    ranked = [c.plan for c in d.candidates]
    ids = {e.id for e in blocked}
    assert d.decision.plan not in ids and d.decision.plan_class == "DC"
    first_blocked = min(i for i, p in enumerate(ranked) if p in ids)
    assert all(p in ids for p in ranked[first_blocked:])  # blocked plans come last


def test_the_robot_goes_on_while_the_person_is_away_even_with_work_left_for_them(plan_set):
    """Found by ``hrc simulate --human free --absence-rate 0.2`` (5 of 300 runs stuck): the person puts
    cube 3 and leaves while the robot is on its way to fetch the triangle. No plan gives the robot cube 4
    as well (its triangle comes last in the pile, and it is already on the triangle's leg), so the
    dispatcher kept the one plan that agreed with what was seen; then it refused the robot's own arrival
    at the triangle, and the robot stood there for good. A robot event that happened is a fact: it is
    accepted, the robot goes on, and when the person is back and puts cube 4 the triangle follows."""
    d, _ = _in_process(plan_set)
    seen = [(0.0, "human", "cube1", "fetch", "depart"), (2.86, "robot", "cube2", "fetch", "depart"),
            (8.345, "human", "cube1", "fetch", "arrive"), (8.345, "human", "cube1", "fetch", "start"),
            (12.308, "human", "cube1", "fetch", "end"), (12.308, "human", "cube1", "put", "depart"),
            (16.818, "human", "cube1", "put", "arrive"), (16.818, "human", "cube1", "put", "start"),
            (21.287, "robot", "cube2", "fetch", "arrive"), (21.287, "robot", "cube2", "fetch", "start"),
            (22.171, "human", "cube1", "put", "end"), (22.171, "human", "cube3", "fetch", "depart"),
            (25.512, "human", "cube3", "fetch", "arrive"), (25.512, "human", "cube3", "fetch", "start"),
            (26.287, "robot", "cube2", "fetch", "end"), (26.287, "robot", "cube2", "put", "depart"),
            (28.365, "human", "cube3", "fetch", "end"), (28.365, "human", "cube3", "put", "depart"),
            (31.512, "robot", "cube2", "put", "arrive"), (31.512, "robot", "cube2", "put", "start"),
            (36.123, "robot", "cube2", "put", "end"), (36.123, "robot", "triangle", "fetch", "depart"),
            (37.304, "human", "cube3", "put", "arrive"), (37.304, "human", "cube3", "put", "start"),
            (40.018, "human", "cube3", "put", "end")]
    for t, agent, action, phase, event in seen:
        d.observe(Observation(t, event, agent, action, phase))
    away = d.observe(Observation(40.018, "away", "human"))
    assert away.human_away and isinstance(away.robot, RobotStep)
    assert (away.robot.action, away.robot.phase, away.robot.event) == ("triangle", "fetch", "arrive")
    arrived = d.observe(Observation(42.151, "arrive", "robot", "triangle", "fetch"))  # was refused
    assert arrived.plan is not None and not arrived.stopped
    d.observe(Observation(53.289, "back", "human"))
    for t, phase, event in ((53.289, "fetch", "depart"), (56.388, "fetch", "arrive"), (56.388, "fetch", "start"),
                            (59.064, "fetch", "end"), (59.064, "put", "depart"), (62.413, "put", "arrive"),
                            (62.413, "put", "start"), (65.907, "put", "end")):
        last = d.observe(Observation(t, event, "human", "cube4", phase))
    assert isinstance(last.robot, RobotStep) and last.robot.action == "triangle"


def test_a_compile_with_packed_stnus_dispatches_as_one_with_files(plan_set, tmp_path, capsys):
    """``hrc compile --stnu archive`` (the option for large tasks) packs the STNUs into stnu.zip; the
    dispatcher reads them from there and decides exactly as from one GraphML file per plan. With
    ``--stnu none`` there is nothing to dispatch with: one error line that says how to go on."""
    packed = tmp_path / "packed"
    assert main(["compile", str(WORKSHOP), "--out", str(packed), "--stnu", "archive", "--no-report", "-q"]) == 0
    assert not (packed / "stnu").exists() and (packed / "stnu.zip").is_file()
    a, b = Dispatcher(plan_set), Dispatcher(load_plan_set(packed))
    assert a.decision == b.decision
    for obs in (Observation(0, "depart", "human", "cube1", "fetch"),
                Observation(2.86, "depart", "robot", "cube2", "fetch"),
                Observation(8.3, "arrive", "human", "cube1", "fetch")):
        assert a.observe(obs) == b.observe(obs)
    bare = tmp_path / "bare"
    assert main(["compile", str(WORKSHOP), "--out", str(bare), "--stnu", "none", "--no-report", "-q"]) == 0
    capsys.readouterr()
    assert main(["dispatch", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "--stnu graphml or --stnu archive" in err[0]


def test_a_robot_acknowledgement_outside_its_window_is_accepted_marked_and_ranked(plan_set):
    """Issue 26's policy: an acknowledgement says the event happened, so it is accepted; the answer says
    how it stood to what the robot was told (early, late, unasked), and the plans are re-ranked from it."""
    d, send = _in_process(plan_set)
    answer = json.loads(send('{"t": 0.5, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}'))
    step = answer["robot"]
    assert "earliest" in step and step["earliest"] > 1 and "ack" not in answer
    msg = {"agent": "robot", "action": step["action"], "phase": step["phase"], "event": step["event"]}
    early = json.loads(handle_line(d.fork(), json.dumps({"t": 1.0, **msg})))
    assert early["ok"] and early["ack"] == {"early": round(step["earliest"] - 1.0, 3),
                                            "window": [step["earliest"], step["latest"]]}
    on_time = json.loads(handle_line(d.fork(), json.dumps({"t": step["earliest"], **msg})))
    assert on_time["ok"] and "ack" not in on_time
    late_t = step["latest"] + 5
    late = json.loads(handle_line(d.fork(), json.dumps({"t": late_t, **msg})))
    assert late["ok"] and late["ack"] == {"late": 5.0, "window": [step["earliest"], step["latest"]]}
    # acting early or late costs the promise: not every plan left is DC any more
    assert early["candidates"] != on_time["candidates"] or late["candidates"] != on_time["candidates"]
    # an event the robot was not told to do (here: it was told to wait for the person)
    fresh, send_fresh = _in_process(plan_set)
    waiting = fresh.decision.robot
    assert isinstance(waiting, WaitFor)
    unasked = json.loads(send_fresh(json.dumps({"t": 0.2, **msg})))
    assert unasked["ok"] and unasked["ack"] == {"unasked": True, "told": {"wait_for": str(waiting)}}


def test_one_bad_clock_value_cannot_wedge_a_run(plan_set):
    """A tick at 1e9 s used to move the run's clock past every later message; now it is refused, and so is
    any message more than MAX_JUMP after the last; a real long pause goes in steps of at most MAX_JUMP."""
    from hrc.dispatch.validation import MAX_JUMP

    d, send = _in_process(plan_set)
    assert json.loads(send('{"t": 1, "event": "tick"}'))["ok"]
    refused = json.loads(send('{"t": 1e9, "event": "tick"}'))
    assert not refused["ok"] and "clock error" in refused["error"] and d.now == 1
    assert not json.loads(send(json.dumps({"t": 1 + MAX_JUMP + 0.5, "event": "tick"})))["ok"]
    assert json.loads(send('{"t": 2, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}'))["ok"]
    for t in (2 + MAX_JUMP, 2 + 2 * MAX_JUMP):  # an afternoon away, told in steps
        assert json.loads(send(json.dumps({"t": t, "event": "tick"})))["ok"]
    assert d.now == 2 + 2 * MAX_JUMP


def test_a_partial_output_dispatches_only_when_allowed(folder, tmp_path, capsys):
    partial = tmp_path / "partial"
    shutil.copytree(folder, partial)
    text = (partial / "compiled.json").read_text()
    (partial / "compiled.json").write_text(text.replace('"counts"', '"partial": true,\n "counts"', 1))
    assert main(["dispatch", str(partial)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "--allow-partial" in err and err.count("\n") == 1
    run = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(partial), "--allow-partial"],
                         input='{"t": 0, "event": "tick"}\n', capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert run.returncode == 0 and json.loads(run.stdout.splitlines()[0])["ok"], run.stderr


def test_a_redundant_message_gets_the_last_answer_again_unchanged_at_no_cost(plan_set):
    """A tick within the 0.05 s gap, and the last accepted message again whole, change nothing: answered
    `ok`, the previous answer marked unchanged, and the dispatcher's state not even rebuilt (the same
    object), where before the tick was refused."""
    from hrc.dispatch.protocol import TICK_GAP, is_accepted

    d, send = _in_process(plan_set)
    first = send('{"t": 0, "event": "tick"}')
    assert json.loads(first)["ok"] and is_accepted(first)
    depart = '{"t": 0.5, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}'
    taken = send(depart)
    state = d._state
    for line in ('{"t": 0.5, "event": "tick"}', '{"t": 0.53, "event": "tick"}', json.dumps({"t": 0.5 + TICK_GAP * 0.99,
                 "event": "tick"}), depart, depart.replace('"t": 0.5', '"t": 0.50')):
        again = send(line)
        assert again == taken[:-1] + ', "unchanged": true}', line  # the previous answer, byte for byte, marked
        assert json.loads(again)["ok"] is True and not is_accepted(again)
        assert d._state is state, line  # nothing taken, nothing ranked again
    later = json.loads(send(json.dumps({"t": 0.5 + TICK_GAP, "event": "tick"})))  # the gap's end: time passes
    assert later["ok"] and "unchanged" not in later and d.now == 0.5 + TICK_GAP and d._state is not state
    # a repeat that is no longer the last accepted message is a duplicate event: refused as before
    dup = json.loads(send(depart.replace('"t": 0.5', '"t": 0.6')))
    assert dup["ok"] is False and "duplicate" in dup["error"], dup
    assert not json.loads(send(depart))["ok"]  # time goes backwards: not the last message any more
    assert not json.loads(send('{"t": 0.52, "event": "tick"}'))["ok"]  # before the last accepted message


def test_an_undo_again_is_never_redundant(plan_set):
    d, send = _in_process(plan_set)
    send('{"t": 1, "agent": "human", "action": "cube1", "phase": "fetch", "event": "start"}')
    assert json.loads(send('{"t": 2, "event": "undo"}'))["ok"] and d.history == ()
    again = json.loads(send('{"t": 2, "event": "undo"}'))
    assert again["ok"] is False and "nothing to undo" in again["error"]


def test_redundant_messages_log_and_resume_byte_for_byte(plan_set, tmp_path):
    """Answered unchanged, logged with their answer (not synced: `is_accepted` is false), and a resume
    (which answers every logged message again and compares the bytes) and a replay agree."""
    from hrc.dispatch.durable import LoggedDispatcher
    from hrc.dispatch.logfile import read_log
    from hrc.dispatch.protocol import replay

    path = tmp_path / "run.log"
    logged = LoggedDispatcher.create(Dispatcher(plan_set), path)
    lines = ['{"t": 0, "event": "tick"}', '{"t": 0.01, "event": "tick"}',
             '{"t": 1, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}',
             '{"t": 1, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}',
             '{"t": 1.04, "event": "tick"}', '{"t": 1.2, "event": "tick"}']
    answers = [logged.submit(line.encode()) for line in lines]
    logged.close()
    assert [json.loads(a).get("unchanged", False) for a in answers] == [False, True, False, True, True, False]
    assert all(json.loads(a)["ok"] for a in answers)
    resumed, info = LoggedDispatcher.resume(Dispatcher(plan_set), path)
    resumed.close()
    assert info.messages == len(lines) and resumed.dispatcher.accepted == logged.dispatcher.accepted
    assert len(resumed.dispatcher.accepted) == 3
    pairs = list(replay(Dispatcher(plan_set), read_log(path)))
    assert [got for got, _ in pairs] == [want for _, want in pairs] == answers
