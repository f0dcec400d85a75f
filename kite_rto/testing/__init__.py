"""The test rig that runs outside pytest too: never imported by the runtime path (checked by ``.importlinter``).

Processes the fault tests start with ``python -m`` (:mod:`.fault_relay`, which drops and delays messages between two
nodes or crashes the kite; :mod:`.setpoint_flood`, a foreign publisher of /rto/setpoints), the fault table that
``scripts/faults.sh`` prints (:mod:`.fault_table`), and a node process started and stopped for a test or a
benchmark (:mod:`.launch`). Helpers only the tests import live in ``test/support/``.
"""
