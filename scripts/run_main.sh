#!/usr/bin/env bash
# README command 1: set everything up, then run the main job on simulated hardware over the
# embedded in-process CAN bus. Extra arguments go to `spacearm demo`.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
exec "$ROOT/.venv/bin/spacearm" demo "$@"
