"""Path-following controller for the figure-eight (pure core: one :meth:`PathController.command` per sample).

Structure (Erhard & Strauch 2013 / Fagiano et al. 2014 style), all from measured quantities only:

1. **Dead-time compensation**: the state measured now is propagated over the steering dead time with the
   nominal model (``KiteModel.state_step_py``) and the commands already sent but not yet applied (the controller
   keeps its own copy of the actuator's delay line and rate limit). The command computed now acts on that
   predicted state.
2. **Guidance**: closest point on the path (warm-started path parameter), desired course
   ``chi_d = chi_path - atan(e / L)`` from the signed cross-track error ``e`` and a look-ahead distance ``L``,
   converted to a desired orientation ``psi_d`` by inverting the drift ``theta' ~ cos psi - tan(theta)/E``.
3. **Turn-rate inversion**: ``psi' = w_ap g_s delta + phi' cos(theta)``; the geodesic turn rate wanted is the
   path's curvature feedforward plus ``k_psi (psi_d - psi)``, so
   ``delta = (k_psi e_psi - kappa v + k_i int e) / (w_ap g_s)``. ``w_ap`` comes from the anemometer and the
   model's shear, scaled by an on-line factor that matches the model's speed to the measured angular speed;
   the steering gain g_s is also corrected on line from the measured turn rate.
4. **Saturation** ``|delta| <= delta_max``, rate limit, and anti-windup (the integrator is frozen while the
   command saturates).

Setpoint changes are validated (a bad one raises :class:`SetpointError` and leaves the path unchanged) and
applied by blending the setpoints linearly over ``blend_time`` seconds: the reference moves continuously.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from ..kite.actuator import Actuator, step_toward
from ..kite.model import KiteModel
from ..kite.params import KiteParams, check_range
from .path import DEFAULT_TURN_MARGIN, FigureEightPath, SetpointBox, Setpoints, SetpointError, validate_setpoints
from .wind_follow import WindFollower, WindFollowSettings

__all__ = ["ControllerSettings", "ControllerStatus", "PathController", "SetpointError"]

TWO_PI = 2.0 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % TWO_PI - math.pi


@dataclass(frozen=True)
class ControllerSettings:
    """Tuning of :class:`PathController`.

    Attributes:
        dt: controller sample time, s (must equal the plant's).
        dead_time: steering dead time to compensate, s (0 disables the prediction).
        rate_limit: actuator rate limit assumed in the prediction and applied to the commands, 1/s.
        delta_max: steering limit, normalized, in (0, 1].
        look_ahead: look-ahead distance L of the guidance law, rad of arc (times r for m).
        k_psi: orientation-error gain, 1/s.
        k_i: integral gain, turn rate (rad/s) per (rad of cross-track x s).
        integral_limit: bound on the integral of the cross-track error, rad s.
        turn_margin: fraction of delta_max the tightest path turn may use (setpoint feasibility).
        blend_time: duration of the linear blend from old to new setpoints, s.
        speed_filter: time constant of the wind-scale estimate (measured vs model speed), s.
        gain_filter: time constant of the steering-gain estimate, s (0 disables it).
        box: accepted setpoint box.
        follow_wind: :class:`~kite_rto.flight.wind_follow.WindFollowSettings`: centre the path on the estimated
            mean wind direction (the measurement's ``wind_direction``, a wind vane).
    """

    dt: float = 0.02
    dead_time: float = 0.25
    rate_limit: float = 5.0
    delta_max: float = 1.0
    look_ahead: float = 0.06
    k_psi: float = 3.0
    k_i: float = 0.5
    integral_limit: float = 0.05
    turn_margin: float = DEFAULT_TURN_MARGIN
    blend_time: float = 10.0
    speed_filter: float = 3.0
    gain_filter: float = 5.0
    box: SetpointBox = field(default_factory=SetpointBox)
    follow_wind: WindFollowSettings = field(default_factory=WindFollowSettings)

    def __post_init__(self):
        n = type(self).__name__
        check_range(n, "dt", self.dt, 0.0, 1.0, low_open=True)
        check_range(n, "dead_time", self.dead_time, 0.0, 5.0)
        check_range(n, "rate_limit", self.rate_limit, 0.0, low_open=True)
        check_range(n, "delta_max", self.delta_max, 0.0, 1.0, low_open=True)
        check_range(n, "look_ahead", self.look_ahead, 0.0, 1.0, low_open=True)
        for f in ("k_psi", "speed_filter"):
            check_range(n, f, getattr(self, f), 0.0, low_open=True)
        for f in ("k_i", "integral_limit", "blend_time", "gain_filter"):
            check_range(n, f, getattr(self, f), 0.0)
        check_range(n, "turn_margin", self.turn_margin, 0.0, 1.0, low_open=True)


@dataclass
class ControllerStatus:
    """Diagnostics of the last :meth:`PathController.command` (for logging and lap statistics).

    s: path parameter of the measured position; cross_track: its signed cross-track error, rad;
    s_pred / cross_track_pred: same at the dead-time-predicted state; delta: command sent;
    saturated: True if the command hit delta_max; wind_scale, gain_scale: on-line correction factors;
    setpoints: the (blended) setpoints in use; direction: the azimuth the path is centred on, rad.
    """

    s: float = 0.0
    cross_track: float = 0.0
    s_pred: float = 0.0
    cross_track_pred: float = 0.0
    delta: float = 0.0
    saturated: bool = False
    wind_scale: float = 1.0
    gain_scale: float = 1.0
    setpoints: Setpoints | None = None
    direction: float = 0.0


class PathController:
    """Steers the kite along the figure-eight of the current setpoints.

    Args:
        model: the shared :class:`KiteModel` (its ``state_step_py`` is used for the dead-time prediction).
        model_params: the controller's (nominal) :class:`KiteParams`; never the plant's.
        setpoints: initial :class:`Setpoints` (validated; raises :class:`SetpointError`).
        settings: :class:`ControllerSettings`.

    Call :meth:`command` once per plant sample with the latest measurement (any object with attributes
    ``t, theta, phi, psi, theta_dot, phi_dot, psi_dot, wind_ref``); it returns ``delta`` in
    ``[-delta_max, delta_max]``.
    """

    def __init__(self, model: KiteModel, model_params: KiteParams, setpoints: Setpoints,
                 settings: ControllerSettings | None = None):
        self.model = model
        self.params = model_params
        self.settings = settings or ControllerSettings()
        st = self.settings
        self._c = self._validate(setpoints)
        self._c_from = self._c
        self._blend = 1.0
        self.path = FigureEightPath(self._c)
        self._p = model_params.as_vector()
        self._i_wref = KiteParams.names().index("w_ref")
        self._actuator = Actuator(st.dead_time, st.rate_limit, st.dt)   # own copy of the kite's actuator
        self._last_cmd = 0.0
        self._s = None
        self._s_pred = None
        self._int = 0.0
        self._wind_scale = 1.0
        self._gain_scale = 1.0
        self._gain_num = 0.0
        self._gain_den = 0.0
        self.status = ControllerStatus(setpoints=self._c)
        self.wind = WindFollower(st.follow_wind, st.dt) if st.follow_wind.enabled else None
        """The :class:`~kite_rto.flight.wind_follow.WindFollower` the path follows (None: the path stays put)."""

    # ----------------------------------------------------------------------------- setpoints
    def _validate(self, c) -> Setpoints:
        st = self.settings
        return validate_setpoints(c, st.box, self.params, delta_max=st.delta_max, margin=st.turn_margin)

    @property
    def setpoints(self) -> Setpoints:
        """The target setpoints (the last valid ones accepted)."""
        return self._c

    def set_setpoints(self, c) -> Setpoints:
        """Validate and switch to ``c`` smoothly; raises :class:`SetpointError` and keeps the old path if bad.

        The reference blends linearly from the current (possibly blended) setpoints to ``c`` over
        ``settings.blend_time`` s; intermediate setpoints are not re-validated (both ends are).
        """
        c = self._validate(c)
        self._c_from = self._current_setpoints()
        self._c = c
        self._blend = 0.0 if self.settings.blend_time > 0 else 1.0
        self.path = FigureEightPath(self._current_setpoints())
        return c

    RETUNABLE = ("look_ahead", "k_psi", "k_i", "blend_time")
    """Settings :meth:`retune` may change while flying (the others size the delay line or the setpoint check)."""

    def retune(self, **changes) -> ControllerSettings:
        """Change tuning settings of :data:`RETUNABLE` in flight; the next :meth:`command` uses them.

        Raises ``ValueError`` (:class:`ParameterError` for a bad value) and changes nothing if refused. A blend in
        progress continues with the new ``blend_time`` from where it is; 0 ends it at once.
        """
        other = sorted(set(changes) - set(self.RETUNABLE))
        if other:
            raise ValueError(f"PathController.retune: {', '.join(other)} cannot change in flight; "
                             f"retunable: {', '.join(self.RETUNABLE)}")
        self.settings = replace(self.settings, **changes)
        if self.settings.blend_time <= 0.0 and self._blend < 1.0:
            self._blend = 1.0
            self.path = FigureEightPath(self._c)
        return self.settings

    def _current_setpoints(self) -> Setpoints:
        if self._blend >= 1.0:
            return self._c
        a, b, w = self._c_from, self._c, self._blend
        return Setpoints(a.theta_0 + w * (b.theta_0 - a.theta_0), a.A_phi + w * (b.A_phi - a.A_phi),
                         a.A_theta + w * (b.A_theta - a.A_theta))

    # ------------------------------------------------------------------------------- control
    def in_path_frame(self, m):
        """``m`` as the path sees it: turned to the direction the path is centred on (``m`` itself when the path
        does not follow the wind); what lap detection and experiments read."""
        return m if self.wind is None else self.wind.to_path_frame(m)

    def command(self, m) -> float:
        """Steering command for measurement ``m`` (one call per sample), normalized, ``|delta| <= delta_max``."""
        st = self.settings
        if self._blend < 1.0:
            self._blend = min(1.0, self._blend + st.dt / st.blend_time)
            self.path = FigureEightPath(self._current_setpoints())
        if self.wind is not None:
            self.status.direction = self.wind.update(m.wind_direction)
            m = self.wind.to_path_frame(m)
        theta, phi, psi = m.theta, m.phi, m.psi
        p = self._p
        p[self._i_wref] = max(m.wind_ref, 0.5) * self._wind_scale
        self._adapt(m)

        # 1. dead-time prediction with the commands in flight
        x = [theta, phi, psi]
        step, dt = self.model.state_step_py, st.dt
        for applied in self._actuator.pending():
            x = step(x, applied, p, dt)[0]
        th_p, ph_p, psi_p = x

        # 2. guidance at the predicted state
        path = self.path
        cp_now = path.closest_point(theta, phi) if self._s is None else path.track(theta, phi, self._s)
        self._s = cp_now.s
        cp = path.closest_point(th_p, ph_p, s_guess=cp_now.s, window=(-0.2, 0.8)) if self._s_pred is None \
            else path.track(th_p, ph_p, self._s_pred)
        self._s_pred = cp.s
        e = cp.cross_track
        chi_d = cp.course - math.atan(e / st.look_ahead)
        # invert the drift: velocity ~ (cos psi - k, -sin psi) must point along chi_d
        k = math.tan(th_p) / self.params.E
        sc, cc = math.sin(chi_d), math.cos(chi_d)
        lam = -k * cc + math.sqrt(max(1.0 - (k * sc) ** 2, 0.0))
        psi_d = -math.atan2(lam * sc, lam * cc + k)
        e_psi = _wrap(psi_d - psi_p)

        # 3. turn-rate inversion: geodesic turn rate = psi' - phi' cos(theta) = w_ap g_s delta
        w_ap, speed = self._w_ap_and_speed(x, p)
        v = speed / self.params.r                      # rad/s of arc
        kappa = path.curvature(cp.s)
        rate = st.k_psi * e_psi - kappa * v + st.k_i * self._int
        g = w_ap * self.params.g_s * self._gain_scale
        u = rate / g if g > 1e-6 else 0.0

        # 4. saturation, rate limit, anti-windup
        sat = abs(u) >= st.delta_max
        u = min(max(u, -st.delta_max), st.delta_max)
        u = step_toward(self._last_cmd, u, self._actuator.max_change)
        if not sat or (self._int * e < 0):
            self._int = min(max(self._int + e * st.dt, -st.integral_limit), st.integral_limit)
        self._last_cmd = u
        self._actuator.push(u)
        s = self.status
        s.s, s.cross_track, s.s_pred, s.cross_track_pred = cp_now.s, cp_now.cross_track, cp.s, e
        s.delta, s.saturated, s.wind_scale, s.gain_scale = u, sat, self._wind_scale, self._gain_scale
        s.setpoints = path.setpoints
        return u

    def _w_ap_and_speed(self, x, p):
        """Model apparent wind w_ap (m/s) and kite speed (m/s) at state x with the current parameters p."""
        xdot, (w_ap, _wind) = self.model.rhs_py(x, self._actuator.applied, p)
        speed = self.params.r * math.hypot(xdot[0], math.sin(x[0]) * xdot[1])
        return w_ap, speed

    def _adapt(self, m) -> None:
        """Update the wind-scale (speed ratio) and steering-gain estimates from the measured rates."""
        st = self.settings
        x = [m.theta, m.phi, m.psi]
        xdot, (w_ap, _wind) = self.model.rhs_py(x, self._actuator.applied, self._p)
        v_model = math.hypot(xdot[0], math.sin(m.theta) * xdot[1])
        v_meas = math.hypot(m.theta_dot, math.sin(m.theta) * m.phi_dot)
        if v_model > 1e-3:
            a = st.dt / st.speed_filter
            ratio = min(max(v_meas / v_model, 0.5), 2.0)
            self._wind_scale = min(max(self._wind_scale * (1.0 + a * (ratio - 1.0)), 0.3), 3.0)
        if st.gain_filter > 0:
            y = m.psi_dot - m.phi_dot * math.cos(m.theta)       # measured geodesic turn rate, rad/s
            u = w_ap * self.params.g_s * self._actuator.applied  # model's prediction with gain 1
            f = math.exp(-st.dt / st.gain_filter)
            self._gain_num = f * self._gain_num + y * u
            self._gain_den = f * self._gain_den + u * u
            if self._gain_den > 1.0:
                self._gain_scale = min(max(self._gain_num / self._gain_den, 0.5), 1.5)
