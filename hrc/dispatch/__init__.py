"""The dispatcher (Strassmair & Taylor 2014, section V.B): online, from a compiled plan set to the robot's
next step. `Dispatcher` (`hrc.dispatch.dispatcher`) runs the paper's cycle on each message: update the
history, set validation (`hrc.dispatch.validation`), set ranking (`hrc.dispatch.ranking`), decision.
`hrc.dispatch.plan_set` loads an `hrc compile` output folder; `hrc.dispatch.messages` holds the message
types; `hrc.dispatch.protocol` the JSON-lines protocol shared by `hrc dispatch` and the console, with
`hrc.dispatch.limits` (what a message may be), `hrc.dispatch.logfile` (the log: format, reader, locked
writer), `hrc.dispatch.durable` (write-ahead logging and crash resume) and `hrc.dispatch.stdio` (the
loop of ``hrc dispatch``, group commit). See docs/dispatch.md.
"""

from hrc.dispatch.dispatcher import UNDO_SECONDS, Dispatcher
from hrc.dispatch.messages import (
    EVENTS,
    LEG_EVENTS,
    Candidate,
    Decision,
    HumanOption,
    Observation,
    RobotStep,
    WaitFor,
    observation_from_json,
)

__all__ = ["EVENTS", "LEG_EVENTS", "UNDO_SECONDS", "Candidate", "Decision", "Dispatcher", "HumanOption",
           "Observation", "RobotStep", "WaitFor", "observation_from_json"]
