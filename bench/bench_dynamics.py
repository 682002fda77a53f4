"""Rigid-body plant benchmark: prints a table of measured figures against targets.

    .venv/bin/python bench/bench_dynamics.py [--cycles 300] [--configs 200]

Figures: the simulated plant's physics per 1 ms sub-step with coupled rigid-body dynamics
(Panda, 7 joints; UR10, 6 joints; every joint servoed by a PD callback as the simulated drives
install, brakes released, gravity on) next to the joint-level plant it replaces; the largest
difference of the plant's gravity torques and mass matrix (built from the arm file's
[[links]]) from Pinocchio's own reading of the URDF at random postures; FK + Jacobian per call
of an imported arm with a prismatic joint (TIAGo, 8 joints); and the lockstep checkout's
wall time on the virtual bus with and without the rigid-body plant.
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "kinematics"))

from bench_kinematics import bench_fkj, cpu_model, print_table  # noqa: E402
from spacearm.base.config.arm import load_arm_config  # noqa: E402
from spacearm.base.kinematics import KinematicData, KinematicModel  # noqa: E402
from spacearm.base.kinematics.arm_import import import_arm  # noqa: E402
from spacearm.firmware_sim.geometry import GeometryErrors  # noqa: E402
from spacearm.firmware_sim.plant import Plant, PlantConfig  # noqa: E402
from spacearm.firmware_sim.rigid_body_config import RigidBodyParams  # noqa: E402
from urdf_reference import URDFS, PinocchioChain  # noqa: E402

TARGET_SUBSTEP_US = 50.0
TARGET_AGREEMENT = 1e-9
G = (0.0, 0.0, -9.81)


def plant_for(arm: str, rigid: bool, substeps: int = 20) -> Plant:
    config = load_arm_config(ROOT / f"configs/arm/{arm}.toml")
    plant_config = PlantConfig(substeps=substeps, geometry=GeometryErrors(arm=f"configs/arm/{arm}.toml"),
                               rigid_body=RigidBodyParams(gravity=G) if rigid else None)
    plant = Plant.create(len(config.joints), plant_config)
    for joint, q0 in zip(plant.joints, config.postures["ready"]):
        joint.q = joint.theta = q0
        joint.brake_engaged = False
        # a PD servo like the simulated drive's (motor-side N m), holding the start posture
        joint.controller = (lambda target: lambda s, q, qd: 2.0 * (target - q) - 0.2 * qd)(q0)
    return plant


def us_per_substep(plant: Plant, cycles: int, dt: float = 0.02) -> float:
    """Median microseconds of physics per sub-step over `cycles` plant steps (20 ms, 20 sub-steps)."""
    plant.step(dt)
    times = np.empty(cycles)
    for k in range(cycles):
        t0 = time.perf_counter_ns()
        plant.step(dt)
        times[k] = time.perf_counter_ns() - t0
    return float(np.median(times)) / 1e3 / plant.config.substeps


def agreement(arm: str, configs: int) -> tuple[float, float]:
    """Max |gravity torque| and |mass matrix| difference, plant vs Pinocchio from the URDF."""
    plant = plant_for(arm, rigid=True)
    dyn = plant.dynamics
    dyn.set_armature(np.zeros(dyn.nq))
    urdf, base, tip = URDFS[arm]
    ref = PinocchioChain(urdf, base, tip, list(plant.true_model.joint_names))
    worst_g = worst_m = 0.0
    for q in plant.true_model.random_configurations(configs, np.random.default_rng(1)):
        worst_g = max(worst_g, float(np.abs(dyn.gravity(q) - ref.gravity(q, np.array(G))).max()))
        worst_m = max(worst_m, float(np.abs(dyn.mass_matrix(q) - ref.mass_matrix(q)).max()))
    return worst_g, worst_m


def checkout_wall_time(plant: str) -> float | None:
    """Wall seconds of `spacearm demo --job checkout --clock lockstep` (None if it failed)."""
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "spacearm.console.main", "demo", "--job", "checkout", "--clock", "lockstep",
                          "--plant", plant, "--record-dir", "/tmp/bench_dynamics_runs"],
                         cwd=ROOT, capture_output=True, text=True)
    return time.perf_counter() - t0 if run.returncode == 0 else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=300, help="plant steps (20 ms each) timed per figure")
    parser.add_argument("--configs", type=int, default=200, help="random postures for the agreement")
    parser.add_argument("--skip-checkout", action="store_true", help="leave out the lockstep checkout rows")
    args = parser.parse_args()
    print(f"machine : {platform.platform()} | {cpu_model()} | {platform.machine()}")
    print(f"python  : {platform.python_version()} | numpy {np.__version__} | cores {os.cpu_count()} | "
          f"loadavg {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    rows = []

    def row(arm: str, figure: str, measured: str, target: str, passed: bool | None) -> None:
        rows.append((arm, figure, measured, target, "-" if passed is None else "pass" if passed else "FAIL"))

    for arm in ("panda", "ur10"):
        n = len(load_arm_config(ROOT / f"configs/arm/{arm}.toml").joints)
        us = us_per_substep(plant_for(arm, rigid=True), args.cycles)
        row(arm, f"plant sub-step, rigid-body dynamics, {n} joints (median)", f"{us:.1f} us",
            f"<= {TARGET_SUBSTEP_US:.0f} us", us <= TARGET_SUBSTEP_US)
        us = us_per_substep(plant_for(arm, rigid=False), args.cycles)
        row(arm, f"plant sub-step, joint-level plant, {n} joints (median)", f"{us:.1f} us", "reference", None)
        g, m = agreement(arm, args.configs)
        row(arm, f"gravity torque vs Pinocchio from URDF, max of {args.configs}", f"{g:.1e} N m",
            f"<= {TARGET_AGREEMENT:.0e}", g <= TARGET_AGREEMENT)
        row(arm, f"mass matrix vs Pinocchio from URDF, max of {args.configs}", f"{m:.1e} kg m^2",
            f"<= {TARGET_AGREEMENT:.0e}", m <= TARGET_AGREEMENT)
    tiago = KinematicModel.from_config(import_arm(*URDFS["tiago"])[1])
    us = bench_fkj(tiago, KinematicData(tiago), np.random.default_rng(2))
    row("tiago", "FK+Jacobian single call, prismatic + 7 revolute (median)", f"{us:.1f} us", "<= 50 us", us <= 50.0)
    if not args.skip_checkout:
        plain = checkout_wall_time("configs/plant/oru_testbed_nominal.toml")
        rigid = checkout_wall_time("configs/plant/oru_testbed_ground.toml")
        fmt = lambda t: "failed" if t is None else f"{t:.2f} s"   # noqa: E731
        row("oru_testbed_6dof", "lockstep checkout wall time, joint-level plant", fmt(plain), "reference", None)
        ok = plain is not None and rigid is not None and rigid <= 1.5 * plain
        row("oru_testbed_6dof", "lockstep checkout wall time, rigid-body plant (ground)", fmt(rigid),
            "<= 1.5x joint-level", ok)

    return print_table(rows)


if __name__ == "__main__":
    sys.exit(main())
