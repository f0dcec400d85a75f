"""The 3-D scene of a flight, as pure geometry for the viewers (RViz2, Foxglove): no ROS here.

Everything is in the ``anchor`` frame of the measurements (m; x downwind, z up, origin at the tether's ground
anchor). A scene is a list of :class:`Shape` (one per thing drawn): the kite (a delta wing pointing along its
heading), the tether, the reference figure-eight, the flown trail, the wind arrow, the ``h_min`` plane (the
optimizer's minimum-altitude constraint) and a text label. ``kite_rto.tools.markers`` turns it into a
``visualization_msgs/MarkerArray``; the pacing (:class:`ScenePacer`) and the trail (:class:`Trail`) are here too so
that they are tested without DDS.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..kite.params import ParameterError

__all__ = ["Shape", "SceneStyle", "KiteView", "Trail", "ScenePacer", "SceneTracker", "heading_vector", "build_scene",
           "SHAPE_KINDS", "NAMESPACES"]

SHAPE_KINDS = ("line_strip", "triangle_list", "arrow", "cube", "text")
"""The primitives a scene uses (each maps to one ``visualization_msgs/Marker`` type)."""

NAMESPACES = ("kite", "tether", "reference", "trail", "wind", "h_min", "label")
"""One shape per namespace at most; the marker id is always 0."""


@dataclass(frozen=True)
class Shape:
    """One drawn thing.

    Attributes:
        ns: namespace (one of :data:`NAMESPACES`).
        kind: one of :data:`SHAPE_KINDS`.
        points: (N, 3) vertices, m (line strip: the polyline; triangle list: 3 per triangle; arrow: tail, head).
        color: (r, g, b, a) in [0, 1].
        scale: (3,) marker scale: line width in x for lines; shaft diameter, head diameter, head length for an
            arrow; box size for a cube; text height in z, m.
        position: (3,) centre of a cube or the text, m.
        text: the label's text (kind ``text``).
    """

    ns: str
    kind: str
    points: np.ndarray
    color: tuple
    scale: tuple
    position: tuple = (0.0, 0.0, 0.0)
    text: str = ""

    def __post_init__(self):
        if self.kind not in SHAPE_KINDS:
            raise ValueError(f"Shape.kind = {self.kind!r}: expected one of {', '.join(SHAPE_KINDS)}")
        pts = np.asarray(self.points, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"Shape {self.ns}: non-finite vertex in {pts.tolist()}")
        object.__setattr__(self, "points", pts)


@dataclass(frozen=True)
class SceneStyle:
    """Sizes (m), scales and colours of the scene.

    Attributes:
        wing_span: span of the drawn kite, m (exaggerated: a 400 m tether makes a real kite a dot).
        wing_length: nose-to-tail length of the drawn kite, m.
        line_width: tether and trail width, m.
        path_width: reference path width, m.
        wind_scale: wind arrow length per wind speed, s (m per m/s).
        plane_thickness: thickness of the h_min plane, m.
        text_height: label height, m.
    """

    wing_span: float = 24.0
    wing_length: float = 16.0
    line_width: float = 1.0
    path_width: float = 2.0
    wind_scale: float = 5.0
    plane_thickness: float = 0.5
    text_height: float = 12.0
    colors: dict = field(default_factory=lambda: {
        "kite": (1.0, 0.45, 0.0, 1.0), "tether": (0.6, 0.6, 0.6, 1.0), "reference": (0.1, 0.8, 0.2, 0.9),
        "trail": (0.2, 0.4, 1.0, 0.9), "wind": (0.3, 0.8, 1.0, 1.0), "h_min": (1.0, 0.1, 0.1, 0.15),
        "label": (1.0, 1.0, 1.0, 1.0)})


@dataclass(frozen=True)
class KiteView:
    """What is drawn of the kite at one sample.

    Attributes:
        t: sample time (the stamp), s.
        position: (x, y, z) of the kite in the anchor frame, m.
        psi: heading angle, rad (0 = towards the zenith, the model's convention); None draws the wing along the
            tangent towards the zenith.
    """

    t: float
    position: tuple
    psi: float | None = None


def heading_vector(position, psi: float) -> np.ndarray:
    """Unit vector of the kite's heading at ``position`` (m, anchor frame) for heading angle ``psi`` (rad).

    With ``theta`` the angle from the downwind x axis and ``phi`` the azimuth (``p = r (cos theta, sin theta sin phi,
    sin theta cos phi)``), the model flies ``theta' ~ cos psi`` and ``phi' ~ -sin psi``: the heading is
    ``cos psi e_theta - sin psi e_phi`` with the unit tangents ``e_theta`` (towards the zenith) and ``e_phi``.
    """
    x, y, z = (float(v) for v in position)
    r = math.sqrt(x * x + y * y + z * z)
    if not r > 0.0:
        raise ValueError(f"heading_vector: position {position}: expected a point away from the anchor")
    theta = math.acos(max(-1.0, min(1.0, x / r)))
    phi = math.atan2(y, z)
    e_theta = np.array([-math.sin(theta), math.cos(theta) * math.sin(phi), math.cos(theta) * math.cos(phi)])
    e_phi = np.array([0.0, math.cos(phi), -math.sin(phi)])
    return math.cos(psi) * e_theta - math.sin(psi) * e_phi


def _wing(position, psi, style: SceneStyle) -> np.ndarray:
    """Two triangles (both windings, so both faces show): nose ahead of ``position``, wing tips behind it."""
    p = np.asarray(position, dtype=float)
    h = heading_vector(p, 0.0 if psi is None else psi)
    n = p / np.linalg.norm(p)                           # along the tether, outwards
    s = np.cross(n, h)                                  # span direction
    nose = p + 0.5 * style.wing_length * h
    left = p - 0.5 * style.wing_length * h + 0.5 * style.wing_span * s
    right = p - 0.5 * style.wing_length * h - 0.5 * style.wing_span * s
    return np.array([nose, left, right, nose, right, left])


def build_scene(kite: KiteView | None, reference=None, trail=None, wind: float | None = None, h_min: float | None = None,
                z_ref: float = 10.0, style: SceneStyle | None = None) -> list[Shape]:
    """The shapes of one scene.

    Args:
        kite: the kite at the current sample (None before the first: no kite, tether or label).
        reference: (N, 3) points of the reference figure-eight, m (None or empty: not drawn).
        trail: (M, 3) recent kite positions, oldest first, m (fewer than 2: not drawn).
        wind: horizontal wind at the anemometer, m/s (None: no arrow); the arrow starts above the anchor at the
            anemometer height ``z_ref`` (m) and points downwind, ``style.wind_scale`` m per m/s long.
        h_min: minimum altitude of the optimizer's constraint, m (None: no plane); a thin translucent box at that
            height under the flight window (x from 0 to the tether length, y within +-0.8 tether length).
        style: sizes and colours.
    """
    st = style or SceneStyle()
    c = st.colors
    shapes = []
    r = 400.0
    if kite is not None:
        p = np.asarray(kite.position, dtype=float).reshape(3)
        r = float(np.linalg.norm(p)) or r
        shapes.append(Shape("kite", "triangle_list", _wing(p, kite.psi, st), c["kite"], (1.0, 1.0, 1.0)))
        shapes.append(Shape("tether", "line_strip", np.array([[0.0, 0.0, 0.0], p]), c["tether"],
                            (st.line_width, 0.0, 0.0)))
        label = f"t = {kite.t:.1f} s   z = {p[2]:.0f} m" + (f"   wind {wind:.1f} m/s" if wind is not None else "")
        shapes.append(Shape("label", "text", np.zeros((0, 3)), c["label"], (0.0, 0.0, st.text_height),
                            position=(float(p[0]), float(p[1]), float(p[2]) + 2.0 * st.text_height), text=label))
    if reference is not None and len(reference) >= 2:
        shapes.append(Shape("reference", "line_strip", np.asarray(reference, dtype=float), c["reference"],
                            (st.path_width, 0.0, 0.0)))
    if trail is not None and len(trail) >= 2:
        shapes.append(Shape("trail", "line_strip", np.asarray(trail, dtype=float), c["trail"],
                            (st.line_width, 0.0, 0.0)))
    if wind is not None and math.isfinite(wind) and wind > 0.0:
        tail = np.array([0.0, 0.0, z_ref])
        shapes.append(Shape("wind", "arrow", np.array([tail, tail + [wind * st.wind_scale, 0.0, 0.0]]), c["wind"],
                            (2.0, 5.0, 8.0)))
    if h_min is not None and math.isfinite(h_min):
        shapes.append(Shape("h_min", "cube", np.zeros((0, 3)), c["h_min"], (r, 1.6 * r, st.plane_thickness),
                            position=(0.5 * r, 0.0, float(h_min))))
    return shapes


class Trail:
    """The kite's recent positions: one point every ``step`` s of sample time, the last ``length`` s.

    A sample time lower than the last one (the plant restarted) clears the trail.
    """

    def __init__(self, length: float = 40.0, step: float = 0.1):
        if not (length > 0 and step > 0 and length >= step):
            raise ParameterError(f"Trail: length = {length} s, step = {step} s: expected 0 < step <= length")
        self.step = step
        self._points: deque = deque(maxlen=int(round(length / step)) + 1)
        self._last_t: float | None = None

    def add(self, t: float, position) -> bool:
        """Offer the sample at time ``t`` (s) and ``position`` (m); return True if it was kept."""
        if self._last_t is not None and t < self._last_t:
            self._points.clear()
            self._last_t = None
        if self._last_t is not None and t < self._last_t + self.step - 1e-9:
            return False
        self._points.append(tuple(float(v) for v in position))
        self._last_t = t
        return True

    def points(self) -> np.ndarray:
        """(M, 3) positions, oldest first, m."""
        return np.array(self._points, dtype=float).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self._points)


class ScenePacer:
    """When to publish a scene: once per ``period`` s of sample (simulated) time, and at most ``max_rate`` per wall
    second (0 = no wall limit).

    Pacing on sample time makes a recording hold one scene every ``period`` s of the flight whatever the machine's
    speed; the wall limit keeps a lockstep run that flies many times faster than real time from flooding the viewers
    (a screen shows at most a few tens of frames per second). A sample time lower than the last one (a restarted
    plant) starts the pacing afresh.
    """

    def __init__(self, period: float = 0.1, max_rate: float = 20.0):
        if not period > 0 or not max_rate >= 0:
            raise ParameterError(f"ScenePacer: period = {period} s, max_rate = {max_rate} Hz: expected period > 0 "
                                 "and max_rate >= 0")
        self.period, self.min_wall = period, (1.0 / max_rate if max_rate > 0 else 0.0)
        self._next_t: float | None = None
        self._last_wall: float | None = None

    def due(self, t: float, wall: float) -> bool:
        """True if a scene should be published for the sample at time ``t`` (s) seen at ``wall`` (s, monotonic)."""
        if self._next_t is not None and t < self._next_t - self.period:     # time went back: a new run
            self._next_t = None
        if self._next_t is not None and t < self._next_t - 1e-9:
            return False
        if self._last_wall is not None and wall - self._last_wall < self.min_wall:
            return False
        # the next one is due a whole period after this sample, on the grid of the first one
        if self._next_t is None:
            self._next_t = t + self.period
        else:
            self._next_t += self.period * max(1, math.floor((t - self._next_t) / self.period + 1e-9) + 1)
        self._last_wall = wall
        return True


class SceneTracker:
    """Keeps what the scene needs from the measurements and says when a scene is due.

    Feed it :meth:`position`, :meth:`wind`, :meth:`reference` as they arrive and :meth:`state` for every state
    sample (the plant publishes the state last: its arrival completes a sample); :meth:`state` returns the scene's
    shapes when one is due (:class:`ScenePacer`), else None.

    Args:
        pacer: when to publish.
        trail: the flown trail.
        h_min: minimum altitude drawn as a plane, m (None: no plane).
        z_ref: anemometer height, where the wind arrow starts, m.
        style: sizes and colours.
    """

    def __init__(self, pacer: ScenePacer | None = None, trail: Trail | None = None, h_min: float | None = 100.0,
                 z_ref: float = 10.0, style: SceneStyle | None = None):
        self.pacer = pacer or ScenePacer()
        self.trail = trail or Trail()
        self.h_min, self.z_ref, self.style = h_min, z_ref, style or SceneStyle()
        self._position = None            # (t, (x, y, z))
        self._wind: float | None = None
        self._reference = None
        self.scenes = 0

    def position(self, t: float, xyz) -> None:
        """The kite's position at sample time ``t`` (s), m."""
        self._position = (t, tuple(float(v) for v in xyz))
        self.trail.add(t, xyz)

    def wind(self, t: float, speed: float) -> None:
        """The anemometer's wind at ``t`` (s), m/s."""
        self._wind = float(speed)

    def reference(self, points) -> None:
        """The reference figure-eight, (N, 3) points in m."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        self._reference = pts if len(pts) >= 2 and np.all(np.isfinite(pts)) else None

    def state(self, t: float, psi: float, wall: float) -> list[Shape] | None:
        """A state sample at ``t`` (s) with heading ``psi`` (rad), seen at ``wall`` (monotonic s): the scene's
        shapes if one is due (and a position has been heard), else None."""
        if self._position is None or not self.pacer.due(t, wall):
            return None
        self.scenes += 1
        pos = self._position[1]
        kite = KiteView(t, pos, psi if math.isfinite(psi) else None)
        return build_scene(kite, self._reference, self.trail.points(), self._wind, self.h_min, self.z_ref, self.style)
