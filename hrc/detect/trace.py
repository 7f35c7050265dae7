"""``hrc detect``: a recorded (or live) trace of the person's positions in, the observations the
dispatcher takes out, in time order.

Each input line is a JSON object with the position ``{"t": 12.3, "x": 4.1, "y": 2.0}`` (seconds from
the task's start, metres in the map's frame; other keys are ignored, so a tracker's own fields may
stay), or a message of ``hrc dispatch``'s protocol (one with an ``"event"`` other than ``"position"``:
the robot's acknowledgements, ticks), which goes to the dispatcher behind the detector and is not
written out: where the task graph has the person wait for the robot (cube 3 is put after the robot's
cube 2), the detector needs the robot's events to know when the person may start. A line that is
neither (not JSON, a missing or non-finite number, a time before the last one, too long, not UTF-8,
a message the dispatcher refuses) is refused with one line naming the line number and what is wrong,
and skipped: nothing changes (`Refusal`). The detector runs in front of a dispatcher over the compiled
plan set that hears the detector's events and the stream's other messages
(`hrc.detect.online.DetectingDispatcher`), so every event given is one the remaining plans allow, with
the time the detector estimates it happened. Output lines
are ``{"t", "agent": "human", "action", "phase", "event"}``, the shape ``hrc dispatch`` takes. A team's
(issue 37: more than one person) position lines name their person, ``"agent": "alice"``; each person has
their own detector, and the events given are that person's.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from hrc.dispatch.limits import MAX_LINE, parse_message
from hrc.dispatch.messages import observation_from_json
from hrc.errors import DispatchError, MessageError

from .online import MAX_METRES, DetectingDispatcher

__all__ = ["Refusal", "detect_lines", "read_line"]


@dataclass(frozen=True, slots=True)
class Refusal:
    """Input line `line` (1-based) was skipped: `why`."""

    line: int
    why: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.why}; skipped"


def read_line(data: bytes, people: tuple[str, ...] = ()) -> tuple[float, float, float, str | None] | dict[str, Any]:
    """``(t, x, y, person)`` of a position line (other keys ignored), or the message of another line (one with
    an ``event`` other than ``position``); `DispatchError` saying what is wrong. `people`: a team's (issue 37,
    more than one): the line must name its person (``"agent"``); else the person is None (the one person's,
    ``agent`` ignored as before)."""
    if len(data) > MAX_LINE:
        raise DispatchError(f"longer than {MAX_LINE} bytes")
    try:
        obj: Any = parse_message(data)  # strict: a repeated key, NaN, 1e400 or a 310-digit number refused
    except MessageError as err:
        raise DispatchError(str(err)) from None
    if not isinstance(obj, dict):
        raise DispatchError(f"a JSON object was expected, found {type(obj).__name__}")
    if obj.get("event", "position") != "position":
        return obj
    out = []
    for key in ("t", "x", "y"):
        value = obj.get(key)
        if isinstance(value, bool) or not isinstance(value, int | float) or not -MAX_METRES <= value <= MAX_METRES:
            found = "nothing" if key not in obj else json.dumps(value)[:40]
            raise DispatchError(f"key {key!r}: a finite number (within ±{MAX_METRES:g}) was expected, found {found}")
        out.append(float(value))
    if not 0 <= out[0] <= 1e9:
        raise DispatchError(f"key 't': seconds from the task's start (0 to 1e9) were expected, found {out[0]:g}")
    person = None
    if len(people) > 1:
        person = obj.get("agent")
        if person not in people:
            found = "nothing" if "agent" not in obj else json.dumps(person)[:40]
            raise DispatchError(f"key 'agent': the person the position is of ({', '.join(people)}) was expected, "
                                f"found {found}")
    return out[0], out[1], out[2], person


def detect_lines(d: DetectingDispatcher, lines: Iterable[bytes]) -> Iterator[dict[str, Any] | Refusal]:
    """Feed each line's position to `d`; yield each observation given (in time order) and each refusal."""
    for number, raw in enumerate(lines, 1):
        data = raw.rstrip(b"\r\n")
        if not data.strip():
            continue
        try:
            got = read_line(data, d.people)
            if isinstance(got, dict):
                d.observe(observation_from_json(got))
                continue
            t, x, y, person = got
            given, refused = d.take_position(t, x, y, person)
        except DispatchError as err:
            yield Refusal(number, " ".join(str(err).split())[:300])
            continue
        except Exception as err:  # noqa: BLE001 - supervised: a defect refuses its line, the trace goes on
            yield Refusal(number, " ".join(f"internal error ({type(err).__name__}: {err}); nothing changed"
                                           .split())[:300])
            continue
        for ev, at in given:
            yield {**ev.to_json(person or d.model.human), "t": at}
        for why in refused:
            yield Refusal(number, f"the dispatcher refused the detector's {why}")
