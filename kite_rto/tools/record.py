"""Record the kite_rto topics to an MCAP file that Foxglove, PlotJuggler and ``ros2 bag`` read.

``python -m kite_rto.tools.record --out run.mcap [--duration S] [--log-time sim|wall] [--topics /kite/state ...]``
(console script ``kite_record``; ``ros2 run kite_rto kite_record ...`` after colcon build). Records every project
topic (``TOPICS`` below: the topics of :mod:`kite_rto.nodes.topics` with their message types and the QoS their
publishers offer) until ``--duration`` wall seconds have passed or Ctrl-C / SIGTERM; the file is always closed
and valid.

The file follows the MCAP ``ros2`` profile as ``ros2 bag record -s mcap`` writes it (:mod:`kite_rto.tools.mcap_writer`,
whose names this module re-exports): messages are the CDR bytes that arrived on the wire (raw subscriptions: nothing
is deserialized or re-encoded).

Log time = simulated time (``--log-time sim``, the default): a message's header stamp, or the latest ``/clock`` for
one without (rule in :mod:`kite_rto.tools.record_time`), so Foxglove's and PlotJuggler's timeline is the flight's;
publish time = wall receive time (ns). ``--log-time wall`` logs the wall receive time instead, as ``ros2 bag
record`` without ``--use-sim-time``. ``--lossless``: the recorder acknowledges on ``/kite/recorded`` the simulated time
up to which it has written every sample of the plant's topics, and a lockstep plant waits for it
(:mod:`kite_rto.runtime.recorder_gate`): nothing is lost however busy the machine (the real-time plant never
waits). Each sample is recorded once (the lockstep plant's re-publications of a sample are skipped); samples that
never arrived are counted and reported (the ``wrote`` line and a ``kite_record_gaps`` metadata record: per topic
the number missing and the largest gap). The parameters of every node in the graph are
stored as MCAP ``Metadata`` records, one per node (name = the node's full name, e.g. ``/plant``; fetched through its
``get_parameters`` service when the recorder first sees it), one ``kite_record`` record says how the file was
written, and a ``kite_rto_run`` record (:data:`RUN_METADATA`) holds the last run description heard on ``/rto/run``
(the optimizer's settings and plant, JSON), so that ``kite_report --mcap`` judges the recording against its run.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, Vector3Stamped, WrenchStamped
from nav_msgs.msg import Path
from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header, String, UInt32
from visualization_msgs.msg import MarkerArray

from ..nodes import topics as T
from ..nodes.namespace import add_namespace_option, namespace_args
from ..nodes.interface import LAP_HISTORY, LATCHED, MEASUREMENTS, RELIABLE_10, ns_to_stamp
from ..nodes.spin import request_exit, run_node
from ..runtime.recorder_gate import WINDOW_SAMPLES
from .graph_params import GraphParameters
from .mcap_writer import McapRecording, generated_definition, message_definition, qos_yaml, type_name
from .record_time import LOG_TIME_MODES, PER_SAMPLE, SampleGaps, SimLogTime

__all__ = ["TOPICS", "RUN_METADATA", "topic_type", "type_name", "message_definition", "generated_definition",
           "qos_yaml", "McapRecording", "RecordNode", "main"]

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
    T.PLANT_CONFIG: (String, LATCHED),
    T.RUN: (String, LATCHED),
    T.RECORDED: (Header, RELIABLE_10),
}
"""Every project topic -> (message class, QoS its publisher offers). A test checks it covers ``nodes.topics``."""

PLANT_TOPICS = (T.CLOCK, T.STATE, T.POSITION, T.TENSION, T.WIND)
"""The plant's per-sample topics: a lossless recorder acknowledges the samples it has written of every one of them."""

RUN_METADATA = "kite_rto_run"
"""Name of the metadata record that holds the last ``/rto/run`` description heard (key ``description``: JSON)."""


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


