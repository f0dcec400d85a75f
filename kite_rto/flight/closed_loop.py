"""Pure closed-loop runner: plant + path controller + lap detector, sample by sample.

The ROS controller node calls exactly the same :meth:`PathController.command` per received measurement; this
runner only replaces the messages by direct calls (``delta = controller.command(m); m = plant.step(delta)``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .controller import ControllerSettings, PathController
from .laps import LapDetector, LapStats
from ..kite.params import KiteParams
from .path import DEFAULT_SETPOINTS, Setpoints
from ..kite.model import shared_model
from ..kite.plant import KitePlant, PlantConfig

__all__ = ["ClosedLoopResult", "run_closed_loop", "make_closed_loop"]

_SERIES = ("t", "theta", "phi", "psi", "delta", "tension", "altitude", "wind_ref", "s", "cross_track")


@dataclass
class ClosedLoopResult:
    """Time series of one closed-loop run, one row per sample: the measurement the controller received and
    what it answered.

    Arrays: t s; theta, phi, psi rad (measured, in the path's frame: :meth:`PathController.in_path_frame`); delta (command answering the sample); tension N;
    altitude m; wind_ref m/s; s path parameter; cross_track rad (signed, at the measured position).
    laps: :class:`LapStats` of the complete laps; crashes: plant crash count during the run.
    """

    t: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    psi: np.ndarray
    delta: np.ndarray
    tension: np.ndarray
    altitude: np.ndarray
    wind_ref: np.ndarray
    s: np.ndarray
    cross_track: np.ndarray
    laps: list = field(default_factory=list)
    crashes: int = 0

    def rms_cross_track_deg(self, t_from: float = 0.0) -> float:
        """RMS cross-track error after ``t_from`` s, deg."""
        m = self.t >= t_from
        return float(np.degrees(np.sqrt(np.mean(self.cross_track[m] ** 2))))

    def laps_after(self, t_from: float) -> list[LapStats]:
        """Laps that start at or after ``t_from`` s."""
        return [lap for lap in self.laps if lap.t_start >= t_from]


def run_closed_loop(plant: KitePlant, controller: PathController, duration: float,
                    laps: LapDetector | None = None, record: bool = True) -> ClosedLoopResult:
    """Run ``duration`` seconds of closed loop from the plant's current state.

    Args:
        plant: a :class:`KitePlant` (or anything with ``measure()``, ``step(delta)``, ``dt``).
        controller: a :class:`PathController` with the same sample time.
        duration: s.
        laps: lap detector to feed (a fresh one if None).
        record: keep the time series (False: only laps and crashes, arrays are empty).
    """
    if abs(controller.settings.dt - plant.dt) > 1e-12:
        raise ValueError(f"controller dt = {controller.settings.dt!r} s differs from plant dt = {plant.dt!r} s")
    n = int(round(duration / plant.dt))
    laps = laps or LapDetector()
    rows = np.empty((n if record else 0, len(_SERIES)))
    m = plant.measure()
    crashes0 = m.crashes
    crashes = crashes0
    status = controller.status
    for k in range(n):
        delta = controller.command(m)
        if m.crashes != crashes:
            crashes = m.crashes
            laps.reset()
        mp = controller.in_path_frame(m)         # laps are counted around the path, wherever it is centred
        z = m.position[2]
        laps.update(m.t, mp.theta, mp.phi, m.tension, z, status.cross_track, m.wind_ref)
        if record:
            rows[k] = (m.t, mp.theta, mp.phi, mp.psi, delta, m.tension, z, m.wind_ref, status.s, status.cross_track)
        m = plant.step(delta)
    crashes = m.crashes
    cols = {name: rows[:, i].copy() for i, name in enumerate(_SERIES)}
    return ClosedLoopResult(**cols, laps=list(laps.laps), crashes=crashes - crashes0)


def make_closed_loop(setpoints: Setpoints = DEFAULT_SETPOINTS, plant_config: PlantConfig | None = None,
                     seed: int = 0, settings: ControllerSettings | None = None,
                     model_params: KiteParams | None = None) -> tuple[KitePlant, PathController]:
    """A plant and a controller with matching sample time (nominal model parameters by default)."""
    plant = KitePlant(plant_config or PlantConfig(), seed=seed)
    settings = replace(settings or ControllerSettings(), dt=plant.dt)
    controller = PathController(shared_model(), model_params or KiteParams(), setpoints, settings)
    return plant, controller
