"""Every process of the stack ends on SIGINT or SIGTERM, whatever started it: here started as
a script's `cmd &` starts it (SIGINT ignored, inherited; Python then installs no Ctrl-C
handler of its own: the hub ran on for 608 s). bench/shutdown_timing.py measures the wall time
from the signal to the exit and the CPU time the process spent in it; both are printed with
the load and the reference loop at any load (bench/bench_console.py reports them against the
README's one second). Asserted at any load: the behaviour - each process ends on the signal
alone, the hub with exit 0, and does at most a second of its own work (CPU) on the way out.
The one second of wall time is asserted only on an idle machine (1-minute load below 1.5): on a
loaded one a process at normal priority waits seconds for a core, the load's doing, not the
shutdown's (the CPU time says which)."""
from __future__ import annotations

import os
import signal
import socket

import pytest

from bench.reference_work import reference_loop_seconds
from bench.shutdown_timing import start_in_background, time_to_exit

SCALE = float(os.environ.get("SPACEARM_TIME_SCALE", "1"))
IDLE_LOAD = 1.5


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
def test_hub_and_simulator_end_within_a_second_of_a_signal(sig, tmp_path, record_property):
    port = free_port()
    hub = start_in_background(["hub", "--port", str(port)], "listening", tmp_path / "hub.log", 60 * SCALE)
    sim = None
    try:
        sim = start_in_background(["sim", "--bus", f"loopback:shutdown@127.0.0.1:{port}",
                                   "--plant", "configs/plant/oru_testbed_nominal.toml"], "nodes ready",
                                  tmp_path / "sim.log", 60 * SCALE)
        load = os.getloadavg()[0]
        took_sim = time_to_exit(sim, sig, 30 * SCALE)     # TimeoutError: it ignored the signal
        took_hub = time_to_exit(hub, sig, 30 * SCALE)
    finally:
        for proc in (sim, hub):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    load = max(load, os.getloadavg()[0])
    reference = reference_loop_seconds(repeats=1)[0]
    line = (f"{signal.Signals(sig).name}: simulator exited in {1e3 * took_sim[0]:.0f} ms ({1e3 * took_sim[1]:.0f} ms "
            f"CPU), hub in {1e3 * took_hub[0]:.0f} ms ({1e3 * took_hub[1]:.0f} ms CPU); load {load:.1f}, reference "
            f"loop {1e3 * reference:.0f} ms; the 1 s wall target is "
            + ("asserted (idle)" if load < IDLE_LOAD else "reported only (not idle)"))
    print(line)
    record_property("shutdown", line)
    assert hub.returncode == 0 and sim.returncode == 0, (hub.returncode, sim.returncode)
    assert took_sim[1] <= 1.0 and took_hub[1] <= 1.0, f"more than a second of the process's own work: {line}"
    if load < IDLE_LOAD:
        assert took_sim[0] <= 1.0 and took_hub[0] <= 1.0, line
