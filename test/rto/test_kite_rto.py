"""Kite + GMA glue: experiments from measurements, normalization, a short RTO run, determinism."""
import math
from dataclasses import replace

import numpy as np
import pytest

from kite_rto.flight.closed_loop import make_closed_loop, run_closed_loop
from kite_rto.rto.experiment import ExperimentEvaluator, ExperimentSpec
from kite_rto.flight.shape import setpoints_from_shape
from kite_rto.gma import TrustRegion
from kite_rto.rto.settings import KiteRTOSettings
from kite_rto.rto.session import RTOSession
from kite_rto.rto.builder import make_gma, model_only_optimum
from kite_rto.rto.runner import run_rto
from kite_rto.rto.oracle import plant_performance
from kite_rto.flight.path import Setpoints
from kite_rto.kite.plant import Measurement, PlantConfig


def _synthetic(t, period=10.0, crashes=0, wind=8.0, tension=5e5, z=150.0):
    phi = 0.5 * math.sin(2 * math.pi * t / period)
    return Measurement(t=t, theta=0.5, phi=phi, psi=0.0, theta_dot=0.0, phi_dot=0.0, psi_dot=0.0,
                       tension=tension, position=(0.0, 0.0, z), wind_ref=wind, delta=0.0, crashes=crashes,
                       step=int(round(t / 0.05)))


def test_evaluator_drops_settling_laps_and_averages_whole_laps():
    spec = ExperimentSpec(settle_time=5.0, settle_laps=1, n_laps=2, h_min=100.0, w_nominal=8.0)
    ev = ExperimentEvaluator(spec)
    ev.start(0.0, [0.5, 0.6, 0.1])
    out, t = None, 0.0
    while out is None and t < 100:
        t += 0.05
        # the first 15 s fly at 300 kN / 120 m: the settle window plus the dropped lap; afterwards 500 kN / 150 m
        late = t > 15.0
        out = ev.update(_synthetic(t, tension=5e5 if late else 3e5, z=150.0 if late else 120.0))
    assert out is not None and out.valid and not out.crashed and out.n_laps == 2
    # laps start at t = 10, 20, 30 (upward zero crossings of phi); first counted start >= 5 s is t = 10 (dropped)
    assert [round(lap.t_start) for lap in out.laps] == [20, 30]
    assert out.cost == pytest.approx(-500.0, rel=1e-6)            # kN, normalized at the nominal wind
    assert out.constraint == pytest.approx(100.0 - 150.0)          # m
    assert out.t_end == pytest.approx(40.0, abs=0.1)
    assert ev.update(_synthetic(t + 0.05)) is None                 # one outcome per start


def test_evaluator_normalizes_by_measured_wind_and_flags_crash():
    spec = ExperimentSpec(settle_time=0.0, settle_laps=0, n_laps=2, w_nominal=8.0, wind_source="anemometer")
    ev = ExperimentEvaluator(spec)
    ev.start(0.0)
    out, t = None, 0.0
    while out is None:
        t += 0.05
        out = ev.update(_synthetic(t, wind=10.0, tension=5e5))     # stronger wind: 500 kN * (8/10)^2 = 320 kN
    assert out.cost == pytest.approx(-320.0, rel=1e-6) and out.mean_tension_kn == pytest.approx(500.0)
    ev.start(t)
    out = None
    for _ in range(100):
        t += 0.05
        out = ev.update(_synthetic(t, crashes=1 if t > ev.t_start + 2.0 else 0))
        if out is not None:
            break
    assert out is not None and out.crashed and not out.valid


def test_normalization_reduces_lap_scatter_under_turbulence():
    plant, ctl = make_closed_loop(Setpoints.from_degrees(30, 46, 7), PlantConfig(wind_model="uniform"), seed=3)
    laps = run_closed_loop(plant, ctl, 330.0, record=False).laps_after(30.0)
    assert len(laps) >= 12
    raw = np.array([lap.mean_tension for lap in laps])
    norm = np.array([lap.tension_coefficient for lap in laps]) * 64.0
    assert np.std(norm) < 0.5 * np.std(raw)


