"""The 3-D turbulent wind field: Mann box statistics, frozen advection, periodic tiling, the cache, the plant."""
import math
import os
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.kite.params import KiteParams, ParameterError
from kite_rto.kite.plant import PLANT_PARAMS, KitePlant, PlantConfig
from kite_rto.kite.wind_field import FieldWind, MannBox, WindFieldSettings, cache_dir, iec_coherence

SMALL = WindFieldSettings(points=(1024, 32, 16), spacing=(8.0, 16.0, 20.0))     # 8 km x 512 m x 320 m, ~1 s
TINY = WindFieldSettings(points=(64, 8, 8), spacing=(8.0, 16.0, 20.0))


def field(seed=1, settings=SMALL, noise=0.0):
    box = MannBox(settings, settings.sigma(PLANT_PARAMS), seed)
    return FieldWind(box, PLANT_PARAMS, noise, np.random.default_rng(0))


def series(wind, point, times):
    out = []
    for t in times:
        wind.advance(t)
        out.append(wind.turbulence_at(*point))
    return np.array(out)


def test_iec_numbers_of_the_default_field():
    s = WindFieldSettings()
    assert s.hub_wind(PLANT_PARAMS) == pytest.approx(8.0 * 20.0**0.2)              # 14.56 m/s at 200 m
    assert s.sigma(PLANT_PARAMS) == pytest.approx(0.14 * (0.75 * 8.0 * 20.0**0.2 + 5.6))
    assert iec_coherence(0.0, 0.0, 10.0) == 1.0
    expected = math.exp(-12 * math.hypot(0.01 * 140 / 9, 0.12 * 140 / 340.2))
    assert iec_coherence(0.01, 140.0, 9.0) == pytest.approx(expected)


def test_box_mean_and_intensity(cache):
    wind = field()
    sigma = SMALL.sigma(PLANT_PARAMS)
    u = wind.box.u()
    assert abs(u.mean()) < 1e-6 and u.std() == pytest.approx(sigma, rel=1e-6)
    # sampled like the plant: between grid points, across the box, over one box transit
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(250, 400, 4000), rng.uniform(-200, 200, 4000), rng.uniform(20, 300, 4000)])
    vals = []
    for t in np.linspace(0.0, 1024 * 8.0 / wind.mean_speed, 50):
        wind.advance(t)
        vals += [wind.turbulence_at(*p) for p in pts[:80]]
    vals = np.array(vals)
    assert abs(vals.mean()) < 0.15 * sigma
    assert vals.std() == pytest.approx(sigma, rel=0.2)          # trilinear interpolation smooths a little


def test_correlation_falls_with_separation(cache):
    wind = field(seed=2)
    times = np.arange(0.0, 1024 * 8.0 / wind.mean_speed, 1.0)
    corr = {16.0: [], 48.0: [], 112.0: []}
    for z in (60.0, 100.0, 140.0, 180.0, 220.0, 260.0):          # average over lines: one line is a noisy estimate
        for y in (-120.0, -8.0):
            ref = series(wind, (300.0, y, z), times)
            for dy in corr:
                corr[dy].append(np.corrcoef(ref, series(wind, (300.0, y + dy, z), times))[0, 1])
    c16, c48, c112 = (np.mean(v) for v in corr.values())
    assert c16 > c48 > c112 and c16 > 0.6 and c112 < 0.2


def test_frozen_advection_and_periodic_tiling(cache):
    wind = field()
    wind.advance(3.0)
    a = wind.turbulence_at(320.0, 17.0, 143.0)
    wind.advance(5.0)
    assert wind.turbulence_at(320.0 + 2.0 * wind.mean_speed, 17.0, 143.0) == pytest.approx(a, abs=1e-9)
    assert wind.turbulence_at(320.0 + 2.0 * wind.mean_speed + 1024 * 8.0, 17.0, 143.0) == pytest.approx(a, abs=1e-9)


def test_anemometer_reads_the_field_at_z_ref(cache):
    wind = field()
    for t in (0.0, 7.3, 100.0):
        wind.advance(t)
        assert wind.anemometer() == pytest.approx(PLANT_PARAMS.w_ref + wind.turbulence_at(0.0, 0.0, 10.0), abs=1e-9)


def test_kite_reference_wind_gives_the_field_through_the_profile(cache):
    wind = field()
    wind.advance(12.0)
    x, y, z = 330.0, -40.0, 180.0
    w_ref = wind.kite_reference_wind((x, y, z))
    shear_profile = w_ref * (z / PLANT_PARAMS.z_ref) ** PLANT_PARAMS.shear
    mean_profile = PLANT_PARAMS.w_ref * (z / PLANT_PARAMS.z_ref) ** PLANT_PARAMS.shear
    assert shear_profile == pytest.approx(mean_profile + wind.turbulence_at(x, y, z))


def test_cache_per_seed_and_settings(tmp_path, monkeypatch):
    cache = tmp_path
    monkeypatch.setenv("KITE_RTO_CACHE", str(cache))
    a = MannBox(TINY, 2.0, 5)
    b = MannBox(TINY, 3.0, 5)                        # another sigma: the same cached box, scaled
    c = MannBox(TINY, 2.0, 6)
    d = MannBox(replace(TINY, length_scale=20.0), 2.0, 5)
    assert a.generated and not b.generated and c.generated and d.generated
    assert a.path == b.path and len({a.path, c.path, d.path}) == 3
    assert a.path.startswith(str(cache)) and cache_dir() == str(cache / "wind")
    monkeypatch.delenv("KITE_RTO_CACHE")
    assert cache_dir().endswith(os.path.join("kite_rto", "wind"))
    np.testing.assert_allclose(b.u(), 1.5 * a.u(), rtol=1e-6, atol=1e-6)
    assert not np.allclose(a.u(), c.u())


def test_plant_flies_in_the_field(cache):
    cfg = replace(PlantConfig(), wind_model="field", wind_field=SMALL)
    plant = KitePlant(cfg, seed=1)
    ms = [plant.step(0.1 * math.sin(0.01 * k)) for k in range(3000)]
    assert isinstance(plant.wind, FieldWind)
    anemo = np.array([m.wind_ref for m in ms])
    assert abs(anemo.mean() - PLANT_PARAMS.w_ref) < 3.0 and anemo.std() > 0.5
    assert all(math.isfinite(m.tension) for m in ms)
    again = KitePlant(cfg, seed=1)
    assert [again.step(0.1 * math.sin(0.01 * k)) for k in range(3000)] == ms


def test_disabled_turbulence_is_a_steady_wind_with_either_model():
    quiet = replace(PlantConfig(), wind_model="field").without_disturbances()
    assert quiet == PlantConfig().without_disturbances()
    assert KitePlant(quiet).step(0.0).wind_ref == PLANT_PARAMS.w_ref


@pytest.mark.parametrize("kwargs", [{"turbulence_class": "D"}, {"hub_height": 0.0}, {"points": (512, 16)},
                                    {"spacing": (8.0, -1.0, 10.0)}])
def test_invalid_field_settings(kwargs):
    with pytest.raises(ParameterError, match="WindFieldSettings"):
        WindFieldSettings(**kwargs)


def test_invalid_wind_model():
    with pytest.raises(ParameterError, match="wind_model"):
        PlantConfig(wind_model="mann")
