"""The path controller and the path's projection compute bit for bit what the code at commit 78e9f26 computed.

``controller_reference.npz`` (beside this file) holds what that code answered, recorded by
``python test/flight/test_controller_bits.py --record`` before the per-sample work was made faster: every steering
command and status value of a 20 s closed-loop flight with two setpoint changes and two retunings (plant: the
uniform gust, seed 0; its trajectory is itself pinned by ``benchmarks/bench_plant.py``), of 300 scripted
measurements that jump off the path (saturation, anti-windup, the projection's fall-backs), and the closest points
and turn radii of the path for random positions. It stores the commands and a SHA-256 of the float64 bytes of each
block (the status values and setpoints in use with them): equality is bit for bit, no tolerance.

Should the plant's trajectory change on purpose, record again at a commit whose controller is known to be the
reference one and say so in the commit message.
"""
import hashlib
import math
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from kite_rto.flight.closed_loop import make_closed_loop
from kite_rto.flight.controller import ControllerSettings, PathController
from kite_rto.flight.path import DEFAULT_SETPOINTS, FigureEightPath, Setpoints
from kite_rto.kite.model import shared_model
from kite_rto.kite.params import KiteParams
from kite_rto.kite.plant import PlantConfig

REFERENCE = Path(__file__).resolve().parent / "controller_reference.npz"
FLIGHT_SAMPLES = 1000          # 20 s at dt = 0.02 s
SCRIPTED_SAMPLES = 300
PATH_POINTS = 4000


def _status_row(ctl: PathController, delta: float) -> list:
    """The command and every number of the controller's status (rad, 1, and the setpoints in use in rad)."""
    s = ctl.status
    return [delta, s.s, s.cross_track, s.s_pred, s.cross_track_pred, float(s.saturated), s.wind_scale,
            s.gain_scale, *s.setpoints.as_array()]


def _flight() -> np.ndarray:
    """20 s closed loop; new setpoints at 3 s and 10 s, blend shortened to 4 s at 5 s and ended at 12 s."""
    plant, ctl = make_closed_loop(DEFAULT_SETPOINTS, PlantConfig(wind_model="uniform"), seed=0)
    events = {150: lambda: ctl.set_setpoints(Setpoints.from_degrees(33.0, 50.0, 7.5)),
              250: lambda: ctl.retune(blend_time=4.0, k_psi=3.5),
              500: lambda: ctl.set_setpoints(Setpoints.from_degrees(36.0, 47.0, 7.2)),
              600: lambda: ctl.retune(blend_time=0.0)}
    rows, m = [], plant.measure()
    for k in range(FLIGHT_SAMPLES):
        if k in events:
            events[k]()
        delta = ctl.command(m)
        rows.append(_status_row(ctl, delta))
        m = plant.step(delta)
    return np.array(rows)


def _scripted() -> np.ndarray:
    """Measurements near the path, heading off it, that jump every 60 samples: saturation, anti-windup and the
    fall-backs of the projection; no steering-gain estimate (gain_filter 0)."""
    settings = ControllerSettings(delta_max=0.8, gain_filter=0.0)
    ctl = PathController(shared_model(), KiteParams(), DEFAULT_SETPOINTS, settings)
    path = FigureEightPath(DEFAULT_SETPOINTS)
    rows = []
    for k in range(SCRIPTED_SAMPLES):
        t = k * 0.02
        s = 0.5 * t + 2.0 * (k // 60)
        theta, phi = path.point(s)
        m = SimpleNamespace(t=t, theta=theta + 0.02 * math.sin(3.0 * t) + 0.2 * (k // 60 == 3), phi=phi,
                            psi=-path.course(s) + 0.6 * math.sin(1.3 * t), theta_dot=-0.05 + 0.1 * math.cos(t),
                            phi_dot=0.28, psi_dot=0.4 * math.sin(0.7 * t), wind_ref=8.0 + math.sin(0.2 * t))
        rows.append(_status_row(ctl, ctl.command(m)))
    return np.array(rows)


def _path() -> np.ndarray:
    """Closest points (global, windowed, tracked from a nearby and from a far s), curvature, course, speed and
    tangent at random positions near two paths, and their turn radii."""
    rng = np.random.default_rng(5)
    rows = []
    for c in (DEFAULT_SETPOINTS, Setpoints.from_degrees(33.0, 50.0, -7.5)):
        path = FigureEightPath(c)
        rows.append([path.effective_turn_radius(400.0, 5.0), *path.max_curvature(), 0.0, 0.0])
        for _ in range(PATH_POINTS // 2):
            s = rng.uniform(0.0, 2 * math.pi)
            theta, phi = path.point(s)
            theta, phi = theta + rng.normal(0.0, 0.03), phi + rng.normal(0.0, 0.03)
            near = (s + rng.normal(0.0, 0.1)) % (2 * math.pi)
            far = (s + rng.choice([0.05, -0.3, 0.7, 2.0])) % (2 * math.pi)
            for cp in (path.closest_point(theta, phi), path.closest_point(theta, phi, s_guess=far),
                       path.track(theta, phi, near), path.track(theta, phi, far)):
                rows.append([cp.s, cp.theta, cp.phi, cp.cross_track, cp.course])
            rows.append([path.curvature(s), path.course(s), path.speed(s), *path.tangent(s)])
    return np.array(rows)


def _digest(a: np.ndarray) -> str:
    """SHA-256 of the float64 bytes of ``a`` (little-endian, C order)."""
    return hashlib.sha256(np.ascontiguousarray(a, dtype="<f8").tobytes()).hexdigest()


def _record() -> None:
    """Store the commands in full (to name the first sample that differs) and a digest of every block."""
    blocks = {"flight": _flight(), "scripted": _scripted(), "path": _path()}
    np.savez_compressed(REFERENCE, flight_delta=blocks["flight"][:, 0], scripted_delta=blocks["scripted"][:, 0],
                        **{f"{k}_sha256": np.array(_digest(v)) for k, v in blocks.items()})
    print(f"wrote {REFERENCE}")


@pytest.fixture(scope="module")
def reference():
    with np.load(REFERENCE) as z:
        return {k: z[k] for k in z.files}


def _assert_same(name: str, got: np.ndarray, reference: dict) -> None:
    """``got`` hashes to the reference digest; else name the first command that differs, if one does."""
    if _digest(got) == str(reference[f"{name}_sha256"]):
        return
    want = reference.get(f"{name}_delta")
    if want is not None and want.shape == got[:, 0].shape and (got[:, 0] != want).any():
        k = int(np.argmax(got[:, 0] != want))
        pytest.fail(f"{name}: command {k} is {got[k, 0]!r}, the reference {want[k]!r}")
    pytest.fail(f"{name}: the values differ from the reference (digest {_digest(got)})")


def test_closed_loop_commands_are_bit_for_bit_the_reference(reference):
    _assert_same("flight", _flight(), reference)


def test_scripted_commands_are_bit_for_bit_the_reference(reference):
    _assert_same("scripted", _scripted(), reference)


def test_path_projection_is_bit_for_bit_the_reference(reference):
    _assert_same("path", _path(), reference)


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit(f"usage: {sys.argv[0]} --record   (overwrites {REFERENCE})")
    _record()
