"""The ROS graph as the pure core sees it: the publishers of a topic as :class:`~kite_rto.runtime.sources.Publisher`
(fully qualified node name and endpoint GID), and the controller's look at its inputs (:class:`InputWatch`).

rclpy offers no per-message sender to a subscription callback spun by the events executor (a callback taking the
message info makes rclpy 7.1's ``EventsExecutor.spin_once`` fail with ``SystemError``, and the SingleThreadedExecutor's
message info has no ``publisher_gid``): who publishes comes from the graph, ``get_publishers_info_by_topic``
(about 0.1 ms per call here).
"""
from __future__ import annotations

from rclpy.clock import Clock, ClockType

from ..runtime.sources import Publisher, SourceWatch, node_name
from .topics import CLOCK, SETPOINTS, STATE, SYNC

__all__ = ["publishers_of", "controller_inputs", "InputWatch", "GRAPH_PERIOD"]

GRAPH_PERIOD = 0.5
"""Wall s between two looks at the graph (several publishers of an input are warned about within this)."""

_TWO_PLANTS = ("more than one plant in this graph (or a killed one DDS still lists)? The controller keeps steering "
               "the kite it flies")


def publishers_of(node, topic: str) -> list[Publisher]:
    """The publishers of ``topic`` in ``node``'s view of the graph (a relative name is in the node's namespace: only
    its own graph's publishers count)."""
    return [Publisher(node_name(i.node_name, i.node_namespace), bytes(i.endpoint_gid).hex())
            for i in node.get_publishers_info_by_topic(topic)]


def controller_inputs(source: str | None, sync: bool) -> dict:
    """The controller's inputs that must have one publisher, and what several of them mean (the warning's end)."""
    inputs = {STATE: _TWO_PLANTS, CLOCK: _TWO_PLANTS,
              SETPOINTS: (f"only {source}'s setpoints apply (setpoint_source), none while another node publishes"
                          if source else "setpoints from more than one node: the latest at each sample applies "
                          "(parameter setpoint_source restricts them to one node)")}
    if sync:
        inputs[SYNC] = "more than one optimizer synchronizing this controller"
    return inputs


class InputWatch:
    """The controller's look at the graph every :data:`GRAPH_PERIOD` wall s (a steady timer on ``node``).

    Warns, throttled, while an input has several publishers (:class:`~kite_rto.runtime.sources.SourceWatch`), lets
    ``loop`` (the :class:`~kite_rto.runtime.steering_loop.SteeringLoop`) publish a pending path or setpoint summary,
    and calls ``resubscribe()`` once the configured setpoint source publishes /rto/setpoints alone again after
    messages were ignored (a new subscription gets its latched setpoints).
    """

    def __init__(self, node, loop, source: str | None, resubscribe):
        self.node, self.loop, self.resubscribe = node, loop, resubscribe
        self.watch = SourceWatch(node.get_logger())
        self.inputs = {node.resolve_topic_name(topic): meaning        # in the node's namespace, /clock as remapped
                       for topic, meaning in controller_inputs(source, loop.sync).items()}
        node.create_timer(GRAPH_PERIOD, self.check, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def check(self) -> None:
        for topic, meaning in self.inputs.items():
            self.watch.update(topic, publishers_of(self.node, topic), meaning)
        self.loop.housekeeping()
        inbox = self.loop.inbox
        if inbox.refresh and inbox.guard.clean():
            inbox.refresh = False
            self.resubscribe()
