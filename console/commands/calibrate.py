"""`spacearm calibrate ...`: kinematic identification studies, fits of data files, FR3 real data,
and the on-orbit routines on the running daemon (laser ranger, eye-in-hand camera)."""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from spacearm.base.paths import CONFIGS
from spacearm.console.client import DEFAULT_API
from spacearm.console.errors import BadInput, CommandFailed, friendly_errors

DEFAULT_BOARD = CONFIGS / "calibration" / "board.toml"
DEFAULT_MOUNT = CONFIGS / "vision" / "mount.toml"


def _fmt_value(name: str, value: float) -> str:
    kind = name.rsplit("_", 1)[0] if not name.startswith(("plane_",)) else "plane"
    if kind in ("d", "a") or name.endswith(("_x", "_y", "_z")):
        return f"{value * 1e3:+.4f} mm"
    if kind == "plane":
        return f"{value:+.6f}"
    return f"{value * 1e3:+.4f} mrad"


def register(app: typer.Typer) -> None:
    cal = typer.Typer(help="Kinematic calibration: paper studies, data fits, real FR3 data.",
                      no_args_is_help=True)

    from spacearm.console.commands.calibrate_study import register_study
    register_study(cal)

    from spacearm.console.commands.calibrate_fit import register_fit
    register_fit(cal)

    @cal.command("fr3")
    @friendly_errors
    def fr3(splits: int = typer.Option(10, min=1, max=1000, help="Random 80/34 splits."),
            seed: int = typer.Option(0),
            data: Path = typer.Option(None, help="samples.csv (default ../shared/data/fr3_eye_in_hand)."),
            general: bool = typer.Option(False, help="Through the general pipeline of `calibrate fit` instead."),
            method: str = typer.Option("lm", help="With --general: lm | lse | ekf | ekf-paper.")) -> None:
        """Fit the real FR3 eye-in-hand data; held-out error, registration-only vs full."""
        from spacearm.controller.calibration.fr3 import DATA, fr3_study, fr3_trusted_study
        from spacearm.controller.calibration.datafile import DataFileError
        from spacearm.controller.calibration.trusted_fit import METHODS
        path = data or DATA
        if not Path(path).exists():
            raise BadInput(f"FR3 data not found: {path}")
        if method not in METHODS:
            raise BadInput(f"unknown method {method!r} ({', '.join(METHODS)})")
        try:
            if general:
                text, _ = fr3_trusted_study(splits=splits, seed=seed, path=path, method=method)
            else:
                text, _ = fr3_study(splits=splits, seed=seed, path=path)
        except DataFileError as exc:
            raise BadInput(str(exc)) from None
        print(text)

    @cal.command("laser")
    @friendly_errors
    def laser(port: str = typer.Option(..., "--port", help="Laser ranger serial device (e.g. /dev/ttyUSB0, or the "
                                                            "pty `spacearm sim` prints)."),
              arm: Path = typer.Option(Path("configs/arm/space_robot_6dof_laser.toml"), "--arm",
                                       help="Nominal arm file the daemon runs (laser-ranger paper arm)."),
              configs: int = typer.Option(50, "--configs", min=10, max=500, help="Identification postures (O3-optimal)."),
              candidates: int = typer.Option(101, "--candidates", min=10, max=10000),
              validation: int = typer.Option(20, "--validation", min=0, max=500, help="Held-out postures."),
              repetitions: int = typer.Option(10, "--repetitions", min=1, max=1000, help="Readings per posture."),
              speed: float = typer.Option(1.0, "--speed", min=0.05, max=1.0, help="Fraction of the joint limits."),
              seed: int = typer.Option(0, "--seed"),
              apply: Optional[Path] = typer.Option(None, "--apply", help="Write the calibrated arm file here."),
              data_out: Optional[Path] = typer.Option(None, "--data-out", help="Save the readings (CSV, plane kind)."),
              api: str = typer.Option(DEFAULT_API, "--api", envvar="SPACEARM_API"),
              token: Optional[str] = typer.Option(None, "--token", envvar="SPACEARM_TOKEN"),
              as_json: bool = typer.Option(False, "--json")) -> None:
        """On-orbit laser-ranger calibration on the running daemon: move, measure, identify, validate."""
        from spacearm.console.arm_session import DaemonArm
        from spacearm.console.client import ApiClient
        from spacearm.controller.calibration.datafile import write_measurements
        from spacearm.controller.calibration.laser_routine import (CalibrationRunError, calibration_section,
                                                          run_laser_calibration, write_calibrated_arm)
        from spacearm.controller.calibration.study_laser import setup as laser_setup
        from spacearm.drivers.laser_ranger import LaserRanger, NoHit, RangerError

        st = laser_setup(arm)
        with ApiClient(api, token) as client, LaserRanger(port) as ranger:
            session = DaemonArm(client, speed=speed)
            status = session.status()
            if len(status.get("joints", [])) != st.model.kin.nq or status.get("arm") != st.model.kin.name:
                raise BadInput(f"--arm {arm} is {st.model.kin.name!r}, the daemon runs arm {status.get('arm')!r}")
            try:
                info = ranger.info()
            except RangerError as exc:
                raise CommandFailed(f"laser ranger on {port} does not answer: {exc}") from None

            def measure():
                try:
                    return ranger.average(repetitions)
                except NoHit:
                    return None

            def progress(phase: str, step: int, total: int) -> None:
                if not as_json:
                    print(f"\r  {phase:<14} posture {step:3d}/{total}", end="", file=sys.stderr, flush=True)

            session.enable()
            try:
                result = run_laser_calibration(
                    st, session.move_to, measure, session.q(), m=configs, n_candidates=candidates,
                    n_validation=validation, sigma=info.sigma / np.sqrt(repetitions), seed=seed,
                    progress=progress)
            except CalibrationRunError as exc:
                if not as_json:
                    print(file=sys.stderr)      # end the progress line
                raise CommandFailed(str(exc)) from None
            if not as_json:
                print(file=sys.stderr)
        if data_out is not None:
            write_measurements(data_out, result.Q, "plane", result.h)
        section = calibration_section(st, result, str(data_out or ""))
        if apply is not None:
            write_calibrated_arm(arm, section, apply)
        summary = {"configurations": len(result.Q), "skipped": result.skipped, "status": result.fit.status,
                   "residual_rms": result.residual_rms, "validation_rms_before": result.validation_rms_before,
                   "validation_rms_after": result.validation_rms_after, "seconds": result.seconds,
                   "errors": result.errors, "applied_to": str(apply) if apply else None,
                   # every held-out posture, so a poor figure can be traced to the postures behind it
                   "validation": [{"q": [float(v) for v in q], "h": float(h), "residual_before": float(b),
                                   "residual_after": float(a)}
                                  for q, h, b, a in zip(result.Q_validation, result.h_validation,
                                                        result.validation_residuals_before,
                                                        result.validation_residuals_after)]}
        if as_json:
            print(json.dumps(summary))
            return
        print(f"identified {len(result.errors)} parameters from {len(result.Q)} postures "
              f"({result.skipped} skipped) in {result.seconds:.1f} s: {result.fit.status}")
        print(f"  identification residual RMS {result.residual_rms * 1e3:.4f} mm")
        print(f"  held-out distance residual RMS: nominal {result.validation_rms_before * 1e3:.4f} mm -> "
              f"calibrated {result.validation_rms_after * 1e3:.4f} mm")
        if len(result.validation_residuals_after):
            worst = int(np.argmax(np.abs(result.validation_residuals_after)))
            print(f"  worst held-out posture: {result.validation_residuals_after[worst] * 1e3:+.4f} mm at q = "
                  f"[{', '.join(f'{v:.4f}' for v in result.Q_validation[worst])}] rad")
        for name, v in sorted(result.errors.items()):
            print(f"  {name:<10} {_fmt_value(name, v):>16}")
        if apply is not None:
            print(f"calibrated arm file written: {apply} (start the daemon with --arm {apply})")

    @cal.command("camera")
    @friendly_errors
    def camera(camera_name: str = typer.Option("spacearm-camera", "--camera", envvar="SPACEARM_CAMERA",
                                               help="Shared-memory frame ring (`spacearm sim --camera NAME "
                                                    "--board ...`)."),
               arm: Path = typer.Option(Path("configs/arm/oru_testbed_6dof.toml"), "--arm",
                                        help="Nominal arm file the daemon runs."),
               board_file: Path = typer.Option(DEFAULT_BOARD, "--board", help="Checkerboard file (nominal pose)."),
               mount_file: Path = typer.Option(DEFAULT_MOUNT, "--mount", help="Nominal camera mount file."),
               configs: int = typer.Option(40, "--configs", min=10, max=500,
                                           help="Identification postures (O3-optimal)."),
               candidates: int = typer.Option(120, "--candidates", min=10, max=10000),
               validation: int = typer.Option(15, "--validation", min=0, max=500, help="Held-out postures."),
               speed: float = typer.Option(1.0, "--speed", min=0.05, max=1.0, help="Fraction of the joint limits."),
               seed: int = typer.Option(0, "--seed"),
               frame_timeout: float = typer.Option(10.0, "--frame-timeout", min=0.1,
                                                   help="s to wait for a frame exposed after the arm settled."),
               apply: Optional[Path] = typer.Option(None, "--apply", help="Write the calibrated arm file here."),
               data_out: Optional[Path] = typer.Option(None, "--data-out",
                                                       help="Save the views (CSV, pose kind: q + board_T_camera)."),
               truth: Optional[Path] = typer.Option(None, "--truth", help="Simulation only: score against this plant "
                                                    "file's true geometry and the board's true_offset."),
               api: str = typer.Option(DEFAULT_API, "--api", envvar="SPACEARM_API"),
               token: Optional[str] = typer.Option(None, "--token", envvar="SPACEARM_TOKEN"),
               as_json: bool = typer.Option(False, "--json")) -> None:
        """On-orbit camera-pose calibration on the running daemon: checkerboard views, identify, validate."""
        from spacearm.console.arm_session import DaemonArm
        from spacearm.console.client import ApiClient
        from spacearm.controller.calibration.camera_routine import (camera_calibration_section, run_camera_calibration,
                                                           score_against_truth, setup_from_files,
                                                           write_camera_calibrated_arm)
        from spacearm.controller.calibration.datafile import write_measurements
        from spacearm.controller.calibration.laser_routine import CalibrationRunError

        st = setup_from_files(arm, board_file, mount_file)
        ring = attach_ring(camera_name, st.image_size)
        try:
            with ApiClient(api, token) as client:
                session = DaemonArm(client, speed=speed)
                status = session.status()
                if len(status.get("joints", [])) != st.kin.nq or status.get("arm") != st.kin.name:
                    raise BadInput(f"--arm {arm} is {st.kin.name!r}, the daemon runs arm {status.get('arm')!r}")
                grab = settled_frame_grabber(ring, session, camera_name, frame_timeout)

                def progress(phase: str, step: int, total: int) -> None:
                    if not as_json:
                        print(f"\r  {phase:<14} posture {step:3d}/{total}", end="", file=sys.stderr, flush=True)

                session.enable()
                q_start = session.q()
                try:
                    result = run_camera_calibration(st, session.move_to, grab, q_start, m=configs,
                                                    n_candidates=candidates, n_validation=validation, seed=seed,
                                                    progress=progress)
                except CalibrationRunError as exc:
                    hint = (f" (simulator: `spacearm sim --camera {camera_name} --board FILE`)"
                            if "not seen" in str(exc) else "")
                    raise CommandFailed(f"{exc}{hint}") from None
                finally:
                    if not as_json:
                        print(file=sys.stderr)
        finally:
            ring.close()
        if data_out is not None:
            write_measurements(data_out, result.Q, "pose", result.board_T_camera)
        if apply is not None:
            try:
                write_camera_calibrated_arm(arm, camera_calibration_section(result, str(data_out or "")), result, apply)
            except CalibrationRunError as exc:
                raise CommandFailed(str(exc)) from None
        scores = None
        if truth is not None:
            from spacearm.base.config.board import load_board
            from spacearm.firmware_sim.plant import load_plant_config
            board = load_board(board_file)
            scores = score_against_truth(st, result, load_plant_config(truth).geometry.true_model(),
                                         board.pose.matrix() @ board.true_offset.matrix(), st.tool_T_camera, q_start)
        _print_camera_result(result, scores, apply, as_json)

    app.add_typer(cal, name="calibrate")


