"""A 3-D turbulent wind field: a Mann-model box (DTU's ``hipersim``), frozen and advected with the mean wind.

The wind at a point ``(x, y, z)`` (m, anchor frame: x downwind, z up) at time ``t`` is

    w(x, y, z, t) = U(z) + u'(x - U_hub t, y, z)

with ``U(z) = w_ref (z / z_ref)^a`` the plant's power-law profile (SPEC §2), ``u'`` the longitudinal component of
the box (Taylor's frozen turbulence, advected at the mean wind at hub height ``U_hub = U(z_hub)``; the box tiles
periodically along x, as the Mann box is periodic there), interpolated trilinearly. With ``components = "u"`` only
``u'`` enters and the wind keeps its direction. With ``components = "uvw"`` the wind at a point is the vector
``(U(z) + u', v', w')`` (the lateral and vertical components, ~0.7-0.8 and ~0.5 of sigma_u in the box), so it turns
and tilts with the gusts: :meth:`FieldWind.kite_wind` gives its speed, direction and tilt, and the plant flies the
model in the frame of that wind (:mod:`~kite_rto.kite.wind_frame`). A drifting mean wind
(:mod:`~kite_rto.kite.mean_wind`) scales ``U`` and turns the whole field, the box advected along the mean direction.
The ground-station anemometer (horizontal speed) and wind vane (direction) at ``(0, 0, z_ref)`` read the same field
there.

Turbulence (IEC 61400-1 ed. 3, normal turbulence model, section 6.3 and annex C):

* turbulence category ``B`` by default: ``I_ref = 0.14`` (A 0.16, C 0.12), ``sigma_1 = I_ref (0.75 U_hub + 5.6)``;
  with the default plant (w_ref 8 m/s at 10 m, shear 0.20) and ``z_hub = 200 m``: ``U_hub = 14.56 m/s``,
  ``sigma_1 = 2.31 m/s``, turbulence intensity 15.9 % at hub height;
* Mann parameters of annex C: ``L = 0.8 Lambda_1 = 33.6 m`` (``Lambda_1 = 42 m`` above 60 m), ``Gamma = 3.9``;
  ``alpha-eps^(2/3)`` is whatever gives ``sigma_1``: the box is generated with 1 and scaled so that the
  standard deviation of its u component is ``sigma_1`` (the box's equivalent ``alpha-eps^(2/3)`` is
  ``scale^2``, reported by :attr:`MannBox.alpha_epsilon`);
* the same sigma_u and length scale hold at every height of the box (Mann's model is homogeneous, and IEC's
  normal turbulence model takes sigma_1 invariant with height): the anemometer at 10 m sees sigma_1 at a mean
  wind of 8 m/s, a turbulence intensity of ~29 % (``bench_wind.py``).

Coherence (``bench_wind.py``): the boxes reproduce the Mann model's own coherence; for vertical separations it
agrees with IEC's exponential coherence model within 0.1, across the wind (y) it is lower than the exponential
model at low frequency and goes negative above ~0.02 Hz (a known difference of the two IEC models).

Default box: 2048 x 32 x 32 points, 8 x 16 x 10 m: 16.4 km along the wind (18.7 min at U_hub before it repeats),
y in [-256, 256) m, z in [0, 320) m; the kite flies ~300-370 m downwind, up to ±250 m sideways, 100-310 m up.
Generating one takes ~5 s and ~450 MB once (one CPU, so the box does not depend on the machine); boxes are cached
per seed and settings as ``.npy`` files in :func:`cache_dir` and memory-mapped when used (start-up < 0.1 s).
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from ..cache import cache_dir as shared_cache_dir
from .model import MIN_WIND_HEIGHT
from .params import KiteParams, ParameterError, check_range
from .mean_wind import MeanWind
from .wind import MIN_REFERENCE_WIND, NormalBlocks, WindModel

__all__ = ["WindFieldSettings", "MannBox", "FieldWind", "FIELD_COMPONENTS", "cache_dir", "IEC_REFERENCE_INTENSITY",
           "iec_coherence", "IEC_COHERENCE_SCALE"]

IEC_REFERENCE_INTENSITY = {"A": 0.16, "B": 0.14, "C": 0.12}
"""IEC 61400-1 ed. 3 turbulence categories: expected turbulence intensity I_ref at 15 m/s."""
IEC_COHERENCE_SCALE = 8.1 * 42.0
"""IEC 61400-1 ed. 3 coherence scale parameter L_c = 8.1 Lambda_1, Lambda_1 = 42 m above 60 m; m."""
FIELD_COMPONENTS = ("u", "uvw")
"""Components of the box the kite flies in: the longitudinal one alone (the wind keeps its direction), or all three
(the wind at the kite turns and tilts with the gusts)."""
_FORMAT = "v2"          # part of the cache key: change it when the generation or scaling changes


def _cell(f: float, n: int) -> tuple:
    """Lower grid index and fraction of the fractional index ``f`` on an axis of ``n`` points, clamped to it."""
    if f <= 0.0:
        return 0, 0.0
    if f >= n - 1:
        return n - 2, 1.0
    i = int(f)
    return i, f - i


def _trilinear(u, a: int, b: int, nz: int, ax: float, ay: float, az: float) -> float:
    """Trilinear interpolation in the flat box ``u`` between the columns at flat indices ``a`` (x below) and ``b``
    (x above), ``nz`` the stride along y, at the fractions ``ax, ay, az``."""
    bz = 1.0 - az
    c00 = u[a] * bz + u[a + 1] * az
    c01 = u[a + nz] * bz + u[a + nz + 1] * az
    c10 = u[b] * bz + u[b + 1] * az
    c11 = u[b + nz] * bz + u[b + nz + 1] * az
    by = 1.0 - ay
    return (c00 * by + c01 * ay) * (1.0 - ax) + (c10 * by + c11 * ay) * ax


def iec_coherence(f, separation: float, mean_wind: float, scale: float = IEC_COHERENCE_SCALE):
    """IEC 61400-1 exponential coherence of the longitudinal component, ``exp(-12 sqrt((f r/V)^2 + (0.12 r/L_c)^2))``.

    ``f`` Hz (scalar or array), ``separation`` r m (perpendicular to the mean wind), ``mean_wind`` V m/s.
    """
    f = np.asarray(f, dtype=float)
    return np.exp(-12.0 * np.sqrt((f * separation / mean_wind) ** 2 + (0.12 * separation / scale) ** 2))


def cache_dir() -> str:
    """Directory of cached wind boxes: the ``wind`` subfolder of :func:`kite_rto.cache.cache_dir`."""
    return shared_cache_dir("wind")


@dataclass(frozen=True)
class WindFieldSettings:
    """Settings of the 3-D turbulent field (see the module docstring for the numbers they give).

    Attributes:
        turbulence_class: IEC 61400-1 turbulence category, ``"A"``, ``"B"`` or ``"C"``.
        hub_height: height whose mean wind sets sigma_1 and the advection speed, m (> 0).
        length_scale: Mann length scale L, m (> 0).
        gamma: Mann anisotropy parameter Gamma (>= 0).
        points: box points (Nx, Ny, Nz) along x (downwind), y, z; each >= 4.
        spacing: box spacing (dx, dy, dz), m (> 0).
        components: one of :data:`FIELD_COMPONENTS`: ``"u"`` (the longitudinal component alone) or ``"uvw"``.
        vane_noise: white noise standard deviation of the ground station's wind vane, rad (>= 0).
    """

    turbulence_class: str = "B"
    hub_height: float = 200.0
    length_scale: float = 33.6
    gamma: float = 3.9
    points: tuple = (2048, 32, 32)
    spacing: tuple = (8.0, 16.0, 10.0)
    components: str = "u"
    vane_noise: float = math.radians(2.0)

    def __post_init__(self):
        n = type(self).__name__
        if self.turbulence_class not in IEC_REFERENCE_INTENSITY:
            raise ParameterError(f"{n}.turbulence_class = {self.turbulence_class!r}: expected one of "
                                 f"{', '.join(IEC_REFERENCE_INTENSITY)}")
        check_range(n, "hub_height", self.hub_height, 0.0, low_open=True)
        check_range(n, "length_scale", self.length_scale, 0.0, low_open=True)
        check_range(n, "gamma", self.gamma, 0.0)
        if len(self.points) != 3 or any(isinstance(v, bool) or not isinstance(v, int) or v < 4 for v in self.points):
            raise ParameterError(f"{n}.points = {self.points!r}: expected three integers >= 4")
        if len(self.spacing) != 3:
            raise ParameterError(f"{n}.spacing = {self.spacing!r}: expected (dx, dy, dz)")
        for i, v in enumerate(self.spacing):
            check_range(n, f"spacing[{i}]", v, 0.0, low_open=True)
        if self.components not in FIELD_COMPONENTS:
            raise ParameterError(f"{n}.components = {self.components!r}: expected one of "
                                 f"{', '.join(FIELD_COMPONENTS)}")
        check_range(n, "vane_noise", self.vane_noise, 0.0)

    def hub_wind(self, params: KiteParams) -> float:
        """Mean wind at hub height of the power-law profile of ``params``, m/s."""
        return params.w_ref * (self.hub_height / params.z_ref) ** params.shear

    def sigma(self, params: KiteParams) -> float:
        """IEC normal-turbulence-model standard deviation of u, ``I_ref (0.75 U_hub + 5.6)``, m/s."""
        return IEC_REFERENCE_INTENSITY[self.turbulence_class] * (0.75 * self.hub_wind(params) + 5.6)


class MannBox:
    """The turbulence ``u', v', w'`` (m/s) of one Mann box, generated once per seed and settings and cached.

    The cache holds the box as generated with ``alpha-eps^(2/3) = 1`` (float32); loading it memory-maps the file
    and scales it to zero mean and standard deviation ``sigma``.

    Args:
        settings: :class:`WindFieldSettings`.
        sigma: standard deviation of u the box is scaled to, m/s (> 0).
        seed: seed of the box (non-negative integer).
        directory: cache directory (:func:`cache_dir` if None).

    Attributes:
        raw_uvw: float32 array (3, Nx, Ny, Nz) of the components u, v, w as generated, read-only (memory-mapped
            from the cache file).
        raw: its u component.
        offset, scale: ``u' = scale * raw - offset`` (m/s); the same ``scale`` for v' and w' (the box's own ratios of
            the components' variances), each with its own offset (:attr:`offsets`: zero means).
        alpha_epsilon: the box's equivalent Mann ``alpha-eps^(2/3)``, ``scale^2``, m^(4/3)/s^2.
        path: the cache file.
        generated: True if this object generated the box (False: read from the cache).
    """

    def __init__(self, settings: WindFieldSettings, sigma: float, seed: int, directory: str | None = None):
        check_range(type(self).__name__, "sigma", sigma, 0.0, low_open=True)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParameterError(f"MannBox.seed = {seed!r}: expected an integer >= 0")
        self.settings, self.sigma, self.seed = settings, float(sigma), int(seed)
        directory = directory or cache_dir()
        s = settings
        key = repr((_FORMAT, s.length_scale, s.gamma, tuple(s.points), tuple(map(float, s.spacing)), self.seed))
        self.path = os.path.join(directory, f"mann_{hashlib.sha1(key.encode()).hexdigest()[:16]}.npy")
        self.generated = not os.path.exists(self.path)
        if self.generated:
            os.makedirs(directory, exist_ok=True)
            raw = self._generate()
            fd, tmp = tempfile.mkstemp(dir=directory, prefix=".mann-", suffix=".tmp")   # unique per process and thread
            try:
                with os.fdopen(fd, "wb") as fh:
                    np.save(fh, raw)
                os.replace(tmp, self.path)             # atomic: a concurrent reader never sees half a file
            except BaseException:
                os.unlink(tmp)
                raise
        self.raw_uvw = np.load(self.path, mmap_mode="r")
        self.raw = self.raw_uvw[0]
        mean, std = float(self.raw.mean(dtype=np.float64)), float(self.raw.std(dtype=np.float64))
        self.scale = self.sigma / std
        self.offset = self.scale * mean
        self.offsets = tuple(self.scale * float(c.mean(dtype=np.float64)) for c in self.raw_uvw)
        self.alpha_epsilon = self.scale**2

    def _generate(self) -> np.ndarray:
        from hipersim import MannTurbulenceField       # slow import (xarray): only when a box is generated
        s = self.settings
        field = MannTurbulenceField.generate(alphaepsilon=1.0, L=s.length_scale, Gamma=s.gamma, Nxyz=s.points,
                                             dxyz=s.spacing, seed=self.seed, n_cpu=1)
        return np.ascontiguousarray(field.uvw, dtype=np.float32)

    def u(self) -> np.ndarray:
        """The scaled box ``u'``, m/s, float64 array (Nx, Ny, Nz) (a copy)."""
        return self.scale * np.asarray(self.raw, dtype=np.float64) - self.offset

    def component(self, i: int) -> np.ndarray:
        """The scaled component ``i`` (0 u', 1 v', 2 w'; zero mean), m/s, float64 array (Nx, Ny, Nz) (a copy)."""
        return self.scale * np.asarray(self.raw_uvw[i], dtype=np.float64) - self.offsets[i]


