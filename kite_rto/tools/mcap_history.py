"""Read an MCAP recording of a kite_rto run (``kite_record``, ``demo --record``) back into what the report uses:
the flown samples, laps, setpoints and optimizer status, the run's description, and the GMA history rebuilt from
/rto/status (with the description in its meta, so that the report judges the recording against its own plant and
floor)."""
from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from ..flight.path import Setpoints
from ..flight.shape import shape_from_setpoints
from ..nodes import topics as T
from ..nodes.interface import stamp_to_ns
from ..rto.run import RUN_KEY, RunDescription
from .record import RUN_METADATA, TOPICS

__all__ = ["read_mcap", "history_from_mcap"]


def read_mcap(path) -> SimpleNamespace:
    """The data of a recording that the reports use.

    Returns ``samples`` = (t, theta, phi) arrays from /kite/state (stamps, s), ``laps`` (dicts of the
    /kite/laps fields plus ``t_end``), ``setpoints`` = list of (sim t, c rad) from /rto/setpoints (sim t = stamp of
    the last sample recorded before it), ``status`` = list of (sim t, key/values) of the optimizer's /rto/status,
    ``reference`` = (theta, phi) of the last /kite/reference_path (or None), ``crashes``, ``topics`` (counts) and
    ``run``: the run's description as JSON text, from the ``kite_rto_run`` metadata record or else the last /rto/run
    message (None: the recording holds none).
    """
    wanted = [T.STATE, T.LAPS, T.SETPOINTS, T.STATUS, T.REFERENCE_PATH, T.CRASHES, T.RUN]
    t, theta, phi = [], [], []
    data = SimpleNamespace(laps=[], setpoints=[], status=[], reference=None, crashes=0, topics={}, run=None)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is not None:
            data.topics = {ch.topic: summary.statistics.channel_message_counts.get(cid, 0)
                           for cid, ch in summary.channels.items()} if summary.statistics else {}
        # file order = arrival order: the same sequence whether log times are simulated (a restarted plant starts
        # again at 0) or wall receive times
        for _schema, channel, message in reader.iter_messages(topics=[T.graph_name(w) for w in wanted],
                                                              log_time_order=False):
            topic = T.relative(channel.topic)       # channels carry the graph's names, /kite/state
            if topic == T.STATE:
                state = deserialize_message(message.data, JointState)
                ns, pos = stamp_to_ns(state.header.stamp), state.position
                if not t or ns * 1e-9 > t[-1]:
                    t.append(ns * 1e-9)
                    theta.append(pos[0])
                    phi.append(pos[1])
                continue
            msg = deserialize_message(message.data, TOPICS[topic][0])
            now = t[-1] if t else 0.0
            if topic == T.LAPS:
                lap = dict(zip(msg.name, msg.position))
                lap["t_end"] = stamp_to_ns(msg.header.stamp) * 1e-9
                data.laps.append(lap)
            elif topic == T.SETPOINTS:
                values = dict(zip(msg.name, msg.position))
                data.setpoints.append((now, np.array([values.get(n, math.nan) for n in Setpoints.names()])))
            elif topic == T.STATUS:
                for st in msg.status:
                    if st.name == "kite_rto/optimizer":
                        data.status.append((now, {kv.key: kv.value for kv in st.values}))
            elif topic == T.REFERENCE_PATH and msg.poses:
                p = np.array([[q.pose.position.x, q.pose.position.y, q.pose.position.z] for q in msg.poses])
                data.reference = (np.arctan2(np.hypot(p[:, 1], p[:, 2]), p[:, 0]), np.arctan2(p[:, 1], p[:, 2]))
            elif topic == T.CRASHES:
                data.crashes = max(data.crashes, int(msg.data))
            elif topic == T.RUN:
                data.run = msg.data
        for record in reader.iter_metadata():
            if record.name == RUN_METADATA and "description" in record.metadata:
                data.run = record.metadata["description"]
    data.samples = (np.array(t), np.array(theta), np.array(phi))
    return data


def _parse_deg(text: str):
    """``"(30.00, 42.00, 6.50) deg"`` -> array in rad (None if it does not parse)."""
    try:
        return np.radians([float(x) for x in text.replace("deg", "").strip().strip("()").split(",")])
    except (AttributeError, ValueError):
        return None


def history_from_mcap(data: SimpleNamespace):
    """Rebuild what the report needs of the optimizer's history from a recording's /rto/status and
    /rto/setpoints: c_0 (the first setpoints), per finished iteration the measured cost and constraint, c_{k+1}
    (0.01 deg resolution, as published) and the decision, the experiments that finished while recording (id,
    purpose, iteration, sim-time end = start of the next one), and in ``meta`` the run's description (under
    ``RUN_KEY``; none when the recording holds none; ``ValueError`` when it is not a description). None if the
    recording has no finished iteration."""
    iterations = {}
    experiments = []                                     # [id, purpose, iteration, t_start]
    done = []                                            # experiments_done of each status
    for _, kv in data.status:
        try:
            done.append(int(kv.get("experiments_done", "")))
        except ValueError:
            pass
        try:
            n = int(kv.get("iteration", 0))
        except ValueError:
            continue
        c_next = _parse_deg(kv.get("c_next_deg"))
        if n >= 1 and n not in iterations and c_next is not None:
            try:
                cost = float(kv["measured_cost_kN"])
                g = float(kv["measured_constraint_m"])
            except (KeyError, ValueError):
                cost, g = math.nan, math.nan
            iterations[n] = SimpleNamespace(k=n - 1, c_next=shape_from_setpoints(c_next), cost=cost,
                                            constraints=np.array([g]),
                                            decision=kv.get("decision", ""))
        exp = kv.get("experiment")
        if exp and (not experiments or experiments[-1][0] != exp):
            try:
                t_start = float(kv.get("experiment_t_start", "nan"))
            except ValueError:
                t_start = math.nan
            try:
                it = int(re.match(r"k(\d+)", exp).group(1))      # k<k>-... or an operator's k<k>m<n>-...
            except (ValueError, AttributeError):
                it = -1
            experiments.append([exp, kv.get("purpose", ""), it, t_start])
    if not iterations:
        return None
    if data.setpoints:
        c0 = data.setpoints[0][1]
    else:
        c0 = next((_parse_deg(kv.get("setpoints_deg")) for _, kv in data.status
                   if kv.get("experiment", "").startswith("k0-")), None)
    if c0 is None:
        return None
    t_last = float(data.samples[0][-1]) if len(data.samples[0]) else math.nan
    finished = done[-1] - done[0] if done else len(experiments) - 1    # the first one seen was running then
    exps = []
    for i, (exp_id, purpose, it, _t0) in enumerate(experiments[:max(finished, 0)]):
        t_end = experiments[i + 1][3] if i + 1 < len(experiments) else t_last
        exps.append((SimpleNamespace(request_id=exp_id, purpose=purpose, iteration=it),
                     SimpleNamespace(extra={"t_end": None if math.isnan(t_end) else t_end})))
    ordered = [iterations[n] for n in sorted(iterations)]
    # in GMA's shape coordinates, like an optimizer's History (the recording has setpoints)
    meta = {} if data.run is None else {RUN_KEY: RunDescription.from_json(data.run).to_dict()}
    return SimpleNamespace(c0=shape_from_setpoints(np.asarray(c0, dtype=float)), iterations=ordered,
                           experiments=exps, meta=meta)
