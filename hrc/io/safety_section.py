"""The task file's `safety:` section (docs/task-format.md): speed and separation monitoring, every value
with its unit ("0.1 s", "1.6 m/s", "1.2 m/s^2", "50 mm"), since a bare number in a safety setting is
the mistake that costs the most. `read_safety` validates and converts to SI; `safety_to_dict` writes it
back (``read_safety(safety_to_dict(s)) == s``)."""

from __future__ import annotations

import re
from typing import Any

from hrc.io.yamldoc import Doc
from hrc.model import Agent, Safety

__all__ = ["read_safety", "safety_to_dict"]

_UNITS = {
    "time": {"s": 1.0, "ms": 1e-3},
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3},
    "speed": {"m/s": 1.0, "mm/s": 1e-3, "km/h": 1 / 3.6},
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0},
}
_SI = {"time": "s", "length": "m", "speed": "m/s", "acceleration": "m/s^2"}
_KEYS = {"human_speed": "speed", "reaction_time": "time", "intrusion": "length", "sensor_uncertainty": "length",
         "robot_uncertainty": "length", "reduced_speed": "speed"}
_STOP = {"speed": "speed", "time": "time", "distance": "length"}
_QUANTITY = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*")
_MAX = {"time": 60.0, "length": 100.0, "speed": 20.0, "acceleration": 100.0}  # far beyond any shop floor


def _quantity(doc: Doc, value: Any, path: tuple, kind: str, positive: bool = False) -> float:
    units = _UNITS[kind]
    example = f"'{0.5 if kind != 'time' else 0.1} {_SI[kind]}'"
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        doc.fail(path, f"expected a {kind} with its unit, e.g. {example}")
    if not isinstance(value, str):
        doc.fail(path, f"the unit is missing: write {value} {_SI[kind]} (or {', '.join(units)})")
    m = _QUANTITY.fullmatch(value)
    if m is None:
        doc.fail(path, f"expected a {kind} with its unit, e.g. {example}, found '{value}'")
    if not m.group(2):
        doc.fail(path, f"the unit is missing: write {m.group(1)} {_SI[kind]} (or {', '.join(units)})")
    if m.group(2) not in units:
        doc.fail(path, f"expected a {kind} in {', '.join(units)}, found the unit '{m.group(2)}'")
    x = float(m.group(1)) * units[m.group(2)]
    if x < 0 or (positive and x == 0):
        doc.fail(path, f"expected a {'positive' if positive else 'non-negative'} {kind}, found '{value}'")
    if x > _MAX[kind]:
        doc.fail(path, f"expected a {kind} of at most {_MAX[kind]:g} {_SI[kind]}, found '{value}'")
    return x


def read_safety(doc: Doc, raw: Any, robot: Agent) -> Safety:
    """The `safety:` mapping at top-level key ``safety`` as a `Safety` (raises `TaskFileError` naming the
    key: a unit missing or unknown, a negative value, measured stops whose time or distance falls as the
    speed rises, a robot faster than its fastest measured stop, an unknown key)."""
    path: tuple = ("safety",)
    m = doc.mapping(raw, path, required=("reaction_time", "stopping"), optional=tuple(k for k in _KEYS
                                                                                       if k != "reaction_time"))
    vals = {k: _quantity(doc, m[k], path + (k,), kind, positive=k in ("human_speed", "reduced_speed"))
            for k, kind in _KEYS.items() if k in m}
    stop = m["stopping"]
    deceleration = None
    stops: list[tuple[float, float, float]] = []
    if isinstance(stop, dict):
        sm = doc.mapping(stop, path + ("stopping",), required=("deceleration",))
        deceleration = _quantity(doc, sm["deceleration"], path + ("stopping", "deceleration"), "acceleration",
                                 positive=True)
    else:
        items = doc.sequence(stop, path + ("stopping",), min_len=1)
        for i, item in enumerate(items):
            ipath = path + ("stopping", i)
            im = doc.mapping(item, ipath, required=tuple(_STOP))
            v, t, d = (_quantity(doc, im[k], ipath + (k,), kind, positive=k == "speed") for k, kind in _STOP.items())
            if stops:
                pv, pt, pd = stops[-1]
                if v <= pv:
                    doc.fail(ipath + ("speed",), f"measured stops go by rising speed: {v:g} m/s after {pv:g} m/s")
                if t < pt:
                    doc.fail(ipath + ("time",), f"the stopping time falls as the speed rises ({t:g} s at "
                                                f"{v:g} m/s after {pt:g} s at {pv:g} m/s)")
                if d < pd:
                    doc.fail(ipath + ("distance",), f"the stopping distance falls as the speed rises ({d:g} m at "
                                                    f"{v:g} m/s after {pd:g} m at {pv:g} m/s)")
            stops.append((v, t, d))
        if robot.speed > stops[-1][0] + 1e-12:
            doc.fail(path + ("stopping",), f"the robot drives at up to {robot.speed:g} m/s, but the fastest "
                                           f"measured stop is at {stops[-1][0]:g} m/s: add a stop at its speed")
    reduced = vals.get("reduced_speed")
    if reduced is not None and reduced >= robot.speed:
        doc.fail(path + ("reduced_speed",), f"a reduced speed must be below the robot's speed ({robot.speed:g} m/s), "
                                            f"found {reduced:g} m/s")
    return Safety(reaction_time=vals.get("reaction_time", 0.0), deceleration=deceleration, stops=tuple(stops),
                  human_speed=vals.get("human_speed", 1.6), intrusion=vals.get("intrusion", 0.0),
                  sensor_uncertainty=vals.get("sensor_uncertainty", 0.0),
                  robot_uncertainty=vals.get("robot_uncertainty", 0.0), reduced_speed=reduced)


def safety_to_dict(s: Safety) -> dict[str, Any]:
    """`s` as the task file writes it (SI units; exact: ``repr`` of each float)."""
    out: dict[str, Any] = {"human_speed": f"{s.human_speed!r} m/s", "reaction_time": f"{s.reaction_time!r} s"}
    if s.deceleration is not None:
        out["stopping"] = {"deceleration": f"{s.deceleration!r} m/s^2"}
    else:
        out["stopping"] = [{"speed": f"{v!r} m/s", "time": f"{t!r} s", "distance": f"{d!r} m"} for v, t, d in s.stops]
    out |= {"intrusion": f"{s.intrusion!r} m", "sensor_uncertainty": f"{s.sensor_uncertainty!r} m",
            "robot_uncertainty": f"{s.robot_uncertainty!r} m"}
    if s.reduced_speed is not None:
        out["reduced_speed"] = f"{s.reduced_speed!r} m/s"
    return out
