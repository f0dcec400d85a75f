"""Shared node plumbing: QoS profiles, stamps, declared parameters, and the ``main`` wrapper."""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..core.params import ParameterError

__all__ = ["RELIABLE_10", "LATCHED", "ParamSpec", "declare_params", "stamp_to_ns", "ns_to_stamp",
           "finite_floats", "run_node"]

RELIABLE_10 = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""Measurements and steering: reliable, depth 10 (lockstep must not lose a sample)."""
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Setpoints: a late joiner gets the current value."""


@dataclass(frozen=True)
class ParamSpec:
    """A declared parameter: name, default, description with units, and an optional numeric range."""

    name: str
    default: object
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(description=self.description)
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(map(str, self.choices))
        if self.low is not None and self.high is not None:
            if isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(self.low), to_value=float(self.high))]
            elif isinstance(self.default, int) and not isinstance(self.default, bool):
                d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)]
        return d

    def check(self, value) -> None:
        """Raise :class:`ParameterError` naming the parameter, the value and what was expected."""
        if isinstance(self.default, bool):
            if not isinstance(value, bool):
                raise ParameterError(f"parameter {self.name} = {value!r}: expected true or false")
            return
        if isinstance(self.default, (int, float)):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParameterError(f"parameter {self.name} = {value!r}: expected a number")
            if isinstance(self.default, int) and not isinstance(value, int):
                raise ParameterError(f"parameter {self.name} = {value!r}: expected an integer")
            if not math.isfinite(value):
                raise ParameterError(f"parameter {self.name} = {value!r}: expected a finite number")
            if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
                raise ParameterError(f"parameter {self.name} = {value!r}: expected a value in "
                                     f"[{self.low}, {self.high}]")
        if self.choices and value not in self.choices:
            raise ParameterError(f"parameter {self.name} = {value!r}: expected one of {', '.join(map(repr, self.choices))}")


def declare_params(node, specs) -> dict:
    """Declare every spec on ``node`` (dynamic typing so a wrong type reaches our check) and return checked values.

    Raises :class:`ParameterError` for the first bad value.
    """
    values = {}
    for s in specs:
        d = s.descriptor()
        d.dynamic_typing = True
        try:
            value = node.declare_parameter(s.name, s.default, d).value
        except (InvalidParameterValueException, InvalidParameterTypeException):
            override = node._parameter_overrides.get(s.name)  # rclpy's own range check refused it
            s.check(override.value if override is not None else None)
            raise
        if isinstance(s.default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        s.check(value)
        values[s.name] = value
    return values


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def ns_to_stamp(ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def finite_floats(values, n: int | None = None) -> list | None:
    """The values as floats if all are finite (and there are ``n`` of them when given), else None."""
    out = [float(v) for v in values]
    if (n is not None and len(out) != n) or not all(map(math.isfinite, out)):
        return None
    return out


def run_node(factory, args=None) -> int:
    """Init rclpy, build the node with ``factory()``, spin, shut down; return the process exit code.

    A :class:`ParameterError` at construction is reported on stderr and gives exit code 2.
    """
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = factory()
        rclpy.spin(node)
    except ParameterError as exc:
        print(f"[kite_rto] refusing to start: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