@pytest.fixture(scope="module")
def quick_settings():
    return KiteRTOSettings(experiment=ExperimentSpec(settle_time=10.0, settle_laps=1, n_laps=2),
                           fd_step=(0.1, 0.1, 0.1)).with_gma(filter_gain=0.8, trust_region=TrustRegion(radius=0.3))


def test_deterministic_rto_improves_on_model_only_optimum(quick_settings):
    c0 = model_only_optimum(KiteRTOSettings()).c
    quiet = PlantConfig().without_disturbances()
    res = run_rto(quiet, seed=0, n_iter=3, settings=quick_settings)
    assert res.success and not res.message and res.crashes == 0 and len(res.records) == 3
    assert np.allclose(res.iterates[0], c0)
    t0, z0 = plant_performance(quiet, c0)
    t3, z3 = plant_performance(quiet, res.iterates[-1])
    assert t3 > t0 + 10.0                               # kN; model-only 545 kN
    assert z3 >= 100.0 - 2.0                            # the judge: min altitude >= h_min - 2 m
    # the measured nominal tension increases iteration by iteration
    nominal = [-r.cost for r in res.records]
    assert nominal[-1] > nominal[0]


def test_same_seed_same_setpoint_sequence(quick_settings):
    settings = replace(quick_settings, experiment=replace(quick_settings.experiment, n_laps=1))
    a = run_rto(PlantConfig(), seed=5, n_iter=1, settings=settings)
    b = run_rto(PlantConfig(), seed=5, n_iter=1, settings=settings)
    ca = [e.c for e in a.experiments] + [a.iterates[-1]]
    cb = [e.c for e in b.experiments] + [b.iterates[-1]]
    assert np.array_equal(np.array(ca), np.array(cb))
    assert [e.outcome.cost for e in a.experiments] == [e.outcome.cost for e in b.experiments]


def test_session_repeats_a_crashed_experiment(quick_settings):
    gma = make_gma(quick_settings)
    session = RTOSession(gma, ExperimentSpec(settle_time=0.0, settle_laps=0, n_laps=1), max_repeats=2)
    c = session.start(0.0)
    assert np.allclose(c, setpoints_from_shape(gma.c))          # GMA works in shape coordinates
    t, again = 0.0, None
    while again is None and t < 50:
        t += 0.05
        again = session.on_measurement(_synthetic(t, crashes=1 if t > 3.0 else 0))
    assert again is not None and np.allclose(again, c) and session.repeats == 1 and not session.experiments


def test_session_flies_the_laps_of_the_effort_schedule(quick_settings):
    """GMA's effort scales the spec's laps: 1 lap per experiment in iteration 0, 2 from iteration 1 on
    (``effort_schedule`` (1, 2)); a crashed experiment is flown again with its own laps."""
    settings = replace(quick_settings, experiment=replace(quick_settings.experiment, settle_time=0.0,
                                                          settle_laps=0, n_laps=1))
    gma = make_gma(settings.with_gma(effort_schedule=(1, 2)))
    session = RTOSession(gma, settings.experiment)
    session.start(0.0)
    t, crash, k1_start = 0.0, 0, None
    while len(session.experiments) < 6 and t < 300:
        t += 0.05
        if session.request.request_id.startswith("k1-0") and k1_start is None:
            k1_start = t
        if k1_start is not None and t > k1_start + 5.0:
            crash = 1                           # one crash, 5 s into iteration 1's first experiment
        session.on_measurement(_synthetic(t, crashes=crash))
    laps = [(log.request_id.split("-")[0], log.outcome.n_laps, log.repeats) for log in session.experiments]
    assert laps == [("k0", 1, 0)] * 4 + [("k1", 2, 1), ("k1", 2, 0)], laps
    assert session.evaluator.n_laps == 2


