"""A scene of :mod:`kite_rto.flight.scene` as a ``visualization_msgs/MarkerArray`` (RViz2, Foxglove).

One marker per shape, namespace = the shape's, id 0, action ADD, no lifetime (a marker stays until the next array
replaces it: every array carries the whole scene, so a viewer that seeks in a recording shows the full scene from
the last array before that time).
"""
from __future__ import annotations

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ..flight.scene import Shape
from ..nodes.interface import ns_to_stamp

__all__ = ["FRAME", "MARKER_TYPES", "PointCache", "marker", "marker_array"]

FRAME = "anchor"
"""The frame of every marker: the measurements' frame (no TF is published; set it as the viewer's fixed frame)."""

MARKER_TYPES = {"line_strip": Marker.LINE_STRIP, "triangle_list": Marker.TRIANGLE_LIST, "arrow": Marker.ARROW,
                "cube": Marker.CUBE, "text": Marker.TEXT_VIEW_FACING}


class PointCache:
    """``geometry_msgs/Point`` objects by coordinates, reused from one scene to the next (the reference path and most
    of the trail repeat: building a Point costs more than finding it). Holds at most ``size`` points."""

    def __init__(self, size: int = 4096):
        self.size, self._points = size, {}

    def points(self, xyz) -> list:
        """Points of an (N, 3) array, m."""
        cache = self._points
        if len(cache) > self.size:
            cache.clear()
        out = []
        for row in map(tuple, xyz.tolist()):
            p = cache.get(row)
            if p is None:
                p = cache[row] = Point(x=row[0], y=row[1], z=row[2])
            out.append(p)
        return out


def marker(shape: Shape, stamp_ns: int, frame: str = FRAME, cache: PointCache | None = None) -> Marker:
    """The marker of one shape, stamped ``stamp_ns`` (ns, the sample's time); ``cache`` reuses Point objects."""
    m = Marker(ns=shape.ns, id=0, type=MARKER_TYPES[shape.kind], action=Marker.ADD, text=shape.text)
    m.header.stamp = ns_to_stamp(stamp_ns)
    m.header.frame_id = frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in shape.position)
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in shape.scale)
    m.color = ColorRGBA(r=float(shape.color[0]), g=float(shape.color[1]), b=float(shape.color[2]),
                        a=float(shape.color[3]))
    m.points = (cache.points(shape.points) if cache is not None
                else [Point(x=x, y=y, z=z) for x, y, z in shape.points.tolist()])
    return m


def marker_array(shapes, stamp_ns: int, frame: str = FRAME, cache: PointCache | None = None) -> MarkerArray:
    """The whole scene as one array (each marker stamped ``stamp_ns`` ns)."""
    return MarkerArray(markers=[marker(s, stamp_ns, frame, cache) for s in shapes])
