#!/usr/bin/env bash
# README command 2: set everything up, then run the whole test suite (unit tests, HIL tests
# over every available CAN transport, and the real-kernel vcan suite in a small VM).
# Extra arguments go to pytest. Two pytest-xdist workers: the HIL tests run in order on one
# of them (conftest.py: pytest_xdist_make_scheduler) while the unit tests share out over both;
# SPACEARM_TEST_WORKERS=0 runs everything in this process, one test after another.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
WORKERS="${SPACEARM_TEST_WORKERS:-2}"
exec "$ROOT/.venv/bin/python" -m pytest -ra --durations=25 -n "$WORKERS" "$@"
