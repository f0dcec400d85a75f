"""Topic names of the kite_rto graph (SPEC §7)."""
from ..flight.steering_loop import SYNC_NAMES

__all__ = ["CLOCK", "STATE", "POSITION", "TENSION", "WIND", "STEERING", "SETPOINTS", "STATUS", "SYNC", "SYNC_NAMES",
           "REFERENCE_PATH", "LAPS", "CRASHES", "WIND_ESTIMATE", "MARKERS"]

CLOCK = "/clock"
STATE = "/kite/state"
POSITION = "/kite/position"
TENSION = "/kite/tension"
WIND = "/kite/wind"
WIND_ESTIMATE = "/kite/wind_estimate"
STEERING = "/kite/steering"
SETPOINTS = "/rto/setpoints"
STATUS = "/rto/status"
SYNC = "/rto/sync"
REFERENCE_PATH = "/kite/reference_path"
LAPS = "/kite/laps"
CRASHES = "/kite/crashes"
MARKERS = "/kite/markers"            # kite_viz (kite_rto.tools.viz): the 3-D scene, visualization_msgs/MarkerArray
