"""The 3-D scene of a flight (kite_rto.flight.scene): geometry, trail, pacing on simulated time, without ROS."""
import math

import numpy as np
import pytest

from kite_rto.flight.path import DEFAULT_SETPOINTS, FigureEightPath
from kite_rto.flight.scene import (NAMESPACES, KiteView, ScenePacer, SceneStyle, SceneTracker, Shape, Trail,
                                   build_scene, heading_vector)
from kite_rto.kite.params import ParameterError

R = 400.0


def position(theta, phi, r=R):
    return r * np.array([math.cos(theta), math.sin(theta) * math.sin(phi), math.sin(theta) * math.cos(phi)])


@pytest.mark.parametrize("theta,phi", [(0.6, 0.0), (0.5, 0.7), (0.9, -0.4)])
def test_heading_follows_the_model_convention(theta, phi):
    """psi = 0 flies towards the zenith (theta grows), psi = pi/2 makes phi decrease (phi' ~ -sin psi)."""
    p = position(theta, phi)
    dt = 1e-6
    for psi in np.linspace(-math.pi, math.pi, 9):
        h = heading_vector(p, psi)
        assert abs(np.linalg.norm(h) - 1.0) < 1e-12
        assert abs(h @ p) < 1e-9                     # tangent to the sphere of the tether
        # the model's direction of motion: theta' ~ cos psi, phi' ~ -sin psi / sin theta (same positive factor)
        ahead = position(theta + dt * math.cos(psi), phi - dt * math.sin(psi) / math.sin(theta))
        step = (ahead - p) / np.linalg.norm(ahead - p)
        np.testing.assert_allclose(h, step, atol=1e-5)
    up = heading_vector(position(theta, 0.0), 0.0)
    assert up[2] > 0 and up[0] < 0                   # towards the zenith: up and back over the anchor
    with pytest.raises(ValueError, match="away from the anchor"):
        heading_vector((0.0, 0.0, 0.0), 0.0)


def test_scene_holds_every_part_in_the_anchor_frame():
    path = FigureEightPath(DEFAULT_SETPOINTS)
    th, ph = path.point(np.linspace(0, 2 * math.pi, 181))
    reference = np.array([position(a, b) for a, b in zip(th, ph)])
    kite_p = position(0.6, 0.3)
    trail = np.array([position(0.6, 0.3 - 0.01 * i) for i in range(5)][::-1])
    style = SceneStyle()
    shapes = build_scene(KiteView(12.34, kite_p, psi=0.4), reference, trail, wind=8.0, h_min=100.0, z_ref=10.0,
                         style=style)
    by = {s.ns: s for s in shapes}
    assert set(by) == set(NAMESPACES)
    kite = by["kite"]
    assert kite.kind == "triangle_list" and kite.points.shape == (6, 3)
    nose = kite.points[0]
    np.testing.assert_allclose(nose, kite_p + 0.5 * style.wing_length * heading_vector(kite_p, 0.4))
    assert abs(np.linalg.norm(kite.points[1] - kite.points[2]) - style.wing_span) < 1e-9
    np.testing.assert_allclose(by["tether"].points, [[0, 0, 0], kite_p])
    np.testing.assert_allclose(by["reference"].points, reference)
    np.testing.assert_allclose(by["trail"].points, trail)
    wind = by["wind"]
    assert wind.kind == "arrow"
    np.testing.assert_allclose(wind.points, [[0, 0, 10.0], [8.0 * style.wind_scale, 0, 10.0]])
    plane = by["h_min"]
    assert plane.kind == "cube" and plane.position[2] == 100.0 and plane.scale[2] == style.plane_thickness
    assert abs(plane.scale[0] - R) < 1e-9 and abs(plane.position[0] - R / 2) < 1e-9
    assert "t = 12.3 s" in by["label"].text and "wind 8.0 m/s" in by["label"].text


def test_scene_leaves_out_what_is_not_known():
    assert build_scene(None) == []
    shapes = build_scene(KiteView(0.0, position(0.6, 0.0)), reference=np.zeros((0, 3)), trail=np.zeros((1, 3)),
                         wind=None, h_min=None)
    assert {s.ns for s in shapes} == {"kite", "tether", "label"}
    assert {s.ns for s in build_scene(None, wind=0.0, h_min=50.0)} == {"h_min"}


def test_shape_refuses_bad_input():
    with pytest.raises(ValueError, match="expected one of"):
        Shape("kite", "sphere", np.zeros((1, 3)), (1, 1, 1, 1), (1, 1, 1))
    with pytest.raises(ValueError, match="non-finite"):
        Shape("kite", "line_strip", [[0, 0, 0], [math.nan, 0, 0]], (1, 1, 1, 1), (1, 1, 1))


def test_trail_keeps_one_point_per_step_and_restarts():
    trail = Trail(length=1.0, step=0.1)
    kept = [trail.add(k * 0.02, (k, 0.0, 0.0)) for k in range(200)]       # 4 s of 50 Hz samples
    assert sum(kept) == 40                                                 # one every 5th sample
    pts = trail.points()
    assert len(pts) == 11 and pts[-1][0] == 195 and np.all(np.diff(pts[:, 0]) == 5)
    assert trail.add(0.0, (-1.0, 0.0, 0.0))                                # time went back: a new run
    assert len(trail) == 1
    with pytest.raises(ParameterError, match="step"):
        Trail(length=0.05, step=0.1)


def test_pacer_is_on_simulated_time_and_capped_on_wall_time():
    pacer = ScenePacer(period=0.1, max_rate=0.0)
    due = [k for k in range(100) if pacer.due(k * 0.02, wall=0.0)]        # no wall limit, all at the same instant
    assert due == list(range(0, 100, 5))                                   # every 0.1 s of simulated time
    assert not pacer.due(1.98, 0.0)                                        # a re-published sample: not again
    assert pacer.due(0.0, 0.0)                                             # time went back: a restarted plant

    capped = ScenePacer(period=0.1, max_rate=20.0)                         # at most one per 0.05 s of wall time
    shown = [k for k in range(500) if capped.due(k * 0.02, wall=k * 0.001)]    # 20x faster than real time
    assert len(shown) == 10                                                # 0.5 s of wall time: 10 at 20 Hz
    assert all(b - a >= 50 for a, b in zip(shown, shown[1:]))
    with pytest.raises(ParameterError, match="period"):
        ScenePacer(period=0.0)


def test_tracker_waits_for_a_position_then_paces():
    tr = SceneTracker(ScenePacer(0.1, 0.0), Trail(10.0, 0.1), h_min=120.0)
    assert tr.state(0.0, 0.0, wall=0.0) is None                            # no position yet
    tr.reference(np.array([position(0.6, p) for p in np.linspace(-0.7, 0.7, 50)]))
    tr.wind(0.0, 7.5)
    scenes = []
    for k in range(51):
        t = k * 0.02
        tr.position(t, position(0.6, 0.01 * k))
        s = tr.state(t, 0.3, wall=0.0)
        if s is not None:
            scenes.append((t, {x.ns: x for x in s}))
    assert [round(t, 2) for t, _ in scenes] == [round(0.1 * i, 2) for i in range(11)]
    last = scenes[-1][1]
    assert set(last) == set(NAMESPACES)
    assert last["h_min"].position[2] == 120.0 and len(last["trail"].points) == 11
    tr.reference(np.full((3, 3), math.nan))                                # a bad path is not drawn
    assert "reference" not in {x.ns for x in tr.state(2.0, math.nan, 0.0)}
