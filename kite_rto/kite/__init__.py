"""The simulated kite: parameters, the Erhard model (written once, in CasADi), the wind and the plant simulation.

Never imports rclpy. Everything else in kite_rto builds on this package.
"""
from .model import STATE_NAMES, KiteModel
from .params import KiteParams, ParameterError, check_range

__all__ = ["KiteModel", "KiteParams", "ParameterError", "STATE_NAMES", "check_range"]
