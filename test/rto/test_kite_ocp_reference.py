"""The OCP's altitude constraint on the reference figure-eight (``KiteOCPSettings.altitude = "reference"``): a
function of the lap's setpoints y(u) alone, so the model cannot keep its altitude by bending its lap in ways the
plant's path controller does not fly (the hidden freedom the default "lap" constraint has)."""
import math

import casadi as ca
import numpy as np
import pytest

from kite_rto.rto.ocp import KiteOCPSettings, model_problem, path_guess, reference_altitudes
from kite_rto.rto.settings import KiteRTOSettings

DEG = math.pi / 180.0
C = np.array([30.0, 50.0, 8.0]) * DEG


def _softmin(z, h_ref, s):
    return h_ref - s * np.log(np.sum(np.exp(-(z - h_ref) / s)))


@pytest.fixture(scope="module", params=["lap", "reference"])
def problem(request):
    return model_problem(settings=KiteOCPSettings(altitude=request.param))


def test_reference_altitudes_closed_form():
    flat = reference_altitudes(np.array([30.0 * DEG, 0.0, 0.0]), 400.0, 32)
    np.testing.assert_allclose(flat, 200.0, rtol=1e-12)          # r sin 30 deg everywhere
    z = reference_altitudes(C, 400.0, 64)
    s = 2 * np.pi * np.arange(64) / 64
    np.testing.assert_allclose(z, 400.0 * np.sin(C[0] + C[2] * np.sin(2 * s)) * np.cos(C[1] * np.sin(s)))
    c = ca.SX.sym("c", 3)
    f = ca.Function("z", [c], [reference_altitudes(c, 400.0, 64)])
    np.testing.assert_allclose(np.asarray(f(C)).ravel(), z, rtol=1e-12)


def test_reference_constraint_is_the_reference_paths_lowest_point():
    pr = model_problem(settings=KiteOCPSettings(altitude="reference"))
    u = path_guess(pr.params, pr.settings, C)
    _, g, y = pr.evaluate(u)
    z = reference_altitudes(np.ravel(y), pr.params.r, 64)
    assert float(np.ravel(g)[0]) == pytest.approx(100.0 - _softmin(z, 100.0, 0.5), abs=1e-9)


def test_only_the_reference_constraint_depends_on_u_through_y_alone(problem):
    """dg/du lies in the row space of dy/du for "reference" (residual ~0), not for "lap" (the model lap's
    altitude moves along directions that keep the setpoints)."""
    u0 = path_guess(problem.params, problem.settings, C)
    jac = ca.Function("j", [problem.u], [ca.jacobian(problem.outputs, problem.u),
                                         ca.jacobian(problem.constraints, problem.u)])
    jy, jg = (np.asarray(v) for v in jac(u0))
    coef, *_ = np.linalg.lstsq(jy.T, jg.ravel(), rcond=None)
    residual = np.linalg.norm(jg.ravel() - jy.T @ coef) / np.linalg.norm(jg)
    if problem.settings.altitude == "reference":
        assert residual < 1e-9
    else:
        assert residual > 0.5


@pytest.mark.parametrize("kwargs,word", [({"altitude": "path"}, "'path'"), ({"reference_samples": 8}, "8"),
                                         ({"reference_samples": True}, "True")])
def test_ocp_settings_name_the_bad_value(kwargs, word):
    with pytest.raises(ValueError, match=word):
        KiteOCPSettings(**kwargs)


def test_the_run_builds_its_ocp_with_its_own_floor():
    """The kite's OCP is the run's: its settings' KiteOCPSettings (the reference altitude by default) and its
    experiment's h_min, not a copy that could differ."""
    from kite_rto.rto.builder import lap_problem
    from kite_rto.rto.experiment import ExperimentSpec
    with pytest.raises(ValueError, match="KiteRTOSettings.ocp = 'reference': expected a KiteOCPSettings"):
        KiteRTOSettings(ocp="reference")
    assert KiteRTOSettings().ocp.altitude == "reference"
    low, high = (KiteRTOSettings(experiment=ExperimentSpec(h_min=h)) for h in (100.0, 115.0))
    p_low, p_high = lap_problem(low), lap_problem(high)
    g_low, g_high = (float(p.evaluate(p_low.u0)[1][0]) for p in (p_low, p_high))
    assert g_high - g_low == pytest.approx(15.0, rel=1e-9)
