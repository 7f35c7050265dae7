"""Errors raised by `hrc`.

Expected outcomes ("not DC", "inconsistent") are results, not exceptions; these are for bad input
and misuse. The CLI maps every `HrcError` to one `error: ...` line and exit status 2.

    HrcError
    ├── InputError                 a file given by the user is wrong (says file, line, key path)
    │   ├── TaskFileError          task YAML
    │   ├── MapFileError           map YAML or DXF floor plan
    │   ├── NetworkFileError       STNU file (GraphML, .stnu, HEATlab JSON)
    │   ├── StppFileError          STPP JSON file (APA)
    │   └── RunFileError           a recorded run (dispatcher log, MCAP) that `hrc learn` cannot use
    ├── UnreachableLocationError   no collision-free path between two locations
    ├── ExecutorError              a parallel or distributed executor failed or cannot be reached
    ├── SimulationError            a simulation asked for something impossible (bad model parameter, policy)
    ├── DetectError                a human action detector's parameter is impossible (hrc.detect)
    ├── ApaError                   an STPP built wrong through the API, or its QP could not be solved
    ├── LogWriteError              a dispatcher's log could not be written or synced (the message was refused)
    └── DispatchError              a dispatcher (hrc.dispatch, or APA's) refused a message (it changed nothing)
        └── MessageError           ... as it was read: too long, too deep, not UTF-8, not strict JSON
"""

from __future__ import annotations

__all__ = [
    "ApaError",
    "DetectError",
    "DispatchError",
    "ExecutorError",
    "HrcError",
    "InputError",
    "LogWriteError",
    "MapFileError",
    "MessageError",
    "NetworkFileError",
    "RunFileError",
    "SimulationError",
    "StppFileError",
    "TaskFileError",
    "UnreachableLocationError",
]


class HrcError(Exception):
    """Root of every error `hrc` raises on purpose."""


class InputError(HrcError):
    """A user's file is wrong: `FILE:LINE: KEY.PATH: what is wrong`.

    `line` is 1-based and optional (YAML gives it, other formats may not); `key` is a dotted key path
    such as ``actions[2].phases[0].duration.human`` and may be empty when the whole file is at fault.
    """

    def __init__(self, file: str, key: str, message: str, line: int | None = None) -> None:
        self.file = str(file)
        self.key = key
        self.message = message
        self.line = line
        where = self.file if line is None else f"{self.file}:{line}"
        text = f"{where}: {key}: {message}" if key else f"{where}: {message}"
        super().__init__(text)


class TaskFileError(InputError):
    """The task YAML is malformed or inconsistent."""


class RunFileError(InputError):
    """A recorded run is damaged, or was made for another task (its header's task digest)."""


class MapFileError(InputError):
    """The map YAML (or its DXF floor plan) is malformed or inconsistent."""


class NetworkFileError(InputError):
    """An STNU file (GraphML, .stnu, HEATlab JSON) is malformed."""


class UnreachableLocationError(HrcError):
    """Motion planning found no collision-free path between two locations for an agent."""


class ExecutorError(HrcError):
    """A parallel or distributed executor failed or could not be reached."""


class SimulationError(HrcError):
    """`hrc simulate` / `hrc.sim` was asked for something impossible: an unknown policy or human model,
    a rate outside [0, 1], a preferred order naming an unknown action."""


class StppFileError(InputError):
    """An STPP JSON file (APA, docs/apa.md) is malformed or inconsistent."""


class DetectError(HrcError):
    """A parameter of the human action detector or of its sensor model is impossible (`hrc.detect`)."""


class ApaError(HrcError):
    """An STPP was built wrong through the API (unknown event, ``lb > ub``, a convex quadratic, ...) or
    its quadratic program could not be solved. Bad files raise `StppFileError` instead."""


class DispatchError(HrcError):
    """A dispatcher refused a message (`hrc.dispatch.Dispatcher`: an observation no remaining plan allows,
    a duplicate, time going backwards, ...; `hrc.apa.dispatch.STPPDispatcher`: an unknown or repeated
    event); its state is unchanged. The message is one line."""


class MessageError(DispatchError):
    """A message refused as it was read (`hrc.dispatch.limits.read_json`): too long, nested too deep, not
    UTF-8, not JSON, or not strict JSON (a key twice, NaN, a number beyond a double or ±2**53). One line."""


class LogWriteError(HrcError):
    """A dispatcher's log could not be written, or synced (`hrc.dispatch.logfile`): the message was
    refused and nothing changed."""
