"""Pure computational core of kite_rto: never imports rclpy."""
from .model import KiteModel, STATE_NAMES
from .params import KiteParams, ParameterError, check_range

__all__ = ["KiteModel", "KiteParams", "ParameterError", "STATE_NAMES", "check_range"]