def attach_ring(name: str, image_size: tuple[int, int]):
    """The camera's frame ring, attached read-only (the simulator or camera driver owns it)."""
    from spacearm.base.vision.frames import ShmFrameRing
    try:
        ring = ShmFrameRing.attach(name, timeout=0.5)
    except FileNotFoundError:
        raise CommandFailed(f"no camera frame ring {name!r}: start the simulator with `spacearm sim --camera "
                            f"{name} --board configs/calibration/board.toml` (or pass --camera NAME)") from None
    except ValueError as exc:
        raise CommandFailed(str(exc)) from None
    if (ring.width, ring.height) != tuple(image_size):
        ring.close()
        raise CommandFailed(f"camera ring {name!r} carries {ring.width}x{ring.height} frames, the camera file "
                            f"says {image_size[0]}x{image_size[1]}")
    return ring


def settled_frame_grabber(ring, session, name: str, timeout: float):
    """grab() for the routine: the first frame exposed after the arm settled. The daemon's
    SYNC number after the move (settling included) is the bound: frames carry the SYNC of
    their exposure. A frame newer (seq) than the one on hand when the move ended is required
    too, so a camera that stops streaming is noticed even if its SYNC numbers are off."""
    import time

    def grab():
        settled_sync = int(session.status()["sync_counter"])
        ring.request_exposure(settled_sync)    # a lockstep camera exposes only when asked
        first = ring.latest()
        seq0 = first.seq if first is not None else 0
        deadline = time.monotonic() + timeout
        while True:
            frame = ring.latest()
            if frame is not None and frame.seq > seq0 and frame.sync >= settled_sync:
                return frame.image
            if time.monotonic() > deadline:
                seen = (f"newest frame seq {frame.seq} exposed at SYNC {frame.sync}" if frame is not None
                        else "no frame at all")
                raise CommandFailed(f"camera {name!r}: no frame exposed after the arm settled (SYNC {settled_sync}) "
                                    f"within {timeout:g} s; {seen}. Is the simulator rendering?")
            time.sleep(0.005)
    return grab


