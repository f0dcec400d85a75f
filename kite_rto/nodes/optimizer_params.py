"""The optimizer node's parameters, their cross-checks and the :class:`~kite_rto.rto.settings.KiteRTOSettings` they
build (shape box checked for trackability)."""
from __future__ import annotations

import math
from dataclasses import replace

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import ShapeBox, setpoints_from_shape
from ..kite.params import KiteParams, ParameterError
from ..rto.ocp import ALTITUDES
from ..rto.settings import KiteRTOSettings
from ..rto.wind_source import WIND_SOURCES
from .parameters import ParamSpec

__all__ = ["PARAMS", "RUN_INDEPENDENT", "cross_check", "run_settings", "settings_from_params"]

_SLOPE_NAMES = {True: "true", False: "false", "extrapolated": "extrapolated", "terms": "terms"}
"""``GMASettings.safe_model_slope`` -> the string of the ``safe_model_slope`` parameter."""
_S = KiteRTOSettings()
_E = _S.experiment
PARAMS = (
    ParamSpec("db", "rto.sqlite", "SQLite file of experiments and iterations (resume source), in an existing "
              "directory"),
    ParamSpec("resume", True, "continue from the database if it holds a run (false: refuse a database that holds "
              "one; a run's settings must match the stored ones to resume it)"),
    ParamSpec("storage_timeout", 60.0, "wall time the optimizer holds its setpoints and retries when it cannot "
              "write the database (disk full, I/O error) before it stops with exit code 3", 1.0, 86400.0, unit="s"),
    ParamSpec("autostart", True, "configure and activate at start-up (a lifecycle node that manages itself); "
              "false: wait unconfigured for lifecycle transitions (ros2 lifecycle set, kite_ctl). A run whose "
              "database says it was paused comes back inactive either way"),
    ParamSpec("n_iter", 10, "GMA iterations to run, then hold the last setpoints (0 = no limit)", 0, 10000,
              unit="iterations", runtime=True),
    ParamSpec("exit_when_done", False, "exit (code 0) once n_iter iterations are done (needs n_iter > 0)",
              runtime=True),
    ParamSpec("n_laps", _E.n_laps, "whole laps averaged per experiment of the first iteration (n_laps_factor "
              "times as many from the second on)", 1, 100, unit="laps"),
    ParamSpec("n_laps_factor", float(_S.gma.averaging_schedule[-1]), "experiments from the second iteration on "
              "average n_laps times this many laps, rounded (near the optimum a short experiment's gradient is as "
              "large as its noise; 1 = as many as the first iteration's)", 1.0, 10.0, unit="dimensionless"),
    ParamSpec("settle_laps", _E.settle_laps, "whole laps dropped after a setpoint change", 0, 100, unit="laps"),
    ParamSpec("settle_time", _E.settle_time, "simulated time after a setpoint change before a lap may count "
              "(< max_duration)", 0.0, 600.0, unit="s"),
    ParamSpec("max_duration", _E.max_duration, "simulated time after which an experiment ends with what it has",
              1.0, 1e5, unit="s"),
    ParamSpec("normalize", _E.normalize, "normalize lap tension by the wind of wind_source (false: raw tension)"),
    ParamSpec("wind_source", _E.wind_source, "the wind the lap tension is normalized by: the ground anemometer "
              "(as is, or delayed by the transport lag to the kite) or the observer that estimates the wind at the "
              "kite from its own motion (published on /kite/wind_estimate)", choices=WIND_SOURCES),
    ParamSpec("h_min", _E.h_min, "minimum altitude (the constraint)", 0.0, 1000.0, unit="m"),
    ParamSpec("gradient", _S.gradient, "plant gradient estimation: directional (DMA: privileged directions "
              "only), or finite differences in every shape coordinate", choices=("directional", "forward",
                                                                                 "central", "least_squares")),
    ParamSpec("n_directions", _S.n_directions, "privileged directions measured per iteration (gradient "
              "directional), at most the setpoints not held at a robustly active bound (3 on the default box: "
              "none is held under the default prior)", 1, 3, unit="directions"),
    ParamSpec("fd_step", float(_S.fd_step[0]), "finite-difference step (directional: along each direction)",
              0.01, 1.0, unit="fraction of the shape box width"),
    ParamSpec("filter_gain", _S.gma.filter_gain, "GMA input filter K", 0.01, 1.0, unit="dimensionless"),
    ParamSpec("modifier_filter", _S.gma.modifier_filter, "GMA filter on the gradient modifiers (1 = none)", 0.01, 1.0,
              unit="dimensionless"),
    ParamSpec("modifier_drift", -1.0 if _S.gma.modifier_drift is None else _S.gma.modifier_drift,
              "GMA modifier filter matched to the gradient noise: bound on the plant-model curvature mismatch "
              "(negative = off: the fixed modifier_filter, and the altitude modifier's own noise filter off too)",
              -1.0, 1.0e6, unit="cost units per squared box width"),
    ParamSpec("model_secant", _S.gma.model_secant, "GMA gradient modifiers from the model's own difference "
              "quotients over the flown points (cancels the finite differences' truncation error up to the "
              "plant-model curvature mismatch; false: plant quotient minus the model's gradient)"),
    ParamSpec("model_secant_cost", _S.gma.model_secant_cost, "with model_secant: correct the cost gradient too "
              "(false: only the altitude constraint's, whose model is the reference figure-eight's geometry; the cost "
              "keeps the plant's quotients)"),
    ParamSpec("altitude_constraint", _S.altitude, "what the model's altitude constraint bounds: the lowest point "
              "of the reference figure-eight of the lap's setpoints (reference: a function of the setpoints alone, "
              "the path controller's tracking error left to GMA's modifiers) or of the model's own free lap (lap)",
              choices=ALTITUDES),
    ParamSpec("trust_radius", _S.gma.trust_radius, "initial trust radius (not below GMA's minimum trust radius)",
              _S.gma.trust_radius_min, 10.0, unit="fraction of the box width"),
    ParamSpec("reject_sigma", -1.0 if _S.gma.reject_sigma is None else _S.gma.reject_sigma, "GMA undoes a step "
              "after which the measured cost rose by more than this many standard errors: back to the previous "
              "point, the trust radius halved where the step moved (negative = never)", -1.0, 100.0,
              unit="standard errors"),
    ParamSpec("bound_sigma", -1.0 if _S.gma.bound_sigma is None else _S.gma.bound_sigma, "GMA holds a setpoint "
              "at a bound of the shape box from the third iteration on unless the held problem's multiplier of it "
              "exceeds this many standard deviations of the cost modifier (negative = never)", -1.0, 100.0,
              unit="standard deviations"),
    ParamSpec("bound_sigma_start", _S.gma.bound_sigma_start, "bound_sigma also holds a setpoint at the bound the run "
              "started on (the model optimum's); false holds only bounds the iterates reached by a step, so the "
              "measurements can move the iterate off a bound the model chose"),
    ParamSpec("safe_both_ends", _S.gma.safe_both_ends, "GMA's safe step learns the altitude constraint's curvature "
              "from both ends of each past step: the gradient at its end predicting its start too (false: from its "
              "start only)"),
    ParamSpec("safe_model_slope", _SLOPE_NAMES[_S.gma.safe_model_slope], "GMA's safe step predicts the altitude "
              "constraint's change with the worse of the measured and the model's slope: true (always), false "
              "(never: the measured slope), extrapolated (when the step extrapolates a difference flown on the other "
              "side of the setpoints), terms (for the extrapolated part of the step alone)",
              choices=tuple(_SLOPE_NAMES.values())),
    ParamSpec("box_theta_0_deg", [round(math.degrees(v), 9) for v in _S.box.theta_0], "optimizer's theta_0 range [low, high]",
              1.0, 89.0, unit="deg"),
    ParamSpec("box_A_phi_deg", [round(math.degrees(v), 9) for v in _S.box.A_phi], "optimizer's A_phi range [low, high]",
              0.1, 89.0, unit="deg"),
    ParamSpec("box_aspect", list(_S.box.aspect), "optimizer's aspect range [low, high], aspect = A_theta / "
              "sqrt(sin theta_0 A_phi); every point of the box must be trackable", 0.01, 2.0, unit="dimensionless"),
)


