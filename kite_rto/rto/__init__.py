"""Real-time optimization of the kite: its periodic optimal control problem, privileged directions, experiment
evaluation, the RTO session shared by the pure runner and the optimizer node, the run's description, the oracle,
the judge and the baselines.

Applies the generic :mod:`kite_rto.gma` library to the kite of :mod:`kite_rto.kite` flown by :mod:`kite_rto.flight`;
never imports rclpy.
"""
