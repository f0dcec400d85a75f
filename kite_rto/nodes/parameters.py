"""Declared node parameters: :class:`ParamSpec` (default, description, unit, range, runtime or read-only) and
:func:`declare_params`, which declares them, checks start-up values and validates (and applies) runtime changes
with rejection reasons that name parameter, value and what was expected.
"""
from __future__ import annotations

import array
import difflib
import math
from dataclasses import dataclass

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

from ..kite.params import ParameterError

__all__ = ["ParamSpec", "READ_ONLY", "declare_params"]


@dataclass(frozen=True)
class ParamSpec:
    """A declared parameter: name, default, description, unit, allowed values, and whether it may change live.

    ``low``/``high`` bound a number, or every element of a list-valued parameter; ``choices`` lists the allowed
    strings (of a string, or of each element of a list of strings); a list-valued parameter has the default's
    length unless ``any_length`` (then one or more elements); ``unit`` is shown with the description ("" for flags, names and counts without a unit);
    ``runtime`` marks a parameter the running node applies when it is set (``ros2 param set``); every other one
    is read-only while the node runs.
    """

    name: str
    default: object
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    unit: str = ""
    runtime: bool = False
    any_length: bool = False

    @property
    def doc(self) -> str:
        """The description with its unit: the descriptor's text, the YAML comment, the README table."""
        return f"{self.description} [{self.unit}]" if self.unit else self.description

    def expected(self) -> str:
        """What a valid value is, in words (used in every rejection message and in the README table)."""
        unit = f" {self.unit}" if self.unit else ""
        d = self.default
        if isinstance(d, bool):
            return "true or false"
        if isinstance(d, (list, tuple)) and d and isinstance(d[0], str):
            return "a list of distinct names, each one of " + ", ".join(map(repr, self.choices))
        if self.choices:
            return "one of " + ", ".join(map(repr, self.choices))
        if isinstance(d, str):
            return "a non-empty string"
        rng = ("" if self.low is None and self.high is None
               else f"[{_bound(self.low, '-inf')}, {_bound(self.high, 'inf')}]")
        if isinstance(d, (list, tuple)):
            count = "1 or more" if self.any_length else str(len(d))
            return f"a list of {count} numbers" + (f", each in {rng}" if rng else "") + unit
        kind = "an integer" if isinstance(d, int) else "a number"
        return f"{kind} in {rng}{unit}" if rng else kind + unit

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(description=self.doc, read_only=not self.runtime)
        d.additional_constraints = self.expected() + ("" if self.runtime else f"; {READ_ONLY}")
        if self.low is not None and self.high is not None:
            if isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(self.low), to_value=float(self.high))]
            elif isinstance(self.default, int) and not isinstance(self.default, bool):
                d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)]
        return d

    def check(self, value) -> None:
        """Raise :class:`ParameterError` naming the parameter, the value and what was expected."""
        if not self._valid(value):
            if isinstance(value, array.array):
                value = value.tolist()
            shown = "<empty or not set>" if value is None else repr(value)   # `-p name:=[]` arrives as NOT_SET
            raise ParameterError(f"parameter {self.name} = {shown}: expected {self.expected()}")

    def _valid(self, value) -> bool:
        d = self.default
        if isinstance(d, bool):
            return isinstance(value, bool)
        if isinstance(d, str):
            if not isinstance(value, str):
                return False
            return value in self.choices if self.choices else value != ""
        if isinstance(d, (list, tuple)) and d and isinstance(d[0], str):
            return (isinstance(value, (list, tuple)) and len(value) > 0 and len(set(value)) == len(value)
                    and all(isinstance(v, str) and v in self.choices for v in value))
        if isinstance(d, (list, tuple)):
            if not isinstance(value, (list, tuple, array.array)):
                return False
            size_ok = len(value) > 0 if self.any_length else len(value) == len(d)
            return size_ok and all(self._number_ok(v, float) for v in value)
        return self._number_ok(value, int if isinstance(d, int) else float)

    def _number_ok(self, value, kind) -> bool:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if kind is int and not isinstance(value, int):
            return False
        return (math.isfinite(value) and (self.low is None or value >= self.low)
                and (self.high is None or value <= self.high))


def _bound(x, unbounded: str) -> str:
    """A range bound as written in messages: integers as they are, floats in their shortest form (1e+07)."""
    if x is None:
        return unbounded
    if isinstance(x, int):
        return str(x)
    return f"{x:g}" if float(f"{x:g}") == x else repr(x)


READ_ONLY = "read-only while running: restart the node to change it"
"""The reason given when a parameter that is not ``runtime`` is set on a running node."""


