#!/usr/bin/env bash
# Runs the vcan subset of hil_tests over real Linux SocketCAN: directly where vcan0 exists
# (or can be created), otherwise inside a QEMU VM booted with virtme-ng (see hil_tests/vm/runner.py).
#   scripts/hil_vm.sh [--vm|--direct] [--paths hil_tests/test_x.py,...] [-- extra pytest args]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec "$ROOT/.venv/bin/python" -m hil_tests.vm.runner "$@"
