"""Closed loops in a wind that turns, for the tests and the benchmark of the path that follows it
(``test/flight/test_wind_follow.py``, ``benchmarks/bench_wind_follow.py``)."""
from __future__ import annotations

import dataclasses

import numpy as np

from ..flight.closed_loop import make_closed_loop
from ..flight.controller import ControllerSettings

__all__ = ["TrueVane", "fly_following"]


class TrueVane:
    """A plant with a perfect vane: every measurement's ``wind_direction`` is the true mean wind direction (the
    reference ground station)."""

    def __init__(self, plant):
        self.plant, self.dt = plant, plant.dt

    def _m(self, m):
        return dataclasses.replace(m, wind_direction=self.plant.wind.mean.direction)

    def measure(self):
        return self._m(self.plant.measure())

    def step(self, delta):
        return self._m(self.plant.step(delta))


def fly_following(config, follow, seed: int, duration: float, true_vane: bool = False):
    """``((t, tension, path direction, crashes) arrays, plant)`` of ``duration`` s of closed loop on the plant
    ``config`` (seed ``seed``) with the controller's ``follow_wind`` = ``follow``; ``true_vane``: the controller reads
    the true mean direction instead of the vane."""
    plant, ctl = make_closed_loop(plant_config=config, seed=seed, settings=ControllerSettings(follow_wind=follow))
    src = TrueVane(plant) if true_vane else plant
    m = src.measure()
    out = []
    for _ in range(round(duration / plant.dt)):
        m = src.step(ctl.command(m))
        out.append((m.t, m.tension, ctl.status.direction, m.crashes))
    return np.array(out).T, plant
