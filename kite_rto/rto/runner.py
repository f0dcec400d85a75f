"""The pure runner: GMA on one continuously flying simulated kite, no ROS (:func:`run_rto`, :class:`RTOResult`).

One :class:`~kite_rto.kite.plant.KitePlant` and one :class:`~kite_rto.flight.controller.PathController` fly
continuously while an :class:`~kite_rto.rto.session.RTOSession` changes the setpoints.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..gma import GMA
from ..flight.closed_loop import make_closed_loop
from ..flight.controller import ControllerSettings
from ..flight.path import Setpoints
from ..flight.shape import setpoints_from_shape
from ..kite.plant import PlantConfig
from .builder import make_gma
from .session import RTOSession
from .settings import KiteRTOSettings

__all__ = ["RTOResult", "run_rto"]


@dataclass
class RTOResult:
    """Outcome of :func:`run_rto`.

    Attributes:
        records: every :class:`IterationRecord`.
        experiments: every :class:`~kite_rto.rto.session.ExperimentLog`.
        iterates: setpoints c_0, c_1, ..., c_K (rad), shape (K + 1, 3);
            c_{k+1} = setpoints_from_shape(records[k].c_next).
        iterate_times: flight time (s) at which each iterate became available (0 for c_0).
        flight_time: total simulated flight time, s.
        crashes: plant crashes during the run.
        seed: plant seed.
        success: the run completed its iterations (or its flight time) without having to stop.
        message: why the run stopped early ("" on success).
        history: GMA's :class:`History` (JSON-serializable).
    """

    records: list
    experiments: list
    iterates: np.ndarray
    iterate_times: np.ndarray
    flight_time: float
    crashes: int
    seed: int
    success: bool
    message: str
    history: object


def run_rto(plant_config: PlantConfig | None = None, seed: int = 0, n_iter: int = 10,
            settings: KiteRTOSettings | None = None, gma: GMA | None = None,
            controller_settings: ControllerSettings | None = None,
            max_flight_time: float = math.inf) -> RTOResult:
    """Fly GMA on one continuously flying simulated kite for ``n_iter`` iterations (pure, no ROS).

    Args:
        plant_config: the real kite (:class:`PlantConfig` defaults: turbulence and noise on).
        seed: plant seed (turbulence and noise); same seed, same setpoint sequence.
        n_iter: GMA iterations to complete.
        settings: :class:`KiteRTOSettings`.
        gma: a fresh GMA to use (default :func:`~kite_rto.rto.builder.make_gma` of ``settings``).
        controller_settings: :class:`ControllerSettings` (``box`` is replaced by ``settings.box``'s
            bounding setpoint box).
        max_flight_time: stop after this much simulated flight, s.
    """
    settings = settings or KiteRTOSettings()
    gma = gma or make_gma(settings)
    cs = replace(controller_settings or ControllerSettings(), box=settings.box.setpoint_box())
    session = RTOSession(gma, settings.experiment, settings.max_repeats)
    c_first = Setpoints.from_array(setpoints_from_shape(gma.next_request().c))
    plant, controller = make_closed_loop(c_first, plant_config, seed=seed, settings=cs)
    m = plant.measure()
    crashes0 = m.crashes
    new = session.start(m.t)
    k0 = len(gma.records)
    while len(gma.records) - k0 < n_iter and not session.stopped and m.t < max_flight_time:
        if new is not None:
            controller.set_setpoints(Setpoints.from_array(new))
        m = plant.step(controller.command(m))
        new = session.on_measurement(controller.in_path_frame(m))
    iterates = [setpoints_from_shape(gma.history.c0 if k0 == 0 else gma.records[k0 - 1].c_next)]
    iterates += [setpoints_from_shape(r.c_next) for r in gma.records[k0:]]
    return RTOResult(records=list(gma.records[k0:]), experiments=session.experiments,
                     iterates=np.array(iterates), iterate_times=np.r_[0.0, session.record_times],
                     flight_time=float(m.t), crashes=m.crashes - crashes0, seed=seed, success=not session.stopped,
                     message=session.message, history=gma.history)
