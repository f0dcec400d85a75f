"""Figure-eight geometry, setpoint validation and the projection round trip."""
import math

import numpy as np
import pytest

from kite_rto.kite.params import KiteParams
from kite_rto.flight.path import (DEFAULT_SETPOINTS, FigureEightPath, SetpointBox, SetpointError, Setpoints,
                                required_turn_radius, validate_setpoints)
from kite_rto.flight.shape import ShapeBox, setpoints_from_shape, shape_from_setpoints
from kite_rto.flight.projection import project_samples

C = Setpoints.from_degrees(35.0, 45.0, 7.0)


def _p3(path, s):
    th, ph = path.point(s)
    return np.array([math.cos(th), math.sin(th) * math.sin(ph), math.sin(th) * math.cos(ph)])


def test_setpoints_array_round_trip():
    c = Setpoints.from_array(C.as_array())
    assert c == C
    assert np.allclose(c.degrees(), (35.0, 45.0, 7.0))
    with pytest.raises(SetpointError):
        Setpoints.from_array([1.0, 2.0])


def test_points_and_tangent_match_finite_differences():
    path = FigureEightPath(C)
    assert path.point(0.0) == pytest.approx((C.theta_0, 0.0))
    assert path.point(math.pi / 2) == pytest.approx((C.theta_0, C.A_phi))
    h = 1e-6
    for s in np.linspace(0.1, 6.2, 13):
        (t1, p1), (t0, p0) = path.point(s + h), path.point(s - h)
        north, east = (t1 - t0) / (2 * h), math.sin(path.point(s)[0]) * (p1 - p0) / (2 * h)
        v = math.hypot(north, east)
        assert path.tangent(s) == pytest.approx((north / v, east / v), abs=1e-6)
        assert path.speed(s) == pytest.approx(v, rel=1e-6)
        # the local metric speed equals the 3D speed on the unit sphere
        assert np.linalg.norm(_p3(path, s + h) - _p3(path, s - h)) / (2 * h) == pytest.approx(v, rel=1e-6)


def test_curvature_is_geodesic_curvature():
    """kappa = -det[P, P', P''] / |P'|^3 on the unit sphere (the model's (theta, phi) frame is left-handed)."""
    path = FigureEightPath(C)
    h = 1e-4
    for s in np.linspace(0.05, 6.2, 17):
        p, pp, pm = _p3(path, s), _p3(path, s + h), _p3(path, s - h)
        d1, d2 = (pp - pm) / (2 * h), (pp - 2 * p + pm) / h**2
        kappa = -np.dot(np.cross(p, d1), d2) / np.linalg.norm(d1) ** 3
        assert path.curvature(s) == pytest.approx(kappa, rel=1e-4, abs=1e-4)
    k, s_max = path.max_curvature()
    assert abs(path.curvature(s_max)) == pytest.approx(k)
    assert path.min_turn_radius(400.0) == pytest.approx(400.0 / k)
    assert path.turn_radius(s_max, 400.0) == pytest.approx(400.0 / k)


def test_tip_curvature_formula():
    """At the lobe end the radius is 4 A_theta^2 / (sin theta_0 A_phi) (rad), from the plane parabola."""
    path = FigureEightPath(C)
    expected = math.sin(C.theta_0) * C.A_phi / (4 * C.A_theta**2)
    # plus the geodesic term cos(theta) dphi/ds = 0 at the tip (dphi/ds = 0)
    assert abs(path.curvature(math.pi / 2)) == pytest.approx(expected, rel=0.02)


@pytest.mark.parametrize("s_true", [0.3, 1.2, 2.5, 3.3, 4.4, 5.9])
@pytest.mark.parametrize("offset", [-0.01, 0.0, 0.015])
def test_closest_point(s_true, offset):
    path = FigureEightPath(C)
    th, ph = path.point(s_true)
    n, e = path.tangent(s_true)
    # move along the normal (-e, n) by `offset` rad of arc
    theta = th - e * offset
    phi = ph + n * offset / math.sin(th)
    cp = path.closest_point(theta, phi)
    assert (cp.s - s_true + math.pi) % (2 * math.pi) - math.pi == pytest.approx(0.0, abs=2e-3)
    assert cp.cross_track == pytest.approx(offset, abs=2e-4)
    warm = path.closest_point(theta, phi, s_guess=s_true - 0.2)
    assert warm.s == pytest.approx(cp.s, abs=1e-6)
    fast = path.track(theta, phi, s_true - 0.05)   # 3 Gauss-Newton steps: per-sample accuracy
    assert fast.s == pytest.approx(cp.s, abs=1e-3)
    assert fast.cross_track == pytest.approx(cp.cross_track, abs=1e-6)


def test_warm_start_keeps_branch_at_the_crossing():
    """At the centre of the eight both branches pass through the same point; warm start picks the right one."""
    path = FigureEightPath(C)
    for s_prev, s_expected in ((-0.02, 0.0), (math.pi - 0.02, math.pi)):
        cp = path.closest_point(C.theta_0, 0.0, s_guess=s_prev % (2 * math.pi))
        assert (cp.s - s_expected + math.pi) % (2 * math.pi) - math.pi == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("c", [C, Setpoints.from_degrees(30, 40, 6), Setpoints.from_degrees(25, 20, -5)])