RUN_INDEPENDENT = ("db", "resume", "storage_timeout", "autostart", "n_iter", "exit_when_done")
"""Parameters that do not change what a stored experiment or iteration means (every other one is stored with a
new run and must match to resume it)."""


def run_settings(v: dict) -> dict:
    """The parameter values a run is created with and resumed only with (name -> value)."""
    return {s.name: v[s.name] for s in PARAMS if s.name not in RUN_INDEPENDENT}


def cross_check(v: dict) -> None:
    """Checks that involve several parameters (start-up and every runtime change)."""
    if not v["settle_time"] < v["max_duration"]:
        raise ParameterError(f"parameters settle_time = {v['settle_time']!r}, max_duration = {v['max_duration']!r}: "
                             "expected settle_time < max_duration (else no lap can count)")
    if v["exit_when_done"] and v["n_iter"] == 0:
        raise ParameterError(f"parameters exit_when_done = {v['exit_when_done']!r}, n_iter = 0: expected n_iter > 0 "
                             "when exit_when_done is true (n_iter = 0 never ends)")


def _shape_box(v: dict) -> ShapeBox:
    """The optimizer's :class:`ShapeBox` from the box parameters; every point of a 3x3x3 grid must track."""
    pairs = {}
    for name, key, scale in (("theta_0", "box_theta_0_deg", math.pi / 180), ("A_phi", "box_A_phi_deg", math.pi / 180),
                             ("aspect", "box_aspect", 1.0)):
        lo, hi = v[key]
        if not lo < hi:
            raise ParameterError(f"parameter {key} = {list(v[key])!r}: expected [low, high] with low < high")
        pairs[name] = (lo * scale, hi * scale)
    try:
        box = ShapeBox(**pairs)
        for x in box.grid(3):
            validate_setpoints(setpoints_from_shape(x), box.setpoint_box(), KiteParams())
    except SetpointError as err:
        raise ParameterError(f"parameters box_theta_0_deg = {list(v['box_theta_0_deg'])}, box_A_phi_deg = "
                             f"{list(v['box_A_phi_deg'])}, box_aspect = {list(v['box_aspect'])}: expected a box "
                             f"whose every point is a trackable figure-eight: {err}") from None
    return box


