#!/usr/bin/env bash
# Set up (if needed) and run the fault-injection suite (issue 7): every fault test, fast and slow, then print the
# measured table and write it to docs/faults.md. Extra arguments go to pytest (e.g. -k crash, -x).
set -uo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh || exit 1
log=$(mktemp -d "${TMPDIR:-/tmp}/kite_rto_faults.XXXXXX")
start=$(date +%s)
KITE_RTO_FAULT_LOG="$log" .venv/bin/python -m pytest test/ros/test_fault*.py -m faults -q "$@"
status=$?
wall=$(( $(date +%s) - start ))
echo
echo "fault suite: ${wall} s wall; rows in $log"
if ! .venv/bin/python -m kite_rto.testing.fault_table "$log" --wall "$wall" && [ "$status" -eq 0 ]; then
  status=1
fi
exit "$status"
