"""`spacearm diagnose`: where a recording departs from the nominal simulation, and why."""
from __future__ import annotations

import contextlib
import errno
import json
import sys
import time
from pathlib import Path

import numpy as np
import typer

from spacearm.console.commands.operate import API_OPTION, TOKEN_OPTION
from spacearm.console.errors import EXIT_FAILED, EXIT_USAGE, friendly_errors
from spacearm.console.errors import report as report_error
from spacearm.offline.diagnosis.analysis import diagnose as run_diagnosis
from spacearm.offline.diagnosis.command_timing import replay_plant
from spacearm.offline.diagnosis.direct_sim import SimTraces, SimulationDiverged, on_arm_drives
from spacearm.offline.diagnosis.column_spec import parse_columns
from spacearm.offline.diagnosis.recording_io import RecordingFormatError, read_recording
from spacearm.offline.diagnosis.report import write_report
from spacearm.firmware_sim.plant import load_plant_config

DEFAULT_NOMINAL = Path("configs/plant/oru_testbed_nominal.toml")


def register(app: typer.Typer) -> None:
    @app.command("diagnose")
    @friendly_errors
    def diagnose(real: Path = typer.Argument(..., help="Recording: the daemon's .mcap or the wide CSV."),
                 sim: Path = typer.Option(None, help="A simulation recording of the same commands (else replay)."),
                 replay: bool = typer.Option(True, help="Replay the commands through the nominal simulator."),
                 nominal: Path = typer.Option(DEFAULT_NOMINAL, help="Nominal plant file the simulator uses."),
                 report: Path = typer.Option(Path("diagnosis"), help="Directory for report.md, PNGs, JSON, "
                                                                     "plant_fitted.toml."),
                 columns: str = typer.Option(None, help="Column map for other files: OURS=EXPR,... with EXPR a "
                                                       "column name or number and an optional scale and offset "
                                                       "(e.g. tau_3=#14*0.125, q_1=pos1*deg, q_1..7=#2..8)."),
                 command: str = typer.Option("recorded", help="recorded: the file's q_cmd columns; measured: the "
                                                              "recording has no command, replay the measured q."),
                 rate: float = typer.Option(None, help="Resample onto this rate, Hz (default: the recording's own)."),
                 dry_run: bool = typer.Option(False, "--dry-run", help="Print how each column was read and stop."),
                 urdf: Path = typer.Option(None, help="The recorded arm's URDF: compare the recorded torques with its "
                                                      "rigid-body model on the measured motion (any arm, N joints)."),
                 heldout_from: float = typer.Option(None, help="Held-out rows from this time on, s (default: the "
                                                               "last 40 %)."),
                 experiment: Path = typer.Option(None, help="When findings are ambiguous or joints did not move, "
                                                            "write the trajectory that separates them here (CSV)."),
                 experiment_plant: Path = typer.Option(None, help="Run the designed experiment through record-sim "
                                                                  "with this plant (standing in for the arm) and "
                                                                  "diagnose it."),
                 run: bool = typer.Option(False, "--run", help="Run the designed experiment on the running "
                                                               "daemon (--api; it needs the control lease and an "
                                                               "enabled arm), fetch its recording and diagnose it."),
                 api: str = API_OPTION, token: str = TOKEN_OPTION,
                 arm: Path = typer.Option(Path("configs/arm/oru_testbed_6dof.toml"),
                                          help="The recorded arm's file: its drive limits (joints.drive table) and "
                                               "joint limits drive the replay and bound the designed experiment."),
                 bus: Path = typer.Option(None, help="Bus file of the recorded arm's drives (scaling, rated "
                                                     "torque); default: the test bed's."),
                 as_json: bool = typer.Option(False, "--json", help="Print the JSON summary.")) -> None:
        """Locate, name and fit the physics the nominal simulator leaves out; show the fit improve."""
        for given in (real, sim, urdf):
            if given is not None and not given.is_file():   # before the plant files: the word typed first
                raise FileNotFoundError(errno.ENOENT, "no such file", str(given))
        nominal_config = on_arm_drives(load_plant_config(nominal), arm, bus)
        try:
            if rate is not None and not (0.0 < rate <= 1e5):
                raise RecordingFormatError(f"--rate {rate}: expected a rate in Hz between 0 and 100000")
            specs = parse_columns(columns)
            period = 1.0 / rate if rate else None
            read_started = time.perf_counter()
            table, lines = read_recording(real, specs, command, period)
            read_s = time.perf_counter() - read_started
            warnings = _warn(lines)
            if dry_run:
                print("\n".join(lines))
                return
            if urdf is not None and run:
                raise RecordingFormatError("--run re-diagnoses with the simulator's replay, not --urdf: drop one")
            if urdf is not None:
                _diagnose_arm(table, urdf, heldout_from, report, real.name, as_json, experiment,
                              time_base_repairs(lines))
                return
            if run:
                from spacearm.console.experiment_run import take_control
                take_control(api, token)
            traces = None
            if sim is not None:
                s, sim_lines = read_recording(sim, specs, command, period)
                warnings += _warn(sim_lines)
                if s.q.shape != table.q.shape:
                    raise RecordingFormatError(f"{sim}: {s.q.shape[0]} rows x {s.q.shape[1]} joints, the recording "
                                               f"has {table.q.shape[0]} x {table.q.shape[1]}")
                traces = SimTraces(s.t, s.q_cmd, s.q, s.dq, s.tau, s.wrench)
        except RecordingFormatError as exc:
            raise report_error(str(exc), "bad_recording", EXIT_USAGE, as_json) from None
        timing_note = None
        replayed = nominal_config
        if real.suffix == ".mcap" and traces is None:      # the daemon's recording: as its drives were driven
            replayed, timing_note = replay_plant(table, nominal_config)
        try:
            with _progress_bar() as progress:
                result = run_diagnosis(table, replayed, traces, progress)
        except SimulationDiverged as exc:
            raise report_error(f"nominal replay of {real.name}: {exc}; check the nominal plant file {nominal}",
                               "replay_diverged", EXIT_FAILED, as_json) from None
        result.timings["read_s"] = read_s
        result.repairs = time_base_repairs(lines)
        data = write_report(result, report, real.name, nominal_config)
        if timing_note:
            data["command_timing"] = timing_note
        data["warnings"] = [line.removeprefix("warning: ") for line in warnings]
        if experiment is not None or experiment_plant is not None or run:
            runner = _on_daemon(api, token) if run else _on_plant(experiment_plant, arm, bus)
            data["experiment"] = _experiment(result, table, nominal_config, arm, experiment or report / "experiment.csv",
                                             runner, report)
        if as_json:
            print(json.dumps(data, indent=2))
            return
        if timing_note:
            print(timing_note)
        print(result.verdict)
        for w in result.repairs:
            print(f"  {w}")
        # every channel, not only the improved ones: a finding must not buy one channel with another
        print(f"  held-out from t = {result.heldout_start:.3g} s; RMS per channel, nominal -> fitted (noise):")
        for c in result.channels:
            change = f"{100 * (1 - c.rms_after / c.rms_before):.0f} % lower" if c.rms_before > 1e-3 * c.noise \
                else "-"
            print(f"  {c.name}{' *' if c.significant else ''}: {c.rms_before:.3g} -> {c.rms_after:.3g} "
                  f"({change}; noise {c.noise:.3g}{'; ' + c.metric if c.metric != 'rms' else ''})")
        print(f"report: {report / 'report.md'}; fitted plant: {report / 'plant_fitted.toml'}; "
              f"{result.timings['total_s']:.1f} s")
        for line in data.get("experiment", {}).get("lines", []):
            print(line)


