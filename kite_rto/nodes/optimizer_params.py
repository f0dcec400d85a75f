"""The optimizer node's parameters, their cross-checks and the :class:`~kite_rto.rto.settings.KiteRTOSettings` they
build (shape box checked for trackability)."""
from __future__ import annotations

import math
from dataclasses import replace

from ..flight.path import SetpointError, validate_setpoints
from ..flight.shape import ShapeBox, setpoints_from_shape
from ..kite.params import KiteParams, ParameterError
from ..rto.ocp import ALTITUDES
from ..gma import MECHANISMS
from ..rto.settings import KiteRTOSettings
from ..rto.wind_source import WIND_SOURCES
from .parameters import ParamSpec

__all__ = ["PARAMS", "RUN_INDEPENDENT", "cross_check", "run_settings", "settings_from_params"]

_S = KiteRTOSettings()
_E = _S.experiment


def _mechanism(path: str, description: str, low: float, high: float, unit: str = "") -> ParamSpec:
    """The parameter ``<mechanism>.<field>`` of one of GMA's mechanisms, defaulting to the kite's value (the
    mechanism's own default where the kite has it off)."""
    name, field = path.split(".")
    settings = getattr(_S.gma, name) or MECHANISMS[name]()
    return ParamSpec(path, getattr(settings, field), description, low, high, unit=unit)


_MECHANISM_PARAMS = (
    _mechanism("modifier_filter.gain", "fixed filter gain b of the gradient modifiers (where no noise-matched gain "
               "applies; 1 = no filtering)", 0.01, 1.0, "dimensionless"),
    _mechanism("noise_filter.drift", "noise-matched modifier filter: bound on the plant-model curvature mismatch "
               "(larger forgets modifiers measured far away sooner)", 0.0, 1.0e6, "cost units per squared box width"),
    _mechanism("noise_filter.constraint_drift", "noise-matched filter of the altitude's gradient modifier, fed "
               "with the altitude's own noise", 0.0, 1.0e6, "m per squared box width"),
    _mechanism("trust_region.radius", "initial trust radius (not below trust_region.min_radius)", 0.01, 10.0,
               "box widths"),
    _mechanism("trust_region.min_radius", "smallest trust radius the adaptation leaves", 0.001, 10.0, "box widths"),
    _mechanism("safe_step.curvature", "prior bound on the altitude constraint's curvature (grows to what the "
               "measured steps show)", 0.0, 1.0e6, "m per squared box width"),
    _mechanism("safe_step.sigma", "standard deviations of the measured altitude and of its predicted change",
               0.0, 100.0, "standard deviations"),
    _mechanism("safe_step.tolerance", "how far below h_min a step may be predicted to take the kite", 0.0, 1000.0,
               "m"),
    _mechanism("safe_step.learn_min_step", "shortest step the curvature bound learns from", 0.0, 1.0, "box widths"),
    _mechanism("undo.sigma", "a step after which the measured cost rose by more than this is undone: back to the "
               "previous point, the trust region narrowed where the step moved", 0.0, 100.0, "standard errors"),
    _mechanism("bound_hold.sigma", "a setpoint at a bound an earlier step reached stays there unless the held "
               "problem's multiplier of it exceeds this", 0.0, 100.0, "standard deviations of the cost modifier"),
    _mechanism("bound_hold.after", "first iteration that holds bounds", 0, 1000, "iterations"),
    _mechanism("settle.step", "a step below this in every setpoint is calm (settle: no perturbation at a settled "
               "point until a change is detected)", 1e-6, 1.0, "box widths"),
    _mechanism("settle.after", "calm iterations that settle the point (and watched measurements that make the "
               "reference)", 1, 100, "iterations"),
    _mechanism("settle.drift", "allowance k of the CUSUM on the watched measurements", 0.0, 10.0,
               "standard deviations"),
    _mechanism("settle.threshold", "decision limit h of the CUSUM: above it a change ends the watch", 0.01, 100.0,
               "standard deviations"),
)
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
    ParamSpec("n_laps", _E.n_laps, "whole laps averaged per experiment at effort 1 (effort_schedule: GMA's "
              "multiples of it by iteration)", 1, 100, unit="laps"),
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
    ParamSpec("filter_gain", _S.gma.filter_gain, "GMA input filter K (1 = full steps)", 0.01, 1.0,
              unit="dimensionless"),
    ParamSpec("backoff", _S.gma.backoff, "GMA tightens the modified altitude constraint by this much", 0.0, 1000.0,
              unit="m"),
    ParamSpec("effort_schedule", list(_S.gma.effort_schedule), "experiment length by GMA iteration, as multiples of "
              "n_laps (the last one holds for every later iteration; near the optimum a short experiment's gradient "
              "is as large as its noise)", 0.1, 100.0, unit="multiples of n_laps", any_length=True),
    ParamSpec("mechanisms", [n for n in MECHANISMS if getattr(_S.gma, n) is not None], "GMA's mechanisms that are "
              "on, each set by its <mechanism>.<field> parameters (docs/gma.md)", choices=tuple(MECHANISMS)),
    ParamSpec("altitude_constraint", _S.ocp.altitude, "what the model's altitude constraint bounds: the lowest point "
              "of the reference figure-eight of the lap's setpoints (reference: a function of the setpoints alone, "
              "the path controller's tracking error left to GMA's modifiers) or of the model's own free lap (lap)",
              choices=ALTITUDES),
    ParamSpec("box_theta_0_deg", [round(math.degrees(v), 9) for v in _S.box.theta_0], "optimizer's theta_0 range [low, high]",
              1.0, 89.0, unit="deg"),
    ParamSpec("box_A_phi_deg", [round(math.degrees(v), 9) for v in _S.box.A_phi], "optimizer's A_phi range [low, high]",
              0.1, 89.0, unit="deg"),
    ParamSpec("box_aspect", list(_S.box.aspect), "optimizer's aspect range [low, high], aspect = A_theta / "
              "sqrt(sin theta_0 A_phi); every point of the box must be trackable", 0.01, 2.0, unit="dimensionless"),
) + _MECHANISM_PARAMS


