"""A simulated tracker: the person's position as a camera, a UWB tag or a lidar leg detector would give
it, for `hrc simulate --detector motion`.

`SensorModel`: positions every ``1 / rate`` seconds, each with independent Gaussian noise of `sigma`
metres per axis, lost with probability `dropout` (independently), and delivered `latency` seconds after
it was measured (stamped with the time it was measured, as trackers stamp them). `Sensor` draws them
for one run from its own generator (never the simulated person's: every run keeps the same person
under every detector).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hrc.errors import DetectError

__all__ = ["Sensor", "SensorModel"]


@dataclass(frozen=True, slots=True)
class SensorModel:
    """The tracker's noise `sigma` (m, per axis), `rate` (Hz), `dropout` (probability a position is lost)
    and `latency` (s from measurement to delivery)."""

    sigma: float = 0.05
    rate: float = 10.0
    dropout: float = 0.0
    latency: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (("sigma", 0.0, 5.0), ("rate", 0.1, 1000.0), ("dropout", 0.0, 0.9),
                             ("latency", 0.0, 60.0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                    or not lo <= value <= hi:
                raise DetectError(f"--sensor-{name} must lie in [{lo:g}, {hi:g}], found {value!r}")

    def to_json(self) -> dict[str, float]:
        return {"sigma": self.sigma, "rate": self.rate, "dropout": self.dropout, "latency": self.latency}


class Sensor:
    """One run's tracker: `measure` at each `next_time`, `due` gives what has arrived by a time."""

    def __init__(self, model: SensorModel, rng: np.random.Generator) -> None:
        self.model = model
        self.rng = rng
        self.k = 0
        self.queue: deque[tuple[float, float, float, float]] = deque()  # (arrives, t, x, y)

    @property
    def next_time(self) -> float:
        """When the next position is measured (s)."""
        return round(self.k / self.model.rate, 6)

    def measure(self, t: float, xy: tuple[float, float] | None) -> None:
        """The position at `t` (None: the person is not on the floor): noise, dropout, latency."""
        self.k += 1
        noise = self.rng.normal(0.0, self.model.sigma, 2)
        lost = self.rng.random() < self.model.dropout
        if xy is None or lost:
            return
        self.queue.append((t + self.model.latency, round(t, 3), round(xy[0] + float(noise[0]), 4),
                           round(xy[1] + float(noise[1]), 4)))

    def next_arrival(self) -> float:
        return self.queue[0][0] if self.queue else math.inf

    def due(self, now: float) -> list[tuple[float, float, float]]:
        out = []
        while self.queue and self.queue[0][0] <= now + 1e-9:
            out.append(self.queue.popleft()[1:])
        return out