def _warn(lines: list[str]) -> list[str]:
    """The reader's warnings (a recording cut off: what was recovered), on stderr at once, before
    minutes of diagnosis on what is left (also under --json, whose stdout stays one document)."""
    warnings = [line for line in lines if line.startswith("warning:")]
    for line in warnings:
        print(line, file=sys.stderr)
    return warnings


def time_base_repairs(lines: list[str]) -> list[str]:
    """What the reader did to the recording's time base (rows dropped, gaps bridged, resampled),
    from its report lines: stated in the verdict, report.md and the JSON, not only --dry-run."""
    out, inside = [], False
    for line in lines:
        if line.startswith("time base:"):
            inside = True
            continue
        if inside and line.startswith("  "):
            out.append(line.strip())
        else:
            inside = False
    return out


@contextlib.contextmanager
def _progress_bar():
    """A rich progress bar on stderr for the stages of a long diagnosis (terminals only)."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import Progress
    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("diagnosis", total=1.0)
        yield lambda stage, done: bar.update(task, completed=done, description=stage)


def _experiment(result, table, nominal_config, arm: Path, out: Path, runner, report: Path) -> dict:
    """Design the experiment that settles the ambiguous findings (spacearm.offline.diagnosis.
    experiment) and, with a runner (a stand-in plant, or the daemon with --run), run it and
    diagnose its recording."""
    from spacearm.base.config.arm import load_arm_config
    from spacearm.offline.diagnosis.experiment import design_experiment, joints_to_excite, limits_from_arm
    from spacearm.offline.diagnosis.honesty import MIN_TRAVEL
    from spacearm.offline.diagnosis.trajectory import save_trajectory
    joints = joints_to_excite(result, table.q, MIN_TRAVEL)
    if not joints:
        return {"joints": [], "lines": ["experiment: nothing ambiguous or unexcited, none needed"]}
    limits = limits_from_arm(arm, table.n_joints)
    traj = design_experiment(joints, table.q[-1], limits, table.dt)
    out.parent.mkdir(parents=True, exist_ok=True)
    save_trajectory(out, traj.t, traj.q)
    lines = [f"experiment: joints {[j + 1 for j in joints]}, {traj.duration:.0f} s, three speeds both ways with "
             f"dwells, within {arm.name}'s limits: {out}"]
    info = {"joints": [j + 1 for j in joints], "trajectory": str(out), "duration_s": traj.duration}
    if runner is None:
        lines.append(f"  run it: spacearm record-sim --plant PLANT --trajectory {out} --out exp.csv, "
                     "then spacearm diagnose exp.csv (or diagnose --run on the daemon)")
    else:
        recording, where, from_daemon = runner(joints, limits, traj, load_arm_config(arm).arm.name, table.n_joints,
                                               report)
        replayed, timing_note = replay_plant(recording, nominal_config) if from_daemon else (nominal_config, None)
        second = run_diagnosis(recording, replayed)
        if timing_note:
            lines.append(f"  {timing_note}")
        write_report(second, report / "experiment", out.name, nominal_config)
        lines.append(f"  after the experiment ({where}): {second.verdict}")
        info["verdict_after"] = second.verdict
        info["ran_on"] = where
    info["lines"] = lines
    return info


def _on_plant(plant: Path | None, arm: Path, bus: Path | None):
    """Runs the experiment through record-sim's direct path with a plant standing in for the arm
    (on the arm's drives)."""
    if plant is None:
        return None

    def run(joints, limits, traj, arm_name, n_joints, report):
        from spacearm.offline.diagnosis.record import record_direct
        return record_direct(on_arm_drives(load_plant_config(plant), arm, bus), traj, None), plant.name, False
    return run


def _on_daemon(api: str, token: str | None):
    """Runs the experiment on the daemon at `api`, which records it (console/experiment_run.py)."""
    def run(joints, limits, traj, arm_name, n_joints, report):
        from spacearm.console.experiment_run import run_experiment
        report.mkdir(parents=True, exist_ok=True)
        path = run_experiment(joints, limits, arm_name, n_joints, report / "experiment.mcap", api, token)
        recording, _ = read_recording(path)
        return recording, f"run on the daemon at {api}, recorded to {path}", True
    return run


def _diagnose_arm(table, urdf: Path, heldout_from: float | None, report: Path, source: str, as_json: bool,
                  experiment: Path | None = None, repairs: list[str] | None = None) -> None:
    """The recorded torques against the URDF's rigid-body model (spacearm.offline.diagnosis.arm_torque)."""
    from spacearm.offline.diagnosis.arm_torque import arm_summary, diagnose_arm
    from spacearm.offline.diagnosis.rigid_body import load_arm
    arm = load_arm(urdf, table.n_joints)
    if not np.any(table.tau):
        raise RecordingFormatError(f"{source}: no torque columns (tau_i): nothing to compare with {urdf.name}")
    try:
        result = diagnose_arm(table, arm, heldout_from)
    except ValueError as exc:
        raise RecordingFormatError(f"{source}: {exc}") from None
    data = arm_summary(result) | {"time_base_repairs": repairs or []}
    if experiment is not None and result.to_excite:
        from spacearm.offline.diagnosis.experiment import design_experiment, limits_from_urdf
        from spacearm.offline.diagnosis.trajectory import save_trajectory
        traj = design_experiment(result.to_excite, table.q[-1], limits_from_urdf(arm), table.dt)
        experiment.parent.mkdir(parents=True, exist_ok=True)
        save_trajectory(experiment, traj.t, traj.q)
        data["experiment"] = {"joints": [j + 1 for j in result.to_excite], "trajectory": str(experiment),
                              "duration_s": traj.duration, "lines": [
                                  f"experiment for joints {[j + 1 for j in result.to_excite]} within {urdf.name}'s "
                                  f"limits, {traj.duration:.0f} s: {experiment} (run it on the arm, record, diagnose)"]}
    report.mkdir(parents=True, exist_ok=True)
    (report / "summary.json").write_text(json.dumps(data, indent=2))
    if as_json:
        print(json.dumps(data, indent=2))
        return
    print(result.verdict)
    for w in repairs or []:
        print(f"  {w}")
    for w in result.not_reported:
        print(f"  not reported: {w}")
    print(f"  held-out from t = {result.heldout_start:.3g} s; torque RMS per joint, rigid-body model -> with findings:")
    for j in result.joints:
        unit = "N" if j.kind == "prismatic" else "N m"
        print(f"  tau_{j.joint + 1}: {j.rms_nominal:.3g} -> {j.rms_fitted:.3g} {unit}" + ("" if j.moved else
                                                                                       " (did not move)"))
    print(f"report: {report / 'summary.json'}; {result.timings['total_s']:.1f} s")
    for line in data.get("experiment", {}).get("lines", []):
        print(line)
