"""Topic names of the kite_rto graph (SPEC §7), relative to the nodes' namespace.

Every name is relative, so a node started with ``--ros-args -r __ns:=/kite2`` publishes and subscribes
``/kite2/kite/state``, ``/kite2/clock``, ...: two graphs in different namespaces share a ROS domain without hearing
each other (docs/network.md *Two kites in one domain*). In the root namespace the names are the familiar
``/kite/state``, ``/clock``. :func:`graph_name` is the name as seen inside a graph (``/kite/state``, whatever its
namespace): what the tools print, take on their command line and name MCAP channels by.
"""
from ..runtime.optimizer_sync import SYNC_NAMES

__all__ = ["CLOCK", "STATE", "POSITION", "TENSION", "WIND", "STEERING", "SETPOINTS", "STATUS", "SYNC", "SYNC_NAMES",
           "REFERENCE_PATH", "LAPS", "CRASHES", "WIND_ESTIMATE", "MARKERS", "MANUAL_SETPOINTS", "PLANT_CONFIG",
           "RUN", "RECORDED", "ALL", "graph_name", "relative"]

CLOCK = "clock"                      # in the root namespace /clock, as use_sim_time and `ros2 topic echo` expect
STATE = "kite/state"
POSITION = "kite/position"
TENSION = "kite/tension"
WIND = "kite/wind"
WIND_ESTIMATE = "kite/wind_estimate"
STEERING = "kite/steering"
SETPOINTS = "rto/setpoints"
STATUS = "rto/status"
SYNC = "rto/sync"
MANUAL_SETPOINTS = "rto/manual_setpoints"   # operator setpoints, taken by a paused optimizer (kite_ctl setpoint)
REFERENCE_PATH = "kite/reference_path"
LAPS = "kite/laps"
CRASHES = "kite/crashes"
PLANT_CONFIG = "kite/plant_config"   # the plant's PlantConfig as JSON (std_msgs/String, latched), once at start-up
RUN = "rto/run"                      # the optimizer's run description as JSON (std_msgs/String, latched)
RECORDED = "kite/recorded"           # a lossless recorder's acknowledgement (std_msgs/Header: written through stamp)
MARKERS = "kite/markers"             # kite_viz (kite_rto.tools.viz): the 3-D scene, visualization_msgs/MarkerArray

ALL = (CLOCK, STATE, POSITION, TENSION, WIND, WIND_ESTIMATE, STEERING, SETPOINTS, STATUS, SYNC, MANUAL_SETPOINTS,
       REFERENCE_PATH, LAPS, CRASHES, MARKERS, PLANT_CONFIG, RUN, RECORDED)
"""Every topic of the graph (relative names)."""


def graph_name(topic: str) -> str:
    """The topic's name inside its graph, ``/kite/state`` for ``kite/state`` (the tools' and MCAP channels' name)."""
    return "/" + topic.lstrip("/")


def relative(name: str) -> str:
    """The relative name of a topic given as the tools take it (``/kite/state`` or ``kite/state``)."""
    return name.lstrip("/")