def test_kite_privileged_directions_under_the_literature_prior_measure_all_three_coordinates():
    from kite_rto.rto.builder import bound_activity, gma_directions
    settings = KiteRTOSettings()
    # the model's constrained optimum keeps theta_0 at its lower bound in every case of the prior, also with the
    # altitude constraint tightened by the prior's altitude error ...
    assert bound_activity(settings) == (-1, 0, 0)
    d = gma_directions(settings)
    # ... but its gradient there changes by more than half its size under the prior: theta_0 is not held
    assert d.fixed.tolist() == [False, False, False]
    assert d.directions.shape == (3, 3)
    np.testing.assert_allclose(d.scaled.T @ d.scaled, np.eye(3), atol=1e-12)
    assert d.singular_values[0] > d.singular_values[1] > 3 * d.singular_values[2] > 0


def test_a_narrow_prior_holds_theta_0_at_its_bound():
    """The mechanism that saves the theta_0 experiment: with the default plant's own offset as the prior (knowledge
    no user has) the theta_0 bound is robustly active and DMA spans the other two coordinates."""
    from kite_rto.rto.builder import gma_directions
    from kite_rto.rto.directions import ModelUncertainty
    narrow = KiteRTOSettings(n_directions=2, uncertainty=ModelUncertainty(E=-0.5, g_s=-0.005, shear=0.05, c_E=1.0))
    d = gma_directions(narrow)
    assert d.fixed.tolist() == [True, False, False]
    width = narrow.box.upper() - narrow.box.lower()
    assert d.gradient[0] * width[0] > 2.0 * np.max(np.abs(d.sensitivity[0])) * width[0] > 0
    assert d.directions.shape == (3, 2) and np.all(d.directions[0] == 0.0)


def test_a_directional_iteration_flies_the_nominal_and_one_experiment_per_direction(quick_settings):
    quiet = PlantConfig().without_disturbances()
    res = run_rto(quiet, seed=0, n_iter=1, settings=quick_settings)
    assert quick_settings.gradient == "directional" and quick_settings.experiments_per_iteration() == 4
    assert len(res.experiments) == 4 and res.records[0].gradient_method == "directional (3 of 3)"
    assert len({round(e.c[0], 9) for e in res.experiments}) > 1     # theta_0 is perturbed too
    rec = res.records[0]
    assert not np.isclose(rec.grad_cost[1], rec.grad_phi_hat[1])


@pytest.mark.parametrize("bad, match", [
    ({"n_directions": 4}, r"KiteRTOSettings.n_directions = 4: expected 1, 2 or 3"),
    ({"gradient": "newton"}, r"KiteRTOSettings.gradient = 'newton': expected one of \('directional'"),
])
def test_kite_rto_settings_reject_bad_values(bad, match):
    with pytest.raises(ValueError, match=match):
        KiteRTOSettings(**bad)


def test_model_uncertainty_rejects_zero_deviation():
    from kite_rto.rto.directions import ModelUncertainty
    with pytest.raises(ValueError, match=r"ModelUncertainty.c_E = 0.0: expected a finite nonzero deviation"):
        ModelUncertainty(c_E=0.0)


def test_runner_and_session_normalize_by_the_wind_observer(quick_settings):
    """The pure runner (through RTOSession) with the observer as the experiment's wind source: every experiment's
    cost is its laps' tension coefficients scaled to the nominal wind, and the laps' wind is the observer's (at
    z_ref through the model's shear 0.15 while the plant's is 0.20: ~15 % above the steady 8 m/s)."""
    spec = replace(quick_settings.experiment, n_laps=1, wind_source="observer")
    res = run_rto(PlantConfig(wind_model="uniform").without_disturbances(), seed=2, n_iter=1,
                  settings=replace(quick_settings, experiment=spec))
    assert res.success and len(res.records) == 1 and res.experiments
    for e in res.experiments:
        out = e.outcome
        assert -out.cost == pytest.approx(np.mean([lap.tension_coefficient for lap in out.laps]) * 64.0 / 1e3)
        assert all(1.1 < math.sqrt(lap.mean_wind_sq) / 8.0 < 1.2 for lap in out.laps), \
            [math.sqrt(lap.mean_wind_sq) for lap in out.laps]
