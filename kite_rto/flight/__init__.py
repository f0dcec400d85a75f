"""Flying the kite along a figure-eight: path family and setpoints, projection, the path-following controller,
lap detection, the sample join of the plant's measurements and the pure closed-loop runner.

Builds on :mod:`kite_rto.kite`; never imports rclpy.
"""