class FieldWind(WindModel):
    """The plant's wind from a :class:`MannBox`: mean power-law profile plus the advected box (module docstring).

    Args:
        box: the :class:`MannBox`.
        params: the plant's :class:`KiteParams` (w_ref, z_ref and shear of the mean profile).
        anemometer_noise: white noise standard deviation of the anemometer, m/s (>= 0).
        rng: generator of the anemometer noise.

    Sampling is pure Python on a flat memory view of the box (8 reads and 7 interpolations per point); outside
    the box in y or z the nearest face is used.
    """

    def __init__(self, box: MannBox, params: KiteParams, anemometer_noise: float, rng: np.random.Generator,
                 components: str = "u", mean: MeanWind | None = None, vane_noise: float = 0.0):
        if components not in FIELD_COMPONENTS:
            raise ParameterError(f"FieldWind.components = {components!r}: expected one of "
                                 f"{', '.join(FIELD_COMPONENTS)}")
        s = box.settings
        self.box = box
        self.w_ref0 = float(params.w_ref)
        self._z_ref, self._shear = float(params.z_ref), float(params.shear)
        self.mean_speed = s.hub_wind(params)            # advection speed, m/s
        nx, ny, nz = s.points
        dx, dy, dz = map(float, s.spacing)
        self._n = (nx, ny, nz)
        self._inv = (1.0 / dx, 1.0 / dy, 1.0 / dz)
        self._y0 = -0.5 * ny * dy                      # box y from -Ny dy / 2, z from 0
        self._flat = memoryview(np.ascontiguousarray(box.raw).reshape(-1))
        self._scale, self._offset = box.scale, box.offset
        self._shift = 0.0                              # U_hub t, m
        self._noise_std = float(anemometer_noise)
        self._normals = NormalBlocks(rng)
        self.components = components
        self.mean = mean
        self.turns = components == "uvw" or (mean is not None and mean.settings.changes)
        """The wind at the kite changes direction: the plant asks :meth:`kite_wind` instead of
        :meth:`kite_reference_wind`."""
        self._vane_std = float(vane_noise)
        self._t = 0.0
        three = components == "uvw"
        # (flat box, offset) of u', v' and w'; empty with the longitudinal component alone
        self._components3 = tuple(zip(
            [self._flat] + [memoryview(np.ascontiguousarray(box.raw_uvw[i]).reshape(-1)) for i in (1, 2)],
            (box.offset,) + box.offsets[1:])) if three else ()
        # the anemometer's line of the box at (y, z) = (0, z_ref), one value per x point: one linear interpolation
        # per sample instead of a trilinear one (u', and v' for the vane)
        dx = float(s.spacing[0])
        self._anemometer_line, self._vane_line = [], []
        for i in range(nx):
            self._shift = -i * dx
            self._anemometer_line.append(self.turbulence_at(0.0, 0.0, self._z_ref))
            self._vane_line.append(self.turbulence3_at(0.0, 0.0, self._z_ref)[1] if three else 0.0)
        self._shift = 0.0

    def advance(self, t: float) -> None:
        """Advect the frozen box to time ``t`` (s) (at the hub-height mean wind of each moment when it drifts)."""
        mean = self.mean
        if mean is None:
            self._shift = self.mean_speed * t
            return
        factor = mean.speed_factor
        mean.advance(t)
        self._shift += self.mean_speed * 0.5 * (factor + mean.speed_factor) * (t - self._t)
        self._t = t

    def turbulence3_at(self, x: float, y: float, z: float) -> tuple:
        """(u', v', w') (m/s) at the point (x, y, z) m of the box's frame at the current time (trilinear; u' as
        :meth:`turbulence_at` computes it, to the bit)."""
        if not self._components3:
            return self.turbulence_at(x, y, z), 0.0, 0.0
        cell = self._cell_of(x, y, z)
        return tuple(self._scale * _trilinear(u, *cell) - off for u, off in self._components3)

    def _cell_of(self, x: float, y: float, z: float) -> tuple:
        """The flat indices of the two corner columns of the point's cell, the stride along z and the fractions."""
        nx, ny, nz = self._n
        ix_, iy_, iz_ = self._inv
        fx = (x - self._shift) * ix_
        fl = math.floor(fx)
        ax = fx - fl
        i0 = int(fl) % nx
        i1 = i0 + 1 if i0 + 1 < nx else 0
        j, ay = _cell((y - self._y0) * iy_, ny)
        k, az = _cell(z * iz_, nz)
        nyz = ny * nz
        return i0 * nyz + j * nz + k, i1 * nyz + j * nz + k, nz, ax, ay, az

    def kite_wind(self, position: tuple) -> tuple:
        """The wind at ``position`` (x, y, z) m of the ground frame: ``(speed m/s, direction rad, tilt rad)``, the
        direction from the ground frame's x towards its y (about z up), the tilt upwards.

        The mean wind (speed factor and direction of :attr:`mean`) carries the box: the point is turned into the
        mean wind's frame, the box sampled there, and its components added to the mean profile along that frame.
        """
        x, y, z = position
        factor, chi = self._mean_now()
        if chi:
            c, s_ = math.cos(chi), math.sin(chi)
            x, y = c * x + s_ * y, -s_ * x + c * y
        hz = z if z > MIN_WIND_HEIGHT else MIN_WIND_HEIGHT
        along = self.w_ref0 * factor * (hz / self._z_ref) ** self._shear
        du, dv, dw = self.turbulence3_at(x, y, z)
        along += du
        horizontal = math.hypot(along, dv)
        return (math.sqrt(horizontal * horizontal + dw * dw), chi + math.atan2(dv, along), math.atan2(dw, horizontal))

    def vane(self) -> float:
        """Wind vane reading at (0, 0, z_ref), rad from the ground frame's x towards y: the mean direction plus the
        horizontal direction of the turbulence there plus measurement noise."""
        factor, chi = self._mean_now()
        along, dv = self._line_values()
        d = chi + math.atan2(dv, self.w_ref0 * factor + along)
        if self._vane_std > 0:
            d += self._vane_std * self._normals.next()
        return d

    def _line_index(self) -> tuple:
        """``(i0, i1, fraction)``: where the anemometer is on its lines (:attr:`_anemometer_line`, the box's x
        points at (0, z_ref), which tile periodically) at the current time."""
        fx = -self._shift * self._inv[0]
        fl = math.floor(fx)
        n = len(self._anemometer_line)
        i0 = int(fl) % n
        return i0, (i0 + 1 if i0 + 1 < n else 0), fx - fl

    def _line_values(self) -> tuple:
        """(u', v') at the anemometer, m/s (linear along the lines)."""
        i0, i1, ax = self._line_index()
        u, v = self._anemometer_line, self._vane_line
        return u[i0] + (u[i1] - u[i0]) * ax, v[i0] + (v[i1] - v[i0]) * ax

    def _mean_now(self) -> tuple:
        """``(speed factor, direction rad)`` of the mean wind now (``(1, 0)`` without a changing one)."""
        mean = self.mean
        return (mean.speed_factor, mean.direction) if mean is not None else (1.0, 0.0)

    def turbulence_at(self, x: float, y: float, z: float) -> float:
        """u' (m/s) at the point (x, y, z) at the current time (trilinear)."""
        return self._scale * _trilinear(self._flat, *self._cell_of(x, y, z)) - self._offset

    def kite_reference_wind(self, position: tuple) -> float:
        """``w_ref0 + u' (z_ref / z)^a``: the reference wind whose profile passes through ``U(z) + u'`` at the
        kite, m/s (never below :data:`MIN_REFERENCE_WIND`)."""
        x, y, z = position
        hz = z if z > MIN_WIND_HEIGHT else MIN_WIND_HEIGHT
        w = self.w_ref0 + self.turbulence_at(x, y, z) * (self._z_ref / hz) ** self._shear
        return MIN_REFERENCE_WIND if MIN_REFERENCE_WIND > w else w

    def anemometer(self) -> float:
        """Anemometer reading at (0, 0, z_ref), m/s: the horizontal speed of the mean wind plus the turbulence
        there (u' alone, or u' and v' with ``components = "uvw"``) plus measurement noise."""
        if self.turns:
            along, dv = self._line_values()
            w = math.hypot(self.w_ref0 * self._mean_now()[0] + along, dv)
            if self._noise_std > 0:
                w += self._noise_std * self._normals.next()
            return 0.0 if 0.0 > w else w
        i0, i1, ax = self._line_index()
        line = self._anemometer_line
        w = self.w_ref0 + line[i0] + (line[i1] - line[i0]) * ax
        if self._noise_std > 0:
            w += self._noise_std * self._normals.next()
        return 0.0 if 0.0 > w else w
