"""The graph's namespace on the command line: the ROS arguments that put a process's nodes into one graph.

Two graphs share a ROS domain when each runs in its own namespace (``--ros-args -r __ns:=/kite2``): every topic
name of :mod:`.topics` is relative, so it resolves under the namespace. rclpy's time source subscribes the
*absolute* ``/clock`` whatever the namespace, so :func:`with_graph_clock` adds the remap rule ``/clock:=clock``
(:data:`GRAPH_CLOCK_RULE`) after the user's arguments: rcl expands a rule's replacement in the node's namespace,
so a node in ``/kite2`` with ``use_sim_time`` follows ``/kite2/clock``, its own plant's clock, and a node in the
root namespace ``/clock`` as before. rcl applies the first rule that matches a name, so a ``/clock:=...`` rule
the user gives wins over this one.
"""
from __future__ import annotations

import argparse
import re

__all__ = ["NamespaceError", "GRAPH_CLOCK_RULE", "check_namespace", "with_graph_clock", "namespace_args",
           "tool_ros_args", "add_namespace_option"]

GRAPH_CLOCK_RULE = "/clock:=clock"
"""Remap rule: the time source's ``/clock`` resolves to the graph's own clock (``<namespace>/clock``)."""



class NamespaceError(ValueError):
    """Not a fully qualified ROS namespace (the message names the value and what was expected). Imports nothing
    heavy, so a tool's ``--help`` stays instant."""


_NAMESPACE = re.compile(r"/|(/[A-Za-z_][A-Za-z0-9_]*)+")


def check_namespace(namespace: str) -> str:
    """``namespace`` if it is a fully qualified ROS namespace (``/`` or ``/kite2``, ``/field/kite_1``), else
    :class:`NamespaceError` naming it."""
    if not isinstance(namespace, str) or not _NAMESPACE.fullmatch(namespace):
        raise NamespaceError(f"namespace {namespace!r}: expected / or an absolute ROS namespace such as /kite2 "
                             "(segments of letters, digits and _, not starting with a digit)")
    return namespace


def with_graph_clock(argv) -> list:
    """``argv`` (as for ``rclpy.init``: program name first) followed by the rule :data:`GRAPH_CLOCK_RULE`."""
    return [*argv, "--ros-args", "-r", GRAPH_CLOCK_RULE]


def namespace_args(namespace: str | None) -> list:
    """The ROS arguments that put a node into ``namespace`` (none for None or ``/``)."""
    if namespace is None or check_namespace(namespace) == "/":
        return []
    return ["--ros-args", "-r", f"__ns:={namespace}"]


def tool_ros_args(prog: str, argv, namespace: str | None) -> list:
    """``rclpy.init`` arguments of a tool: its command line, its ``--namespace`` as ``-r __ns:=`` (a ``-r __ns:=``
    already in ``argv`` comes first and wins) and :data:`GRAPH_CLOCK_RULE`."""
    return with_graph_clock([prog, *argv, *namespace_args(namespace)])


def _namespace_type(text: str) -> str:
    try:
        return check_namespace(text)
    except NamespaceError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_namespace_option(parser: argparse.ArgumentParser) -> None:
    """``--namespace NS``: the graph to work with (same as ``--ros-args -r __ns:=NS``; default: the root)."""
    parser.add_argument("--namespace", type=_namespace_type, default=None, metavar="NS",
                        help="the graph's ROS namespace, e.g. /kite2 (same as --ros-args -r __ns:=NS; default: "
                             "the root namespace)")
