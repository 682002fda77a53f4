"""Daemon cycle timing: real time at 20 ms and 4 ms with a console polling status at 20 Hz,
lockstep speed-up over real time, CPU per cycle, and the daemon's memory over the run.

    .venv/bin/python bench/bench_daemon.py [--duration 600] [--duration-4ms 120]
                                           [--transport loopback|virtual] [--cpu-load 2]
    .venv/bin/python bench/bench_daemon.py --lockstep-only      # the cost of one cycle (~3 min)

The simulator runs as its own process (loopback) or in-process (virtual); the daemon runs
in this process, recording every cycle (MCAP and raw CAN trace, as `spacearm daemon` does,
serialised by helper processes whose CPU is shown beside the share);
the polling console is a separate process using the real command API. Percentiles cover
every cycle of the run. --cpu-load N runs N CPU-bound processes beside the real-time runs
(hil_tests/cpu_load.py). Every row names the machine load and the host's CPU steal of its run:
on 2 shared cores wall-clock figures follow the load, CPU per cycle much less so.

CPU per cycle (lockstep, in-process bus, where both sides share one thread): "simulator" is
the thread CPU of handling one SYNC (device code, plant step, TPDOs out and decoded by the
master); "daemon" is the rest of the cycle's thread CPU (supervision, modes, RPDOs, recording
hand-off). Threads beside the cycle (CAN trace batching, timers) are in the process figure.

Lockstep cycle costs are judged in reference units (bench/reference_work.py, timed in this
run): process CPU per cycle as a share of a pure-Python loop's CPU, and as a multiple of the
PDO floor (the cycle's own frames packed and unpacked with precompiled struct).

The cycle's objects and the threads beside it (issue 35, 2026-11-30; the master's and the
simulator's halves measured each against main, alternating, medians, load 4.9-9.2, steal
<= 0.3 %). Master: a JointState's reported objects in one itemgetter call, no node health
snapshots the daemon never reads, one expected-TPDO set per SYNC, supervision's limits compared
as Python floats (numpy only past a limit), the cycle's states (Command, Snapshot, ArmState,
end-effector and F/T states, the lockstep Tick) built without their dataclass __init__, the
loopback burst encoded in one call: daemon CPU per cycle 0.150 -> 0.126 ms, Python calls per
cycle 799 -> 703; 8 nodes virtual recording on 0.348 -> 0.327 %, loopback 0.385 -> 0.337 %,
Panda 0.387 -> 0.348 % (4 rounds). Simulator: its timer beside a lockstep controller wakes at
most every 50 ms (93 -> 25 passes a second) and reports lateness without the per-thread /proc
reads (each a GIL hand-over with the cycle thread): 0.013-0.033 -> 0.002-0.005 ms per cycle;
the F/T sample without a per-axis loop (6.3 -> 3.7 us), the SYNC-time heartbeat checks without
a call where they would do nothing, the resting Panda two calls per joint less: simulator part
0.103 -> 0.097 ms, 8 nodes virtual recording on 0.359 -> 0.327 %, Panda 0.402 -> 0.369 % (6
rounds). lockstep_fingerprint identical with the core and without, each and merged. Tried and
left: the trace tap and send_frames' length check as one operation (slower at these burst
sizes), the wrench norms in Python floats (numpy's dot differs in the last bit: FMA).
A second simulator round: the drives' mode-of-operation check called only for new bytes (a
declared pure check), the end effector at rest in one sub-step, a drive's SYNC end and its
actual-value write in one core call (_simcore.c drive_end_write), the F/T sensor's counts reused
for an identical reading: 676 -> 601 Python calls per cycle, simulator part 0.100 -> 0.095 ms (7
rounds, load 6.6-10.7; the share rows within their noise). A batched pass over all joints in the
master (step, RPDO frames and state without a driver method call per joint; bit-identical) saved
nothing measured without a profiler (same-process A/B every 50 cycles: 125.4 vs 125.0 us daemon
CPU per cycle) and was left out: cProfile's cost per call had made the method calls look like a
fifth of the daemon's half. What a swap of each part for a replay of its last result shows: step
and RPDO packing ~25 us, the joints' states ~12 us per cycle; the lever there is the data layout
(RPDOs packed from the values just computed, TPDO values as per-PDO tuples, not (index, sub) dict
keys at ~36 ns a lookup and round() at ~65 ns).
The master's PDOs by data layout (issue 35, 2026-11-30): a joint's RPDOs are packed straight
from the values its step computed (drivers/joint_rpdos.py: the layout compiled once into one
generated call per driver, no (index, sub) lookup per object, no round() of a zero
feed-forward); a SYNC burst that brings all of a node's TPDOs in its layout's order is kept as
the node's tuple (drivers/reported_values.py), read by position by the joints' step and state
and the end effector's and F/T's state, and merged into the values dict only when the dict is
read; the daemon's read takes each joint's position, velocity, torque and state without a
JointState (ArmState.readings), the Measurement's columns by one zip. Same-process A/B (old and
new path every 25 cycles, 6000 cycles, medians of blocks, load 20): cycle thread CPU 253.5 ->
226.3 us recording on, 232.4 -> 200.8 us off, Panda 285.8 -> 266.3 us (the read alone 3.7-6.7
us of it at load 11). This bench, 5 rounds alternating with main (load 13.7-19.4, steal <= 0.4
%), medians: 8 nodes virtual recording on 0.355 -> 0.344 % (daemon CPU 0.123 -> 0.116 ms),
loopback 0.407 -> 0.349 % (daemon process 0.358 -> 0.305 ms), Panda 0.364 -> 0.372 % (daemon
0.131 -> 0.126 ms): at that load a run's share varies by 1.5x, the rows do not resolve ~10 %.
lockstep_fingerprint identical to main with the core and without. Tried and left: the trace
tap taking a burst as one list laid out by slices (3x faster in a loop, nothing in situ: -1 and
-2 us in two same-process A/Bs).

Where one lockstep cycle's thread CPU goes (8 nodes, virtual bus, recording on; cProfile own
time grouped by part, `bench/profile_lockstep.py --record --cycles 1000`; 2026-11-29, load
6.4, with bursts on the bus (below): profiled 2.85 ms per cycle and 1218 Python calls per
cycle, against 1513 calls for the tree before them (3.39 ms profiled at load 6.5); cProfile
inflates every Python call, so the shares overstate per-call parts):

| part of the cycle | ms/cycle | share |
| --- | --- | --- |
| Python built-ins and libraries called from all parts (dict.get, min/max/round, struct) | 0.73 | 26 % |
| master: PDO decode/encode, device drivers (drivers/cyclic_io, devices) | 0.61 | 22 % |
| simulator: object dictionary, PDO/SDO engine | 0.30 | 11 % |
| simulator: drives (CiA 402, servo; what the core leaves and its calls) | 0.25 | 9 % |
| controller: daemon cycle, modes, planning | 0.25 | 9 % |
| simulator: plant physics (end effector, F/T, what the core leaves) | 0.21 | 7 % |
| simulator: SYNC routing | 0.16 | 5.6 % |
| simulator: compiled core (firmware_sim/_simcore.c) | 0.09 | 3.3 % |
| bus: transport and frame delivery | 0.07 | 2.6 % |
| controller: recording hand-off (serialisation is in helper processes) | 0.06 | 2.3 % |
| controller: supervision | 0.06 | 2.2 % |
| other spacearm code | 0.03 | 1 % |

The simulator's frames in the core (issue 35, 2026-11-30): a burst's RPDOs are stored by one
call of the compiled core (_simcore.c rpdo_burst, under one hold of the SYNC lock) and a SYNC's
TPDOs of every node sampled into its burst by another (tpdo_burst), for the nodes whose frames
the Python path would handle plainly (live, OPERATIONAL, no line gate, no fault switch on the
frames, decoders and tables current); any other frame or node goes the Python way, which is also
the pure-Python path. The drives read their settings, encoder readings and tables without a
call for a cached answer, the end effector's sub-steps are one call, and the simulator's
wall-clock timer takes the SYNC lock only for a heartbeat that is due (each acquisition while the
SYNC thread held it cost GIL hand-overs) and lists /proc/self/task only when the threads changed.
profile_lockstep --record, 1000 cycles (load 10.8 / 11.6): 1225 -> 967 Python calls per cycle,
the simulator's parts 1.05 -> 0.74 ms profiled. This bench over main (01067d0) and this tree
alternating (12 / 11 runs, load 9.6-16.5, steal 0 %), medians: 8 nodes virtual recording on
0.518 -> 0.437 % (process CPU 0.476 -> 0.394 ms, the simulator's part 0.140 -> 0.118 ms),
recording off 0.468 -> 0.397 %, Panda 0.562 -> 0.480 % (simulator 0.153 -> 0.146 ms), loopback
0.450 -> 0.463 % (the daemon's process; the simulator's 0.283 -> 0.275 ms). At that load one run's
share varies by up to 2x; lockstep_fingerprint identical to main with the core and without.
What is left in the simulator: per drive the Python around the core's calls (the SYNC begin and
end, the plant's period), the F/T sample, the SYNC-time heartbeat and consumer checks (9 nodes a
SYNC), and the timer's per-thread /proc reads (each pread a GIL hand-over beside the cycle).

Bursts (issue 35): a cycle's frames go over the bus as two bursts and a SYNC, not as ~38
frames one by one. The in-process bus's send_frames hands a burst (the master's RPDOs, a
SYNC's TPDOs) to each receiver whole, taps first, as the loopback hub forwards one, in one
call where its listener has on_frames; the loopback bus hands a read's frames over the same
way. The simulator routes a burst's RPDOs without a call per frame, the master decodes a
burst's TPDOs under one hold of its lock, the trace tap takes a burst in one call. An RPDO
calls a device's on_write only for the objects it reacts to (SimNode.WRITE_REACTIONS, in the
core and in Python); a CiA 402 axis outside a fault reset takes state and controlword from a
(statusword, goal) table. Bus part 0.34 -> 0.07 ms profiled; lockstep_fingerprint identical
to the tree before, with the core and without. The rigid-body sub-step reads each joint's
gear kind, static friction and rotor inertia from a tuple kept per parameter set (Panda:
2137 -> 1977 Python calls per cycle). This bench, 5 rounds alternating with the tree before
(07a73bd; load 3.5-10.5, steal <= 0.2 %), medians: 8 nodes virtual recording on 0.596 ->
0.509 % (runs 0.636, 0.710, 0.596, 0.520, 0.527 / 0.493, 0.613, 0.630, 0.509, 0.499),
recording off 0.537 -> 0.451 %, loopback 0.519 -> 0.465 %, Panda 0.907 -> 0.758 %; the cycle
thread's halves (medians of runs) simulator 0.152 -> 0.141 ms, daemon 0.217 -> 0.206 ms. An
earlier 3 rounds without the rigid-body change (load 4.9-10.5): 0.545 -> 0.434 %, 0.503 ->
0.384 %, 0.492 -> 0.441 %, 0.797 -> 0.708 %. Still 1.4-2.3x from the targets:
the master's per-joint drivers and dataclasses (JointState, health snapshots, Measurement's
arrays), the controller's small-array numpy, and per node the simulator's PDO engine calls;
the Panda's coupled plant runs its drives' servo in Python every sub-step (a compiled servo
step computes the same bits, but as Python floats where the Python path has numpy scalars:
the recorded motor torques' repr changes, so it was left out).

The compiled core (issue 35; firmware_sim/_simcore.c, a plain C extension built by setup.py,
optional: firmware_sim/simcore.py, SPACEARM_PURE_PYTHON=1 switches it off) runs the
simulator's steady SYNC path per node: a drive's SYNC begin that changes no state (its RPDO
objects read straight from the data store, the CSP interpolation), a rigid joint's whole
period of sub-steps under its drive's servo law (powered off or CSP), a CSP drive's SYNC end
that changes no state (brake timing, following error, statusword, actual values),
CyclicObjects' writes into the store, the RPDO store and the TPDO sampling. Transitions,
ramps, halt, profile position, faults, elastic gears, coupled plants (the contact cell, the
Panda's rigid body), fault switches and anything Python would raise on stay on the Python
path. Both compute the same bits: -ffp-contract=off and Python's order of operations;
bench/lockstep_fingerprint.py (5 scenarios) identical to the tree before, with the core and
without; tests/firmware_sim/test_simcore.py compares each function with its Python path on
random inputs, and two lockstep runs whole.
Measured 2026-11-29 (this bench, `--lockstep-only --lockstep-cycles 4000`, the tree before and
this one alternating, 3 rounds, load 6.3-7.9, steal <= 0.2 %), medians of the judged CPU
shares: 8 nodes virtual recording on 0.739 -> 0.567 % (runs 0.586, 0.739, 0.802 / 0.608,
0.567, 0.535), recording off 0.609 -> 0.519 %, Panda 0.946 -> 0.864 %, loopback 0.511 ->
0.509 % (that row is the daemon's process alone, which the core does not touch; the
simulator's process there 0.423 -> 0.300 ms per cycle); the simulator's part of the
in-process cycle (medians per run) 0.21-0.25 -> 0.15-0.17 ms. An earlier round (load 2.9-4.6,
before the SYNC end was compiled): 0.559 -> 0.487 %, 0.557 -> 0.458 %, 0.897 -> 0.747 %. In one
run with the core switched on and off every 25 cycles (`bench/profile_lockstep.py
--compare-core`, 4000 cycles, load 9.5) the cycle thread costs 0.368 against 0.454 ms, 0.81x.
The targets (0.23 / 0.34 / 0.33 %) are still 2-2.6x away: what is left is the master's half
(drivers' per-joint state machines and dataclasses, the daemon's cycle: now the larger half of
the in-process cycle), one Python call per frame and receiver in the bus, and the simulator's
remaining per-node Python (SYNC routing, the F/T sensor and end effector, the calls into the
core).

Recording (issue 35): the cycle packs one fixed-size record (one precompiled struct) straight
into a shared-memory ring (controller/recording/record_ring.py) and publishes it with one
8-byte store, no system call; a writer process takes the ring every 50 ms and serialises MCAP,
the in-process bus's CAN trace is formatted by another (controller/daemon/recorder_process.py,
controller/recording/trace_stream.py); the trace's tap sees each frame before the receivers
(base/transport `add_tap`) and collects it in a flat list. In the cycle thread (in situ,
2026-11-29, load 1.8, thread CPU around the daemon's `_record`): the hand-off 10 us median per
cycle against 30 us when each record was a pipe write (the write alone ~20 us median in situ,
0.6 us in a loop of its own), the tap ~0.1 us per frame, the /stats summary 0.08 ms once a
second of recording; the trace's batching thread 5 us per cycle recorded (~0.8 %: marshalling
~40 values a cycle).

How the share is measured: the judged figure switches recording off and on every 25 cycles
inside one recording run (`interleaved_recording`: the recorder out of the cycle, the tap off
the bus, the helper processes idle), so both states see the same machine: on this shared
machine consecutive 100-cycle segments in one state differ by up to 2x in CPU per cycle, so
segments are short and the share is a median over blocks (on, off, off, on). The trace's
batching thread wakes every 0.2 s (~15 segments) and lands on on and off segments alike, so the
medians leave it out (until 2026-11-29 the judged share did so, ~0.8-1 % of the cycle): its CPU over
the run, on its own thread clock, per cycle recorded, is added to the judged share. What it
still leaves out: the helper processes' own CPU (their row), and what their work costs this
process on a 2-core machine, which falls on on and off segments alike.
Measured 2026-11-29 (`--lockstep-only --lockstep-cycles 4000`, this bench file run over the
tree before the ring and over this one, alternating, 3 rounds; load 2.3-5.4, steal <= 0.5 %):
interleaved share (judged, batching thread included) 9.2 % before (rounds 10.4, 9.2, 8.3; runs
9.8, 10.4, 10.9 / 9.2, 5.8, 10.8 / 8.3, 7.8, 12.9) against 7.8 % with the ring (7.8, 8.1, 6.4;
runs 5.5, 7.8, 10.1 / 6.7, 8.1, 9.0 / 6.4, 7.8, 5.7); the batching thread 0.8-1.1 % in both.
An A/A check of the method (blocks of four segments all recording, same run) gives -2.4 to
+1.1 % per run: one run's share is good to about 2 points, hence the median of three. The
separate-runs rows (12-21 % in both trees) see what the interleaved rows cannot: an off run has
no helper processes, whose ~0.11 ms of CPU per cycle (17-19 % of the unrecorded cycle's, MCAP
JSON and zstd, trace formatting) shares the 2 cores, caches and memory with the cycle.
Separate on and off runs (the pairs row) compare different moments of a shared machine:
identical off runs differ by up to 50 % in CPU per cycle there (2026-11-27, load 3.3:
1.25-1.87 ms); their share is printed for information.

Both halves are per-frame and per-object Python: no single part is the floor, which is why the
cycle costs ~160x its PDO floor (the compiled core takes the simulator's steady per-node work,
above; the frames and the master's objects remain).

The master's half (drivers/, base/transport, controller/daemon; 2026-11-28, cProfile own time
of the master's functions and of the built-ins they call, recording off, load 3.6-4.0):
2.02 -> 1.31 ms and 1344 -> 803 Python calls per cycle, profiled. PDO codecs are compiled
with the layout (devices.PdoCodec) and a TPDO is decoded in the listener's one call through
a route fixed when the network is built; the expected TPDO set is a union of per-node sets;
supervision's thresholds are worked out once per limits object; the controller's heartbeat
goes out without a can.Message. This bench, 3 runs each alternating with the tree before
(load 0.1-2.9, steal <= 0.5 %), medians: 8 nodes virtual recording on 1.118 -> 0.879 % of
the reference loop (daemon thread 0.379 -> 0.260 ms per cycle), recording off 0.971 -> 0.812 %,
loopback 0.776 -> 0.628 %, Panda 1.313 -> 1.179 %. What is left on the master's side is one
Python call per frame and receiver in the in-process bus, the drivers' per-joint state
machines and dataclasses, and on loopback the socket writes and reads (py-spy: ~40 % of the
daemon's on-CPU samples in LoopbackBus._sendall/_recv_internal).

The master's PDOs and the controller's cycle, again (issue 35, 2026-11-30): a SYNC's TPDO burst
is decoded node by node (drivers/tpdo_burst.py: one struct per node over the burst's joined
payloads, a plan per COB-ID sequence, the per-frame path for anything a plan does not cover;
22 frames 15 -> 9 us in a loop), the RPDOs are packed in CyclicIO.write from what the layout
compiled (no call per driver), set-point clamps are comparisons (not 18 min/max calls), the
end effector's and F/T states skip value() calls and generators; in the controller,
supervision's array tests are np.count_nonzero (0.2 us; ndarray.any() 0.9 us), the command's
zeros skip zeros_like's dispatch, the command goes to the drivers by tolist(), and an empty
request queue is looked at, not raised from. profile_lockstep --record: 1226 -> 1071 Python
calls per cycle (2.77 -> 2.51 ms profiled, load 12.6). This bench, 6 rounds alternating with
the tree before (01067d0; load 7.6-12.7, steal <= 0.2 %), medians: 8 nodes virtual recording
on 0.498 -> 0.422 % (runs 0.511, 0.513, 0.543, 0.485, 0.465, 0.435 / 0.428, 0.399, 0.484,
0.416, 0.432, 0.405), recording off 0.452 -> 0.361 %, loopback 0.464 -> 0.414 %;
lockstep_fingerprint identical. Still ~1.8x / 1.2x from the targets: the master's values
dicts keyed by (index, sub) (updating a cycle's ~70 values is ~6 us of the 9), a state object
per joint and per node each cycle, the controller's small-array numpy (0.2-1 us an
operation), and the simulator's half.

The simulator's per-drive glue (issue 35, 2026-11-30): the CiA 402 and end-effector states as
module constants (State.X / EeState.X are Enum class lookups on Python 3.11, ~0.1 us each
against ~0.01 us for a global; a drive's steady SYNC made ~6, the end effector's ~20), a drive's
SYNC-end flags and statusword bits from one per-state lookup, the end effector's two settings
from param()'s cache inline, the encoder reading inline in readings(). Same process, main's
methods swapped in every 25 cycles (4000 cycles): simulator CPU per SYNC 106.7 -> 98.7 us (ORU,
load 10.6), 142.3 -> 124.1 us (load 13.0), Panda 114.9 -> 106.3 us; an A/A run of the method
0.999. This bench, 4 rounds alternating with main (load 10.6-14.5): the rows within their noise
(8 nodes virtual recording on 0.330 / 0.330 %, simulator part 0.089 / 0.084 ms; loopback, whose
row is the daemon's process alone, 0.446 / 0.370 %). lockstep_fingerprint identical to main
with the core and without. Left out, measured: one core call per SYNC for all steady drives
(begin, period, end, actual values) would move the glue, not remove it: the glue is ~75
attribute reads and writes per drive and SYNC, which Python 3.11's specialised bytecode does
in 12-16 ns and C's PyObject_GetAttr in ~38 ns; the core's own calls are 0.25-0.4 us of each
phase's 0.8-1.5 us (drive in a loop of its own). Likewise tpdo_burst (~0.6 us of checks per
node, perf: generic getattr and dict lookups, nothing dominant) and rpdo_burst: each check reads
a switch that tests and the master may flip at any time, so a plan built once would need
change notifications on the nodes and their fault switches.
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.base.runtime.priority import use_normal  # noqa: E402
from hil_tests.harness import CpuSteal, free_port  # noqa: E402
from bench.reference_work import pdo_floor_seconds, reference_loop_seconds  # noqa: E402

POLLER = """
import sys, time
from spacearm.console.client import ApiClient
client = ApiClient(sys.argv[1]); period = 1 / float(sys.argv[2]); end = time.monotonic() + float(sys.argv[3])
n = 0
while time.monotonic() < end:
    client.call("status"); n += 1
    time.sleep(period)
