"""ORU changeout benchmark: the paper's stiffness experiment, randomised insertions, the full
changeout on the demo plant with hidden errors (open loop vs the closed-loop approach on the
camera, lockstep and real time), randomised approaches open vs closed loop on the same draws,
and the vision time per frame. Prints one table.

    .venv/bin/python bench/bench_oru.py [--trials 200] [--approaches 200] [--seed 1] [--skip-realtime]
    .venv/bin/python bench/bench_oru.py --only-approaches --approaches 200 [--workers 2] [--approaches-results DIR]

The stiffness experiment and the insertions run the plant and the controller's own contact
code (spacearm.controller.oru.flow's ContactTask in the ImpedanceMode, the drives' servo law) in one
loop without the CAN transport (offline/contact/direct_loop.py) for speed; the full changeout
runs the daemon, the simulated nodes and the simulated camera (shared-memory ring, the
daemon's vision worker) over the embedded virtual CAN bus; the randomised approaches run the
approach mode, the camera renderer and the vision pipeline in one loop
(offline/scenarios/approach_trials.py: ~10 s per closed-loop trial here), one draw a trial of
the changeout_approach campaign on Dask (configs/campaigns/changeout_approach.toml).
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.offline.scenarios.changeout import run_changeout  # noqa: E402
from spacearm.offline.contact.trials import ContactTrials, run_stiffness_direct  # noqa: E402
from spacearm.firmware_sim.runner import start_simulator  # noqa: E402
from spacearm.controller.impedance.config import load_impedance  # noqa: E402
from spacearm.offline.scenarios.changeout import ChangeoutFailed, start_camera  # noqa: E402
from spacearm.offline.campaign.report import wilson_interval  # noqa: E402
from hil_tests.harness import CpuSteal  # noqa: E402

IMPEDANCE = load_impedance()


def vision_timing(seed: int, frames: int = 30) -> list[tuple[str, str, str]]:
    """bench_vision's timing on rendered frames (full frame and tracking, accuracy beside)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_vision import timing
    from spacearm.controller.vision.pipeline import VisionPipeline
    from spacearm.firmware_sim.camera.simulator import CameraSimulator
    pipe = VisionPipeline.from_configs()
    rows = [r for r in timing(pipe, CameraSimulator.from_configs(scene_seed=0, noise_seed=seed), frames,
                              np.random.default_rng(seed)) if "time per" in r][:2]   # OpenCV's configured threads
    out = []
    for r in rows:
        name, measured, target, _, accuracy = (p.strip() for p in r.split("|"))
        out.append((name.replace("time per 1360x1024 frame, ", ""), f"{measured}; {accuracy}", target))
    return out


INSERTION_CAMPAIGN = ROOT / "configs" / "campaigns" / "insertion.toml"


def insertions(n: int, seed: int, workers: int | None) -> dict:
    """The randomised insertions as a campaign on Dask (configs/campaigns/insertion.toml with this
    run's count and seed; `spacearm campaign` runs, resumes and replays the same trials)."""
    from spacearm.offline.campaign.runner import run_campaign
    from spacearm.offline.campaign.schema import campaign_from_text
    from spacearm.offline.campaign.store import ResultStore
    text = INSERTION_CAMPAIGN.read_text()
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", text)
    text = re.sub(r"(?m)^trials = \d+", f"trials = {n}", text)
    results = Path(tempfile.mkdtemp(prefix="bench-oru-insertions-"))
    run_campaign(campaign_from_text(text, str(INSERTION_CAMPAIGN)), results, workers=workers)
    rows = ResultStore(results).rows()
    print(f"  insertion trials: {results} (Parquet, one file per trial)", file=sys.stderr)
    ok = [r for r in rows if r["success"]]
    figure = lambda name, of=rows: np.array([r[f"f_{name}"] for r in of if r.get(f"f_{name}") is not None])  # noqa: E731
    return {
        "success": len(ok) / n, "n": n,
        "lateral": figure("peak_lateral_force"), "torque": figure("peak_torque"),
        "insert": figure("peak_insert_force"),
        "time": figure("arm_time", ok) if ok else np.array([math.nan]),
        "wall": np.array([r["w_trial_wall_time"] for r in rows if r.get("w_trial_wall_time") is not None]),
        "failures": [r["failure"] or r["error"] for r in rows if not r["success"]][:3],
    }


