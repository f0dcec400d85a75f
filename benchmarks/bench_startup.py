"""Optimizer start-up as an operator sees it: wall time from process start to the first answer of
``get_parameters``, to the first ``/rto/status`` (and its phases), and to the first ``/rto/setpoints``.

    .venv/bin/python benchmarks/bench_startup.py                 # cold (empty start-up cache) and warm, 1 run each
    .venv/bin/python benchmarks/bench_startup.py --repeats 3

Cold: ``KITE_RTO_CACHE`` points at a new empty directory, so the model optimum and the privileged directions are
computed; warm: the same directory again, so they are read back (:mod:`kite_rto.rto.startup_cache`). Prints a table.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import GetParameters
from sensor_msgs.msg import JointState

from kite_rto.nodes.interface import LATCHED, RELIABLE_10
from kite_rto.tools.graph import isolated_ros_env, node_command


def one_start(env: dict, node) -> dict:
    """Start an optimizer and measure; returns wall seconds of each event and the status phases seen."""
    phases, got = [], {}
    sub_s = node.create_subscription(DiagnosticArray, "/rto/status",
                                     lambda m: phases.append(m.status[0].message), RELIABLE_10)
    sub_c = node.create_subscription(JointState, "/rto/setpoints", lambda m: got.setdefault("setpoints", 1), LATCHED)
    client = node.create_client(GetParameters, "/optimizer/get_parameters")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.monotonic()
        proc = subprocess.Popen(node_command("optimizer", {"db": os.path.join(tmp, "rto.sqlite")}), env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        out, future = {}, None
        try:
            while time.monotonic() - t0 < 300 and not {"setpoints", "status", "params"} <= set(out):
                if "params" not in out:
                    if future is None and client.service_is_ready():
                        future = client.call_async(GetParameters.Request(names=["n_iter"]))
                    if future is not None and future.done():
                        out["params"] = time.monotonic() - t0
                rclpy.spin_once(node, timeout_sec=0.01)
                if phases and "status" not in out:
                    out["status"] = time.monotonic() - t0
                if got and "setpoints" not in out:
                    out["setpoints"] = time.monotonic() - t0
        finally:
            proc.terminate()
            proc.wait(30)
    node.destroy_subscription(sub_s)
    node.destroy_subscription(sub_c)
    node.destroy_client(client)
    out["phases"] = list(dict.fromkeys(p for p in phases if p.startswith("starting")))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=1, help="runs of each of cold and warm")
    args = ap.parse_args(argv)
    env = isolated_ros_env(int(os.environ.get("ROS_DOMAIN_ID", 88)))
    rclpy.init()
    node = rclpy.create_node("bench_startup")
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env["KITE_RTO_CACHE"] = cache
        for label in ("cold", "warm"):
            runs = []
            for _ in range(args.repeats):
                if label == "cold":
                    subprocess.run(["rm", "-rf", os.path.join(cache, "startup")], check=True)
                runs.append(one_start(env, node))
            rows.append((label, runs))
    print(f"{'start':6} {'get_parameters s':>17} {'first status s':>15} {'first setpoints s':>18}  phases seen")
    for label, runs in rows:
        med = {k: statistics.median(r[k] for r in runs if k in r) if any(k in r for r in runs) else float("nan")
               for k in ("params", "status", "setpoints")}
        print(f"{label:6} {med['params']:17.2f} {med['status']:15.2f} {med['setpoints']:18.2f}  "
              f"{'; '.join(runs[0]['phases'])}")
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
