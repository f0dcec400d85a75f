"""Lap detection and per-lap statistics, fed one sample at a time (plant measurements or model trajectories).

A lap starts and ends where phi crosses zero upwards (s = 0 of the reference path for A_phi > 0). Hysteresis
makes this robust to noise and turbulence: a crossing only counts after phi has been below ``-hysteresis``
since the last one, and its time is interpolated linearly between the two samples around it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kite.params import check_range
from .projection import project_samples

__all__ = ["LapStats", "LapCrossing", "LapDetector"]


@dataclass(frozen=True)
class LapStats:
    """Statistics of one complete lap.

    Attributes:
        index: 0 for the first complete lap.
        t_start, t_end, duration: s.
        mean_tension: time-averaged line tension, N.
        min_altitude: m.
        rms_cross_track_deg: RMS cross-track error, deg (NaN if not supplied).
        mean_wind_sq: time average of the reference wind squared, (m/s)^2 (NaN if not supplied).
        tension_coefficient: mean_tension / mean_wind_sq, N/(m/s)^2: the mean tension normalized by the
            measured dynamic pressure, which removes most of the lap-to-lap turbulence scatter.
        projection: ``(theta_0, A_phi, A_theta)`` of the lap (rad), :func:`project_samples` of the lap
            resampled uniformly in time.
        n_samples: raw samples in the lap.
    """

    index: int
    t_start: float
    t_end: float
    duration: float
    mean_tension: float
    min_altitude: float
    rms_cross_track_deg: float
    mean_wind_sq: float
    tension_coefficient: float
    projection: tuple
    n_samples: int


class LapCrossing:
    """Where laps start and end, from ``(t, phi)`` alone: the shared rule of :class:`LapDetector` and of the
    experiment's end (:class:`~kite_rto.rto.experiment_end.ExperimentEnd`).

    A crossing is an upward zero crossing of phi after phi was below ``-hysteresis`` (rad), at the time
    interpolated between the two samples around it; a lap (from one crossing to the next) counts if its duration
    is within ``[min_duration, max_duration]`` s and it holds at least :data:`MIN_SAMPLES` samples.
    """

    MIN_SAMPLES = 5
    """Fewest samples of a lap that counts."""

    def __init__(self, hysteresis: float, min_duration: float, max_duration: float):
        self.hysteresis, self.min_duration, self.max_duration = hysteresis, min_duration, max_duration
        self.crossed = False              # the last sample crossed zero upwards
        self.reset()

    def reset(self) -> None:
        """Forget the lap in progress."""
        self._armed, self._t_cross, self._prev, self._n = False, None, None, 0

    def update(self, t: float, phi: float) -> tuple[float, float] | None:
        """Add one sample (t s, phi rad); ``(t_start, t_end)`` s of the lap it completes, else None."""
        prev, self._prev = self._prev, (t, phi)
        if phi < -self.hysteresis:
            self._armed = True
        lap, self.crossed = None, False
        if self._armed and prev is not None and prev[1] < 0.0 <= phi:
            t_cross = prev[0] + (t - prev[0]) * (-prev[1]) / (phi - prev[1])
            self._armed, self.crossed = False, True
            if self._t_cross is not None and self._n >= self.MIN_SAMPLES \
                    and self.min_duration <= t_cross - self._t_cross <= self.max_duration:
                lap = (self._t_cross, t_cross)
            self._t_cross, self._n = t_cross, 0
        self._n += 1
        return lap


class LapDetector:
    """Detects laps in a stream of samples and returns their :class:`LapStats`.

    Args:
        hysteresis: phi must go below ``-hysteresis`` (rad) between two counted upward zero crossings.
        min_duration, max_duration: laps outside this range (s) are discarded (crash, relaunch, lost path).
        n_resample: samples per lap for the projection (uniform in time).
    """

    def __init__(self, hysteresis: float = math.radians(2.0), min_duration: float = 2.0,
                 max_duration: float = 120.0, n_resample: int = 128):
        check_range("LapDetector", "hysteresis", hysteresis, 0.0, low_open=True)
        check_range("LapDetector", "min_duration", min_duration, 0.0)
        check_range("LapDetector", "max_duration", max_duration, min_duration, low_open=True)
        if n_resample < 8:
            raise ValueError(f"LapDetector.n_resample = {n_resample!r}: expected an integer >= 8")
        self.hysteresis, self.min_duration, self.max_duration = hysteresis, min_duration, max_duration
        self.n_resample = int(n_resample)
        self.laps: list[LapStats] = []
        self.crossing = LapCrossing(hysteresis, min_duration, max_duration)
        self._buf: list[tuple] = []

    def reset(self) -> None:
        """Forget the lap in progress (e.g. after a crash or a setpoint change); completed laps are kept."""
        self.crossing.reset()
        self._buf = []

    def update(self, t: float, theta: float, phi: float, tension: float = math.nan, altitude: float = math.nan,
               cross_track: float = math.nan, wind_ref: float = math.nan) -> LapStats | None:
        """Add one sample (t s, theta/phi rad, tension N, altitude m, cross_track rad, wind_ref m/s).

        Returns the :class:`LapStats` of the lap completed by this sample, else None.
        """
        sample = (t, theta, phi, tension, altitude, cross_track, wind_ref)
        lap = self.crossing.update(t, phi)
        result = None
        if self.crossing.crossed:
            if lap is not None:
                result = self._close(*lap, sample)
            self._buf = []
        self._buf.append(sample)
        return result

    def _close(self, t_start: float, t_end: float, last: tuple) -> LapStats:
        buf = self._buf
        duration = t_end - t_start
        a = np.array(buf, dtype=float)
        t = a[:, 0]
        # boundary samples interpolated at the crossing times
        tq = t_start + duration * np.arange(self.n_resample) / self.n_resample
        theta = np.interp(tq, np.r_[t, last[0]], np.r_[a[:, 1], last[1]])
        phi = np.interp(tq, np.r_[t, last[0]], np.r_[a[:, 2], last[2]])
        tension = np.interp(tq, t, a[:, 3])
        wind_sq = np.interp(tq, t, a[:, 6] ** 2)
        e = a[:, 5]
        stats = LapStats(
            index=len(self.laps), t_start=t_start, t_end=t_end, duration=duration,
            mean_tension=float(np.mean(tension)), min_altitude=float(np.min(a[:, 4])),
            rms_cross_track_deg=float(np.degrees(np.sqrt(np.mean(e ** 2)))),
            mean_wind_sq=float(np.mean(wind_sq)),
            tension_coefficient=float(np.mean(tension) / np.mean(wind_sq)),
            projection=tuple(float(v) for v in project_samples(theta, phi)), n_samples=len(buf))
        self.laps.append(stats)
        return stats
