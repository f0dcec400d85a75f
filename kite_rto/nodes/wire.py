"""Fast message I/O for the lockstep hot path, where rclpy's per-message Python cost dominates.

A :class:`MessageTemplate` serializes a stamped message whose strings and sequence lengths never change by putting
the stamp and the float64 values into the RMW's own serialization of an example message (one ``struct`` format;
verified against ``rclpy.serialization.deserialize_message`` at construction, else it logs a warning and builds
ordinary messages). A :class:`JointStateReader` reads stamp and positions from a raw (serialized)
``sensor_msgs/JointState``, checked once against rclpy's deserializer (else a logged fallback to it). The wire
format, types and QoS are unchanged: subscribers see ordinary messages. Why they stay (2-core machine, CPU time):
publishing the plant's five messages of a sample takes 17 us with templates and 62 us as rclpy messages, reading a
steering command 1.4 us and 11 us; lockstep with both nodes on templates met 50x real time, without them it did not
(see docs/benchmarks.md).
"""
from __future__ import annotations

import math
import struct
from operator import itemgetter

from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from .interface import ns_to_stamp, stamp_to_ns

__all__ = ["MessageTemplate", "JointStateReader", "cdr_serialize"]

_ENDIAN = {b"\x00\x01": "<", b"\x00\x00": ">"}     # CDR encapsulation: little / big endian, plain CDR
_SENTINEL_SEC, _SENTINEL_NSEC = 0x2A3B4C5D, 0x1E2F3A4B


class MessageTemplate:
    """Serialize ``build(stamp, values)`` fast for messages whose layout does not depend on the values.

    ``build(stamp: builtin_interfaces/Time, values: list[float]) -> message`` is the readable reference. At
    construction the template serializes ``build`` with sentinel stamp and values, finds where they sit in the
    bytes, and compiles one ``struct`` format (constant bytes + stamp + float64s) and the order of its arguments.
    It is used only if, for test values, its bytes deserialize (the RMW's own type support) to a message equal to
    ``build(...)``; otherwise ``logger`` gets a warning and :meth:`__call__` returns ``build(...)``'s message.
    Either result can be given to ``Publisher.publish``. (The example is serialized by :func:`cdr_serialize`
    rather than rclpy's ``serialize_message``, because rmw_fastrtps leaves CDR alignment padding uninitialized.)
    """

    def __init__(self, build, n_values: int, logger=None):
        self.build = build
        self.n_values = n_values
        self._pack = None
        why = None
        try:
            compiled = self._compile()
            if compiled is None:
                why = "stamp and values not found in order in the serialized example"
            elif not self._verify(*compiled):
                why = "its bytes do not deserialize to the built message"
            else:
                self._pack, self._order, self._consts = compiled
        except Exception as exc:  # noqa: BLE001 - any surprise: use the plain path, and say so
            why = f"{type(exc).__name__}: {exc}"
        if why is not None and logger is not None:
            logger.warning(f"message template for {getattr(build, '__name__', build)} not used ({why}): "
                           "publishing ordinary rclpy messages (slower)")

    @property
    def compiled(self) -> bool:
        """True when the compiled serializer is in use (False: the logged fallback)."""
        return self._pack is not None

    def __call__(self, stamp_ns: int, values):
        """Serialized message (``bytes``) or, on the fallback path, the message object."""
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        if self._pack is not None:
            return self._pack(*self._order((sec, nsec, *values) + self._consts))
        return self.build(Time(sec=sec, nanosec=nsec), list(values))

    def _compile(self):
        """``(pack, order, consts)``: ``pack(*order((sec, nsec, *values) + consts))`` gives the bytes; or None."""
        values = [math.ldexp(1.0 + (i + 1) / 64.0, -700 + 3 * i) for i in range(self.n_values)]
        ref = cdr_serialize(self.build(Time(sec=_SENTINEL_SEC, nanosec=_SENTINEL_NSEC), values))
        e = _ENDIAN.get(bytes(ref[:2]))
        if e is None:
            return None
        fields = [(ref.find(struct.pack(e + "iI", _SENTINEL_SEC, _SENTINEL_NSEC)), "iI", 8, (0, 1))]
        fields += [(ref.find(struct.pack(e + "d", v)), "d", 8, (2 + i,)) for i, v in enumerate(values)]
        offsets = [f[0] for f in fields]
        if min(offsets) < 0 or offsets != sorted(offsets):
            return None                 # not found, or not in argument order: use the fallback
        n_args = 2 + self.n_values
        fmt, order, consts, pos = e, [], [], 0
        for off, code, size, args in fields:
            if off < pos:
                return None
            if off > pos:               # constant bytes before this field
                fmt += f"{off - pos}s"
                order.append(n_args + len(consts))
                consts.append(bytes(ref[pos:off]))
            fmt += code
            order += args
            pos = off + size
        if pos < len(ref):
            fmt += f"{len(ref) - pos}s"
            order.append(n_args + len(consts))
            consts.append(bytes(ref[pos:]))
        getter = itemgetter(*order) if len(order) > 1 else (lambda a, i=order[0]: (a[i],))
        return struct.Struct(fmt).pack, getter, tuple(consts)

    def _verify(self, pack, order, consts) -> bool:
        tests = [(0, 0, [0.0] * self.n_values),
                 (1_234_567, 999_999_999, [(-1.0) ** i * (i + 0.1) * 1e3 for i in range(self.n_values)]),
                 (2**31 - 1, 5, [math.pi / (i + 1) for i in range(self.n_values)])]
        for sec, nsec, v in tests:
            data = pack(*order((sec, nsec, *v) + consts))
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

    def prim(code, value):
        size = struct.calcsize(code)
        out.extend(bytes(-(len(out) - 4) % size))          # align to the size, counted after the header
        out.extend(struct.pack("<" + code, value))

    def write(typ, value):
        if typ in _PRIM:
            prim(_PRIM[typ], value)
        elif typ == "string":
            data = value.encode() + b"\x00"
            prim("I", len(data))
            out.extend(data)
        elif typ.startswith("sequence<") and typ.endswith(">") and "," not in typ:
            prim("I", len(value))
            for v in value:
                write(typ[9:-1], v)
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
    return sec * 1_000_000_000 + nsec, unpack(f"{e}{count}d", raw, o)


