"""Shared node plumbing: QoS profiles, stamps, declared parameters, the ``main`` wrapper, and fast message I/O.

Fast message I/O (for the lockstep hot path, where rclpy's per-message Python cost dominates): a
:class:`MessageTemplate` serializes a stamped message whose strings and sequence lengths never change by patching
the stamp and the float64 values into the RMW's own serialization of an example message (verified byte for byte
against ``rclpy.serialization.serialize_message`` at construction, else it falls back to building the message);
:func:`joint_state_from_raw` reads stamp and positions from a raw (serialized) ``sensor_msgs/JointState``. The
wire format, types and QoS are unchanged: subscribers see ordinary messages.
"""
from __future__ import annotations

import array
import math
import os
import struct
import sys
from dataclasses import dataclass

import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from ..kite.params import ParameterError

__all__ = ["RELIABLE_10", "MEASUREMENTS", "LATCHED", "ParamSpec", "READ_ONLY", "declare_params", "stamp_to_ns", "ns_to_stamp",
           "finite_floats", "run_node", "request_exit", "MessageTemplate", "cdr_serialize", "joint_state_from_raw"]

RELIABLE_10 = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""Measurements and steering: reliable, depth 10 (lockstep must not lose a sample)."""
MEASUREMENTS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
"""Publishers of per-sample topics (measurements, steering): reliable with a deep history (20 s of samples at
50 Hz), so that a subscriber stalled by CPU load (a recorder, a monitor) catches up instead of losing samples.
Subscribers stay at ``RELIABLE_10``: the depth is not part of QoS compatibility."""
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Setpoints: a late joiner gets the current value."""


@dataclass(frozen=True)
class ParamSpec:
    """A declared parameter: name, default, description, unit, allowed values, and whether it may change live.

    ``low``/``high`` bound a number, or every element of a list-valued parameter; ``choices`` lists the allowed
    strings; ``unit`` is shown with the description ("" for flags, names and counts without a unit);
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
        if self.choices:
            return "one of " + ", ".join(map(repr, self.choices))
        if isinstance(d, str):
            return "a non-empty string"
        rng = ("" if self.low is None and self.high is None
               else f"[{_bound(self.low, '-inf')}, {_bound(self.high, 'inf')}]")
        if isinstance(d, (list, tuple)):
            return f"a list of {len(d)} numbers" + (f", each in {rng}" if rng else "") + unit
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
        if isinstance(d, (list, tuple)):
            return (isinstance(value, (list, tuple, array.array)) and len(value) == len(d)
                    and all(self._number_ok(v, float) for v in value))
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
    runs on all of them. Raises :class:`ParameterError` for the first bad value (``run_node``: exit code 2).

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
    if cross_check is not None:
        cross_check(dict(values))
    _watch_params(node, {s.name: s for s in specs}, values, apply, cross_check)
    return values


def _normalized(spec: ParamSpec, value):
    """A checked value in the type of the default (an integer given for a float parameter becomes a float)."""
    if isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(spec.default, (list, tuple)):
        return [float(v) for v in value]
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


EXECUTOR_ENV = "KITE_RTO_EXECUTOR"
"""Environment variable: ``single`` forces rclpy's SingleThreadedExecutor where :func:`run_node` would use the
events executor (``events``, the default for nodes that opt in)."""


def request_exit(node, code: int = 0) -> None:
    """Make the node's process exit with ``code`` once the current callback returns.

    Under :func:`run_node`'s events executor loop this only sets a flag (an exception escaping a callback would be
    logged as FATAL by the C++ executor); under ``rclpy.spin(node)`` or any other executor it raises
    :class:`SystemExit`, which propagates out of the spin call as before. Callbacks should return right after it.
    """
    if getattr(node, "_kite_run_loop", False):
        node._kite_exit_code = code
        return
    raise SystemExit(code)


def exit_requested(node) -> bool:
    """True once :func:`request_exit` was called for ``node`` under the events executor loop."""
    return getattr(node, "_kite_exit_code", None) is not None


def _events_executor(context):
    """rclpy's C++ events executor (Jazzy: ``rclpy.experimental``), or None when unavailable or disabled."""
    if os.environ.get(EXECUTOR_ENV, "events").strip().lower() in ("single", "singlethreaded", "default"):
        return None
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return None
    return EventsExecutor(context=context)


def _spin_events(node, executor) -> int:
    # The Jazzy backport's ``EventsExecutor.spin()`` holds the GIL while it waits and did not dispatch timers on
    # these machines (signals and other threads starve); ``spin_once`` with a timeout works: the GIL is released
    # while waiting, timers (also STEADY_TIME ones) fire, Ctrl-C raises KeyboardInterrupt here.
    node._kite_run_loop = True
    node._kite_exit_code = None
    executor.add_node(node)
    ok = node.context.ok
    spin_once = executor.spin_once
    try:
        while ok():
            spin_once(timeout_sec=0.25)
            if node._kite_exit_code is not None:
                return node._kite_exit_code
        return 0
    finally:
        try:
            executor.remove_node(node)
        except Exception:  # noqa: BLE001 - best effort at shutdown
            pass