def declare_params(node, specs, apply=None, cross_check=None) -> dict:
    """Declare every spec on ``node``, check the values, and validate (and apply) later changes.

    Start-up: each parameter is declared with its descriptor (dynamic typing, so a wrong type reaches our
    check; ``read_only`` unless ``spec.runtime``), checked by :meth:`ParamSpec.check`, then ``cross_check(values)``
    runs on all of them. Raises :class:`ParameterError` for the first bad value, or for a value given to a
parameter the node does not have (a typo; ``run_node``: exit code 2).

    Running: a set-parameters request is checked the same way (then ``cross_check`` on the values it would leave)
    and, if every parameter is ``runtime`` and valid, ``apply(changes)`` is called (it must raise
    :class:`ParameterError` before changing anything when it refuses) and the returned dict is updated in
    place; otherwise the request is rejected with a reason that names parameter, value and what was expected,
    or says the parameter is read-only while running.
    """
    specs = tuple(specs)
    if any(s.runtime for s in specs) and apply is None:
        raise TypeError("declare_params: runtime parameters need an apply callback")
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
        s.check(value)
        values[s.name] = _normalized(s, value)
    _refuse_unknown(node, specs)
    if cross_check is not None:
        cross_check(dict(values))
    _watch_params(node, {s.name: s for s in specs}, values, apply, cross_check)
    return values


def _refuse_unknown(node, specs) -> None:
    """Raise :class:`ParameterError` for a value given to ``node`` (``-p``, a params file) that it does not have.

    rclpy silently ignores an override of an undeclared parameter, so a typo (``-p w_reff:=20.0``) would run with
    the default. Parameters rclpy itself declares (``use_sim_time``, ...) and QoS overrides are accepted.
    """
    known = {s.name for s in specs}
    unknown = sorted(n for n in node._parameter_overrides
                     if n not in known and not node.has_parameter(n) and not n.startswith("qos_overrides."))
    if not unknown:
        return
    name = unknown[0]
    close = difflib.get_close_matches(name, sorted(known), n=1)
    hint = f"did you mean {close[0]}?" if close else f"its parameters are: {', '.join(sorted(known))}"
    value = node._parameter_overrides[name].value
    value = value.tolist() if isinstance(value, array.array) else value
    more = f" (also unknown: {', '.join(unknown[1:])})" if len(unknown) > 1 else ""
    raise ParameterError(f"unknown parameter {name} = {value!r}: node {node.get_name()} has no such parameter; "
                         f"{hint}{more}")


def _normalized(spec: ParamSpec, value):
    """A checked value in the type of the default (an integer given for a float parameter becomes a float)."""
    if isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(spec.default, (list, tuple)):
        return [v if isinstance(v, str) else float(v) for v in value]
    return value


def _watch_params(node, specs: dict, values: dict, apply, cross_check) -> None:
    """Register the runtime validation of :func:`declare_params` on ``node``."""

    def reason(parameter_list) -> str | None:
        """Why this set-parameters request is refused, or None (parameters not in ``specs`` pass through)."""
        merged = dict(values)
        for p in parameter_list:
            s = specs.get(p.name)
            if s is None:
                continue
            value = p.value.tolist() if isinstance(p.value, array.array) else p.value
            if not s.runtime:
                return f"parameter {p.name} = {value!r}: {READ_ONLY}"
            try:
                s.check(value)
            except ParameterError as err:
                return str(err)
            merged[p.name] = _normalized(s, value)
        if cross_check is not None:
            try:
                cross_check(merged)
            except (ParameterError, ValueError) as err:
                return str(err)
        return None

    def on_set(parameter_list) -> SetParametersResult:
        why = reason(parameter_list)
        if why is not None:
            return SetParametersResult(successful=False, reason=why)
        changes = {p.name: _normalized(specs[p.name], p.value) for p in parameter_list if p.name in specs}
        if changes:
            try:
                apply(dict(changes))
            except (ParameterError, ValueError) as err:
                return SetParametersResult(successful=False, reason=str(err))
            values.update(changes)
            node.get_logger().info("parameters changed: " + ", ".join(f"{k} = {v!r}" for k, v in changes.items()))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)

    # rclpy refuses a read-only parameter, and a value outside a descriptor's range, before any on-set callback
    # runs, with its own wording. The public setters are wrapped so that every refusal of a declared parameter
    # reads like the start-up check (parameter, value, expected) and read-only ones say how to change them.
    set_one_by_one, set_atomically = node.set_parameters, node.set_parameters_atomically

    def set_parameters(parameter_list):
        out = []
        for p in parameter_list:
            why = reason([p])
            out.append(SetParametersResult(successful=False, reason=why) if why is not None
                       else set_one_by_one([p])[0])
        return out

    def set_parameters_atomically(parameter_list):
        why = reason(parameter_list)
        return SetParametersResult(successful=False, reason=why) if why is not None \
            else set_atomically(parameter_list)

    node.set_parameters = set_parameters
    node.set_parameters_atomically = set_parameters_atomically
