"""Print the messages of a kite_rto topic, laid out like ``ros2 topic echo`` (for pip installs without ros2cli).

``python -m kite_rto.tools.echo /kite/state [--once | --count N] [--timeout S] [--namespace NS]`` (console script
``kite_echo``). Topic names are the graph's (``/kite/state``); with ``--namespace /kite2`` (or ``--ros-args -r
__ns:=/kite2``) they resolve in that graph (``/kite2/kite/state``).
The message type and QoS come from the project's topic table (:data:`kite_rto.tools.record.TOPICS`), so no
type argument is needed; ``--list`` prints the table. Messages are separated by ``---``; Ctrl-C ends quietly.
Exit code 0, or 1 when ``--timeout`` passed without the requested messages, 2 for an unknown topic.
"""
from __future__ import annotations

import argparse
import math
import re
import sys
import time

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from ..nodes.namespace import add_namespace_option, tool_ros_args
from ..nodes.topics import graph_name, relative
from .mcap_writer import type_name
from .record import TOPICS, subscriber_qos, topic_type

__all__ = ["to_yaml", "run_cli", "main"]

_PLAIN = re.compile(r"^[A-Za-z_/][A-Za-z0-9_./ ()-]*$")
_YAML_WORDS = {"true", "false", "yes", "no", "on", "off", "null", "~", "y", "n"}


def _scalar(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return ".nan"
        if math.isinf(v):
            return ".inf" if v > 0 else "-.inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, (bytes, bytearray)):           # byte / uint8[] fields
        return str(v[0]) if len(v) == 1 else "[" + ", ".join(str(b) for b in v) + "]"
    s = str(v)
    if _PLAIN.match(s) and s.lower() not in _YAML_WORDS and not s.endswith(" "):
        return s
    return "'" + s.replace("'", "''") + "'"


def _is_message(v) -> bool:
    return hasattr(v, "get_fields_and_field_types")


def _lines(value, indent: str) -> list:
    """YAML lines of a message's fields at ``indent``."""
    out = []
    for name in value.get_fields_and_field_types():
        out += _field(name, getattr(value, name), indent)
    return out


def _field(name: str, v, indent: str) -> list:
    if _is_message(v):
        return [f"{indent}{name}:"] + _lines(v, indent + "  ")
    if isinstance(v, (bytes, bytearray)) or not hasattr(v, "__len__") or isinstance(v, str):
        return [f"{indent}{name}: {_scalar(v)}"]
    items = list(v)                                  # list, tuple, array.array, numpy array
    if not items:
        return [f"{indent}{name}: []"]
    out = [f"{indent}{name}:"]
    for item in items:
        if _is_message(item):
            sub = _lines(item, indent + "  ")
            out.append(f"{indent}- {sub[0].lstrip()}" if sub else f"{indent}- {{}}")
            out += sub[1:]
        else:
            out.append(f"{indent}- {_scalar(item.item() if hasattr(item, 'item') else item)}")
    return out


def to_yaml(msg) -> str:
    """The message as ``ros2 topic echo`` lays it out (YAML block style, one field per line)."""
    return "\n".join(_lines(msg, "")) + "\n"


def run_cli(make_node, argv, done, duration: float = 0.0, poll: float = 0.1) -> int:
    """Init rclpy with the ROS arguments in ``argv``, build ``make_node()``, spin until ``done()`` is true,
    ``duration`` (node-clock seconds, 0 = no limit) has passed, Ctrl-C or shutdown; return 0 (130 never: for a
    viewer Ctrl-C is the normal way out). Output that goes to a closed pipe ends the command quietly."""
    rclpy.init(args=argv)
    node = None
    try:
        node = make_node()
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        start = None
        while rclpy.ok(context=node.context) and not done():
            executor.spin_once(timeout_sec=poll)
            if duration:
                now = node.get_clock().now().nanoseconds
                if now == 0:                        # sim time not received yet
                    continue
                start = now if start is None else start
                if (now - start) * 1e-9 >= duration:
                    break
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except BrokenPipeError:
        sys.stderr.close()                          # nothing more can be said on a closed pipe
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def parse_args(argv):
    ap = argparse.ArgumentParser(prog="kite_echo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("topic", nargs="?", help=f"one of: {', '.join(graph_name(t) for t in sorted(TOPICS))}")
    ap.add_argument("--once", action="store_true", help="print one message and exit")
    ap.add_argument("--count", type=int, default=0, help="exit after N messages")
    ap.add_argument("--timeout", type=float, default=0.0,
                    help="give up (exit code 1) after S wall seconds without the requested messages")
    ap.add_argument("--list", action="store_true", help="list the kite_rto topics and their types")
    ap.add_argument("--use-sim-time", action="store_true", help="use /clock for the node's clock")
    add_namespace_option(ap)
    return ap.parse_args(argv)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(remove_ros_args(["kite_echo", *argv])[1:])
    if args.list or not args.topic:
        if not args.list:
            print("kite_echo: name a topic, one of:", file=sys.stderr)
        for topic, (cls, qos) in sorted(TOPICS.items()):
            print(f"{graph_name(topic):24s} {type_name(cls)}", file=sys.stdout if args.list else sys.stderr)
        return 0 if args.list else 2
    try:
        topic = relative(args.topic)
        cls = topic_type(topic)
    except KeyError as exc:
        print(f"kite_echo: {exc.args[0]}", file=sys.stderr)
        return 2
    wanted = 1 if args.once else max(args.count, 0)
    seen = [0]
    t0 = time.monotonic()

    def callback(msg):
        if wanted and seen[0] >= wanted:
            return
        sys.stdout.write(to_yaml(msg) + "---\n")
        sys.stdout.flush()
        seen[0] += 1

    def make_node():
        overrides = [Parameter("use_sim_time", value=True)] if args.use_sim_time else []
        node = Node("kite_echo", parameter_overrides=overrides)
        node.create_subscription(cls, topic, callback, subscriber_qos(topic, 100))
        return node

    def done():
        if wanted and seen[0] >= wanted:
            return True
        return bool(args.timeout) and time.monotonic() - t0 > args.timeout

    code = run_cli(make_node, tool_ros_args("kite_echo", argv, args.namespace), done)
    if code == 0 and args.timeout and wanted and seen[0] < wanted:
        print(f"kite_echo: {seen[0]} of {wanted} messages on {args.topic} within {args.timeout:g} s",
              file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main())
