"""The figure-eight follows the wind: the path's frame turned to the estimated mean wind direction.

A ground station centres the figure-eight on the measured mean wind direction (SPEC §2): a path left at the old
azimuth loses tension roughly as ``cos^2`` of the misalignment. :class:`WindFollower` estimates that direction from
the wind vane (rad from the ground frame's x towards y, one reading per sample): a first-order filter of time
constant ``filter_time`` (the vane at 10 m turns with every gust, ~10 deg rms in the default field, with a
correlation time of seconds), whose output moves at most ``rate_limit`` rad/s. The controller flies its path in the
frame of that direction: :meth:`WindFollower.to_path_frame` turns a ground-frame measurement into it (the tether,
the heading and the rates, :mod:`~kite_rto.kite.wind_frame`), and everything that reads the kite's angles
relative to the path (lap detection, experiments) reads them there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..kite.params import ParameterError, check_range
from ..kite.wind_frame import rotate_motion, rotate_vector, wind_rotation

__all__ = ["WindFollowSettings", "WindFollower", "PathFrameMeasurement"]

@dataclass(frozen=True)
class WindFollowSettings:
    """How the path follows the wind direction.

    Attributes:
        enabled: centre the path on the estimated mean wind direction (False: on the ground frame's x for ever).
        filter_time: time constant of the vane's filter, s (> 0).
        rate_limit: fastest turn of the path, rad/s (> 0).
    """

    enabled: bool = False
    filter_time: float = 20.0
    rate_limit: float = math.radians(2.0)

    def __post_init__(self):
        n = type(self).__name__
        if not isinstance(self.enabled, bool):
            raise ParameterError(f"{n}.enabled = {self.enabled!r}: expected True or False")
        check_range(n, "filter_time", self.filter_time, 0.0, low_open=True)
        check_range(n, "rate_limit", self.rate_limit, 0.0, low_open=True)


class PathFrameMeasurement:
    """A measurement in the path's frame: ``theta, phi, psi`` (rad), their rates (rad/s) and ``position`` (m)
    turned; every other attribute that of the ground-frame measurement it wraps."""

    __slots__ = ("theta", "phi", "psi", "theta_dot", "phi_dot", "psi_dot", "position", "_ground")

    def __init__(self, ground, state, rates, position):
        self._ground = ground
        self.theta, self.phi, self.psi = state
        self.theta_dot, self.phi_dot, self.psi_dot = rates
        self.position = position

    def __getattr__(self, name):
        return getattr(self._ground, name)

    @property
    def altitude(self) -> float:
        """z, m (a turn about the vertical keeps it)."""
        return self.position[2]


class WindFollower:
    """The estimated mean wind direction the path is centred on (module docstring).

    Args:
        settings: :class:`WindFollowSettings`.
        dt: sample time, s (> 0).
    """

    def __init__(self, settings: WindFollowSettings, dt: float):
        if not dt > 0:
            raise ParameterError(f"WindFollower: dt = {dt!r}: expected a sample time > 0 s")
        self.settings = settings
        self.dt = float(dt)
        self._a = 1.0 - math.exp(-self.dt / settings.filter_time)
        self._max_step = settings.rate_limit * self.dt
        self.filtered = None                 # the filter's state, rad (None before the first reading)
        self.direction = 0.0                 # the path's direction, rad
        self._rot = None

    def update(self, vane: float) -> float:
        """One vane reading (rad; NaN or infinite readings are skipped); returns the path's new direction (rad)."""
        if not math.isfinite(vane):
            return self.direction
        if self.filtered is None:
            self.filtered = vane
        else:                                  # filter the angle's change, not the angle: no jump at +-pi
            self.filtered += self._a * math.remainder(vane - self.filtered, math.tau)
        d = self.filtered - self.direction
        d = self._max_step if d > self._max_step else -self._max_step if d < -self._max_step else d
        if d:
            self.direction += d
            self._rot = None
        return self.direction

    def to_path_frame(self, m):
        """``m`` (ground frame: ``theta, phi, psi``, rates, ``position``) in the frame of :attr:`direction`; ``m``
        itself while the direction is exactly 0."""
        if self.direction == 0.0:
            return m
        if self._rot is None:
            self._rot = wind_rotation(self.direction)
        state, rates = rotate_motion((m.theta, m.phi, m.psi), (m.theta_dot, m.phi_dot, m.psi_dot), self._rot)
        return PathFrameMeasurement(m, state, rates, rotate_vector(self._rot, m.position))
