"""The dispatcher's JSON-lines protocol: one message in, one answer out, and replay from a log
(docs/dispatch.md).

One JSON object per line in, exactly one JSON object per line out: the `Decision` (``"ok": true``) or a
refusal ``{"t": ..., "ok": false, "error": "one line"}`` that changed nothing. `handle_line` (a line of
text) and `answer` (a line's bytes, as ``hrc dispatch`` reads them and its log keeps them) never raise.

Before the dispatcher sees a message, it must be at most `MAX_LINE` bytes of UTF-8, nested at most
`MAX_DEPTH` deep (`hrc.dispatch.limits`), and well formed (`observation_from_json`).

**Redundant messages** (`redundant`) are answered, not refused, and not taken: a tick less than
`TICK_GAP` run seconds after the last accepted message, and an exact repeat of the last accepted message
(a controller's retry; an ``undo`` is never a repeat) would tell the dispatcher nothing new, and a
re-ranking costs a few milliseconds. They get the current decision again, the answer to the last
accepted message, marked ``"unchanged": true`` (its ``t`` is that message's: the state is as of then),
at the cost of writing it out: a clock ticking at 20 Hz or 10,000 times a second gets valid answers and
cannot bury the messages that matter. Each check depends only on the message and the dispatcher's
state, so a replay answers the same messages the same way, byte for byte.

The log that makes a run replayable is `hrc.dispatch.logfile`'s; `hrc.dispatch.durable` writes it ahead
of every change. `replay` feeds a log's messages to a fresh dispatcher over the same compiled folder
and yields each answer with the logged one.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from hrc.errors import DispatchError, HrcError, MessageError

from .dispatcher import Dispatcher
from .limits import MAX_DEPTH, MAX_INT, MAX_LINE, parse_message
from .logfile import LogContents
from .messages import Observation, observation_from_json

__all__ = ["MAX_DEPTH", "MAX_LINE", "TICK_GAP", "answer", "check_header", "handle_line", "is_accepted", "log_header",
           "redundant", "replay"]

TICK_GAP = 0.05
"""Run seconds: a tick closer than this to the last accepted message changes nothing (`redundant`)."""


def _dumps(obj: Any) -> str:
    text = json.dumps(obj, ensure_ascii=False, allow_nan=False)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:  # a lone surrogate quoted in an error: escape it, or no stream could carry it
        text = json.dumps(obj, ensure_ascii=True, allow_nan=False)
    return text


def _refusal(t: Any, reason: str) -> str:
    if isinstance(t, bool) or not isinstance(t, int | float) or not -MAX_INT <= t <= MAX_INT:
        t = None  # (NaN and infinities too: every comparison with NaN is false)
    return _dumps({"t": t, "ok": False, "error": " ".join(reason.split())[:500]})


def handle_line(dispatcher: Dispatcher, line: str) -> str:
    """Answer one message line (see the module docstring); never raises, refusals change nothing.

    Supervised: whatever goes wrong while one message is handled (a defect included) becomes that
    message's refusal, ``internal error (...)``, and the dispatcher's state is as it was (each accepted
    message replaces the state whole, `Dispatcher.observe`), so the next message is answered as usual.
    """
    try:
        return _handle_line(dispatcher, line)
    except Exception as err:  # noqa: BLE001 - a bug must not end a run; the state was not changed
        return _refusal(None, f"internal error ({type(err).__name__}: {err}); nothing changed")


def _handle_line(dispatcher: Dispatcher, line: str) -> str:
    try:
        obj = parse_message(line)
    except MessageError as err:
        return _refusal(None, str(err))
    t = obj.get("t") if isinstance(obj, dict) else None
    if isinstance(obj, dict) and obj.get("event") == "position":
        return _position(dispatcher, obj, t)
    try:
        obs = observation_from_json(obj)
        if redundant(dispatcher, obs):
            return _dumps({**dispatcher.decision.to_json(), "unchanged": True})
        decision = dispatcher.observe(obs)
    except DispatchError as err:
        return _refusal(t, str(err))
    except Exception as err:  # noqa: BLE001 - a bug must not end a run; the state was not changed
        return _refusal(t, f"internal error ({type(err).__name__}: {err}); nothing changed")
    return _dumps(decision.to_json())


def redundant(dispatcher: Dispatcher, obs: Observation) -> bool:
    """Whether `obs` would change nothing (see the module docstring): a tick at most `TICK_GAP` s after
    the last accepted message (not before it: that is time going backwards, refused), or the last
    accepted message again, whole (an ``undo`` again undoes one more). The first message never is. O(1)."""
    accepted = dispatcher.accepted
    if not accepted:
        return False
    if obs.event == "tick":
        return dispatcher.now <= obs.t < dispatcher.now + TICK_GAP
    return obs.event != "undo" and obs == accepted[-1]


def _position(dispatcher: Dispatcher, obj: dict[str, Any], t: Any) -> str:
    """A tracked position (``"event": "position"``): for a dispatcher with a human action detector in front
    of it (`hrc.detect.online.DetectingDispatcher`), refused otherwise."""
    take = getattr(dispatcher, "answer_position", None)
    if take is None:
        return _refusal(t, "a position needs the motion detector: start hrc dispatch (or the console) with "
                           "--detect motion")
    try:
        return _dumps(take(obj))
    except DispatchError as err:
        return _refusal(t, str(err))
    except Exception as err:  # noqa: BLE001 - a bug must not end a run; the state was not changed
        return _refusal(t, f"internal error ({type(err).__name__}: {err}); nothing changed")


def answer(dispatcher: Dispatcher, data: bytes) -> str:
    """Answer one message given as the bytes of its line (without the ``\\n``; a ``\\r`` before it is
    ignored), as ``hrc dispatch`` reads it from its input and its log keeps it. Never raises."""
    if len(data) > MAX_LINE:
        return _refusal(None, f"message longer than {MAX_LINE} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return _refusal(None, "message is not UTF-8")
    return handle_line(dispatcher, text.rstrip("\r\n"))


def is_accepted(answer_line: str) -> bool:
    """Whether an answer of `handle_line` / `answer` accepted its message (it changed the state: an
    answer marked ``unchanged`` did not)."""
    out = json.loads(answer_line)
    return bool(out.get("ok") is True and out.get("unchanged") is not True)


def _digest(dispatcher: Dispatcher) -> str:
    return dispatcher.plan_set.digest


def log_header(dispatcher: Dispatcher, version: int) -> dict[str, Any]:
    """The header of a log of `dispatcher`'s compiled plan set: the set's digest and size."""
    from hrc.io.task_file import task_digest

    # "task": the task's digest, so that `hrc learn` can tell a log of this task from another's (the
    # compiled digest alone depends on the compile too); a replay checks "compiled" only
    header = {"hrc_dispatch_log": version, "compiled": _digest(dispatcher), "plans": len(dispatcher.plan_set),
              "task": task_digest(dispatcher.plan_set.task)}
    team = _team(dispatcher)
    if team is not None:  # a team other than one person and one robot (issue 37): who is who, in task order
        header["team"] = team
    detect = _detect(dispatcher)
    if detect is not None:  # a run with a detector in front replays only with the same detector
        header["detect"] = detect
    if dispatcher.max_observation_delay is not None:  # and one with a stated delay only with the same
        header["max_observation_delay"] = dispatcher.max_observation_delay
    on_demand = _on_demand(dispatcher)
    if on_demand is not None:  # and one that compiles on demand only so (`hrc.dispatch.on_demand`)
        header["on_demand"] = on_demand
    return header


def _team(dispatcher: Dispatcher) -> dict[str, str] | None:
    """The task's agents and their kinds (``{"human": "human", "robot": "robot", "robot2": "robot"}``), for a
    team other than one person and one robot; None for those (their log header is as it always was)."""
    kinds = {a.id: a.kind.value for a in dispatcher.plan_set.task.agents}
    values = list(kinds.values())
    return None if sorted(values) == ["human", "robot"] else kinds


def _on_demand(dispatcher: Dispatcher) -> dict[str, Any] | None:
    settings = getattr(dispatcher, "on_demand", None)  # `hrc.dispatch.on_demand.OnDemandSettings`
    return None if settings is None else dict(settings.header())


def _detect(dispatcher: Dispatcher) -> dict[str, Any] | None:
    settings = getattr(dispatcher, "detect_settings", None)
    return None if settings is None else dict(settings())


def check_header(dispatcher: Dispatcher, contents: LogContents, path: str) -> None:
    """Raise `HrcError` when the log was written for another compiled plan set than `dispatcher`'s."""
    policy = contents.header.get("policy")  # a simulated run's (`hrc simulate --keep-logs`)
    if policy == "fixed":
        raise HrcError(f"{path}: the log of a simulated run under the fixed policy: no dispatcher gave its "
                       "answers (the fixed plan's orders), so none replays them")
    if (policy == "feasible-only") != dispatcher.feasible_only and policy is not None:
        raise HrcError(f"{path}: the log of a simulated run under the {policy} policy: "
                       + ("give --feasible-only" if policy == "feasible-only" else "leave out --feasible-only"))
    digest = _digest(dispatcher)
    if not dispatcher.plan_set.named_by(contents.header.get("compiled")):
        raise HrcError(f"{path}: the log was written for another compiled plan set "
                       f"(compiled {contents.header.get('compiled')!r}, this folder {digest!r})")
    if contents.header.get("team") != _team(dispatcher):
        raise HrcError(f"{path}: the log was written for another team (the log: {contents.header.get('team')}; "
                       f"this folder: {_team(dispatcher)})")
    if contents.header.get("detect") != _detect(dispatcher):
        raise HrcError(f"{path}: the log was written with other detector settings (the log: "
                       f"{contents.header.get('detect') or 'buttons'}; now: {_detect(dispatcher) or 'buttons'}): "
                       "give the same --detect and --sensor-sigma")
    if contents.header.get("on_demand") != _on_demand(dispatcher):
        raise HrcError(f"{path}: the log was written with other compile-on-demand settings (the log: "
                       f"{contents.header.get('on_demand') or 'off'}; now: {_on_demand(dispatcher) or 'off'})")
    if contents.header.get("max_observation_delay") != dispatcher.max_observation_delay:
        raise HrcError(f"{path}: the log was written with another --max-observation-delay (the log: "
                       f"{contents.header.get('max_observation_delay')}; now: {dispatcher.max_observation_delay})")


def replay(dispatcher: Dispatcher, contents: LogContents, path: str = "log") -> Iterator[tuple[str, str]]:
    """Feed the log's messages to `dispatcher` (fresh, over the same compiled folder); yield each answer
    with the logged one. Raises `HrcError` when the log was written for another compiled folder."""
    check_header(dispatcher, contents, path)
    for message in contents.messages:
        yield answer(dispatcher, message.data), message.answer
