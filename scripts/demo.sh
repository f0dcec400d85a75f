#!/usr/bin/env bash
# Set up (if needed) and run the main job. Extra arguments go to the demo (see --help).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/bootstrap.sh
exec .venv/bin/python -m kite_rto.tools.demo "$@"