def settings_from_params(v: dict) -> KiteRTOSettings:
    """The run's settings from the parameter values ``v``; :class:`ParameterError` names a bad value."""
    try:
        spec = replace(_E, n_laps=v["n_laps"], settle_laps=v["settle_laps"], settle_time=v["settle_time"],
                       max_duration=v["max_duration"], normalize=v["normalize"], wind_source=v["wind_source"],
                       h_min=v["h_min"])
        drift = None if v["modifier_drift"] < 0 else v["modifier_drift"]
        return replace(_S, experiment=spec, box=_shape_box(v), gradient=v["gradient"],
                       n_directions=v["n_directions"], fd_step=(v["fd_step"],) * 3, altitude=v["altitude_constraint"]
                       ).with_gma(filter_gain=v["filter_gain"], modifier_filter=v["modifier_filter"],
                                  modifier_drift=drift, model_secant=v["model_secant"],
                                  model_secant_cost=v["model_secant_cost"], trust_radius=v["trust_radius"],
                                  averaging_schedule=(1.0, v["n_laps_factor"]),
                                  reject_sigma=None if v["reject_sigma"] < 0 else v["reject_sigma"],
                                  bound_sigma=None if v["bound_sigma"] < 0 else v["bound_sigma"],
                                  bound_sigma_start=v["bound_sigma_start"],
                                  safe_both_ends=v["safe_both_ends"],
                                  safe_model_slope={n: k for k, n in _SLOPE_NAMES.items()}[v["safe_model_slope"]],
                                  # the altitude's own noise filter is part of the noise-matched one
                                  constraint_drift=None if drift is None else _S.gma.constraint_drift)
    except ValueError as err:
        raise ParameterError(str(err)) from None
