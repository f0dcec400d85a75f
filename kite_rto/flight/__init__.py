"""Flying the kite along a figure-eight: path family and setpoints, projection, the path-following controller,
lap detection and the pure closed-loop runner.

Builds on :mod:`kite_rto.kite`; never imports rclpy.
"""
