"""The nodes' per-sample logic without ROS: what the plant, controller and optimizer nodes do with each message.

The controller's steering loop (:mod:`.steering_loop`, which owns its optimizer synchronization :mod:`.optimizer_sync`,
its setpoint inbox :mod:`.setpoint_inbox` and its look at who publishes an input :mod:`.sources`), the sample join
and timeline rule (:mod:`.sample_join`), the optimizer's run (:mod:`.optimizer_run`) with its database at start-up
(:mod:`.run_db`), the operator's event log (:mod:`.operator_log`) and the full-disk hook (:mod:`.store_fault`), and
the real-time plant's pacing (:mod:`.pace`). Wall time, graph counts and stamps are passed in, so all of it runs
and is tested without DDS.

Builds on :mod:`kite_rto.flight`, :mod:`kite_rto.gma` and :mod:`kite_rto.kite`; never imports rclpy or a message
package.
"""
