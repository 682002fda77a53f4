"""Every process of the stack ends on SIGINT or SIGTERM, whatever started it: here started as
a script's `cmd &` starts it (SIGINT ignored, inherited; Python then installs no Ctrl-C
handler of its own: the hub ran on for 608 s). Measured and printed: the wall time from the
signal to the exit and the CPU time the process spent in it (os.wait4). The README's one
second is asserted on the wall time only on an idle machine (1-minute load below 1.5): on a
loaded one a process at normal priority waits seconds for a core, which is the load's
doing, not the shutdown's (the CPU time says which)."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCALE = float(os.environ.get("SPACEARM_TIME_SCALE", "1"))


def free_port() -> int:
    import socket
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_in_background(args: list[str], ready: str, log: Path) -> subprocess.Popen:
    """`spacearm ARGS &` from a non-interactive shell: SIGINT ignored before exec."""
    handle = open(log, "w")
    proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", *args], cwd=ROOT, stdout=handle,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    deadline = time.monotonic() + 60 * SCALE
    while not re.search(ready, log.read_text(errors="replace")):
        assert proc.poll() is None, log.read_text()
        assert time.monotonic() < deadline, f"not ready: {log.read_text()[-500:]}"
        time.sleep(0.05)
    return proc


def cpu_so_far(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def time_to_exit(proc: subprocess.Popen, sig: int) -> tuple[float, float]:
    """(wall s from the signal to the exit, CPU s spent in between)."""
    before = cpu_so_far(proc.pid)
    sent = time.monotonic()
    proc.send_signal(sig)
    deadline = sent + 30 * SCALE
    while time.monotonic() < deadline:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return time.monotonic() - sent, usage.ru_utime + usage.ru_stime - before
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    pytest.fail(f"still running {30 * SCALE:.0f} s after {signal.Signals(sig).name}")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
def test_hub_and_simulator_end_within_a_second_of_a_signal(sig, tmp_path):
    port = free_port()
    hub = start_in_background(["hub", "--port", str(port)], "listening", tmp_path / "hub.log")
    sim = None
    try:
        sim = start_in_background(["sim", "--bus", f"loopback:shutdown@127.0.0.1:{port}",
                                   "--plant", "configs/plant/oru_testbed_nominal.toml"], "nodes ready", tmp_path / "sim.log")
        took_sim = time_to_exit(sim, sig)
        took_hub = time_to_exit(hub, sig)
    finally:
        for proc in (sim, hub):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    load = os.getloadavg()[0]
    print(f"{signal.Signals(sig).name}: simulator exited in {1e3 * took_sim[0]:.0f} ms ({1e3 * took_sim[1]:.0f} ms CPU), "
          f"hub in {1e3 * took_hub[0]:.0f} ms ({1e3 * took_hub[1]:.0f} ms CPU); load {load:.1f}")
    assert hub.returncode == 0, hub.returncode
    if load < 1.5:
        assert took_sim[0] <= 1.0 and took_hub[0] <= 1.0, (took_sim, took_hub)
