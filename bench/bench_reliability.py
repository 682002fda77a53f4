"""Reliability figures: faults injected / survived with a safe state, worst time to safe state
per fault class (cycles of 20 ms and ms), fuzz cases run / crashes.

    .venv/bin/python bench/bench_reliability.py [--repeat 1] [--fuzz-examples 300]

Runs the fault-injection suite (hil_tests/test_faults_*.py: daemon and simulator as separate
processes, real-time 20 ms clock, loopback hub with frame loss/reorder/cut) `--repeat` times
and the fuzz suite (tests/fuzz/) once, collecting what the tests measured (hil_tests/faults.py
writes one line per fault to SPACEARM_FAULT_RESULTS; the fuzz conftest counts cases), and
prints the table. "to stop": injection -> protective stop in status, as control cycles
executed (what the bounds are about) and wall time (longer than cycles x 20 ms when the
loaded machine overruns); "to rest": -> every drive
disabled and every joint at rest (quick-stop ramp done, brakes on).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PERIOD_MS = 20.0

# test name -> (fault class, expected reaction) for the tests that end in a protective stop or
# tolerate the fault; bounds in cycles as asserted in the tests.
FAULTS = {
    "test_heartbeat_loss_stops_the_arm": ("node heartbeat stops", 20),
    "test_emcy_drive_fault_stops_the_arm": ("EMCY / drive fault", 10),
    "test_joint_stall_mid_motion_stops_on_following_error": ("joint stall -> following error", 25),
    "test_ft_overload_stops_the_arm": ("F/T overload", 10),
    "test_ft_jump_stops_the_arm": ("F/T jump", 10),
    "test_frozen_ft_sensor_stops_the_arm": ("F/T frozen", 40),
    "test_joint_limit_hit_stops_the_arm": ("joint limit hit", 10),
    "test_jogging_console_that_vanishes_stops_the_jog": ("command watchdog: console gone", 10),
    "test_silent_jogging_console_stops_after_the_keepalive": ("command watchdog: console silent", 65),
    "test_waiting_console_keeps_its_jog_alive": ("(no fault) waiting console keeps jog", None),
    "test_planned_move_runs_to_its_end_without_its_console": ("(no fault) move --no-wait runs", None),
    "test_bus_blackout_stops": ("bus blackout", 12),
    "test_frame_loss_and_reordering_end_at_the_target_or_in_a_stop": ("1 % frame loss + reorder", None),
    "test_daemon_connection_cut_and_back_is_tolerated_or_stops": ("transport disconnect + reconnect", None),
    "test_daemon_killed_mid_motion_restarts_disabled_with_brakes_on": ("daemon killed mid-motion", None),
    "test_node_restart_is_an_unexpected_bootup_and_stops": ("node restart (boot-up)", 10),
    "test_simulator_killed_mid_motion_stops": ("simulator killed mid-motion", 12),
    "test_laser_ranger_timeout_raises_within_bounded_time": ("laser ranger timeout", None),
    "test_laser_ranger_garbage_is_rejected_then_raises": ("laser ranger garbage", None),
    "test_marker_lost_mid_approach_stops_within_lost_frames": ("marker lost mid-approach (core)", 8),
    "test_camera_stopping_mid_approach_stops_after_the_frame_timeout": ("camera stops mid-approach (core)", 503),
}
# tests whose injected fault is itself missing process data or heartbeats
MISSING_DATA_FAULTS = {"test_heartbeat_loss_stops_the_arm", "test_bus_blackout_stops",
                       "test_simulator_killed_mid_motion_stops", "test_node_restart_is_an_unexpected_bootup_and_stops"}
# the fault name each test passes to wait_safe -> test name
WAIT_NAMES = {
    "heartbeat lost": "test_heartbeat_loss_stops_the_arm", "EMCY / drive fault": "test_emcy_drive_fault_stops_the_arm",
    "joint stall": "test_joint_stall_mid_motion_stops_on_following_error", "F/T overload": "test_ft_overload_stops_the_arm",
    "F/T jump": "test_ft_jump_stops_the_arm", "F/T frozen": "test_frozen_ft_sensor_stops_the_arm",
    "joint limit": "test_joint_limit_hit_stops_the_arm",
    "jogging console vanished": "test_jogging_console_that_vanishes_stops_the_jog",
    "jogging console silent": "test_silent_jogging_console_stops_after_the_keepalive",
    "bus blackout": "test_bus_blackout_stops", "node restart": "test_node_restart_is_an_unexpected_bootup_and_stops",
    "simulator killed": "test_simulator_killed_mid_motion_stops",
}


def run_pytest(paths: list[str], env: dict, junit: Path) -> None:
    cmd = [sys.executable, "-m", "pytest", *paths, "-q", "-p", "no:cacheprovider", f"--junitxml={junit}",
           "-W", "ignore::DeprecationWarning"]
    subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def outcomes(junit: Path) -> dict[str, list[bool]]:
    result: dict[str, list[bool]] = defaultdict(list)
    if not junit.exists():
        return result
    for case in ET.parse(junit).getroot().iter("testcase"):
        name = case.get("name", "").split("[")[0]
        failed = any(child.tag in ("failure", "error") for child in case)
        skipped = any(child.tag == "skipped" for child in case)
        if not skipped:
            result[name].append(not failed)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1, help="runs of the fault suite")
    parser.add_argument("--fuzz-examples", type=int, default=300, help="hypothesis cases per fuzz test")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="spacearm-reliability-"))
    results_file, counts_file = work / "faults.jsonl", work / "fuzz.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT), SPACEARM_FAULT_RESULTS=str(results_file),
               SPACEARM_FUZZ_COUNTS=str(counts_file), SPACEARM_FUZZ_EXAMPLES=str(args.fuzz_examples))
    fault_outcomes: dict[str, list[bool]] = defaultdict(list)
    for i in range(args.repeat):
        junit = work / f"faults{i}.xml"
        run_pytest(["hil_tests/test_faults_devices.py", "hil_tests/test_faults_process.py",
                    "hil_tests/test_faults_ranger.py", "hil_tests/test_faults_camera.py"], env, junit)
        for name, oks in outcomes(junit).items():
            fault_outcomes[name] += oks
    junit = work / "fuzz.xml"
    run_pytest(["tests/fuzz"], env, junit)
    fuzz_outcomes = outcomes(junit)

    # Every stop counts where it happened: starvation of the controller is coded late_cycle
    # and never stops the arm, so a stop for missing data or a lost heartbeat in a test that
    # injected another fault is not excused here but listed as a finding.
    measured: dict[str, list[dict]] = defaultdict(list)
    findings: list[str] = []
    late_cycles = starved_checks = 0
    if results_file.exists():
        for line in results_file.read_text().splitlines():
            r = json.loads(line)
            test = WAIT_NAMES.get(r["fault"], r["fault"])
            measured[test].append(r)
            late_cycles += r.get("late_cycles", 0)
            starved_checks += r.get("starved_checks", 0)
            if r.get("code") in ("pdo_missing", "heartbeat_lost") and test not in MISSING_DATA_FAULTS:
                findings.append(f"{FAULTS.get(test, (test,))[0]}: stopped [{r['code']}] {r['reason'][:90]}")

    print(f"reliability on {platform.node()} ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at the end), "
          f"python {platform.python_version()}, fault suite x{args.repeat}")
    print(f"\n{'fault':<40} {'injected':>8} {'safe':>5} {'worst to stop':>22} {'worst to rest':>14} {'bound':>8} "
          f"{'late cycles':>11}")
    total = survived = 0
    for test, (label, bound) in FAULTS.items():
        oks = fault_outcomes.get(test, [])
        if not oks:
            print(f"{label:<40} {'not run':>8}")
            continue
        total += len(oks)
        survived += sum(oks)
        rs = measured.get(test, [])
        stop = max((r["to_stop"] for r in rs), default=None)
        cyc = max((r.get("cycles", 0) for r in rs), default=None)
        rest = [r["to_rest"] for r in rs if r["to_rest"] == r["to_rest"]]
        stop_txt = f"{cyc:4d} cyc {stop * 1e3:7.0f} ms" if stop is not None else "-"
        rest_txt = f"{max(rest) * 1e3:8.0f} ms" if rest else "-"
        bound_txt = f"{bound} cyc" if bound else "-"
        late = sum(r.get("late_cycles", 0) for r in rs)
        print(f"{label:<40} {len(oks):>8} {sum(oks):>5} {stop_txt:>22} {rest_txt:>14} {bound_txt:>8} {late:>11}")
    print(f"{'total':<40} {total:>8} {survived:>5}")
    print(f"late cycles (the controller was starved; its missing data excused, no stop): {late_cycles} "
          f"in {sum(len(v) for v in measured.values())} measured faults; starved heartbeat checks: {starved_checks}")
    print(f"stops for missing data or a lost heartbeat in a test injecting another fault (findings, "
          f"expected 0): {len(findings)}")
    for finding in findings:
        print(f"  {finding}")

    counts = json.loads(counts_file.read_text()) if counts_file.exists() else {}
    print(f"\n{'fuzz target':<40} {'cases':>8} {'crashes':>8}")
    crashes = sum(1 for oks in fuzz_outcomes.values() for ok in oks if not ok)
    for name, n in sorted(counts.items()):
        print(f"{name:<40} {n:>8}")
    print(f"{'total (failing fuzz tests = crashes)':<40} {sum(counts.values()):>8} {crashes:>8}   target 0")
    print(f"\nraw results in {work}")


if __name__ == "__main__":
    main()
