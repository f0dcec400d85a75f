"""Validated parameter dataclasses for the kite model (SI units, angles in rad)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

__all__ = ["ParameterError", "KiteParams", "check_range"]


class ParameterError(ValueError):
    """A parameter value is outside its allowed range; the message names field, value and range."""


def check_range(owner: str, name: str, value, low=None, high=None, *, low_open=False, high_open=False):
    """Raise :class:`ParameterError` unless ``low (<|<=) value (<|<=) high`` and value is a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{owner}.{name} = {value!r}: expected a number")
    if not math.isfinite(value):
        raise ParameterError(f"{owner}.{name} = {value!r}: expected a finite number")
    lo_ok = low is None or (value > low if low_open else value >= low)
    hi_ok = high is None or (value < high if high_open else value <= high)
    if not (lo_ok and hi_ok):
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        rng = f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"
        raise ParameterError(f"{owner}.{name} = {value!r}: expected a value in {rng}")


@dataclass(frozen=True)
class KiteParams:
    """Parameters of the Erhard & Strauch kite model (SPEC §2). Defaults are the nominal model.

    Attributes:
        r: tether length, m (> 0).
        area: projected kite area A, m^2 (> 0).
        rho: air density, kg/m^3 (> 0).
        E: lift-to-drag (glide) ratio, dimensionless (> 0).
        g_s: turning constant, rad/m per unit of normalized steering delta (> 0).
        w_ref: wind speed at the reference height, m/s (> 0).
        z_ref: reference height of the wind profile, m (> 0).
        shear: power-law exponent a of w = w_ref (z/z_ref)^a, dimensionless (>= 0, <= 1).
        c_E: glide loss when steering, E_eff = E - c_E delta^2 (0 for the nominal model, >= 0).
    """

    r: float = 400.0
    area: float = 300.0
    rho: float = 1.2
    E: float = 5.0
    g_s: float = 0.04
    w_ref: float = 8.0
    z_ref: float = 10.0
    shear: float = 0.15
    c_E: float = 0.0

    def __post_init__(self):
        name = type(self).__name__
        for f in ("r", "area", "rho", "E", "g_s", "w_ref", "z_ref"):
            check_range(name, f, getattr(self, f), 0.0, low_open=True)
        check_range(name, "shear", self.shear, 0.0, 1.0)
        check_range(name, "c_E", self.c_E, 0.0)
        if self.E - self.c_E <= 0.0:
            raise ParameterError(
                f"{name}.c_E = {self.c_E!r}: expected a value in [0, E) = [0, {self.E:g}) "
                "so that the glide ratio stays positive at full steering")

    def as_vector(self) -> list[float]:
        """Values in the order of :meth:`names` (the CasADi parameter vector)."""
        return [float(getattr(self, f.name)) for f in fields(self)]

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in fields(cls)]