DEMO_PLANT = "configs/plant/oru_cell_errors.toml"
CHANGEOUT_BUS = "configs/oru/bus_shared_machine.toml"


def changeout(clock: str, bus_config: str, vision: bool = True, plant: str = DEMO_PLANT, keep_daemon: bool = False,
              frame_rate: float | None = None):
    """(wall s, ChangeoutResult or None, failure message or None, vision worker times s)
    (+ the daemon, shut down, with keep_daemon)."""
    bus = f"virtual:bench-oru-{time.monotonic_ns()}"
    sim = start_simulator(bus, bus_config, plant, time_base="sync" if clock == "lockstep" else "wall")
    ring = camera = None
    if vision:
        ring, camera = start_camera(sim, frame_rate)
    daemon = Daemon(DaemonOptions(bus=bus, bus_config=bus_config, clock=clock, api=None, record_dir=None,
                                  camera=camera))
    started = time.monotonic()
    try:
        daemon.start()
        thread = threading.Thread(target=daemon.run, daemon=True)
        thread.start()
        try:
            result, failure = run_changeout(daemon, lambda name, f: None, plant=sim.plant), None
        except ChangeoutFailed as exc:
            result, failure = None, str(exc)
        daemon.request_stop()
        thread.join(5)
        times = list(daemon.vision.processing_times) if daemon.vision is not None else []
        out = (time.monotonic() - started, result, failure, times)
        return (*out, daemon) if keep_daemon else out
    finally:
        daemon.request_stop()
        daemon.shutdown()
        sim.stop()
        if ring is not None:
            ring.close()


def changeout_rows(label: str, wall: float, result, failure: str | None) -> list[tuple[str, str, str]]:
    if result is None:
        return [(f"full changeout, {label}", f"FAILED after {wall:.0f} s: {failure}"[:200], "success")]
    rows = [(f"full changeout, {label}: success, wall time", f"done, {wall:.1f} s wall ({result.arm_time:.1f} s arm)",
             "success" + ("; <= 120 s wall" if label.startswith("lockstep") else ""))]
    for s in result.stages:
        err = "-" if s.approach_error is None else \
            f"{1e3 * s.approach_error[0]:.2f} mm / {math.degrees(s.approach_error[1]):.3f} deg"
        met = s.approach_error is not None and s.approach_error[0] <= 1e-3 and s.approach_error[1] <= math.radians(0.3)
        cam = f", {s.detected}/{s.frames} frames" if s.frames else ""
        rows.append((f"  stage {s.number}: arm time; approach error at handover ({s.approach}{cam})",
                     f"{s.arm_time:.1f} s; {err}", f"<= 1 mm / 0.3 deg: {'met' if met else 'MISSED'}"))
        rows.append((f"  stage {s.number}: peak contact force / torque / insertion force",
                     f"{s.peak_force:.1f} N / {s.peak_torque:.2f} N m / {s.peak_insert_force:.1f} N",
                     f"<= {IMPEDANCE.force_limit:.0f} N / {IMPEDANCE.torque_limit:.0f} N m (stop limits)"))
    return rows


APPROACH_CAMPAIGN = ROOT / "configs" / "campaigns" / "changeout_approach.toml"


def approaches(n: int, seed: int, workers: int | None = None, results: Path | None = None,
               scheduler: str | None = None) -> list[tuple[str, str, str]]:
    """The randomised approaches as a campaign on Dask (configs/campaigns/changeout_approach.toml
    with this run's count and seed: each trial flies one draw open loop and closed loop). A result
    directory given again resumes: only the unfinished trials run."""
    from spacearm.offline.campaign.runner import run_campaign
    from spacearm.offline.campaign.schema import campaign_from_text
    from spacearm.offline.campaign.store import ResultStore
    text = APPROACH_CAMPAIGN.read_text()
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", text)
    text = re.sub(r"(?m)^trials = \d+", f"trials = {n}", text)
    results = results or Path(tempfile.mkdtemp(prefix="bench-oru-approaches-"))
    run_campaign(campaign_from_text(text, str(APPROACH_CAMPAIGN)), results, scheduler, workers, resume=True)
    print(f"  approach trials: {results} (Parquet, one file per trial; --approaches-results resumes)", file=sys.stderr)
    return approach_rows(ResultStore(results).rows())