# ------------------------------------------------------------------------------------------ recorder node
class RecordNode:
    """Raw subscriptions on ``node``, one per topic (QoS matched to its publishers, deep queues), that write every
    message to a :class:`McapRecording` as it arrives: log time by :class:`~kite_rto.tools.record_time.SimLogTime`
    (``log_time`` = ``sim`` or ``wall``), publish time = wall receive time; re-published samples skipped. The last
    ``/rto/run`` message is kept for :meth:`run_description`. ``ack(stamp_ns)``: called when every sample of the
    plant's topics through ``stamp_ns`` has been written (at least every tenth of the plant's window; None: never)."""

    def __init__(self, node, recording: McapRecording, topics, depth: int = 1000, log_time: str = "sim", ack=None):
        self.node = node
        self.recording = recording
        self.started = time.monotonic()
        self.clock = SimLogTime({t: type_name(TOPICS[t][0]) for t in topics}, log_time)
        self._last_run = None               # CDR bytes of the last /rto/run message
        self._ack = ack
        self._acked = None                  # the stamp last acknowledged (ns)
        self._plant_topics = [t for t in PLANT_TOPICS if t in topics]
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
                if self._ack is not None and topic in PLANT_TOPICS:
                    self.acknowledge(final=False)
            if topic == T.RUN:
                self._last_run = data
        return callback

    def acknowledge(self, final: bool = True) -> None:
        """Acknowledge the samples written through the oldest latest stamp of the plant's topics, when it has moved
        on by a tenth of the plant's window (``final``: whenever it has moved on at all)."""
        stamps = [self.clock.last_stamp(t) for t in self._plant_topics]
        if not stamps or None in stamps:
            return
        through = min(stamps)
        period = self.clock.gaps.period_ns(self._plant_topics[0]) or 0
        step = 1 if final else max(1, period * (WINDOW_SAMPLES // 10))
        if self._acked is None or through - self._acked >= step:
            self._acked = through
            self._ack(through)

    def run_description(self) -> str | None:
        """The JSON text of the last ``/rto/run`` message recorded (None: none came)."""
        return None if self._last_run is None else deserialize_message(self._last_run, String).data


def _make_node(args):
    class _Recorder(Node):
        def __init__(self):
            super().__init__("kite_record")
            self.recording = McapRecording(args.out, use_files=not args.no_msg_files)
            ack = None
            if args.lossless:
                self.pub_ack = self.create_publisher(Header, T.RECORDED, RELIABLE_10)
                ack = self._acknowledge
            self.rec = RecordNode(self, self.recording, args.topics, log_time=args.log_time, ack=ack)
            self.recording.add_metadata("kite_record", {
                "log_time": args.log_time, "publish_time": "wall receive time",
                "lossless": "yes: a lockstep plant waits for this recorder" if args.lossless else "no",
                "topics": " ".join(map(T.graph_name, args.topics)),
                "started_wall": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "ros_domain_id": os.environ.get("ROS_DOMAIN_ID", "0"), "namespace": self.get_namespace(),
                "duplicates": "re-published samples of " + " ".join(sorted(PER_SAMPLE)) + " skipped"})
            if not args.no_params:
                self.params = GraphParameters(self, self.recording.add_metadata)
            self.get_logger().info(f"recording {len(args.topics)} topics of {self.get_namespace()} to {args.out}"
                                   + (f" for {args.duration:g} s" if args.duration else " until Ctrl-C"))
            steady = RclClock(clock_type=ClockType.STEADY_TIME)
            if args.duration:
                self.create_timer(0.1, self._check, clock=steady)
            if args.lossless:       # what the step rule holds back, acknowledged within 0.1 s
                self.create_timer(0.1, self.rec.acknowledge, clock=steady)

        def _acknowledge(self, stamp_ns: int) -> None:
            self.pub_ack.publish(Header(stamp=ns_to_stamp(stamp_ns), frame_id=self.get_fully_qualified_name()))

        def _check(self):
            if time.monotonic() - self.rec.started >= args.duration:
                request_exit(self, 0)

        def destroy_node(self):
            run = self.rec.run_description()
            if run is not None:                                     # what the recorded run is, for its report
                self.recording.add_metadata(RUN_METADATA, {"description": run})
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
    ap.add_argument("--lossless", action="store_true",
                    help="a lockstep plant waits for this recorder, so that it loses no sample however busy the "
                         "machine (acknowledgements on /kite/recorded; the real-time plant never waits)")
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
