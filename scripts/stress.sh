#!/usr/bin/env bash
# Run the DDS tests of the fast suite under load: a CPU hog on every core (busy processes at normal priority) and
# random delivery delays inside every node (KITE_RTO_INJECT_DELAY, see docs/faults.md), N times in a row.
#
#   ./scripts/stress.sh                    # 5 repeats, hog on every core, delays up to 2 ms
#   ./scripts/stress.sh --repeats 2 --hogs 4 --delay 0.05 -- -k optimizer     # extra pytest arguments after --
#
# Prints one line per repeat and a summary ("stress: R repeats, F failed"); exits 1 if any repeat failed.
# Logs: runs/stress/repeat-<i>.log.
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=5
hogs=$(nproc)
delay=0.002
marker="ros and not slow"
while [ $# -gt 0 ]; do
  case "$1" in
    --repeats) repeats=$2; shift 2 ;;
    --hogs) hogs=$2; shift 2 ;;
    --delay) delay=$2; shift 2 ;;
    --marker) marker=$2; shift 2 ;;
    -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --) shift; break ;;
    *) echo "stress.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
./scripts/bootstrap.sh
mkdir -p runs/stress
pids=()
stop_hogs() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap stop_hogs EXIT
for _ in $(seq "$hogs"); do
  .venv/bin/python -c "while True: pass" &
  pids+=($!)
done
echo "stress: $hogs CPU hogs, delivery delays up to $delay s, $repeats repeats of pytest -m '$marker' $*"
failed=0
for i in $(seq "$repeats"); do
  log=runs/stress/repeat-$i.log
  start=$(date +%s)
  if KITE_RTO_INJECT_DELAY="$delay:$i" .venv/bin/python -m pytest -q -m "$marker" "$@" >"$log" 2>&1; then
    verdict=passed
  else
    verdict=FAILED
    failed=$((failed + 1))
  fi
  echo "  repeat $i: $verdict in $(( $(date +%s) - start )) s ($(tail -n 1 "$log"))"
done
echo "stress: $repeats repeats, $failed failed"
[ "$failed" -eq 0 ]
