"""The simulator's and the hub's own lateness report: the frame round-trips, a late wake is
reported at once (after the inhibit time), an on-time producer once per event-timer period,
and the simulator sends its report on the bus where the master's listener receives it."""
from __future__ import annotations

import os
import threading
import time
import uuid

import canopen

from spacearm.base.canopen import peer_timing
from spacearm.base.canopen.peer_timing import LatenessMeter, decode
from spacearm.drivers.peer_timing import PeerTimingListener
from spacearm.firmware_sim.runner import start_simulator


def test_report_round_trips_and_starts_a_new_interval():
    meter = LatenessMeter(period=1.0, inhibit=0.1, late_wake=0.005)
    meter.woke(0.001, 10.0)
    meter.woke(0.300, 10.2)
    report = decode(meter.report(10.2))
    assert (report.late, report.wakes) == (1, 2) and abs(report.max_lateness - 0.300) < 1e-4
    assert report.policy in ("normal", "SCHED_FIFO", "SCHED_RR")
    assert decode(meter.report(11.2)) == peer_timing.TimingReport(0, 0.0, 0, report.policy, report.priority)


def test_late_wake_is_reported_after_the_inhibit_time_on_time_wakes_once_a_period():
    meter = LatenessMeter(period=1.0, inhibit=0.1, late_wake=0.005)
    meter.woke(0.0, 0.0)
    assert not meter.due(0.5) and meter.due(1.0)
    meter.report(1.0)
    meter.woke(0.2, 1.05)                      # a late wake: an event
    assert not meter.due(1.09) and meter.due(1.1)


def test_lateness_saturates_and_short_frames_are_not_reports():
    meter = LatenessMeter()
    meter.woke(10.0, 0.0)
    assert decode(meter.report(1.0)).max_lateness == 0xFFFF * 1e-4
    assert decode(b"\x00" * 7) is None


def test_simulator_publishes_its_own_timing_to_the_master():
    bus = f"virtual:peer-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    listener = PeerTimingListener(network)
    network.connect(interface="virtual", channel=bus.split(":", 1)[1])
    sim = start_simulator(bus)
    sim.lateness.period = 0.2
    try:
        deadline = time.monotonic() + 5.0
        while not listener.reports()["simulator"] and time.monotonic() < deadline:
            time.sleep(0.05)
        (received, report), *_ = listener.reports()["simulator"]
        assert report.wakes > 0 and report.scheduling
        assert listener.reports()["hub"] == []          # no hub on a virtual bus
    finally:
        sim.stop()
        network.disconnect()


def test_hub_reports_go_only_to_clients_that_ask_for_them():
    from spacearm.base.transport.hub import LoopbackHub
    from spacearm.base.transport.loopback import LoopbackBus

    hub = LoopbackHub("127.0.0.1", 0, timing_reports=True)
    hub.lateness.period = 0.2
    hub.start()
    master = LoopbackBus("peer", "127.0.0.1", hub.port, hub_reports=True, autostart=False)
    node = LoopbackBus("peer", "127.0.0.1", hub.port, autostart=False)
    try:
        deadline, got = time.monotonic() + 5.0, None
        while got is None and time.monotonic() < deadline:
            msg = master.recv(0.2)
            if msg is not None and msg.arbitration_id == peer_timing.HUB_COB_ID:
                got = decode(bytes(msg.data))
        assert got is not None and got.wakes > 0      # the hub's timer ticks every 10 ms
        assert node.recv(0.5) is None                 # a node on the same channel never sees them
    finally:
        master.shutdown()
        node.shutdown()
        hub.stop()


def test_a_device_on_a_report_cob_id_is_not_taken_for_a_report():
    network = canopen.Network()
    PeerTimingListener(network, device_cob_ids={peer_timing.HUB_COB_ID})
    assert peer_timing.SIMULATOR_COB_ID in network.subscribers and peer_timing.HUB_COB_ID not in network.subscribers


def test_the_worst_late_wakes_cause_round_trips_and_an_on_time_interval_has_none():
    meter = LatenessMeter(period=1.0, inhibit=0.1, late_wake=0.005, measure_causes=False)
    meter._worst_cause = "gil"          # as _cause() found it for the worst late wake
    meter._worst, meter._late, meter._wakes = 0.05, 1, 3
    assert decode(meter.report(1.0)).cause == "gil"
    meter.woke(0.001, 1.5)
    assert decode(meter.report(2.0)).cause == ""


def test_wake_cause_splits_lateness_by_what_the_process_did_meanwhile():
    from spacearm.base.canopen.peer_timing import wake_cause
    assert wake_cause(0.040, own_queue=0.030, own_cpu=0.0001, all_busy=0.031) == "core"
    assert wake_cause(0.040, own_queue=0.001, own_cpu=0.0001, all_busy=0.035) == "gil"
    assert wake_cause(0.040, own_queue=0.001, own_cpu=0.0001, all_busy=0.002) == "stopped"


def test_a_late_wake_inside_host_steal_is_the_hosts_whatever_the_guest_saw(monkeypatch):
    """The hypervisor held a vCPU: inside the guest that reads as a wait for a core. The report
    waits for the guest's steal count to catch up, then names the host; a late wake with no
    steal keeps what schedstat said."""
    steal = [(5, 7)]
    monkeypatch.setattr(peer_timing, "host_steal", lambda: steal[0])
    meter = LatenessMeter(period=1.0, inhibit=0.1, late_wake=0.005)
    meter.woke(0.001, 0.0)
    meter.report(0.0)
    meter.woke(0.001, 1.00)
    meter._cause = lambda lateness: "core"        # what schedstat says of the stalled vCPU
    meter.woke(0.100, 1.11)                       # ... 100 ms late
    assert not meter.due(1.11) and meter.due(1.11 + peer_timing.STEAL_SETTLE)
    steal[0] = (5, 17)                            # 10 ticks (100 ms) stolen on vCPU 1, counted late
    assert decode(meter.report(1.15)).cause == "host"
    meter.woke(0.001, 1.20)
    meter.woke(0.100, 1.40)                       # late again, no steal this time
    assert decode(meter.report(1.5)).cause == "core"


