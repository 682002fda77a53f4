"""HIL laser-ranger calibration: absolute position error of the simulated arm before and after
`spacearm calibrate laser --apply`, over 50 random validation poses (target >= 85 % reduction).

    .venv/bin/python bench/bench_calibration_hil.py [--configs 50] [--validation 20] [--speed-up 1]

The simulator (plant with the laser-ranger paper's Table 2 errors, ranger on a pty) and the
daemon (lockstep) run in this process on the in-process bus; the routine drives the daemon
through its TCP command API and reads the ranger through pyserial, exactly as the console
command does. The true geometry is read from the plant file only to score the result.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.console.arm_session import DaemonArm  # noqa: E402
from spacearm.console.client import ApiClient  # noqa: E402
from spacearm.controller.calibration.laser_routine import calibration_section, run_laser_calibration, write_calibrated_arm  # noqa: E402
from spacearm.controller.calibration.study_laser import setup as laser_setup  # noqa: E402
from spacearm.base.config.arm import load_arm_config  # noqa: E402
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions  # noqa: E402
from spacearm.base.kinematics.forward import fk  # noqa: E402
from spacearm.base.kinematics.model import KinematicData, KinematicModel  # noqa: E402
from spacearm.drivers.laser_ranger import LaserRanger, NoHit  # noqa: E402
from spacearm.firmware_sim.plant import load_plant_config  # noqa: E402
from spacearm.firmware_sim.runner import start_simulator  # noqa: E402

PLANT = ROOT / "configs/plant/space_robot_laser_errors.toml"
ARM = ROOT / "configs/arm/space_robot_6dof_laser.toml"


def positions(model: KinematicModel, Q: np.ndarray) -> np.ndarray:
    data = KinematicData(model)
    return np.array([fk(model, data, q)[:3, 3].copy() for q in Q])


def arm_file(speed_up: float, workdir: Path) -> Path:
    if speed_up == 1.0:
        return ARM
    text = ARM.read_text()
    for key in ("velocity", "acceleration", "jerk"):
        text = re.sub(rf"{key} = ([0-9.eE+-]+)", lambda m, k=key: f"{k} = {speed_up * float(m.group(1))!r}", text)
    out = workdir / "arm_fast.toml"
    out.write_text(text)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", type=int, default=50)
    ap.add_argument("--validation", type=int, default=20)
    ap.add_argument("--repetitions", type=int, default=10)
    ap.add_argument("--speed-up", type=float, default=1.0, help="scale the joint speed limits (1 = the arm file)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="spacearm-calhil-"))
    arm = arm_file(args.speed_up, work)
    bus = f"virtual:calhil-{os.getpid()}"
    sim = start_simulator(bus, "configs/bus/arm.toml", PLANT)
    api = f"unix:{work / 'api.sock'}"
    daemon = Daemon(DaemonOptions(bus=bus, arm=arm, clock="lockstep", api=api, record_dir=None))
    daemon.start()
    runner = threading.Thread(target=daemon.run, daemon=True)
    runner.start()
    t0 = time.monotonic()
    try:
        st = laser_setup(arm)
        with ApiClient(api) as client, LaserRanger(sim.laser.port) as ranger:
            session = DaemonArm(client)
            session.enable()
            sigma = ranger.info().sigma / np.sqrt(args.repetitions)

            def measure():
                try:
                    return ranger.average(args.repetitions)
                except NoHit:
                    return None
            result = run_laser_calibration(st, session.move_to, measure, session.q(), m=args.configs,
                                           n_validation=args.validation, sigma=sigma, seed=args.seed)
        arm_time = daemon.core.motion_time
    finally:
        daemon.request_stop()
        runner.join(10)
        daemon.shutdown()
        sim.stop()
    wall = time.monotonic() - t0
    calibrated = work / "arm_calibrated.toml"
    write_calibrated_arm(arm, calibration_section(st, result, "bench"), calibrated)
    config = load_arm_config(calibrated)
    truth = load_plant_config(PLANT).geometry.true_model()
    nominal, identified = KinematicModel.from_config(config, calibrated=False), KinematicModel.from_config(config)
    Q = nominal.random_configurations(50, np.random.default_rng(args.seed + 100), margin=0.1)
    p = positions(truth, Q)
    before = np.linalg.norm(positions(nominal, Q) - p, axis=1)
    after = np.linalg.norm(positions(identified, Q) - p, axis=1)
    reduction = 1 - after.mean() / before.mean()
    rows = [
        ("postures used / skipped (beam missed)", f"{len(result.Q)} + {len(result.Q_validation)} validation / {result.skipped}", "", ""),
        ("identification", f"{result.fit.status}, {len(result.errors)} parameters", "", ""),
        ("held-out distance residual RMS nominal -> calibrated",
         f"{result.validation_rms_before * 1e3:.3f} -> {result.validation_rms_after * 1e3:.3f} mm", "", ""),
        ("absolute position error, 50 poses, mean nominal -> calibrated",
         f"{before.mean() * 1e3:.3f} -> {after.mean() * 1e3:.3f} mm", "", ""),
        ("absolute position error, 50 poses, max nominal -> calibrated",
         f"{before.max() * 1e3:.3f} -> {after.max() * 1e3:.3f} mm", "", ""),
        ("reduction of the mean absolute error", f"{100 * reduction:.1f} %", ">= 85 %", reduction >= 0.85),
        ("arm time / wall time", f"{arm_time:.0f} s / {wall:.0f} s", "", ""),
    ]
    print(f"HIL laser calibration | joint speed x{args.speed_up:g} | {args.configs} configs, "
          f"{args.repetitions} readings each | load {os.getloadavg()[0]:.2f}")
    width = max(len(r[0]) for r in rows)
    for name, measured, target, ok in rows:
        verdict = "" if ok == "" else ("pass" if ok else "FAIL")
        print(f"{name:<{width}}  {measured:<40}  {target:<9}  {verdict}")


if __name__ == "__main__":
    main()
