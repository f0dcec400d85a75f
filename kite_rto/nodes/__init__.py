"""Thin ROS 2 nodes: each turns messages and parameters into calls to :mod:`kite_rto.core`."""
