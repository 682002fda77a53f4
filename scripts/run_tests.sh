#!/usr/bin/env bash
# README command 2: set everything up, then run the whole test suite (unit tests, HIL tests
# over every available CAN transport, and the real-kernel vcan suite in a small VM).
# Extra arguments go to pytest.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec "$ROOT/.venv/bin/python" -m pytest -ra "$@"
