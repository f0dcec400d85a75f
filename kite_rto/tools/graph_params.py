"""The parameters of every node in the graph, fetched through the nodes' standard parameter services.

:class:`GraphParameters` looks at the graph every ``period`` wall seconds; for each node it has not asked yet (not
itself, not hidden ``_`` names) it calls ``<node>/list_parameters`` and then ``<node>/get_parameters``, and hands
``(node full name, {parameter: value text})`` to a callback. ``kite_record`` writes each answer as an MCAP
``Metadata`` record, so a recording says with which parameters its nodes ran (as they were when the recorder first
saw each node).
"""
from __future__ import annotations

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.clock import Clock, ClockType

__all__ = ["GraphParameters", "value_text"]


def value_text(v) -> str:
    """An ``rcl_interfaces/ParameterValue`` as text: ``0.02``, ``400``, ``true``, ``lockstep``, ``[30.0, 40.0]``."""
    t = v.type
    if t == ParameterType.PARAMETER_BOOL:
        return "true" if v.bool_value else "false"
    if t == ParameterType.PARAMETER_INTEGER:
        return str(v.integer_value)
    if t == ParameterType.PARAMETER_DOUBLE:
        return repr(float(v.double_value))
    if t == ParameterType.PARAMETER_STRING:
        return v.string_value
    if t == ParameterType.PARAMETER_BYTE_ARRAY:
        return "[" + ", ".join(str(int.from_bytes(b, "little") if isinstance(b, bytes) else b)
                               for b in v.byte_array_value) + "]"
    if t == ParameterType.PARAMETER_BOOL_ARRAY:
        return "[" + ", ".join("true" if b else "false" for b in v.bool_array_value) + "]"
    if t == ParameterType.PARAMETER_INTEGER_ARRAY:
        return "[" + ", ".join(str(i) for i in v.integer_array_value) + "]"
    if t == ParameterType.PARAMETER_DOUBLE_ARRAY:
        return "[" + ", ".join(repr(float(x)) for x in v.double_array_value) + "]"
    if t == ParameterType.PARAMETER_STRING_ARRAY:
        return "[" + ", ".join(v.string_array_value) + "]"
    return "<not set>"


class GraphParameters:
    """Asks each node of the graph for its parameters once (see the module doc).

    Args:
        node: the asking rclpy node (graph queries, clients, a steady timer).
        on_parameters: called as ``on_parameters(full_name, {name: value text})`` once per node answered.
        period: wall seconds between looks at the graph.
        tries: looks at a node's services before giving up on it (its services are discovered after it).
    """

    def __init__(self, node, on_parameters, period: float = 1.0, tries: int = 20):
        self.node, self.on_parameters, self.tries = node, on_parameters, tries
        self._pending: dict = {}            # full name -> [list client, get client, tries left, busy]
        self.done: dict = {}                # full name -> {name: text}
        self.given_up: set = set()          # nodes without reachable parameter services
        self._own = self._full(node.get_namespace(), node.get_name())
        self._timer = node.create_timer(period, self.look, clock=Clock(clock_type=ClockType.STEADY_TIME))

    @staticmethod
    def _full(ns: str, name: str) -> str:
        return f"{ns.rstrip('/')}/{name}"

    def look(self) -> None:
        """One look at the graph: ask the new nodes of this node's namespace (its graph: another graph may share
        the domain), retry those whose services were not there yet."""
        own_ns = self.node.get_namespace()
        for name, ns in self.node.get_node_names_and_namespaces():
            full = self._full(ns, name)
            if (ns != own_ns or full == self._own or name.startswith("_") or full in self.done or full in self._pending
                    or full in self.given_up):
                continue
            self._pending[full] = [self.node.create_client(ListParameters, f"{full}/list_parameters"),
                                   self.node.create_client(GetParameters, f"{full}/get_parameters"), self.tries, False]
        for full, entry in list(self._pending.items()):
            lister, getter, left, busy = entry
            if busy:
                continue
            if not (lister.service_is_ready() and getter.service_is_ready()):
                entry[2] = left - 1
                if entry[2] <= 0:
                    self.given_up.add(full)
                    self._pending.pop(full)
                continue
            entry[3] = True
            lister.call_async(ListParameters.Request(depth=0)).add_done_callback(
                lambda f, full=full: self._listed(full, f))

    def _listed(self, full: str, future) -> None:
        entry = self._pending.get(full)
        res = future.result()
        if entry is None or res is None:
            return
        names = sorted(res.result.names)
        entry[1].call_async(GetParameters.Request(names=names)).add_done_callback(
            lambda f: self._got(full, names, f))

    def _got(self, full: str, names: list, future) -> None:
        res = future.result()
        if full not in self._pending or res is None:
            return
        values = {n: value_text(v) for n, v in zip(names, res.values)}
        self.done[full] = values
        self._pending.pop(full, None)       # its clients stay: destroying one inside its own callback is unsafe
        self.on_parameters(full, values)
