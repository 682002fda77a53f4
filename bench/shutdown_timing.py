"""How long a stack process takes to end after SIGINT or SIGTERM, as a script's `cmd &` starts
it (SIGINT ignored before exec, inherited: Python then installs no Ctrl-C handler of its own,
and the hub once ran on for 608 s). Measured: the wall time from the signal to the exit and
the CPU time the process spent in between (os.wait4), which says whether a slow exit was the
process's own work or a loaded machine's wait for a core. Used by bench/bench_console.py (the
figures against the README's one second) and tests/console/test_shutdown.py (the behaviour).
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def start_in_background(args: list[str], ready: str, log: Path, timeout: float = 60.0) -> subprocess.Popen:
    """`spacearm ARGS &` from a non-interactive shell: SIGINT ignored before exec; returns once
    the log shows `ready`."""
    handle = open(log, "w")
    proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", *args], cwd=ROOT, stdout=handle,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    deadline = time.monotonic() + timeout
    while not re.search(ready, log.read_text(errors="replace")):
        if proc.poll() is not None:
            raise RuntimeError(f"{args[0]} exited before it was ready: {log.read_text()[-500:]}")
        if time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            raise TimeoutError(f"{args[0]} not ready within {timeout:.0f} s: {log.read_text()[-500:]}")
        time.sleep(0.05)
    return proc


def cpu_so_far(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def time_to_exit(proc: subprocess.Popen, sig: int, give_up: float = 30.0) -> tuple[float, float]:
    """(wall s from the signal to the exit, CPU s spent in between); TimeoutError (the process
    killed) when it is still running `give_up` s after the signal."""
    before = cpu_so_far(proc.pid)
    sent = time.monotonic()
    proc.send_signal(sig)
    while time.monotonic() < sent + give_up:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return time.monotonic() - sent, usage.ru_utime + usage.ru_stime - before
        time.sleep(0.005)
    proc.kill()
    proc.wait()
    raise TimeoutError(f"still running {give_up:.0f} s after {signal.Signals(sig).name}")
