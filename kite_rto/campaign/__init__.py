"""Scenario campaigns: GMA and its baselines on plant variants, each judged against its own oracle.

:mod:`.scenarios` names the plant variants (which ones the kite defaults were chosen on, which ones only report);
:mod:`kite_rto.rto.judge` re-flies a run's iterates on the scenario's deterministic plant. Pure core: never imports
ROS 2.
"""
