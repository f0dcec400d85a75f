"""Record the kite_rto topics to an MCAP file that Foxglove, PlotJuggler and ``ros2 bag`` read.

``python -m kite_rto.tools.record --out run.mcap [--duration S] [--log-time sim|wall] [--topics /kite/state ...]``
(console script ``kite_record``; ``ros2 run kite_rto kite_record ...`` after colcon build). Records every project
topic (``TOPICS`` below: the topics of :mod:`kite_rto.nodes.topics` with their message types and the QoS their
publishers offer) until ``--duration`` wall seconds have passed or Ctrl-C / SIGTERM; the file is always closed
and valid.

The file follows the MCAP ``ros2`` profile as ``ros2 bag record -s mcap`` writes it: one schema per message type
(encoding ``ros2msg``, the type's ``.msg`` text followed by every dependency's text after a ``====...`` and
``MSG: pkg/Type`` line), one channel per topic (message encoding ``cdr``, ``offered_qos_profiles`` metadata), and
messages as the CDR bytes that arrived on the wire (raw subscriptions: nothing is deserialized or re-encoded).

Log time = simulated time (``--log-time sim``, the default): a message's header stamp, or the latest ``/clock`` for
one without (rule in :mod:`kite_rto.tools.record_time`), so Foxglove's and PlotJuggler's timeline is the flight's;
publish time = wall receive time (ns). ``--log-time wall`` logs the wall receive time instead, as ``ros2 bag
record`` without ``--use-sim-time``. Each sample is recorded once (the lockstep plant's re-publications of a sample
are skipped); samples that never arrived are counted and reported (the ``wrote`` line and a ``kite_record_gaps``
metadata record: per topic the number missing and the largest gap). The parameters of every node in the graph are
stored as MCAP ``Metadata`` records, one per node (name = the node's full name, e.g. ``/plant``; fetched through its
``get_parameters`` service when the recorder first sees it), and one ``kite_record`` record says how the file was
written.
"""
from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from mcap.writer import CompressionType, Writer
from mcap_ros2 import __version__ as MCAP_ROS2_VERSION
from nav_msgs.msg import Path
from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import UInt32
from visualization_msgs.msg import MarkerArray

from ..nodes import topics as T
from ..nodes.namespace import add_namespace_option, namespace_args
from ..nodes.interface import LAP_HISTORY, LATCHED, MEASUREMENTS, RELIABLE_10
from ..nodes.spin import request_exit, run_node
from .graph_params import GraphParameters
from .record_time import LOG_TIME_MODES, PER_SAMPLE, SampleGaps, SimLogTime

__all__ = ["TOPICS", "topic_type", "type_name", "message_definition", "generated_definition", "qos_yaml",
           "McapRecording", "RecordNode", "main"]

TOPICS: dict = {
    T.CLOCK: (Clock, MEASUREMENTS),
    T.STATE: (JointState, MEASUREMENTS),
    T.POSITION: (PointStamped, MEASUREMENTS),
    T.TENSION: (WrenchStamped, MEASUREMENTS),
    T.WIND: (Vector3Stamped, MEASUREMENTS),
    T.WIND_ESTIMATE: (Vector3Stamped, MEASUREMENTS),
    T.STEERING: (JointState, MEASUREMENTS),
    T.REFERENCE_PATH: (Path, LATCHED),
    T.LAPS: (JointState, LAP_HISTORY),
    T.CRASHES: (UInt32, LATCHED),
    T.SETPOINTS: (JointState, LATCHED),
    T.STATUS: (DiagnosticArray, RELIABLE_10),
    T.SYNC: (JointState, MEASUREMENTS),
    T.MANUAL_SETPOINTS: (JointState, RELIABLE_10),
    T.MARKERS: (MarkerArray, RELIABLE_10),
}
"""Every project topic -> (message class, QoS its publisher offers). A test checks it covers ``nodes.topics``."""


def topic_type(topic: str):
    """Message class of a project topic; ``KeyError`` naming the known topics if it is not one."""
    try:
        return TOPICS[topic][0]
    except KeyError:
        raise KeyError(f"{topic} is not a kite_rto topic; known: "
                       f"{', '.join(T.graph_name(t) for t in sorted(TOPICS))}") from None


def subscriber_qos(topic: str, depth: int = 10) -> QoSProfile:
    """QoS for a subscriber that must match the publisher: reliable; transient-local for latched topics."""
    offered = TOPICS[topic][1]
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(depth, offered.depth),
                      reliability=ReliabilityPolicy.RELIABLE, durability=offered.durability)


# ----------------------------------------------------------------------------------- message definitions
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


# ------------------------------------------------------------------------------------------- MCAP writer
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


