"""Writing an MCAP file in the ``ros2`` profile as ``ros2 bag record -s mcap`` writes it (:class:`McapRecording`),
with each message type's ``ros2msg`` schema (:func:`message_definition`) and each channel's
``offered_qos_profiles`` metadata (:func:`qos_yaml`). ``kite_record`` (:mod:`kite_rto.tools.record`) feeds it the
CDR bytes that arrive on the wire; ``kite_foxglove`` serves the same schemas.

One schema per message type (encoding ``ros2msg``, the type's ``.msg`` text followed by every dependency's text
after a ``====...`` and ``MSG: pkg/Type`` line), one channel per topic (message encoding ``cdr``), messages as CDR
bytes (nothing is deserialized or re-encoded).
"""
from __future__ import annotations

import importlib
import os
import re
import sys

from mcap.writer import CompressionType, Writer
from mcap_ros2 import __version__ as MCAP_ROS2_VERSION
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from ..nodes import topics as T

__all__ = ["type_name", "message_definition", "generated_definition", "generated_definition_text", "qos_yaml",
           "McapRecording"]


def type_name(cls) -> str:
    """``sensor_msgs/msg/JointState`` for the class ``sensor_msgs.msg.JointState``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"


_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
               "int64", "uint64", "string"}
# A field type at the start of a line (rosbag2's rule for finding the dependencies of a .msg text).
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


def _share_dirs() -> list:
    dirs = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in (sys.prefix, sys.base_prefix):
        if prefix not in dirs:
            dirs.append(prefix)
    return [os.path.join(p, "share") for p in dirs]


def _msg_file_text(package: str, name: str) -> str | None:
    for share in _share_dirs():
        path = os.path.join(share, package, "msg", name + ".msg")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as f:
                return f.read()
    return None


def _class_of(pkg_type: str):
    package, name = pkg_type.split("/")[0], pkg_type.split("/")[-1]
    return getattr(importlib.import_module(f"{package}.msg"), name)


_IDL_TO_MSG = {"double": "float64", "float": "float32", "boolean": "bool", "octet": "byte", "long double": "float64"}


def _msg_field_type(idl: str) -> str:
    """rclpy's field type string (``sequence<double>``, ``double[3]``, ``std_msgs/Header``) -> .msg syntax."""
    m = re.fullmatch(r"sequence<(.+?)(?:, (\d+))?>", idl)
    if m:
        return _msg_field_type(m.group(1)) + (f"[<={m.group(2)}]" if m.group(2) else "[]")
    m = re.fullmatch(r"(.+)\[(\d+)\]", idl)
    if m:
        return _msg_field_type(m.group(1)) + f"[{m.group(2)}]"
    return _IDL_TO_MSG.get(idl, idl)


def generated_definition_text(cls) -> str:
    """The ``.msg`` text of one type rebuilt from the class (fields only: constants and comments are not needed
    to decode and are left out)."""
    return "".join(f"{_msg_field_type(t)} {name}\n" for name, t in cls.get_fields_and_field_types().items())


def _definition_text(pkg_type: str, use_files: bool) -> str:
    package, name = pkg_type.split("/")[0], pkg_type.split("/")[-1]
    text = _msg_file_text(package, name) if use_files else None
    return text if text is not None else generated_definition_text(_class_of(pkg_type))


def _dependencies(text: str, package: str) -> list:
    deps = set()
    for m in _FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def _full_text(cls, use_files: bool) -> str:
    root = f"{cls.__module__.split('.')[0]}/{cls.__name__}"
    seen: set = set()

    def append(pkg_type: str, depth: int) -> str:
        if depth <= 0:
            raise RuntimeError(f"message definition of {root} nests too deep")
        text = _definition_text(pkg_type, use_files)
        out = text
        for dep in _dependencies(text, pkg_type.split("/")[0]):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + "=" * 80 + "\nMSG: " + dep + "\n" + append(dep, depth - 1)
        return out

    return append(root, 50)