print(n)
"""


ORU = ("configs/arm/oru_testbed_6dof.toml", "configs/bus/arm.toml", "configs/plant/oru_testbed_nominal.toml")
PANDA = ("configs/arm/panda.toml", "configs/bus/panda.toml", "configs/plant/panda_nominal.toml")  # rigid body, 7 joints


# lockstep cycle wall time as a share of the reference loop's, per row (issue 35)
REFERENCE_TARGETS = {"virtual, recording on": 0.0023, "loopback, recording on": 0.0034,
                     "virtual, recording on, Panda rigid body": 0.0033}

_HUB: list = []


def own_hub():
    """This benchmark's own loopback hub, at SCHED_FIFO 50 like the daemon and the simulator
    (the default address may be served by someone else's hub at normal priority)."""
    if not _HUB:
        from spacearm.base.transport.hub import HubProcess
        _HUB.append(HubProcess(rt_priority=50))
    return _HUB[0]


def rss_mb() -> float:
    with open("/proc/self/status") as handle:
        for line in handle:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def process_cpu(pid: int) -> float:
    """CPU seconds (user + system, all threads) a process has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# threads that tick by the wall clock, not by cycles: their CPU per cycle follows how long the run
# took on a loaded machine (the in-process simulator's heartbeat producer, the master's monitor)
WALL_CLOCK_THREADS = ("sim-heartbeat", "arm-heartbeat-monitor")
RECORDING_THREADS = ("can-trace-stream",)   # the recording's only thread in the daemon (trace_stream.py)


def threads_cpu(names: tuple[str, ...]) -> float:
    """CPU seconds this process's threads of these names have used so far (each thread's CPU
    clock, to the nanosecond: /proc's clock ticks of 10 ms are ~5 us per cycle of a 4000-cycle run)."""
    total = 0.0
    for thread in threading.enumerate():
        if thread.name in names and thread.ident is not None and thread.is_alive():
            try:
                total += time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
            except (OSError, AttributeError):      # gone meanwhile, or no per-thread clocks here
                try:
                    fields = Path(f"/proc/self/task/{thread.native_id}/stat").read_text().rsplit(")", 1)[1].split()
                except FileNotFoundError:
                    continue
                total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def helpers_cpu(pids: list[int]) -> float:
    """CPU seconds the recording's helper processes (MCAP writer, CAN trace) have used so far."""
    total = 0.0
    for pid in pids:
        try:
            total += process_cpu(pid)
        except (FileNotFoundError, ProcessLookupError):
            pass
    return total


def settle(pids: list[int], timeout: float = 10.0) -> None:
    """Wait until the helper processes have finished starting (their CPU stops growing while
    no cycle runs), so their per-cycle figure does not carry their imports."""
    last, deadline = -1.0, time.monotonic() + timeout
    while pids and time.monotonic() < deadline:
        now = helpers_cpu(pids)
        if now == last:
            return
        last = now
        time.sleep(0.2)


def start_sim(bus: str, rt_priority: int, arm: tuple[str, str, str] = ORU):
    """Start the simulated nodes; returns (stop, the in-process Simulator or None, the
    simulator's process id)."""
    if bus.startswith("virtual:"):
        from spacearm.firmware_sim.runner import start_simulator
        sim = start_simulator(bus, arm[1], arm[2], time_base="wall" if rt_priority else "sync")
        return sim.stop, sim, os.getpid()
    proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", "sim", "--bus", bus,
                             "--bus-config", arm[1], "--plant", arm[2], "--rt-priority", str(rt_priority)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        if "nodes ready" in line:
            break
    return (lambda: (proc.terminate(), proc.wait(10))), None, proc.pid


def node_frames(sim) -> int:
    """CAN frames the in-process simulated nodes received and sent so far (0 out of process)."""
    if sim is None:
        return 0
    return sum(node.stats.rx_frames + node.stats.tx_frames for node in sim.nodes.values())


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def run(bus_kind: str, clock: str, period: float, duration: float, poll_hz: float,
        record_dir: Path | None, arm: tuple[str, str, str] = ORU) -> dict:
    bus = f"virtual:bench-{time.monotonic_ns()}" if bus_kind == "virtual" else own_hub().spec(f"bench-{time.monotonic_ns()}")
    # Real time as `spacearm daemon` runs it: SCHED_FIFO 50 for the daemon and the simulated
    # nodes (base/runtime/priority.py); lockstep at normal priority. A previous real-time run left
    # this thread at SCHED_FIFO: back to normal first, children inherit the policy.
    use_normal()
    rt_priority = 50 if clock == "realtime" else 0
    stop_sim, sim, sim_pid = start_sim(bus, rt_priority, arm)
    api = f"tcp:127.0.0.1:{free_port()}"
    daemon = Daemon(DaemonOptions(bus=bus, arm=Path(arm[0]), bus_config=Path(arm[1]), clock=clock, period=period,
                                  api=api, record_dir=record_dir, rt_priority=rt_priority))
    try:
        daemon.start()
        cycles = int(duration / period) if clock == "realtime" else int(duration)
        poller = None
        if poll_hz:
            poller = subprocess.Popen([sys.executable, "-c", POLLER, api, str(poll_hz), str(duration)],
                                      cwd=ROOT, stdout=subprocess.PIPE, text=True, preexec_fn=use_normal,
                                      env={**os.environ, "PYTHONPATH": str(ROOT)})
        rss_start = rss_mb()
        memory = []
        sampler_stop = threading.Event()

        def sample():
            while not sampler_stop.wait(max(1.0, duration / 20)):
                memory.append(rss_mb())
        threading.Thread(target=sample, daemon=True).start()
        # statistics of the run only, percentiles over all of its cycles
        daemon.stats = type(daemon.stats)(daemon.options.thresholds, window=cycles + 1)
        cycle_cpu: list[float] = []
        sim_cpu: list[float] | None = None
        if clock == "lockstep":
            # thread CPU of every cycle; the in-process simulator's share of it is its SYNC handling
            if sim is not None:
                sim.cpu_samples = sim_cpu = []
            cycle_once = daemon.cycle_once

            def timed_cycle():
                started = time.thread_time()
                snapshot = cycle_once()
                cycle_cpu.append(time.thread_time() - started)
                return snapshot
            daemon.cycle_once = timed_cycle
        helpers = daemon.recorder.helper_pids() if daemon.recorder is not None else []
        settle(helpers)       # before the clocks start: its sleeps are nobody's cycle
        wall = time.monotonic()
        own_cpu = time.process_time()
        sim_process_cpu = process_cpu(sim_pid) if sim is None else 0.0
        helper_cpu = helpers_cpu(helpers)
        timer_cpu = threads_cpu(WALL_CLOCK_THREADS)
        trace_thread_cpu = threads_cpu(RECORDING_THREADS)
        frames = node_frames(sim)
        steal = CpuSteal()
        load = os.getloadavg()[0]
        daemon.run(max_cycles=cycles)
        wall = time.monotonic() - wall
        own_cpu = time.process_time() - own_cpu
        sim_process_cpu = process_cpu(sim_pid) - sim_process_cpu if sim is None else None
        helper_cpu = helpers_cpu(helpers) - helper_cpu
        timer_cpu = threads_cpu(WALL_CLOCK_THREADS) - timer_cpu
        trace_thread_cpu = threads_cpu(RECORDING_THREADS) - trace_thread_cpu
        frames = node_frames(sim) - frames
        steal_fraction = steal.fraction()
        load = max(load, os.getloadavg()[0])
        sampler_stop.set()
        polls = int(poller.communicate(timeout=duration + 30)[0] or 0) if poller else 0
        s = daemon.stats.summary()
        daemon_cpu = ([c - m for c, m in zip(cycle_cpu, sim_cpu[-len(cycle_cpu):])]
                      if sim_cpu and len(sim_cpu) >= len(cycle_cpu) else cycle_cpu)
        return {"clock": clock, "period": period, "cycles": s.cycles, "wall": wall, "summary": s,
                "scheduling": daemon.scheduling, "steal": steal_fraction, "load": load,
                "process_cpu": own_cpu, "sim_process_cpu": sim_process_cpu, "recording_helpers_cpu": helper_cpu,
                "cycle_path_cpu": own_cpu - timer_cpu, "recording_threads_cpu": trace_thread_cpu, "cycle_cpu": cycle_cpu, "sim_cpu": sim_cpu or [],
                "daemon_cpu": daemon_cpu, "joints": daemon.hardware.dof,
                # nothing is injected: any stop is a false fault (code), late cycles are excused misses
                "stop": daemon.core.stop_reason, "late_cycles": daemon.hardware.late_cycles,
                "starved_checks": daemon.hardware.network.stats.starved_checks,
                "frames_per_cycle": frames / max(1, s.cycles) if sim is not None else None,
                "polls": polls, "rss_start": rss_start, "rss_end": rss_mb(),
                "rss_mid": memory[len(memory) // 2] if memory else rss_start}
    finally:
        daemon.shutdown()
        stop_sim()


def interleaved_recording(cycles: int, segment: int = 25) -> dict:
    """What recording costs the cycle, measured inside one recording run (8 nodes, virtual):
    recording is switched off and on every `segment` cycles (on, off, off, on, ...), so what
    the machine does meanwhile (other processes, the host) falls on both alike. Off takes the
    recorder out of the cycle and the CAN trace's tap off the bus; its helper processes stay,
    idle. Per segment: this process's CPU (all threads) and the cycle thread's; the share is
    the median over blocks of four segments (on, off, off, on), robust to a burst of other
    work hitting a few segments. The CAN trace's batching thread wakes every 0.2 s (~15
    segments) and lands on on and off segments alike, so the medians leave it out: its CPU
    over the run, per cycle recorded, is measured on its own clock and added to the share."""
    use_normal()
    bus = f"virtual:bench-{time.monotonic_ns()}"
    stop_sim, _, _ = start_sim(bus, 0)
    records = Path(tempfile.mkdtemp(prefix="spacearm-bench-interleaved-"))
    daemon = Daemon(DaemonOptions(bus=bus, arm=Path(ORU[0]), bus_config=Path(ORU[1]), clock="lockstep", period=0.02,
                                  api=None, record_dir=records))
    segments: list[tuple[bool, float, float]] = []     # on, process CPU, cycle thread CPU
    try:
        daemon.start()
        recorder = daemon.recorder
        tap_bus, _, tap = recorder._can_trace._in_process      # the in-process bus's tap (can_trace.py)
        daemon.run(max_cycles=300)     # first calls, not measured
        settle(recorder.helper_pids())
        steal, load, on = CpuSteal(), os.getloadavg()[0], True
        trace_thread = threads_cpu(RECORDING_THREADS)
        for k in range(cycles // segment):
            wanted = k % 4 in (0, 3)
            if wanted != on:
                on = wanted
                daemon.recorder = recorder if on else None
                (tap_bus._taps.add if on else tap_bus._taps.remove)(tap)
            process, thread = time.process_time(), time.thread_time()
            daemon.run(max_cycles=segment)
            segments.append((on, time.process_time() - process, time.thread_time() - thread))
        trace_thread = threads_cpu(RECORDING_THREADS) - trace_thread
        if not on:
            daemon.recorder = recorder
            tap_bus._taps.add(tap)
        info = recorder.info()
        blocks = [segments[i:i + 4] for i in range(0, len(segments) - 3, 4)]
        shares = [[_block_share(block, j) for block in blocks] for j in (1, 2)]
        per_cycle = {state: tuple(sum(s[j] for s in segments if s[0] is state)
                                  / (segment * sum(1 for s in segments if s[0] is state)) for j in (1, 2))
                     for state in (True, False)}
        on_cycles = segment * sum(1 for s in segments if s[0])
        return {"per_cycle": per_cycle, "share": [statistics.median(v) for v in shares],
                "batching": trace_thread / on_cycles / per_cycle[True][0],
                "load": max(load, os.getloadavg()[0]), "steal": steal.fraction(), "segment": segment,
                "cycles": cycles, "recorded": info.cycles, "dropped": info.dropped}
    finally:
        daemon.shutdown()
        stop_sim()
        shutil.rmtree(records, ignore_errors=True)


def _block_share(block: list[tuple[bool, float, float]], j: int) -> float:
    """(on - off) / on of figure j over a block's two on and two off segments."""
    on = sum(segment[j] for segment in block if segment[0])
    return (on - sum(segment[j] for segment in block if not segment[0])) / on


def interleaved_rows(runs: list[dict]) -> list[tuple]:
    """The recording's share from interleaved runs (median over runs judged): the median over
    blocks of process CPU plus the trace batching thread's CPU, which the medians leave out."""
    process = [r["share"][0] + r["batching"] for r in runs]
    thread = [r["share"][1] for r in runs]
    listed = lambda values: ", ".join(f"{100 * v:.1f}" for v in values)
    median = statistics.median(process)
    ms = lambda state, i: statistics.median(1e3 * r["per_cycle"][state][i] for r in runs)
    first = runs[0]
    return [
        (f"recording's share of the lockstep cycle, interleaved (8 nodes, virtual; on/off every "
         f"{first['segment']} cycles in one run; process CPU; median of blocks, of {len(runs)} runs)",
         f"{100 * median:.1f} % (runs: {listed(process)} %)", "<= 10 %", median <= 0.10),
        ("  of which the CAN trace's batching thread (its own CPU clock, per cycle recorded)",
         f"{100 * statistics.median(r['batching'] for r in runs):.1f} % (runs: {listed([r['batching'] for r in runs])} %)",
         "", ""),
        ("  the cycle thread's CPU alone (median of blocks)",
         f"{100 * statistics.median(thread):.1f} % (runs: {listed(thread)} %)", "", ""),
        ("  process CPU per cycle recording on / off (medians)", f"{ms(True, 0):.3f} / {ms(False, 0):.3f} ms", "", ""),
        ("  machine load / host CPU steal over the runs",
         f"{min(r['load'] for r in runs):.1f}-{max(r['load'] for r in runs):.1f} / "
         f"{100 * min(r['steal'] for r in runs):.1f}-{100 * max(r['steal'] for r in runs):.1f} %", "", ""),
        ("  cycles handed over / dropped (first run: warm-up and on segments)", f"{first['recorded']} / {first['dropped']}",
         "", ""),
    ]


def recording_share_rows(pairs: list[tuple[dict, dict]]) -> list[tuple]:
    """What recording costs the daemon: process CPU per cycle with recording on against off, per
    alternating pair of runs (median judged); the helper processes' CPU beside it for information."""
    per_cycle = lambda r, key: r[key] / r["cycles"]
    shares = [(per_cycle(on, "process_cpu") - per_cycle(off, "process_cpu")) / per_cycle(on, "process_cpu")
              for on, off in pairs]
    walls = [(per_cycle(on, "wall") - per_cycle(off, "wall")) / per_cycle(on, "wall") for on, off in pairs]
    helpers = statistics.median(per_cycle(on, "recording_helpers_cpu") for on, _ in pairs)
    off_cpu = statistics.median(per_cycle(off, "process_cpu") for _, off in pairs)
    paths = [(per_cycle(on, "cycle_path_cpu") - per_cycle(off, "cycle_path_cpu")) / per_cycle(on, "cycle_path_cpu")
             for on, off in pairs]
    # the cycle thread's median CPU per cycle (robust to the slices a loaded machine's neighbours
    # take) plus the recording's own thread
    typical = lambda r: percentile(r["cycle_cpu"], 0.5) + per_cycle(r, "recording_threads_cpu")
    medians = [(typical(on) - typical(off)) / typical(on) for on, off in pairs]
    share = statistics.median(shares)
    runs = [r for pair in pairs for r in pair]
    listed = lambda values: ", ".join(f"{100 * v:.0f}" for v in values)
    return [
        (f"recording's share from separate runs (8 nodes, virtual; daemon process CPU, median of {len(pairs)} "
         "on/off pairs; the machine's state differs between runs: see the interleaved rows)",
         f"{100 * share:.1f} % (pairs: {listed(shares)} %); wall {100 * statistics.median(walls):.0f} %", "", ""),
        ("  the same without the wall-clock timer threads (heartbeats: CPU per wall second, not per cycle)",
         f"{100 * statistics.median(paths):.1f} % (pairs: {listed(paths)} %)", "", ""),
        ("  the same from the cycle thread's median CPU per cycle (+ the trace batching thread)",
         f"{100 * statistics.median(medians):.1f} % (pairs: {listed(medians)} %)", "", ""),
        ("  machine load / host CPU steal over the pairs",
         f"{min(r['load'] for r in runs):.1f}-{max(r['load'] for r in runs):.1f} / "
         f"{100 * min(r['steal'] for r in runs):.1f}-{100 * max(r['steal'] for r in runs):.1f} %", "", ""),
        ("  recording helpers' CPU per cycle (MCAP writer, CAN trace formatter: own niced processes)",
         f"{1e3 * helpers:.3f} ms = {100 * helpers / off_cpu:.1f} % of the unrecorded cycle's", "", ""),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="s of the 20 ms real-time run (issue: 600)")
    ap.add_argument("--duration-4ms", type=float, default=None,
                    help="s of the 4 ms run (default: --duration; 0: skip it)")
    ap.add_argument("--transport", default="loopback", choices=["loopback", "virtual"])
    ap.add_argument("--lockstep-cycles", type=int, default=2000)
    ap.add_argument("--lockstep-only", action="store_true", help="skip the real-time runs")
    ap.add_argument("--realtime-only", action="store_true", help="skip the lockstep runs")
    ap.add_argument("--recording-pairs", type=int, default=4,
                    help="alternating recording on/off lockstep runs (8 nodes, virtual) behind the recording's "
                         "share, the first pair being the rows above (on 2 shared cores one pair is noise)")
    ap.add_argument("--interleaved-runs", type=int, default=3,
                    help="runs switching recording on and off inside the run (the judged recording share)")
    ap.add_argument("--cpu-load", type=int, default=0,
                    help="CPU-bound processes beside the real-time runs (issue 22: 2)")
    args = ap.parse_args()
    rows = []
    records = Path(tempfile.mkdtemp(prefix="spacearm-bench-daemon-"))
    realtime = []
    if not args.lockstep_only:
        from hil_tests.cpu_load import CpuLoad
        with CpuLoad(args.cpu_load):
            realtime = [("20 ms", run(args.transport, "realtime", 0.02, args.duration, 20, records))]
            duration_4ms = args.duration if args.duration_4ms is None else args.duration_4ms
            if duration_4ms > 0:     # --duration-4ms 0: the 20 ms run only
                realtime.append(("4 ms", run(args.transport, "realtime", 0.004, duration_4ms, 20, records)))
    # Lockstep on both transports: in-process (the embedded default bus, frames handled inline)
    # and loopback (simulator in its own process, frames through the hub).
    # Recording on as the daemon runs by default; once off to show what recording costs.
    # Then the rigid-body plant (Pinocchio) with 7 joints: the Panda of the any-arm issue.
    # The reference workloads are timed before and after the lockstep runs, in this process.
    reference = [] if args.realtime_only else [reference_loop_seconds()]
    if not args.realtime_only:     # warm-up, not reported: the first run in a process pays for first calls
        run("virtual", "lockstep", 0.02, min(300, args.lockstep_cycles), 0, None)
    locks = [] if args.realtime_only else [
        (f"{kind}, recording {'on' if rec else 'off'}", run(kind, "lockstep", 0.02, args.lockstep_cycles, 0, rec))
        for kind, rec in (("virtual", records), ("virtual", None), ("loopback", records))]
    if not args.realtime_only:
        locks.append(("virtual, recording on, Panda rigid body",
                      run("virtual", "lockstep", 0.02, args.lockstep_cycles, 0, records, PANDA)))
        by_kind = dict(locks)
        pairs = [(by_kind["virtual, recording on"], by_kind["virtual, recording off"])]
        for i in range(1, args.recording_pairs):   # alternating which of the two runs first
            first, second = (records, None) if i % 2 == 0 else (None, records)
            runs = {d: run("virtual", "lockstep", 0.02, args.lockstep_cycles, 0, d) for d in (first, second)}
            pairs.append((runs[records], runs[None]))
        interleaved = [interleaved_recording(args.lockstep_cycles) for _ in range(args.interleaved_runs)]
        reference.append(reference_loop_seconds())
    shutil.rmtree(records, ignore_errors=True)
    for hub in _HUB:
        hub.stop()
    ms = lambda v: f"{1e3 * v:.3f} ms"
    for name, r in realtime:
        s = r["summary"]
        p99_target = "<= 1 ms" if r["period"] == 0.02 else "<= 0.5 ms"
        rows += [
            (f"real time {name}: period error median", ms(s.period_error_median), "", ""),
            (f"real time {name}: period error p99", ms(s.period_error_p99), p99_target,
             s.period_error_p99 <= (0.001 if r["period"] == 0.02 else 0.0005)),
            (f"real time {name}: period error max", ms(s.period_error_max), "<= 5 ms" if r["period"] == 0.02 else "",
             s.period_error_max <= 0.005 if r["period"] == 0.02 else ""),
            (f"real time {name}: execution median / p99", f"{ms(s.execution_median)} / {ms(s.execution_p99)}",
             "p99 <= 3 ms" if r["period"] == 0.02 else "", s.execution_p99 <= 0.003 if r["period"] == 0.02 else ""),
            (f"real time {name}: of which compute (no TPDO wait) median / p99",
             f"{ms(s.compute_median)} / {ms(s.compute_p99)}", "", ""),
            (f"real time {name}: overruns (skipped cycles)", f"{s.overruns} ({s.skipped_cycles}) of {s.cycles}",
             "0" if r["period"] == 0.02 else "", s.overruns == 0 if r["period"] == 0.02 else ""),
            (f"real time {name}: false faults (stops, nothing injected)",
             "0" if r["stop"] is None else f"1: [{r['stop'].code.value}] {r['stop'].message}"[:48], "0",
             r["stop"] is None),
            (f"real time {name}: late cycles excused / starved heartbeat checks",
             f"{r['late_cycles']} / {r['starved_checks']}", "", ""),
            (f"real time {name}: status polls answered", f"{r['polls']} in {r['wall']:.0f} s", "20 Hz", ""),
            (f"real time {name}: host CPU steal / machine load during the run",
             f"{100 * r['steal']:.1f} % / {r['load']:.1f} ({args.cpu_load} CPU-bound neighbours)", "", ""),
            (f"real time {name}: daemon RSS start / mid / end",
             f"{r['rss_start']:.1f} / {r['rss_mid']:.1f} / {r['rss_end']:.1f} MB", "no growth", ""),
        ]
    if reference:
        ref_wall = statistics.median(r[0] for r in reference)
        ref_cpu = statistics.median(r[1] for r in reference)
        rows.append(("reference loop (s += i*i, 2e6 i) wall / CPU, median before+after",
                     f"{ms(ref_wall)} / {ms(ref_cpu)}", "", ""))
    for kind, lock in locks:
        speedup = lock["cycles"] * lock["period"] / lock["wall"]
        nodes = lock["joints"] + 2
        wall_per_cycle = lock["wall"] / lock["cycles"]
        cpu_per_cycle = lock["process_cpu"] / lock["cycles"]
        # Targets in reference units (issue 35): 3x below the slower machine's measured cost,
        # 2.51 / 3.73 / 3.65 ms per cycle against its ~370 ms reference loop.
        target = REFERENCE_TARGETS.get(kind)
        # Judged on CPU (process CPU per cycle against the loop's CPU): on a busy machine both wall
        # figures stretch, but by how much depends on how many threads each keeps runnable.
        share = cpu_per_cycle / ref_cpu
        rows.append((f"lockstep cycle / reference loop ({nodes} nodes, {kind})",
                     f"{100 * share:.3f} % CPU, {100 * wall_per_cycle / ref_wall:.3f} % wall",
                     f"<= {100 * target:.2f} %" if target else "", share <= target if target else ""))
        if lock["frames_per_cycle"]:
            floor_wall, _ = pdo_floor_seconds(round(lock["frames_per_cycle"] * 1000))
            rows.append(("  cycle / PDO floor (same frames packed+unpacked with struct)",
                         f"{wall_per_cycle / (floor_wall / 1000):.0f}x ({lock['frames_per_cycle']:.1f} frames/cycle)",
                         "", ""))
        rows.append((f"  speed-up over real time (for information)",
                     f"{speedup:.1f}x ({lock['cycles']} cycles in {lock['wall']:.1f} s, "
                     f"{1e3 * wall_per_cycle:.2f} ms/cycle)", "", ""))
        rows.append(("  machine load / host CPU steal", f"{lock['load']:.1f} / {100 * lock['steal']:.1f} %", "", ""))
        rows.append(("  false faults (stops, nothing injected) / late cycles / starved checks",
                     ("0" if lock["stop"] is None else f"1: [{lock['stop'].code.value}]")
                     + f" / {lock['late_cycles']} / {lock['starved_checks']}", "0", lock["stop"] is None))
        rows.append(("  process CPU per cycle (all threads)", ms(cpu_per_cycle), "", ""))
        if lock["sim_process_cpu"] is not None:     # loopback: the simulator is its own process
            rows.append(("  simulator process CPU per cycle (all threads)",
                         ms(lock["sim_process_cpu"] / lock["cycles"]), "", ""))
        for label, samples in (("simulator", lock["sim_cpu"]), ("daemon", lock["daemon_cpu"])):
            if samples:
                rows.append((f"  CPU per cycle, {label}: median / p99",
                             f"{ms(percentile(samples, 0.5))} / {ms(percentile(samples, 0.99))}", "", ""))
    if not args.realtime_only:
        rows += recording_share_rows(pairs)
        if interleaved:
            rows += interleaved_rows(interleaved)
    print(f"machine: {platform.platform()} | {os.cpu_count()} cores | python {platform.python_version()} | "
          f"real-time transport {args.transport} | load {os.getloadavg()[0]:.2f} at the end | "
          f"real-time runs: {realtime[0][1]['scheduling'] if realtime else '-'}")
    width = max(len(r[0]) for r in rows)
    print(f"{'figure':<{width}}  {'measured':<48}  {'target':<12}  result")
    for figure, measured, target, ok in rows:
        result = "" if ok == "" else ("pass" if ok else "FAIL")
        print(f"{figure:<{width}}  {measured:<48}  {target:<12}  {result}")


if __name__ == "__main__":
    main()