def test_projection_round_trip(c):
    s = 2 * math.pi * np.arange(200) / 200 + 0.37          # uniform in s, arbitrary start
    th, ph = FigureEightPath(c).point(s)
    assert project_samples(th, ph) == pytest.approx(c.as_array(), abs=1e-9)


def test_default_setpoints_are_valid():
    box = SetpointBox()
    assert validate_setpoints(DEFAULT_SETPOINTS, box) == DEFAULT_SETPOINTS


def test_every_point_of_the_default_shape_box_is_trackable():
    """The optimizer's box: a 7x7x7 grid in shape coordinates passes validate_setpoints (default margin)."""
    shape = ShapeBox()
    box = shape.setpoint_box()
    assert box == SetpointBox() or all(
        lo_d <= lo_s and hi_s <= hi_d
        for name in Setpoints.names()
        for (lo_s, hi_s), (lo_d, hi_d) in [(getattr(box, name), getattr(SetpointBox(), name))])
    for x in shape.grid(7):
        validate_setpoints(setpoints_from_shape(x), SetpointBox())


def test_the_bounding_setpoint_box_is_not_all_trackable():
    """Why the optimizer needs shape coordinates: a corner of the bounding box (30, 42, 10.5) deg is a too
    tall figure, (40, 62, 5.5) deg a too flat one."""
    for c in (Setpoints.from_degrees(30, 42, 10.5), Setpoints.from_degrees(40, 62, 5.5)):
        with pytest.raises(SetpointError, match="infeasible turn"):
            validate_setpoints(c)


def test_shape_coordinates_round_trip_numeric_and_symbolic():
    import casadi as ca
    c = DEFAULT_SETPOINTS.as_array()
    x = shape_from_setpoints(c)
    assert x[2] == pytest.approx(c[2] / math.sqrt(math.sin(c[0]) * c[1]))
    assert setpoints_from_shape(x) == pytest.approx(c, abs=1e-15)
    sym = ca.SX.sym("c", 3)
    f = ca.Function("f", [sym], [setpoints_from_shape(shape_from_setpoints(sym)), shape_from_setpoints(sym)])
    back, xs = f(c)
    assert np.asarray(back).ravel() == pytest.approx(c, abs=1e-15)
    assert np.asarray(xs).ravel() == pytest.approx(x, abs=1e-15)
    box = ShapeBox()
    assert box.to_unit(box.from_unit([0.2, 0.5, 0.9])) == pytest.approx([0.2, 0.5, 0.9])
    assert box.from_unit([0, 0, 0]) == pytest.approx(setpoints_from_shape(box.lower()))


@pytest.mark.parametrize("bounds", [{"aspect": (0.2, 0.1)}, {"theta_0": (0.5, math.radians(95))},
                                    {"A_phi": (math.nan, 1.0)}])
def test_shape_box_rejects_bad_bounds(bounds):
    with pytest.raises(SetpointError, match="ShapeBox"):
        ShapeBox(**bounds)


@pytest.mark.parametrize("bad, words", [
    ((math.nan, 0.8, 0.12), ["theta_0", "nan", "finite"]),
    ((0.6, math.inf, 0.12), ["A_phi", "inf"]),
    ((math.radians(60), 0.8, 0.12), ["theta_0", "outside", "60"]),
    ((0.6, 0.8, math.radians(-7)), ["A_theta", "outside"]),
])
def test_validate_rejects_with_reason(bad, words):
    with pytest.raises(SetpointError) as err:
        validate_setpoints(bad)
    for w in words:
        assert w in str(err.value)


def test_validate_rejects_infeasible_turn():
    """(22, 15, 4) deg (the model optimum quoted in SPEC) needs a ~5 m turn radius."""
    wide = SetpointBox(theta_0=(0.3, 1.2), A_phi=(0.1, 1.0), A_theta=(0.01, 0.2))
    c = Setpoints.from_degrees(22, 15, 4)
    with pytest.raises(SetpointError, match="infeasible turn"):
        validate_setpoints(c, wide)
    assert FigureEightPath(c).min_turn_radius(400) < 10
    assert required_turn_radius(KiteParams(), 1.0, 1.0) == pytest.approx(25.0)


def test_negative_a_theta_is_the_mirrored_reverse_path():
    """A_theta < 0 is the same figure flown the other way round (mirror phi -> -phi, s -> -s)."""
    a, b = FigureEightPath(C), FigureEightPath(Setpoints(C.theta_0, C.A_phi, -C.A_theta))
    for s in np.linspace(0, 6, 7):
        th, ph = b.point(s)
        th2, ph2 = a.point(-s)
        assert (th, ph) == pytest.approx((th2, -ph2))
    box = SetpointBox(A_theta=(-math.radians(7.5), -math.radians(6.0)))
    assert validate_setpoints(Setpoints(C.theta_0, C.A_phi, -C.A_theta), box)


def test_effective_turn_radius_includes_drift():
    """Without drift (E -> inf) it is the geometric radius; with drift, turns flown downwards count tighter."""
    path = FigureEightPath(C)
    assert path.effective_turn_radius(400.0, 1e9) == pytest.approx(path.min_turn_radius(400.0), rel=1e-3)
    k = math.tan(C.theta_0 + abs(C.A_theta)) / 5.0
    assert path.min_turn_radius(400.0) / (1 + k) <= path.effective_turn_radius(400.0, 5.0) < path.min_turn_radius(400.0)
