"""Real time beside other work (issue: the changeout and the main job hold their 20 ms on a
busy machine). Each test runs beside two CPU-bound processes (hil_tests/cpu_load.py), asserts
no protective stop, and reports what the load cost as junit properties (record_property):
skipped cycles, overruns, period error p99, the simulator's own late wakes and their cause,
the load average and CPU steal over the test. Targets (0 skipped cycles, p99 <= 1 ms) are the
bench's (bench/bench_realtime.py), not asserted here: a starved CI machine is not a fault of
the stack, a protective stop is.

- ORU changeout stage 1 on separate processes in real time, as the issue ran it: `spacearm hub`
  and `spacearm sim --plant configs/oru/plant_cell.toml` at --rt-priority 50, `spacearm daemon`
  on the realtime clock (SCHED_FIFO 50), `spacearm oru run --stages 1`.
- The main job, `spacearm demo --stages 1` (real time, camera, one process plus its render
  process): the same stage with the closed-loop approach on the camera.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import pytest

from spacearm.base.config.arm import load_arm_config
from hil_tests.conftest import ROOT, child_env
from hil_tests.harness import CpuSteal, StealTimeline, free_port, xfail_if_the_host_stalled_a_vcpu
from hil_tests.test_daemon_console import Console

pytestmark = [pytest.mark.hil, pytest.mark.multiprocess, pytest.mark.slow, pytest.mark.under_load]

PLANT = "configs/oru/plant_cell.toml"


def _record_conditions(record_property, steal: CpuSteal) -> None:
    record_property("load_average", f"{os.getloadavg()[0]:.1f}")
    record_property("cpu_steal_percent", f"{100 * steal.fraction():.1f}")


def test_oru_stage_1_in_real_time_on_separate_processes(loopback_hub, launch, tmp_path, time_scale, record_property,
                                                         request):
    steal, timeline = CpuSteal(), StealTimeline()
    request.addfinalizer(timeline.stop)
    bus = loopback_hub.spec(f"rt-oru-{os.getpid()}-{time.monotonic_ns()}")
    launch(["-m", "spacearm.console.main", "sim", "--plant", PLANT, "--rt-priority", "50"], bus_spec=bus,
           ready="nodes ready")
    api = f"tcp:127.0.0.1:{free_port()}"
    launch(["-m", "spacearm.console.main", "daemon", "--clock", "realtime", "--rt-priority", "50", "--api", api,
            "--no-record"], bus_spec=bus, ready="spacearm daemon:", timeout=30)
    op = Console(api, tmp_path / "operator")
    # a stop before the changeout (idle, or on the way to ready) is judged below, with the
    # figures, as one in the changeout is
    ready = map(str, load_arm_config("configs/arm/oru_testbed_6dof.toml").postures["ready"])
    for step in (["enable"], ["move", "joints", *ready]):
        moved = op.run(*step, check=False)
        if moved.returncode:
            break
    started = op.run("oru", "run", "--stages", "1", "--no-wait", check=False) if moved.returncode == 0 else moved
    if started.returncode:      # refused (a stop came first): judged below like one in the changeout
        oru = {"state": "not started", "failure": started.stdout + started.stderr}
    else:
        deadline = time.monotonic() + 300 * time_scale
        while (oru := json.loads(op.run("oru", "status", "--json").stdout))["state"] in ("running", "paused") \
                and not oru.get("pause"):
            assert time.monotonic() < deadline, oru
            time.sleep(1.0)
    status = op.status()
    stats, peers = status["stats"], (status.get("nodes") or {}).get("peers") or {}
    record_property("skipped_cycles", stats["skipped_cycles"])
    record_property("overruns", stats["overruns"])
    record_property("cycles", stats["cycles"])
    # nodes' answers after the daemon's TPDO wait, within their period: slow, never counted as loss
    record_property("late_answers", (status.get("network") or {}).get("late_answers", 0))
    record_property("period_error_p99_ms", f"{1e3 * stats['period_error_p99']:.3f}")
    record_property("scheduling", status.get("scheduling", ""))
    for name, peer in peers.items():
        record_property(f"{name}_late", f"{peer['late_cycles']} of {peer['cycles']}, max "
                                        f"{1e3 * peer['max_lateness']:.1f} ms, {peer.get('cause') or '-'}")
    _record_conditions(record_property, steal)
    xfail_if_the_host_stalled_a_vcpu(status, timeline, peers)
    assert status["stop"] is None, (status["stop"], status.get("nodes"))
    assert moved.returncode == 0, moved.stdout + moved.stderr
    assert oru["state"] == "done", (oru.get("failure"), oru.get("pause"))
    assert "SCHED_FIFO 50" in status.get("scheduling", ""), status.get("scheduling")


def test_main_job_stage_1_in_real_time(tmp_path, time_scale, record_property):
    steal = CpuSteal()
    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "demo", "--stages", "1",
                          "--record-dir", str(tmp_path / "runs")], capture_output=True, text=True, cwd=ROOT,
                         env=child_env({"COLUMNS": "200"}), timeout=600 * time_scale, stdin=subprocess.DEVNULL)
    text = out.stdout + out.stderr
    _record_conditions(record_property, steal)
    summary = re.search(r"period error median ([\d.]+) ms, p99 ([\d.]+) ms, max ([\d.]+) ms; execution p99 "
                        r"([\d.]+) ms; overruns (\d+) \((\d+) cycles skipped\)", text)
    if summary:
        record_property("period_error_p99_ms", summary.group(2))
        record_property("overruns", summary.group(5))
        record_property("skipped_cycles", summary.group(6))
    scheduling = re.search(r"scheduling: (.*)", text)
    record_property("scheduling", scheduling.group(1) if scheduling else "")
    assert out.returncode == 0, text[-3000:]              # a protective stop fails the changeout: exit 1
    assert summary, text[-3000:]
    assert "cycle SCHED_FIFO 50" in text and "simulated nodes SCHED_FIFO 50" in text and "own process" in text, \
        text[-2000:]
