"""Thin ROS 2 nodes: each turns messages and parameters into calls to the pure core (:mod:`kite_rto.kite`, :mod:`kite_rto.flight`, :mod:`kite_rto.rto`, :mod:`kite_rto.gma`)."""