def _print_camera_result(result, scores, apply: Optional[Path], as_json: bool) -> None:
    summary = {"configurations": len(result.Q), "validation_views": len(result.Q_validation),
               "skipped": result.skipped, "status": result.fit.status,
               "residual": result.residual, "validation_before": result.validation_before,
               "validation_after": result.validation_after, "seconds": result.seconds,
               "errors": result.errors, "frames": result.frames, "applied_to": str(apply) if apply else None,
               "truth": vars(scores) if scores is not None else None}
    if as_json:
        print(json.dumps(summary))
        return
    print(f"identified {len(result.errors)} D-H and {len(result.frames)} frame parameters from {len(result.Q)} views "
          f"({result.skipped} skipped) in {result.seconds:.1f} s: {result.fit.status}")
    print(f"  identification residual RMS {result.residual[0] * 1e3:.3f} mm, {result.residual[1] * 1e3:.3f} mrad")
    (pb, rb), (pa, ra) = result.validation_before, result.validation_after
    print(f"  held-out board_T_camera RMS ({len(result.Q_validation)} views): nominal {pb * 1e3:.3f} mm / "
          f"{rb * 1e3:.3f} mrad -> calibrated {pa * 1e3:.3f} mm / {ra * 1e3:.3f} mrad")
    if scores is not None:
        (tb, trb), (ta, tra) = scores.board_T_camera_before, scores.board_T_camera_after
        print(f"  against the true geometry, {scores.postures} fresh board views: board_T_camera RMS "
              f"{tb * 1e3:.3f} mm / {trb * 1e3:.3f} mrad -> {ta * 1e3:.3f} mm / {tra * 1e3:.3f} mrad")
        print(f"  against the true geometry, {scores.postures} random poses: mean absolute tool position error "
              f"{scores.tool_position_before * 1e3:.3f} mm -> {scores.tool_position_after * 1e3:.3f} mm "
              "(arm file with the D-H corrections; the frames absorb base and last-joint errors)")
    for name, v in sorted({**result.errors, **result.frames}.items()):
        print(f"  {name:<10} {_fmt_value(name, v):>16}")
    if apply is not None:
        print(f"calibrated arm file written: {apply} (start the daemon with --arm {apply})")