def test_a_wake_nothing_in_the_guest_explains_is_the_hosts_when_any_steal_was_counted(monkeypatch):
    """Steal is counted in 10 ms ticks: a 23 ms stall may show one tick. A wake no thread of the
    process ran or queued through ("stopped") with a tick of steal around it is the host's; the
    same with a wait for a core keeps "core" (the half-the-lateness rule), and with no steal at
    all it stays "stopped"."""
    steal = [(5, 7)]
    monkeypatch.setattr(peer_timing, "host_steal", lambda: steal[0])
    meter = LatenessMeter(period=1.0, inhibit=0.1, late_wake=0.005)
    meter.woke(0.001, 0.0)
    meter.report(0.0)
    for cause, stolen, named in (("stopped", 1, "host"), ("core", 1, "core"), ("stopped", 0, "stopped")):
        meter.woke(0.001, 1.0)
        meter._cause = lambda lateness, cause=cause: cause
        meter.woke(0.023, 1.1)
        steal[0] = (5, steal[0][1] + stolen)
        assert decode(meter.report(1.2)).cause == named, (cause, stolen)
        del meter._cause


def test_the_host_cause_round_trips_and_an_unknown_one_is_none():
    frame = bytearray(LatenessMeter(measure_causes=False).report(0.0))
    frame[6] = (frame[6] & 3) | 4 << 2
    assert decode(bytes(frame)).cause == "host"
    frame[6] = (frame[6] & 3) | 7 << 2
    assert decode(bytes(frame)).cause == ""


def test_a_thread_holding_the_gil_is_measured_as_the_gil():
    """A timer thread whose wakes wait for another thread of its process that keeps the GIL
    (a long switch interval stands in for a holder that is preempted): its late wakes say gil."""
    import sys
    import threading
    interval = sys.getswitchinterval()
    stop = threading.Event()
    meter = LatenessMeter(late_wake=0.005)
    causes = []

    def spin():
        while not stop.is_set():
            sum(range(2000))

    def timer():
        due = time.monotonic()
        for _ in range(60):
            time.sleep(max(0.0, due - time.monotonic()))
            now = time.monotonic()
            cause = meter.woke(now - due, now)
            if now - due > 0.02:
                causes.append(cause)
            due = now + 0.01
    spinner = threading.Thread(target=spin, daemon=True)
    sys.setswitchinterval(0.05)
    try:
        spinner.start()
        worker = threading.Thread(target=timer)
        worker.start()
        worker.join(30)
    finally:
        stop.set()
        sys.setswitchinterval(interval)
        spinner.join(5)
    assert causes and causes.count("gil") >= len(causes) / 2, causes


def test_a_stopped_process_is_measured_as_stopped():
    """SIGSTOP for 0.3 s: no thread of the process ran nor waited for a core."""
    import os
    import signal
    import subprocess
    import sys
    script = ("import time\nfrom spacearm.base.canopen.peer_timing import LatenessMeter\n"
              "m = LatenessMeter(late_wake=0.005)\nprint('ready', flush=True)\ndue = time.monotonic()\n"
              "for _ in range(150):\n    time.sleep(max(0.0, due - time.monotonic()))\n"
              "    now = time.monotonic(); m.woke(now - due, now); due = now + 0.01\n"
              "print(m._worst, m._worst_cause, flush=True)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGSTOP)
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGCONT)
        worst, cause = proc.stdout.readline().split()
    finally:
        proc.kill()
        proc.wait()
    assert float(worst) >= 0.25 and cause == "stopped", (worst, cause)


def _listed_threads() -> list[tuple[int, int]]:
    """(CPU ns, run-queue ns) of every thread of this process, listed and read afresh."""
    out = []
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/schedstat", "rb") as handle:
                fields = handle.read().split()
        except OSError:
            continue
        out.append((int(fields[0]), int(fields[1])))
    return out


def test_task_times_follow_threads_that_start_and_end_between_wakes():
    """_task_times lists the threads again only when their number changed or one ended: a
    thread started (or ended and replaced) between two calls is still summed, an ended one no
    longer is, as the listing on every call did."""
    peer_timing._task_times()
    gates = [threading.Event() for _ in range(2)]
    started = threading.Thread(target=gates[0].wait)
    started.start()
    try:
        time.sleep(0.01)
        cpu, queue, own = peer_timing._task_times()
        assert str(started.native_id) in peer_timing._task_files
        after = _listed_threads()        # read later: every sum can only have grown
        assert cpu <= sum(c for c, _ in after) and queue <= sum(q for _, q in after)
        assert cpu >= sum(c for c, _ in after) - 50_000_000     # not a thread short (this one's CPU since)
        gates[0].set()
        started.join()
        replacement = threading.Thread(target=gates[1].wait)     # same count, another thread
        replacement.start()
        time.sleep(0.01)
        peer_timing._task_times()
        assert str(started.native_id) not in peer_timing._task_files
        assert str(replacement.native_id) in peer_timing._task_files
        assert set(peer_timing._task_files) == set(os.listdir("/proc/self/task"))
        assert own >= 0
    finally:
        for gate in gates:
            gate.set()
        replacement.join()