def message_definition(cls) -> str:
    """Full ``ros2msg`` definition of ``cls`` as rosbag2 writes it: the ``.msg`` file of the type, then each
    dependency (found recursively, sorted, each once) after a separator line and ``MSG: pkg/Type``. The ``.msg``
    files are looked up in ``$AMENT_PREFIX_PATH/*/share`` and the Python prefix's ``share`` (where the
    ``ros-jazzy-*`` wheels put them); a type without a file is rebuilt from its class."""
    return _full_text(cls, use_files=True)


def generated_definition(cls) -> str:
    """The same as :func:`message_definition`, built from the message classes only (no ``.msg`` files)."""
    return _full_text(cls, use_files=False)


def qos_yaml(qos: QoSProfile) -> str:
    """``offered_qos_profiles`` channel metadata: a YAML list with one profile, rosbag2's (metadata version 9)
    layout; durations 0 = unspecified."""
    zero = "\n    sec: 0\n    nsec: 0"
    return (f"- history: keep_last\n  depth: {qos.depth}\n"
            f"  reliability: {'reliable' if qos.reliability == ReliabilityPolicy.RELIABLE else 'best_effort'}\n"
            f"  durability: {'transient_local' if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL else 'volatile'}\n"
            f"  deadline:{zero}\n  lifespan:{zero}\n  liveliness: automatic\n"
            f"  liveliness_lease_duration:{zero}\n  avoid_ros_namespace_conventions: false\n")


class McapRecording:
    """An MCAP file in the ``ros2`` profile: :meth:`add_topic` once per topic, then :meth:`write` CDR bytes.

    Built on ``mcap.writer.Writer``, the writer inside ``mcap_ros2.writer.Writer``: that wrapper re-encodes message
    objects with its own encoder and registers channels without metadata, while here the CDR bytes come from the
    wire (rclpy raw subscriptions; or ``rclpy.serialization.serialize_message``) and each channel needs the
    ``offered_qos_profiles`` metadata that ``ros2 bag`` reads. Reading back: ``mcap_ros2.reader``.
    """

    def __init__(self, path, use_files: bool = True):
        self.path = str(path)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"kite_rto record (mcap-ros2-support {MCAP_ROS2_VERSION})")
        self._use_files = use_files
        self._schemas: dict = {}
        self.channels: dict = {}
        self.counts: dict = {}
        self._sequence = 0
        self.metadata = 0
        self.closed = False

    def add_topic(self, topic: str, cls, qos: QoSProfile) -> int:
        """Register the topic's channel (and its type's schema); return the channel id. The channel is named by the
        graph's name of the topic (``/kite/state`` for ``kite/state``, whatever the recorded graph's namespace)."""
        name = type_name(cls)
        if name not in self._schemas:
            text = message_definition(cls) if self._use_files else generated_definition(cls)
            self._schemas[name] = self._writer.register_schema(name=name, encoding="ros2msg", data=text.encode())
        cid = self._writer.register_channel(topic=T.graph_name(topic), message_encoding="cdr",
                                            schema_id=self._schemas[name],
                                            metadata={"offered_qos_profiles": qos_yaml(qos)})
        self.channels[topic] = cid
        self.counts[topic] = 0
        return cid

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int | None = None) -> None:
        """Append one CDR-serialized message (``log_time``/``publish_time`` in ns)."""
        self._sequence += 1
        self._writer.add_message(channel_id=self.channels[topic], log_time=log_time, data=data,
                                 publish_time=log_time if publish_time is None else publish_time,
                                 sequence=self._sequence)
        self.counts[topic] += 1

    def add_metadata(self, name: str, values: dict) -> None:
        """One MCAP ``Metadata`` record: ``name`` and string key/values (ignored once the file is closed)."""
        if self.closed:
            return
        self._writer.add_metadata(name, {str(k): str(v) for k, v in values.items()})
        self.metadata += 1

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if not self.closed:
            self.closed = True
            try:
                self._writer.finish()
            finally:
                self._file.close()

    @property
    def total(self) -> int:
        return sum(self.counts.values())
