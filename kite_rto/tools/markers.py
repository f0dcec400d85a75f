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

__all__ = ["FRAME", "MARKER_TYPES", "marker", "marker_array"]

FRAME = "anchor"
"""The frame of every marker: the measurements' frame (no TF is published; set it as the viewer's fixed frame)."""

MARKER_TYPES = {"line_strip": Marker.LINE_STRIP, "triangle_list": Marker.TRIANGLE_LIST, "arrow": Marker.ARROW,
                "cube": Marker.CUBE, "text": Marker.TEXT_VIEW_FACING}


def marker(shape: Shape, stamp_ns: int, frame: str = FRAME) -> Marker:
    """The marker of one shape, stamped ``stamp_ns`` (ns, the sample's time)."""
    m = Marker(ns=shape.ns, id=0, type=MARKER_TYPES[shape.kind], action=Marker.ADD, text=shape.text)
    m.header.stamp = ns_to_stamp(stamp_ns)
    m.header.frame_id = frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in shape.position)
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in shape.scale)
    m.color = ColorRGBA(r=float(shape.color[0]), g=float(shape.color[1]), b=float(shape.color[2]),
                        a=float(shape.color[3]))
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in shape.points.tolist()]
    return m


def marker_array(shapes, stamp_ns: int, frame: str = FRAME) -> MarkerArray:
    """The whole scene as one array (each marker stamped ``stamp_ns`` ns)."""
    return MarkerArray(markers=[marker(s, stamp_ns, frame) for s in shapes])