def run_node(factory, args=None, *, events: bool = False) -> int:
    """Init rclpy, build the node with ``factory()``, spin, shut down; return the process exit code.

    A :class:`ParameterError` at construction is reported on stderr and gives exit code 2. With ``events=True``
    the node is spun by rclpy's C++ events executor (several times less overhead per callback than the
    SingleThreadedExecutor; no coroutine callbacks), unless ``KITE_RTO_EXECUTOR=single`` is set or it is not
    available; the node should then end with :func:`request_exit` rather than raising ``SystemExit``.
    """
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = factory()
        executor = _events_executor(node.context) if events else None
        if executor is not None:
            code = _spin_events(node, executor)
        else:
            rclpy.spin(node)
    except ParameterError as exc:
        print(f"[kite_rto] refusing to start: {exc}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        if rclpy.ok():
            raise
        # Ctrl-C shut rclpy down while a call into it was in flight: rclpy's C++ layer then raises a RuntimeError
        # (pybind11 "Unable to convert call argument ...") instead of ExternalShutdownException. A clean stop.
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


# ------------------------------------------------------------------------------------------ fast message I/O
_ENDIAN = {b"\x00\x01": "<", b"\x00\x00": ">"}     # CDR encapsulation: little / big endian, plain CDR
_SENTINEL_SEC, _SENTINEL_NSEC = 0x2A3B4C5D, 0x1E2F3A4B


class MessageTemplate:
    """Serialize ``build(stamp, values)`` fast for messages whose layout does not depend on the values.

    ``build(stamp: builtin_interfaces/Time, values: list[float]) -> message`` is the readable reference. At
    construction the template serializes ``build`` with sentinel stamp and values, finds where they sit in the
    bytes, and compiles one ``struct`` format (constant bytes + stamp + float64s). It is used only if, for test
    values, its bytes deserialize (``rclpy.serialization``, i.e. the RMW's own type support) to a message equal
    to ``build(...)``; otherwise :meth:`__call__` returns ``build(...)``'s message object. Either result can be
    given to ``Publisher.publish``. (The example is serialized by :func:`cdr_serialize` rather than rclpy's
    ``serialize_message``, because rmw_fastrtps leaves CDR alignment padding uninitialized there.)
    """

    def __init__(self, build, n_values: int):
        self.build = build
        self.n_values = n_values
        self._pack = None
        try:
            pack = self._compile()
            if pack is not None and self._verify(pack):
                self._pack = pack
        except Exception:  # noqa: BLE001 - any surprise: use the plain path
            self._pack = None

    @property
    def fast(self) -> bool:
        """True when the compiled serializer is in use."""
        return self._pack is not None

    def __call__(self, stamp_ns: int, values):
        """Serialized message (``bytes``) or, on the fallback path, the message object."""
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        if self._pack is not None:
            return self._pack(sec, nsec, *values)
        return self.build(Time(sec=sec, nanosec=nsec), list(values))

    def _compile(self):
        values = [math.ldexp(1.0 + (i + 1) / 64.0, -700 + 3 * i) for i in range(self.n_values)]
        ref = cdr_serialize(self.build(Time(sec=_SENTINEL_SEC, nanosec=_SENTINEL_NSEC), values))
        e = _ENDIAN.get(bytes(ref[:2]))
        if e is None:
            return None
        fields = [(ref.find(struct.pack(e + "iI", _SENTINEL_SEC, _SENTINEL_NSEC)), "iI", 8)]
        fields += [(ref.find(struct.pack(e + "d", v)), "d", 8) for v in values]
        offsets = [f[0] for f in fields]
        if min(offsets) < 0 or offsets != sorted(offsets):
            return None                 # not found, or not in argument order: use the fallback
        fmt, args, consts, pos = e, [], {}, 0
        names = ["sec", "nsec"] + [f"v{i}" for i in range(self.n_values)]
        k = 0
        for off, code, size in fields:
            if off < pos:
                return None
            if off > pos:
                fmt += f"{off - pos}s"
                consts[f"_c{len(consts)}"] = bytes(ref[pos:off])
                args.append(f"_c{len(consts) - 1}")
            fmt += code
            n = len(code)
            args += names[k:k + n]
            k += n
            pos = off + size
        if pos < len(ref):
            fmt += f"{len(ref) - pos}s"
            consts[f"_c{len(consts)}"] = bytes(ref[pos:])
            args.append(f"_c{len(consts) - 1}")
        ns = {"_p": struct.Struct(fmt).pack, **consts}
        binds = ", ".join(f"{c}={c}" for c in ["_p", *consts])
        src = f"def pack({', '.join(names)}, {binds}):\n    return _p({', '.join(args)})\n"
        exec(src, ns)  # noqa: S102 - source generated above from field offsets
        return ns["pack"]

    def _verify(self, pack) -> bool:
        tests = [(0, 0, [0.0] * self.n_values),
                 (1_234_567, 999_999_999, [(-1.0) ** i * (i + 0.1) * 1e3 for i in range(self.n_values)]),
                 (2**31 - 1, 5, [math.pi / (i + 1) for i in range(self.n_values)])]
        for sec, nsec, v in tests:
            data = pack(sec, nsec, *v)
            msg = self.build(Time(sec=sec, nanosec=nsec), list(v))
            if deserialize_message(data, type(msg)) != msg:
                return False
        return True


_PRIM = {"boolean": "?", "octet": "B", "char": "B", "uint8": "B", "int8": "b", "int16": "h", "uint16": "H",
         "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "float": "f", "double": "d"}


def cdr_serialize(msg) -> bytes:
    """Plain little-endian CDR (what Fast DDS and Cyclone DDS put on the wire for ROS 2 messages), zero padding.

    Covers primitives, strings, nested messages and unbounded sequences of those; raises ``TypeError`` for other
    field types (wstring, fixed arrays, bounded types are not needed here). :class:`MessageTemplate` checks the
    result against the RMW's deserializer before using it.
    """
    out = bytearray(b"\x00\x01\x00\x00")

    def align(n):
        out.extend(bytes(-(len(out) - 4) % n))

    def prim(code, value):
        size = struct.calcsize(code)
        align(size)
        out.extend(struct.pack("<" + code, value))

    def string(value):
        data = value.encode() + b"\x00"
        prim("I", len(data))
        out.extend(data)

    def write(typ, value):
        if typ in _PRIM:
            prim(_PRIM[typ], value)
        elif typ == "string":
            string(value)
        elif typ.startswith("sequence<") and typ.endswith(">") and "," not in typ:
            inner = typ[9:-1]
            prim("I", len(value))
            for v in value:
                write(inner, v)
        elif "/" in typ and "<" not in typ and "[" not in typ:
            for name, t in value.get_fields_and_field_types().items():
                write(t, getattr(value, name))
        else:
            raise TypeError(f"cdr_serialize: field type {typ!r} not supported")

    for name, t in msg.get_fields_and_field_types().items():
        write(t, getattr(msg, name))
    return bytes(out)


def _cdr_joint_state(raw: bytes):
    """(stamp ns, position tuple) from plain-CDR ``sensor_msgs/JointState`` bytes; None if not parseable."""
    e = _ENDIAN.get(bytes(raw[:2]))
    if e is None or len(raw) < 16:
        return None
    unpack = struct.unpack_from
    sec, nsec = unpack(e + "iI", raw, 4)
    (n,) = unpack(e + "I", raw, 12)                    # header.frame_id
    o = 16 + n
    o = 4 + ((o - 4 + 3) & ~3)
    (count,) = unpack(e + "I", raw, o)                  # name[]
    o += 4
    if count > len(raw):
        return None
    for _ in range(count):
        o = 4 + ((o - 4 + 3) & ~3)
        (n,) = unpack(e + "I", raw, o)
        o += 4 + n
    o = 4 + ((o - 4 + 3) & ~3)
    (count,) = unpack(e + "I", raw, o)                  # position[]
    o += 4
    if count > len(raw):
        return None
    if count:
        o = 4 + ((o - 4 + 7) & ~7)
    position = unpack(f"{e}{count}d", raw, o)
    return sec * 1_000_000_000 + nsec, position


def _cdr_reader_ok() -> bool:
    """Check :func:`_cdr_joint_state` against rclpy's deserializer on this RMW."""
    try:
        for stamp, frame, names, pos in ((0, "", [], []), (3_000_000_123, "anchor", ["theta", "phi", "psi"],
                                                              [0.1, -0.2, 3.0]),
                                         (7, "ab", ["delta"], [0.5]), (2**31 - 1, "abcde", ["a", "bcdefg"], [1e300])):
            msg = JointState(name=names, position=pos, velocity=[1.0] * len(pos))
            msg.header.stamp = ns_to_stamp(stamp)
            msg.header.frame_id = frame
            if _cdr_joint_state(serialize_message(msg)) != (stamp, tuple(pos)):
                return False
        return True
    except (struct.error, TypeError, ValueError):
        return False


_CDR_READER_OK = None


def joint_state_from_raw(raw: bytes) -> tuple[int, tuple]:
    """Stamp (integer ns) and positions of a raw ``sensor_msgs/JointState`` (a ``raw=True`` subscription's bytes).

    Reads plain CDR directly (checked once against rclpy's deserializer); anything else is deserialized by rclpy.
    Raises ``ValueError`` for bytes that are not a JointState.
    """
    global _CDR_READER_OK
    if _CDR_READER_OK is None:
        _CDR_READER_OK = _cdr_reader_ok()
    if _CDR_READER_OK:
        try:
            r = _cdr_joint_state(raw)
        except struct.error:
            r = None
        if r is not None:
            return r
    try:
        msg = deserialize_message(raw, JointState)
    except Exception as exc:  # noqa: BLE001 - rclpy raises various errors for garbage
        raise ValueError(f"not a sensor_msgs/JointState: {exc}") from exc
    return stamp_to_ns(msg.header.stamp), tuple(msg.position)
