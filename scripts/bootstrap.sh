#!/usr/bin/env bash
# Creates everything spacearm needs on a fresh machine: system packages, a virtual
# environment in .venv and the package installed into it (editable). Idempotent and
# quick when nothing changed, so both README commands call it first.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMP="$VENV/.spacearm-installed"

need_apt=()
command -v python3 >/dev/null 2>&1 || need_apt+=(python3 python3-venv python3-pip)
if command -v python3 >/dev/null 2>&1 && ! python3 -c 'import venv, ensurepip' >/dev/null 2>&1; then
    need_apt+=(python3-venv)
fi
# The vcan HIL suite (hil_tests/vm): where the kernel has no CAN support it boots Debian's
# stock kernel (ships vcan.ko) under QEMU with virtme-ng; modprobe and ip run inside the VM
# from the host's (shared, read-only) filesystem. Each is installed only when missing.
if [ "$(uname -s)" = Linux ] && [ "$(uname -m)" = x86_64 ] && [ "${SPACEARM_NO_VM:-0}" != 1 ]; then
    command -v qemu-system-x86_64 >/dev/null 2>&1 || need_apt+=(qemu-system-x86)
    dpkg -s busybox-static >/dev/null 2>&1 || need_apt+=(busybox-static)
    command -v modprobe >/dev/null 2>&1 || need_apt+=(kmod)
    command -v ip >/dev/null 2>&1 || need_apt+=(iproute2)
    compgen -G "/lib/modules/*/kernel/drivers/net/can/vcan.ko*" >/dev/null && compgen -G "/boot/vmlinuz-*" >/dev/null \
        || need_apt+=(linux-image-amd64)
    # CANopenNode (../shared/third_party/canopennode) is built with make for the vcan suite
    command -v cc >/dev/null 2>&1 || need_apt+=(gcc)
    command -v make >/dev/null 2>&1 || need_apt+=(make)
    dpkg -s libc6-dev >/dev/null 2>&1 || need_apt+=(libc6-dev)
fi
# The simulator's compiled core (setup.py builds firmware_sim/_simcore.c) needs a C compiler and
# Python's headers; where it cannot be built the install still succeeds and runs pure Python.
command -v cc >/dev/null 2>&1 || need_apt+=(gcc libc6-dev)
if ! command -v python3 >/dev/null 2>&1; then
    need_apt+=(python3-dev)
elif [ ! -f "$(python3 -c 'import sysconfig; print(sysconfig.get_paths()["include"])')/Python.h" ]; then
    need_apt+=(python3-dev)
fi
# The browser console (console/web): three.js from Debian (served from /usr/share/javascript,
# never fetched at run time) and Chromium for its end-to-end test (Playwright drives it).
dpkg -s libjs-three >/dev/null 2>&1 || need_apt+=(libjs-three)
[ -x /usr/bin/chromium ] || need_apt+=(chromium)
for extra in ${SPACEARM_APT_EXTRA:-}; do need_apt+=("$extra"); done
if ((${#need_apt[@]})); then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    echo "[bootstrap] installing system packages: ${need_apt[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
    echo "[bootstrap] creating virtual environment in $VENV"
    python3 -m venv "$VENV"
fi
# Reinstall only when the dependency list changed; build the compiled core again (the editable
# install builds it into firmware_sim/) when its source changed.
core_status() {
    (cd "$ROOT" && "$VENV/bin/python" -c "from spacearm.firmware_sim.simcore import core
print('[bootstrap] compiled core:', 'built' if core is not None else 'not built, the pure-Python path runs')") || true
}
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
    echo "[bootstrap] installing spacearm and its dependencies"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q -e "$ROOT[dev]"
    touch "$STAMP"
    core_status
elif [ "$ROOT/setup.py" -nt "$STAMP" ] || [ "$ROOT/firmware_sim/_simcore.c" -nt "$STAMP" ]; then
    echo "[bootstrap] building the compiled core"
    "$VENV/bin/python" -m pip install -q --no-deps -e "$ROOT"
    touch "$STAMP"
    core_status
fi