RUN_INDEPENDENT = ("db", "resume", "storage_timeout", "autostart", "n_iter", "exit_when_done")
"""Parameters that do not change what a stored experiment or iteration means (every other one is stored with a
new run and must match to resume it)."""


def run_settings(v: dict) -> dict:
    """The parameter values a run is created with and resumed only with (name -> value); the ``<mechanism>.<field>``
    parameters of a mechanism that is off are not among them (they change nothing the run does)."""
    on = set(v["mechanisms"])
    return {s.name: v[s.name] for s in PARAMS
            if s.name not in RUN_INDEPENDENT and ("." not in s.name or s.name.split(".")[0] in on)}


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


def _gma_settings(v: dict):
    """GMA's settings from the parameters: the listed mechanisms from their dotted parameters, the others off."""
    on = set(v["mechanisms"])
    subs = {}
    for name, cls in MECHANISMS.items():
        fields = {spec.name.split(".")[1]: v[spec.name] for spec in _MECHANISM_PARAMS
                  if spec.name.startswith(name + ".")}
        subs[name] = cls(**fields) if name in on else None
    return replace(_S.gma, filter_gain=v["filter_gain"], backoff=v["backoff"],
                   effort_schedule=tuple(v["effort_schedule"]), **subs)


def settings_from_params(v: dict) -> KiteRTOSettings:
    """The run's settings from the parameter values ``v``; :class:`ParameterError` names a bad value."""
    try:
        spec = replace(_E, n_laps=v["n_laps"], settle_laps=v["settle_laps"], settle_time=v["settle_time"],
                       max_duration=v["max_duration"], normalize=v["normalize"], wind_source=v["wind_source"],
                       h_min=v["h_min"])
        return replace(_S, experiment=spec, box=_shape_box(v), gradient=v["gradient"],
                       n_directions=v["n_directions"], fd_step=(v["fd_step"],) * 3,
                       ocp=replace(_S.ocp, altitude=v["altitude_constraint"]),
                       gma=_gma_settings(v))
    except ValueError as err:
        raise ParameterError(str(err)) from None
