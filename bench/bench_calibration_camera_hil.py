"""HIL camera-pose calibration: board_T_camera and absolute tool errors before and after
`spacearm calibrate camera`, scored against the simulator's true geometry.

    .venv/bin/python bench/bench_calibration_camera_hil.py [--configs 40] [--validation 15] [--speed-up 2]

The stack runs as separate processes, as on the bench: loopback CAN hub, `spacearm sim
--camera NAME --board configs/calibration/board.toml` (plant with hidden D-H errors, the
eye-in-hand camera rendering the checkerboard into shared memory) and `spacearm daemon
--clock lockstep --camera NAME`. The routine runs in this process exactly as the console
command runs it (same frame grabber, same DaemonArm), so every view can also be checked
against the truth: the PnP error of each view tells whether a frame was stale or blurred.
The true geometry is read from the plant and board files only to score the result.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.console.arm_session import DaemonArm  # noqa: E402
from spacearm.console.client import ApiClient  # noqa: E402
from spacearm.console.commands.calibrate import attach_ring, settled_frame_grabber  # noqa: E402
from spacearm.base.config.board import load_board  # noqa: E402
from spacearm.controller.calibration.camera_routine import (run_camera_calibration, score_against_truth,  # noqa: E402
                                                   setup_from_files)
from spacearm.controller.calibration.validation import compare_poses  # noqa: E402
from spacearm.base.kinematics.forward import fk_batch  # noqa: E402
from spacearm.base.spatial import inv_transform  # noqa: E402
from spacearm.base.transport.hub import HubProcess  # noqa: E402
from spacearm.firmware_sim.plant import load_plant_config  # noqa: E402
from hil_tests.harness import free_port  # noqa: E402

PLANT = ROOT / "configs/plant/oru_testbed_errors.toml"
ARM = ROOT / "configs/arm/oru_testbed_6dof.toml"
BOARD = ROOT / "configs/calibration/board.toml"


def scaled_arm(speed_up: float, out: Path) -> Path:
    text = ARM.read_text()
    for key in ("velocity", "acceleration", "jerk"):
        text = re.sub(rf"{key} = ([0-9.eE+-]+)", lambda m, k=key: f"{k} = {speed_up * float(m.group(1))!r}", text)
    out.write_text(text)
    return out


def patient_bus(out: Path) -> Path:
    """Heartbeat loss after 1 s, not 0.25 s: the simulator renders in its own process."""
    text = (ROOT / "configs/bus/arm.toml").read_text().replace("heartbeat_period = 0.1", "heartbeat_period = 0.4")
    out.write_text(text.replace("[bus]\n", "[bus]\nmaster_heartbeat_timeout = 1.5\nlockstep_timeout = 2.0\n", 1))
    return out


def start(args: list[str], ready: str, log: Path, timeout: float = 60.0) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
    with open(log, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", *args], stdout=fh, stderr=subprocess.STDOUT,
                                cwd=ROOT, env=env, start_new_session=True)
    deadline = time.monotonic() + timeout
    while ready not in log.read_text(errors="replace"):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError(f"{' '.join(args[:1])} did not start:\n{log.read_text()[-2000:]}")
        time.sleep(0.05)
    return proc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configs", type=int, default=40)
    ap.add_argument("--candidates", type=int, default=120)
    ap.add_argument("--validation", type=int, default=15)
    ap.add_argument("--speed-up", type=float, default=2.0, help="scale the joint limits (the drives keep up with 2)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="spacearm-camcal-"))
    arm, bus_config = scaled_arm(args.speed_up, work / "arm.toml"), patient_bus(work / "bus.toml")
    camera = f"spacearm-bench-{uuid.uuid4().hex[:8]}"
    hub = HubProcess()
    bus = hub.spec(f"camcal-{os.getpid()}")
    api = f"tcp:127.0.0.1:{free_port()}"
    procs = []
    t0 = time.monotonic()
    try:
        procs.append(start(["sim", "--bus", bus, "--plant", str(PLANT), "--bus-config", str(bus_config),
                            "--camera", camera, "--board", str(BOARD)], "nodes ready", work / "sim.log"))
        procs.append(start(["daemon", "--bus", bus, "--arm", str(arm), "--bus-config", str(bus_config), "--clock",
                            "lockstep", "--api", api, "--no-record", "--camera", camera], "spacearm daemon:",
                           work / "daemon.log"))
        st = setup_from_files(arm, BOARD)
        ring = attach_ring(camera, st.image_size)
        with ApiClient(api) as client:
            session = DaemonArm(client)
            grab = settled_frame_grabber(ring, session, camera, 10.0)
            session.enable()
            q_start = session.q()
            result = run_camera_calibration(st, session.move_to, grab, q_start, m=args.configs,
                                            n_candidates=args.candidates, n_validation=args.validation,
                                            seed=args.seed)
            arm_time = client.call("status")["time"]
        ring.close()
    finally:
        for proc in reversed(procs):
            proc.terminate()
            proc.wait(10)
        hub.stop()
    wall = time.monotonic() - t0
    board = load_board(BOARD)
    true_kin = load_plant_config(PLANT).geometry.true_model()
    true_base_T_board = board.pose.matrix() @ board.true_offset.matrix()
    scores = score_against_truth(st, result, true_kin, true_base_T_board, st.tool_T_camera, q_start)
    # Each measured view against the truth at its measured joint angles: PnP + resolver error.
    views = np.vstack([result.board_T_camera, result.board_T_camera_validation])
    Q = np.vstack([result.Q, result.Q_validation])
    truth = inv_transform(true_base_T_board) @ fk_batch(true_kin, Q) @ st.tool_T_camera
    view_err = compare_poses(truth, views)
    pos, rot = np.linalg.norm(view_err.pos, axis=1), np.linalg.norm(view_err.rot, axis=1)
    (vb, rvb), (va, rva) = result.validation_before, result.validation_after
    (tb, rtb), (ta, rta) = scores.board_T_camera_before, scores.board_T_camera_after
    rows = [
        ("views used / skipped", f"{len(result.Q)} + {len(result.Q_validation)} held out / {result.skipped}", "", ""),
        ("identification", f"{result.fit.status}, {len(result.errors)} D-H + {len(result.frames)} frame", "", ""),
        ("measured views vs truth (PnP), RMS / max",
         f"{np.sqrt(np.mean(pos ** 2)) * 1e3:.2f} / {pos.max() * 1e3:.2f} mm, "
         f"{np.sqrt(np.mean(rot ** 2)) * 1e3:.2f} / {rot.max() * 1e3:.2f} mrad", "", ""),
        ("held-out views board_T_camera RMS nominal -> calibrated",
         f"{vb * 1e3:.2f} -> {va * 1e3:.2f} mm, {rvb * 1e3:.2f} -> {rva * 1e3:.2f} mrad", "", ""),
        (f"true board_T_camera RMS, {scores.postures} fresh views",
         f"{tb * 1e3:.2f} -> {ta * 1e3:.2f} mm, {rtb * 1e3:.2f} -> {rta * 1e3:.2f} mrad", "<= 30 %", ta <= 0.3 * tb),
        (f"true absolute tool position, {scores.postures} random poses, mean",
         f"{scores.tool_position_before * 1e3:.2f} -> {scores.tool_position_after * 1e3:.2f} mm (D-H only)",
         "", ""),
        ("arm time / wall time", f"{arm_time:.0f} s / {wall:.0f} s", "", ""),
    ]
    print(f"HIL camera calibration | joint speed x{args.speed_up:g} | {args.configs} configs, "
          f"{args.validation} held out | load {os.getloadavg()[0]:.2f}")
    width = max(len(r[0]) for r in rows)
    for name, measured, target, ok in rows:
        verdict = "" if ok == "" else ("pass" if ok else "FAIL")
        print(f"{name:<{width}}  {measured:<44}  {target:<9}  {verdict}")


if __name__ == "__main__":
    main()
