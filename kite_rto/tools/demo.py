"""Main job: fly the kite graph in lockstep simulated time and report.

Current stage (foundation): the plant node and the echo pilot (neutral steering) as two processes; the kite is
launched at theta = 30 deg, phi = 0, psi = 0 and must climb to the zenith equilibrium theta = atan(E).
"""
from __future__ import annotations

import argparse
import math
import sys
import time

from .graph import NodeProcess, isolated_ros_env


def parse_args(argv=None):
    ap = argparse.ArgumentParser(prog="kite_rto demo", description=__doc__)
    ap.add_argument("--duration", type=float, default=120.0, help="simulated seconds (default 120)")
    ap.add_argument("--seed", type=int, default=0, help="turbulence/noise seed (default 0)")
    ap.add_argument("--no-turbulence", action="store_true", help="steady wind")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    env = isolated_ros_env()
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from ..core.plant import PLANT_PARAMS
    from ..nodes.common import RELIABLE_10, stamp_to_ns

    rclpy.init()
    rec = Node("demo_recorder")
    samples = []
    rec.create_subscription(JointState, "/kite/state",
                            lambda m: samples.append((stamp_to_ns(m.header.stamp) * 1e-9, m.position[0])), RELIABLE_10)
    print(f"kite_rto demo: plant + neutral pilot, lockstep, {args.duration:.0f} s simulated, seed {args.seed}, "
          f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}")
    pilot = NodeProcess("echo_pilot", {}, env=env)
    plant = NodeProcess("plant", {"duration": args.duration, "seed": args.seed,
                                  "turbulence": not args.no_turbulence}, env=env)
    wall0 = time.monotonic()
    next_report = 10.0
    try:
        while plant.alive():
            rclpy.spin_once(rec, timeout_sec=0.1)
            if samples and samples[-1][0] >= next_report:
                t, th = samples[-1]
                print(f"  t = {t:6.1f} s   theta = {math.degrees(th):6.2f} deg")
                next_report += 10.0
        for _ in range(20):
            rclpy.spin_once(rec, timeout_sec=0.05)
    except KeyboardInterrupt:
        print("interrupted")
    finally:
        pilot.stop()
        code = plant.stop()
        rec.destroy_node()
        rclpy.try_shutdown()
    wall = time.monotonic() - wall0
    if not samples:
        print("no samples received", file=sys.stderr)
        return 1
    tail = [th for t, th in samples if t >= samples[-1][0] - 30.0]
    mean = math.degrees(sum(tail) / len(tail))
    expected = math.degrees(math.atan(PLANT_PARAMS.E))
    ok = abs(mean - expected) < 2.0
    print(f"\nsamples received: {len(samples)}; simulated {samples[-1][0]:.1f} s in {wall:.1f} s wall "
          f"({samples[-1][0] / wall:.1f}x real time)")
    print(f"theta over the last 30 s: {mean:.2f} deg; zenith equilibrium atan(E = {PLANT_PARAMS.E}) = {expected:.2f} deg"
          f" -> {'OK' if ok else 'NOT REACHED'}")
    return 0 if ok and code == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
