"""The plant node's parameters and the :class:`~kite_rto.kite.plant.PlantConfig` they build.

Every parameter that sets a PlantConfig field takes its default from ``PlantConfig()`` through
:data:`CONFIG_FIELDS`; the others (mode, timing, seed) belong to the node.
"""
from __future__ import annotations

import math
from dataclasses import replace

from ..kite.plant import WIND_MODELS, PlantConfig
from .parameters import ParamSpec

__all__ = ["PARAMS", "CONFIG_FIELDS", "config_default", "config_from_params"]

_C = PlantConfig()
CONFIG_FIELDS = {
    "dt": "dt", "substeps": "substeps", "dead_time": "dead_time", "rate_limit": "rate_limit",
    **{name: f"params.{name}" for name in ("r", "area", "rho", "E", "c_E", "g_s", "w_ref", "z_ref", "shear")},
    "turbulence": "turbulence.enabled", "turbulence_intensity": "turbulence.intensity",
    "turbulence_length": "turbulence.length_scale", "anemometer_noise": "turbulence.anemometer_noise",
    "noise_angle_deg": "noise.angle", "noise_rate": "noise.rate", "noise_tension": "noise.tension",
    "launch_theta_deg": "launch_state.0", "wind_model": "wind_model",
}
"""Parameter -> the :class:`PlantConfig` field it sets (dotted path; a number indexes a tuple). Parameters named
``*_deg`` are in degrees, the field in rad. Their defaults are read from ``PlantConfig()``."""


def _field(obj, path: str):
    for part in path.split("."):
        obj = obj[int(part)] if part.isdigit() else getattr(obj, part)
    return obj


def config_default(name: str):
    """The default of the plant parameter ``name``: its :class:`PlantConfig` field, in the parameter's unit."""
    value = _field(_C, CONFIG_FIELDS[name])
    return round(math.degrees(value), 9) if name.endswith("_deg") else value


def _with(default, values: dict):
    """``default`` (a dataclass or tuple) with the fields at the dotted paths of ``values`` replaced, built once."""
    groups = {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        groups.setdefault(head, {})[rest] = value
    if isinstance(default, tuple):
        out = list(default)
        for head, sub in groups.items():
            out[int(head)] = sub[""] if "" in sub else _with(out[int(head)], sub)
        return tuple(out)
    return replace(default, **{head: sub[""] if "" in sub else _with(getattr(default, head), sub)
                               for head, sub in groups.items()})


_d = config_default
PARAMS = (
    ParamSpec("mode", "lockstep", "lockstep (deterministic, fast) or realtime (wall clock x rate_factor)",
              choices=("lockstep", "realtime")),
    ParamSpec("rate_factor", 1.0, "realtime mode: simulated seconds per wall second", 0.01, 100.0,
              unit="sim s/wall s", runtime=True),
    ParamSpec("seed", 0, "seed of turbulence and measurement noise", 0, 2**31 - 1),
    ParamSpec("duration", 0.0, "simulated time after which the node exits (0: run until stopped)", 0.0, 1e7,
              unit="s", runtime=True),
    ParamSpec("dt", _d("dt"), "sample time", 0.001, 0.1, unit="s"),
    ParamSpec("substeps", _d("substeps"), "RK4 steps per sample", 1, 100, unit="steps"),
    ParamSpec("dead_time", _d("dead_time"), "steering dead time (rounded to whole samples)", 0.0, 5.0, unit="s"),
    ParamSpec("rate_limit", _d("rate_limit"), "steering rate limit (normalized delta per second)", 0.01, 1000.0,
              unit="1/s"),
    ParamSpec("r", _d("r"), "tether length", 1.0, 5000.0, unit="m"),
    ParamSpec("area", _d("area"), "kite area", 0.1, 5000.0, unit="m^2"),
    ParamSpec("rho", _d("rho"), "air density", 0.1, 2.0, unit="kg/m^3"),
    ParamSpec("E", _d("E"), "glide ratio of the real kite (> c_E)", 0.5, 30.0, unit="dimensionless"),
    ParamSpec("c_E", _d("c_E"), "glide loss when steering: E - c_E delta^2 (< E)", 0.0, 30.0, unit="dimensionless"),
    ParamSpec("g_s", _d("g_s"), "turning constant", 0.001, 1.0, unit="rad/m"),
    ParamSpec("w_ref", _d("w_ref"), "mean wind at z_ref", 0.5, 40.0, unit="m/s"),
    ParamSpec("z_ref", _d("z_ref"), "reference height of the wind profile", 0.5, 200.0, unit="m"),
    ParamSpec("shear", _d("shear"), "wind shear exponent: w = w_ref (z/z_ref)^shear", 0.0, 1.0,
              unit="dimensionless"),
    ParamSpec("wind_model", _d("wind_model"), "turbulence model: field (3-D Mann box, IEC class B, sampled at the "
              "kite and at the anemometer; generated once per seed and cached) or uniform (one gust on the whole wind, "
              "which the anemometer sees too)", choices=WIND_MODELS),
    ParamSpec("turbulence", _d("turbulence"), "turbulence on the reference wind"),
    ParamSpec("turbulence_intensity", _d("turbulence_intensity"), "gust standard deviation / mean wind", 0.0, 1.0,
              unit="dimensionless"),
    ParamSpec("turbulence_length", _d("turbulence_length"), "turbulence length scale L_W (tau = L_W / w_ref)", 1.0,
              10000.0, unit="m"),
    ParamSpec("anemometer_noise", _d("anemometer_noise"), "anemometer white-noise standard deviation", 0.0, 10.0,
              unit="m/s"),
    ParamSpec("noise_angle_deg", _d("noise_angle_deg"), "angle measurement noise standard deviation", 0.0, 10.0,
              unit="deg"),
    ParamSpec("noise_rate", _d("noise_rate"), "angular-rate measurement noise standard deviation", 0.0, 1.0,
              unit="rad/s"),
    ParamSpec("noise_tension", _d("noise_tension"), "relative tension noise standard deviation (0.01 = 1 %)", 0.0,
              1.0, unit="dimensionless"),
    ParamSpec("launch_theta_deg", _d("launch_theta_deg"), "theta after launch and after a crash (phi = psi = 0)",
              1.0, 89.0, unit="deg"),
    ParamSpec("command_timeout", 1.0, "wall time without steering before flying neutral (lockstep: only once no "
              "publisher of /kite/steering is in the graph)", 0.01, 60.0,
              unit="s (wall)", runtime=True),
    ParamSpec("wait_subscribers", 1, "lockstep: subscribers of /kite/state to wait for before the first step", 0,
              100, unit="subscribers", runtime=True),
    ParamSpec("resend_period", 0.2, "lockstep: wall time before an unanswered sample is re-published", 0.005, 10.0,
              unit="s (wall)", runtime=True),
    ParamSpec("recorder_timeout", 30.0, "lockstep: wall time the plant waits for a lossless recorder (kite_record "
              "--lossless) that lags before it goes on without it (the recording then says where it misses samples)",
              0.1, 86400.0, unit="s (wall)"),
    ParamSpec("one_plant_check", True, "refuse to start (exit 2) where another plant already publishes /kite/state "
              "or /clock; false starts anyway (to see what the other nodes do; two kites: use two domains)"),
)


def config_from_params(v: dict) -> PlantConfig:
    """Build the plant configuration from checked parameter values (raises ParameterError)."""
    return _with(_C, {path: math.radians(v[name]) if name.endswith("_deg") else v[name]
                      for name, path in CONFIG_FIELDS.items()})