def loop_record(row: dict, loop: str) -> dict:
    """One loop's outcome out of a changeout_approach trial's Parquet row."""
    get = lambda name: row.get(f"f_{loop}_{name}")   # noqa: E731
    lateral, angle = get("handover_lateral"), get("handover_angle")
    if row.get("error"):
        success, failure = False, f"trial raised: {row['error']}"
    elif loop == "closed":
        success, failure = bool(row["success"]), row["failure"]
    else:
        success, failure = bool(get("success")), row.get("l_open_failure")
    return {"success": success, "failure": failure, "peak_insert_force": get("peak_insert_force"),
            "handover": None if lateral is None or angle is None else [lateral, angle],
            "wall_time": row.get(f"w_{loop}_wall_time")}


def approach_rows(trials: list[dict]) -> list[tuple[str, str, str]]:
    """The table rows of the randomised approaches, from the campaign's Parquet rows."""
    n = len(trials)
    out = []
    for name, loop, target in (("closed loop (vision)", "closed", ">= 99 %"), ("open loop, same draws", "open", "report")):
        rows = [loop_record(r, loop) for r in trials]
        ok = sum(r["success"] for r in rows)
        low, high = wilson_interval(ok, n)
        err = np.array([r["handover"] for r in rows if r["handover"] is not None]).reshape(-1, 2)
        peak = [r["peak_insert_force"] for r in rows if r["peak_insert_force"] is not None]
        reasons = sorted({(r["failure"] or "not seated")[:60] for r in rows if not r["success"]})
        out.append((f"randomised approaches ({n} trials), {name}: success",
                    f"{100 * ok / n:.1f} % ({ok}/{n}; 95 % Wilson {100 * low:.1f}-{100 * high:.1f} %)", target))
        if len(err):
            mm, deg = 1e3 * err[:, 0], np.degrees(err[:, 1])
            out.append(("  handover error p50 / p90 / p99 / max",
                        " / ".join(f"{np.percentile(mm, p):.2f}" for p in (50, 90, 99, 100)) + " mm, "
                        + " / ".join(f"{np.percentile(deg, p):.3f}" for p in (50, 90, 99, 100)) + " deg", "-"))
        if peak:
            out.append(("  peak insertion force median / max", f"{np.median(peak):.1f} / {max(peak):.1f} N", "-"))
        for reason in reasons[:3]:
            out.append(("  failure", reason, ""))
    walls = [r["w_closed_wall_time"] for r in trials if r.get("w_closed_wall_time") is not None]
    out.append(("  wall time per closed-loop trial median", f"{np.median(walls):.1f} s" if walls else "-", "-"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=int, default=None, help="Dask workers for the insertions and the approaches (default: one per core)")
    parser.add_argument("--approaches", type=int, default=200, help="randomised approaches, open vs closed loop")
    parser.add_argument("--skip-realtime", action="store_true", help="leave out the real-time changeout (4 min)")
    parser.add_argument("--bus-config", default=CHANGEOUT_BUS,
                        help="bus file of the changeout runs (configs/oru/bus_shared_machine.toml: slower "
                             "heartbeats for an overloaded machine)")
    parser.add_argument("--only-approaches", action="store_true",
                        help="run only the randomised approaches (open vs closed loop)")
    parser.add_argument("--approaches-results", type=Path,
                        help="result directory of the approach campaign (Parquet; given again, a run cut short "
                             "resumes: only the unfinished trials run)")
    args = parser.parse_args()
    t_start, steal = time.monotonic(), CpuSteal()
    if args.only_approaches:
        print_table(approaches(args.approaches, args.seed, args.workers, args.approaches_results), t_start, steal)
        return
    trials = ContactTrials()
    rows: list[tuple[str, str, str]] = []

    stiff = run_stiffness_direct(trials)
    err = abs(stiff.displacement[0] - stiff.expected)
    rows.append(("stiffness experiment: x displacement at 5 N (K = 1 N/mm)",
                 f"{1e3 * stiff.displacement[0]:.3f} mm (error {1e3 * err:.3f} mm)", "5 mm, error <= 0.2 mm"))
    rows.append(("stiffness experiment: |y|, |z| drift", f"{1e3 * np.max(np.abs(stiff.displacement[1:])):.3f} mm",
                 "< 0.5 mm"))

    ins = insertions(args.trials, args.seed, args.workers)
    rows.append((f"randomised insertions ({ins['n']}, <= 8 mm, <= 1.5 deg): success",
                 f"{100 * ins['success']:.1f} %", ">= 99 %"))
    rows.append(("  peak lateral force median / max", f"{np.median(ins['lateral']):.2f} / {ins['lateral'].max():.2f} N", "-"))
    rows.append(("  peak torque median / max", f"{np.median(ins['torque']):.3f} / {ins['torque'].max():.3f} N m", "-"))
    rows.append(("  peak insertion force median / max", f"{np.median(ins['insert']):.2f} / {ins['insert'].max():.2f} N",
                 "stop at F_tz = 2.5 N"))
    rows.append(("  time to insert median / max (arm time)", f"{np.median(ins['time']):.2f} / {np.max(ins['time']):.2f} s", "-"))
    rows.append(("  wall time per trial median", f"{np.median(ins['wall']):.2f} s", "-"))

    wall, result, failure, vision_times = changeout("lockstep", args.bus_config)
    rows += changeout_rows("lockstep, closed-loop approach (demo plant)", wall, result, failure)
    wall, result, failure, _ = changeout("lockstep", args.bus_config, vision=False)
    rows += changeout_rows("lockstep, open-loop approach (demo plant, no camera)", wall, result, failure)
    if vision_times:
        t = np.array(vision_times) * 1e3
        rows.append(("vision per frame in the changeout (worker, tracking mostly): median / p99",
                     f"{np.median(t):.1f} / {np.percentile(t, 99):.1f} ms ({len(t)} frames)", "median <= 15 ms"))
    rows += [(f"vision per frame, {r[0]}", r[1], r[2]) for r in vision_timing(args.seed)]
    if not args.skip_realtime:
        wall, result, failure, _ = changeout("realtime", args.bus_config)
        rows += changeout_rows("real time, closed-loop approach", wall, result, failure)
        if result is not None:
            stats = result.stats
            rows.append(("  real time: period error median / p99 / max",
                         f"{1e3 * stats['period_error_median']:.3f} / {1e3 * stats['period_error_p99']:.3f} / "
                         f"{1e3 * stats['period_error_max']:.3f} ms", "-"))
            rows.append(("  execution p99 / max; overruns",
                         f"{1e3 * stats['execution_p99']:.3f} / {1e3 * stats.get('execution_max', math.nan):.3f} ms; "
                         f"{stats['overruns']}", "< 20 ms; 0"))
    if args.approaches > 0:
        rows += approaches(args.approaches, args.seed, args.workers, args.approaches_results)

    print_table(rows, t_start, steal)
    for failure in ins["failures"]:
        print(f"insertion failure: {failure}")


def print_table(rows: list[tuple[str, str, str]], t_start: float, steal: CpuSteal) -> None:
    width = max(len(r[0]) for r in rows)
    print(f"\nbench_oru on {platform.node()} ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}, CPU steal {100 * steal.fraction():.1f} %), Python {platform.python_version()}, "
          f"{time.monotonic() - t_start:.0f} s")
    print(f"{'figure':<{width}}  {'measured':<34}  target")
    for name, value, target in rows:
        print(f"{name:<{width}}  {value:<34}  {target}")


if __name__ == "__main__":
    main()
