"""Plant variants for scenario campaigns (:class:`Scenario`, :data:`SCENARIOS`).

Each scenario is a "real kite" the model does not know, varied over the ranges the literature reports (the
defaults and ranges are in docs/theory.md): glide ratio E 4-5 (Erhard & Strauch; do-mpc draws 5-8), turning
constant g_s 0.03-0.05 rad/m (Erhard & Strauch, table II), reference wind 7-9 m/s and shear exponent 0.1-0.25
(Costello et al. 2017; IEC 61400-1's normal wind profile uses 0.2), steering dead time 0.15-0.4 s (0.25-0.27 s
identified on the TU Delft V3 kite), IEC turbulence class A-C and Mann length scale 20-60 m, h_min 80-120 m
(do-mpc's kite MPC).

``tuning`` marks the scenarios GMA's kite defaults may be chosen on; every claim is reported on all of them, and
the others were not looked at while tuning.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..kite.plant import PLANT_PARAMS, PlantConfig
from ..kite.wind_field import WindFieldSettings
from ..rto.experiment import H_MIN

__all__ = ["Scenario", "SCENARIOS", "scenario", "select_scenarios"]


@dataclass(frozen=True)
class Scenario:
    """One plant variant and its altitude floor.

    Attributes:
        name: short identifier (table rows, cache keys, ``--scenarios``).
        description: what differs from the default plant.
        plant: the :class:`PlantConfig` flown (turbulence and noise on; the judge switches them off).
        h_min: minimum altitude of the constraint, m (GMA's model, experiments and the judge).
        tuning: True if the kite defaults may be chosen on this scenario.
    """

    name: str
    description: str
    plant: PlantConfig = field(default_factory=PlantConfig)
    h_min: float = H_MIN
    tuning: bool = False


def _plant(dead_time: float | None = None, field_changes: dict | None = None, **params) -> PlantConfig:
    config = PlantConfig(params=replace(PLANT_PARAMS, **params))
    if dead_time is not None:
        config = replace(config, dead_time=dead_time)
    if field_changes:
        config = replace(config, wind_field=replace(WindFieldSettings(), **field_changes))
    return config


SCENARIOS: tuple = (
    Scenario("default", "the default plant (E 4.6, c_E 2, g_s 0.035, shear 0.20, 0.25 s dead time, IEC class B)",
             tuning=True),
    Scenario("shear_turbulent", "shear exponent 0.25 and IEC turbulence class A",
             _plant(shear=0.25, field_changes={"turbulence_class": "A"}), tuning=True),
    Scenario("low_glide", "glide ratio 4.2 and glide loss c_E 3 when steering", _plant(E=4.2, c_E=3.0),
             tuning=True),
    Scenario("high_floor", "h_min 115 m: the altitude constraint binds harder", h_min=115.0, tuning=True),
    Scenario("strong_wind", "reference wind 9 m/s", _plant(w_ref=9.0)),
    Scenario("weak_wind", "reference wind 7 m/s", _plant(w_ref=7.0)),
    Scenario("nimble", "turning constant 0.045 rad/m and 0.15 s dead time", _plant(g_s=0.045, dead_time=0.15)),
    Scenario("sluggish", "turning constant 0.030 rad/m and 0.35 s dead time", _plant(g_s=0.030, dead_time=0.35)),
    Scenario("long_eddies", "Mann length scale 60 m (IEC: 33.6 m) and anisotropy 3.0",
             _plant(field_changes={"length_scale": 60.0, "gamma": 3.0})),
    Scenario("calm_short_eddies", "IEC turbulence class C and Mann length scale 20 m",
             _plant(field_changes={"turbulence_class": "C", "length_scale": 20.0})),
    Scenario("good_glide", "glide ratio 5.3 (above the model's 5), glide loss c_E 1, shear 0.12",
             _plant(E=5.3, c_E=1.0, shear=0.12)),
    Scenario("low_floor", "h_min 85 m: the altitude constraint binds less", h_min=85.0),
)
"""The campaign's scenarios; the first four are the tuning set."""


def scenario(name: str) -> Scenario:
    """The scenario called ``name`` (ValueError naming the known ones otherwise)."""
    for s in SCENARIOS:
        if s.name == name:
            return s
    raise ValueError(f"scenario {name!r}: expected one of {', '.join(s.name for s in SCENARIOS)}")


def select_scenarios(spec: str = "all") -> list:
    """Scenarios from ``"all"``, ``"tuning"``, ``"report"`` (not tuning) or comma-separated names."""
    if spec == "all":
        return list(SCENARIOS)
    if spec == "tuning":
        return [s for s in SCENARIOS if s.tuning]
    if spec == "report":
        return [s for s in SCENARIOS if not s.tuning]
    return [scenario(n.strip()) for n in spec.split(",") if n.strip()]