READER_CHECKS = ((0, "", [], []), (3_000_000_123, "anchor", ["theta", "phi", "psi"], [0.1, -0.2, 3.0]),
                 (7, "ab", ["delta"], [0.5]), (2**31 - 1, "abcde", ["a", "bcdefg"], [1e300]))
"""(stamp ns, frame, names, positions) of the JointStates the fast reader is checked with."""


class JointStateReader:
    """Stamp (integer ns) and positions of a raw ``sensor_msgs/JointState`` (a ``raw=True`` subscription's bytes).

    Reads plain CDR directly when that agrees with rclpy's deserializer on this RMW for :data:`READER_CHECKS`
    (checked at construction; otherwise ``logger`` gets a warning and every message is deserialized by rclpy).
    """

    def __init__(self, logger=None):
        self.fast = self._check()
        if not self.fast and logger is not None:
            logger.warning("fast JointState reader disagrees with rclpy's deserializer on this RMW: "
                           "deserializing with rclpy (slower)")

    @staticmethod
    def _check() -> bool:
        try:
            for stamp, frame, names, pos in READER_CHECKS:
                msg = JointState(name=names, position=pos, velocity=[1.0] * len(pos))
                msg.header.stamp = ns_to_stamp(stamp)
                msg.header.frame_id = frame
                if _cdr_joint_state(serialize_message(msg)) != (stamp, tuple(pos)):
                    return False
            return True
        except (struct.error, TypeError, ValueError):
            return False

    def __call__(self, raw: bytes) -> tuple[int, tuple]:
        """Raises ``ValueError`` for bytes that are not a JointState."""
        if self.fast:
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
