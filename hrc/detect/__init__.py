"""The human action detector from motion (Strassmair & Taylor 2014, section V.B): the person's tracked
position in, the observations the buttons give out (depart, arrive, start, end, each at the time it is
estimated to have happened) and, while they walk, the action they are heading for.

`hrc.detect.field` (walking distances on the floor), `hrc.detect.changepoint` (when a person left or
reached a place), `hrc.detect.model` (what the detector knows of a task, its settings),
`hrc.detect.situation` (what the dispatcher knows of the person: the leg under way, the options, the
futures the remaining plans allow), `hrc.detect.filter` (the filter: positions and a
situation in, events out), `hrc.detect.online` (a dispatcher that takes positions: ``hrc dispatch
--detect motion``, the console, the simulator), `hrc.detect.trace` (``hrc detect``: a trace file in,
observations out), `hrc.detect.sensor` (a simulated tracker). A team (issue 37) has one detector per
person, each person's positions naming them. See docs/detect.md.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hrc.detect.filter import Belief, Detected, Track
    from hrc.detect.model import DetectorModel, DetectParams, detector_model
    from hrc.detect.online import DetectingDispatcher, position_from_json, position_message

# Each name from its module when first asked for (PEP 562), not at ``import hrc.detect``: a submodule such
# as `hrc.detect.sensor` (``hrc simulate`` reads its `SensorModel` at every start, buttons or not) would
# otherwise import the filter, the walking-distance field and scipy.ndimage with it (issue 38: about
# 0.4 s of every ``hrc simulate``'s start).
_WHERE = {"Belief": "filter", "Detected": "filter", "Track": "filter", "DetectorModel": "model",
          "DetectParams": "model", "detector_model": "model", "DetectingDispatcher": "online",
          "position_from_json": "online", "position_message": "online"}


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{where}"), name)
    globals()[name] = value
    return value


__all__ = ["Belief", "DetectParams", "Detected", "DetectingDispatcher", "DetectorModel", "Track",
           "detector_model", "position_from_json", "position_message"]