# ------------------------------------------------------------------------------------------ recorder node
class RecordNode:
    """Raw subscriptions on ``node``, one per topic (QoS matched to its publishers, deep queues), that write every
    message to a :class:`McapRecording` as it arrives: log time by :class:`~kite_rto.tools.record_time.SimLogTime`
    (``log_time`` = ``sim`` or ``wall``), publish time = wall receive time; re-published samples skipped."""

    def __init__(self, node, recording: McapRecording, topics, depth: int = 1000, log_time: str = "sim"):
        self.node = node
        self.recording = recording
        self.started = time.monotonic()
        self.clock = SimLogTime({t: type_name(TOPICS[t][0]) for t in topics}, log_time)
        for topic in topics:
            cls, offered = TOPICS[topic]
            recording.add_topic(topic, cls, offered)
            node.create_subscription(cls, topic, self._writer_for(topic), subscriber_qos(topic, depth), raw=True)

    def _writer_for(self, topic: str):
        write = self.recording.write
        now = time.time_ns
        log_time = self.clock.log_time

        def callback(data):     # one argument: the events executor does not pass message info
            wall = now()
            t = log_time(topic, data, wall)
            if t is not None:
                write(topic, data, t, wall)
        return callback


def _make_node(args):
    class _Recorder(Node):
        def __init__(self):
            super().__init__("kite_record")
            self.recording = McapRecording(args.out, use_files=not args.no_msg_files)
            self.rec = RecordNode(self, self.recording, args.topics, log_time=args.log_time)
            self.recording.add_metadata("kite_record", {
                "log_time": args.log_time, "publish_time": "wall receive time",
                "topics": " ".join(map(T.graph_name, args.topics)),
                "started_wall": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "ros_domain_id": os.environ.get("ROS_DOMAIN_ID", "0"), "namespace": self.get_namespace(),
                "duplicates": "re-published samples of " + " ".join(sorted(PER_SAMPLE)) + " skipped"})
            if not args.no_params:
                self.params = GraphParameters(self, self.recording.add_metadata)
            self.get_logger().info(f"recording {len(args.topics)} topics of {self.get_namespace()} to {args.out}"
                                   + (f" for {args.duration:g} s" if args.duration else " until Ctrl-C"))
            if args.duration:
                self.create_timer(0.1, self._check, clock=RclClock(clock_type=ClockType.STEADY_TIME))

        def _check(self):
            if time.monotonic() - self.rec.started >= args.duration:
                request_exit(self, 0)

        def destroy_node(self):
            gaps = self.rec.clock.gaps
            missing = gaps.report()
            self.recording.add_metadata("kite_record_gaps", {      # how complete the file is, for its readers
                T.graph_name(t): f"{n} missing; largest gap {a} .. {b} ns"
                for t, (n, (a, b)) in missing.items()} or {"all": "no sample missing"})
            self.recording.close()
            counts = ", ".join(f"{T.graph_name(t)} {n}" for t, n in self.recording.counts.items() if n)
            dup = sum(self.rec.clock.duplicates.values())
            nodes = len(self.params.done) if hasattr(self, "params") else 0
            print(f"[kite_record] wrote {self.recording.total} messages to {args.out}"
                  + (f" ({counts})" if counts else "")
                  + f"; log time {args.log_time}; {dup} re-published samples skipped; "
                  + SampleGaps.summary(missing, T.graph_name) + f"; parameters of {nodes} nodes",
                  file=sys.stderr, flush=True)
            return super().destroy_node()

    return _Recorder()


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_record", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="MCAP file to write (e.g. run.mcap)")
    ap.add_argument("--duration", type=float, default=0.0, help="wall seconds to record (default: until Ctrl-C)")
    ap.add_argument("--topics", nargs="+", default=[T.graph_name(t) for t in sorted(TOPICS)], metavar="TOPIC",
                    help="topics to record, e.g. /kite/state (default: all kite_rto topics of the graph)")
    ap.add_argument("--log-time", choices=LOG_TIME_MODES, default="sim",
                    help="sim (default): log time = the message's simulated stamp (or the latest /clock); "
                         "wall: the wall receive time")
    ap.add_argument("--no-params", action="store_true",
                    help="do not store the nodes' parameters as metadata records")
    ap.add_argument("--no-msg-files", action="store_true",
                    help="build the schemas from the message classes instead of the installed .msg files")
    add_namespace_option(ap)
    args = ap.parse_args(argv)
    args.topics = [T.relative(t) for t in args.topics]
    return args


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(remove_ros_args(["kite_record", *argv])[1:])
    unknown = [t for t in args.topics if t not in TOPICS]
    if unknown:
        print(f"kite_record: not kite_rto topics: {', '.join(map(T.graph_name, unknown))}; known: "
              f"{', '.join(T.graph_name(t) for t in sorted(TOPICS))}",
              file=sys.stderr)
        return 2
    try:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        open(args.out, "ab").close()
    except OSError as exc:
        print(f"kite_record: cannot write {args.out}: {exc}", file=sys.stderr)
        return 1
    # Ctrl-C / SIGTERM: run_node's handlers (kite_rto.nodes.stop_signals) end the spin loop between two messages,
    # never in the middle of an MCAP write; the recording is then closed by destroy_node.
    return run_node(lambda: _make_node(args), ["kite_record", *argv, *namespace_args(args.namespace)], events=True)


if __name__ == "__main__":
    sys.exit(main())
