"""`spacearm demo`: the main job on simulated hardware over the embedded virtual CAN bus.

Starts the simulated devices and the daemon in this process (python-can's virtual bus),
runs the ORU changeout (or the functional checkout) with progress output, and prints a
summary; the recording (MCAP + raw CAN trace + CSV export) stays in the run directory.

The changeout runs the ORU paper's three control methods over the bus: open-loop free motion
(subtasks 1, 7, 13), the closed-loop approach on the eye-in-hand camera (2, 8: the simulated
camera renders into a shared-memory frame ring, the daemon's vision worker measures the
store's marker) and impedance control (3, 6, 9, 12), on a plant whose arm and stores carry
hidden errors (configs/plant/oru_cell_errors.toml). `--no-vision` flies 2 and 8 open loop.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from spacearm.console.errors import BadInput, CommandFailed, friendly_errors
from spacearm.console.status_view import overrun_causes_text
from spacearm.controller.daemon.command_api import ApiError
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.controller.recording.csv_export import export_csv
from spacearm.offline.scenarios.changeout import ChangeoutFailed, run_changeout, start_camera
from spacearm.offline.scenarios.checkout import CheckoutFailed, run_checkout
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.base.runtime.priority import GIL_SWITCH_INTERVAL, describe, use_fifo
from spacearm.drivers.errors import DriverError
from spacearm.firmware_sim.runner import start_simulator


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def demo(arm: Path = typer.Option(Path("configs/arm/oru_testbed_6dof.toml"), help="Arm file."),
             plant: Path = typer.Option(None, help="Simulated plant (the hidden truth); default: the ORU "
                                                   "cell (changeout) or the bare arm (checkout)."),
             job: str = typer.Option("changeout", help="changeout (ORU paper Table 1, four stages) or "
                                                       "checkout (the arm's functional checkout)."),
             bus_config: Path = typer.Option(None, help="Bus file; default: configs/oru/bus_shared_machine.toml "
                                                        "(changeout: 0.25 s heartbeats, as the ORU HIL tests use) "
                                                        "or the standard one."),
             clock: str = typer.Option("realtime", help="realtime (20 ms wall-clock cycle) or lockstep (fast)."),
             record_dir: Path = typer.Option(Path("runs"), help="Where the recording goes."),
             vision: bool = typer.Option(True, help="closed-loop approach on the camera (changeout); "
                                                    "--no-vision: open loop to the nominal pre-contact pose."),
             stages: str = typer.Option("", help="changeout stages to run, e.g. 1,2 (default: all four)."),
             rt_priority: int = typer.Option(50, "--rt-priority", min=0, max=99,
                                             help="SCHED_FIFO priority of the cycle and the simulated nodes with "
                                                  "--clock realtime, as `daemon` runs its cycle (0: normal "
                                                  "scheduling); vision runs 10 below, the camera renders in its "
                                                  "own process at SCHED_FIFO 1")) -> None:
        """Main job: boot the simulated arm over CAN, run the ORU changeout, summarise."""
        if job not in ("changeout", "checkout"):
            raise BadInput(f"--job: expected changeout or checkout, got {job!r}")
        try:
            stage_list = [int(v) for v in stages.split(",") if v.strip()] or None
        except ValueError:
            raise BadInput(f"--stages: expected numbers like 1,2 got {stages!r}") from None
        plant = plant or Path(CHANGEOUT_PLANT if job == "changeout" else "configs/plant/oru_testbed_nominal.toml")
        bus_config = bus_config or (CHANGEOUT_BUS if job == "changeout" else DEFAULT_BUS_CONFIG)
        console = Console()
        bus = f"virtual:demo-{time.monotonic_ns()}"
        console.print(f"[bold]spacearm[/] main job: simulated devices + daemon on [cyan]{bus}[/] ({clock} clock)")
        realtime = clock == "realtime" and rt_priority > 0
        if realtime:
            # Before the nodes' threads start (they inherit it), as `daemon` does for its cycle:
            # the nodes and the cycle share this interpreter, so every thread in it that can hold
            # the GIL runs at this priority too (bench/bench_realtime.py gil: a normal-priority
            # thread preempted while it holds the GIL kept a FIFO thread waiting 100+ ms).
            sys.setswitchinterval(GIL_SWITCH_INTERVAL)
            problem = use_fifo(rt_priority)
            if problem:
                console.print(f"scheduling: {problem}")
        nodes_scheduling = describe()
        simulator = start_simulator(bus, bus_config, plant, time_base="sync" if clock == "lockstep" else "wall")
        daemon = None
        cycle_thread = None
        scheduling = ""
        ring = None
        try:
            camera = None
            if job == "changeout" and vision:
                ring, camera = start_camera(simulator)
                console.print(f"camera: {simulator.camera.period * 1e3:.0f} ms exposures rendered into shared memory "
                              f"[cyan]{camera}[/] (spacearm console-web --camera {camera} shows them)")
            daemon = Daemon(DaemonOptions(bus=bus, arm=arm, bus_config=bus_config, clock=clock,
                                          api=None, record_dir=record_dir, camera=camera,
                                          rt_priority=rt_priority if realtime else 0))
            started = time.monotonic()
            daemon.start()
            console.print(f"CAN network up: {daemon.hardware.node_count} nodes booted, configured by SDO "
                          f"and operational in {time.monotonic() - started:.2f} s")
            cycle_thread = threading.Thread(target=daemon.run, name="control-cycle", daemon=True)
            cycle_thread.start()
            with Progress(TextColumn("{task.description:<46}"), BarColumn(), TextColumn("{task.percentage:>5.1f} %"),
                          TimeElapsedColumn(), console=console) as progress:
                tasks: dict[int, int] = {}

                def on_progress(index: int, name: str, fraction: float) -> None:
                    if index not in tasks:
                        tasks[index] = progress.add_task(name, total=1.0)
                    progress.update(tasks[index], completed=fraction)

                if job == "changeout":
                    overall = progress.add_task("ORU changeout", total=1.0)

                    def on_stage(name: str, fraction: float) -> None:
                        progress.update(overall, completed=fraction, description=name[:46])
                    result = run_changeout(daemon, on_stage, plant=simulator.plant, stages=stage_list)
                else:
                    result = run_checkout(daemon, on_progress)
            daemon.request_stop()
            cycle_thread.join(timeout=5)
            scheduling = scheduling_line(daemon, simulator, nodes_scheduling)
        except (CheckoutFailed, ChangeoutFailed, DriverError, ApiError) as exc:
            raise CommandFailed(str(exc)) from None
        finally:
            if daemon is not None:
                daemon.request_stop()
                if cycle_thread is not None:
                    cycle_thread.join(timeout=5)    # its last cycles still use the network
                daemon.shutdown()
            simulator.stop()
            if ring is not None:
                ring.close()
        (_changeout_summary if job == "changeout" else _summary)(console, result)
        console.print(scheduling)
        if result.recording:
            csv_path = Path(result.recording).with_suffix(".csv")
            exported = export_csv(result.recording, csv_path)
            console.print(f"recording: {result.recording} (+ {Path(result.recording).with_suffix('.can.log').name}, "
                          f"{csv_path.name}: {exported.rows} cycles"
                          + (f", {len(exported.gaps)} gaps" if exported.gaps else ", no gaps") + ")")


CHANGEOUT_PLANT = "configs/plant/oru_cell_errors.toml"
# When the camera rendered in this process beside the nodes and the daemon, the standard 0.1 s
# heartbeats were lost (0.25 s silences) in lockstep on a loaded 2-core machine; it renders in
# its own process now, and the main job keeps the ORU HIL tests' bus.
CHANGEOUT_BUS = Path("configs/oru/bus_shared_machine.toml")


def scheduling_line(daemon: Daemon, simulator, nodes: str) -> str:
    """Which scheduling each part of the main job had."""
    parts = [f"cycle {daemon.scheduling}", f"simulated nodes {nodes}"]
    vision = getattr(daemon, "vision", None)
    if vision is not None:
        parts.append(f"vision {getattr(vision, 'scheduling', 'in the cycle (lockstep)')}")
    camera = simulator.camera
    if camera is not None:
        renderer = camera.render_process
        parts.append(f"camera renderer {renderer.scheduling() if renderer is not None else 'a thread here, normal'}")
    return "scheduling: " + "; ".join(parts)


def _changeout_summary(console: Console, result) -> None:
    table = Table(title="ORU changeout summary", caption="approach error: against the simulator's truth at the "
                  "handover to contact; camera: results / detected / latency exposure->use (controller time) / "
                  "vision time per frame; contact: peak force / torque / insertion force")
    for column in ("stage", "arm s", "approach", "error mm / deg", "camera", "contact N / N m / N"):
        table.add_column(column, justify="left" if column in ("stage", "approach") else "right")
    for s in result.stages:
        err = (f"{1e3 * s.approach_error[0]:.2f} / {math.degrees(s.approach_error[1]):.3f}"
               if s.approach_error else "-")
        how = s.approach.replace(" (vision)", "") + (f" x{s.approach_attempts}" if s.approach_attempts > 1 else "")
        cam = "-"
        if s.frames:
            cam = f"{s.frames} / {100 * s.detected / s.frames:.0f} % / {_ms(s.latency)} / {_ms(s.processing)} ms"
        table.add_row(f"{s.number} {s.name}", f"{s.arm_time:.1f}", how, err, cam,
                      f"{s.peak_force:.1f} / {s.peak_torque:.2f} / {s.peak_insert_force:.1f}")
    console.print(table)
    for where, (position, angle) in result.seat_errors.items():
        console.print(f"final pose error (simulator truth) {where}: {1e3 * position:.2f} mm / "
                      f"{math.degrees(angle):.3f} deg")
    for note in result.notes:
        console.print(f"note: {note}")
    s = result.stats
    console.print(f"changeout {result.arm_time:.1f} s arm time; {result.cycles} cycles in {result.wall_time:.1f} s wall; "
                  f"period error median {1e3 * s['period_error_median']:.3f} ms, p99 {1e3 * s['period_error_p99']:.3f} ms, "
                  f"max {1e3 * s['period_error_max']:.3f} ms; execution p99 {1e3 * s['execution_p99']:.3f} ms; "
                  f"overruns {s['overruns']} ({s.get('skipped_cycles', 0)} cycles skipped)"
                  + overrun_causes_text(s))


def _ms(value) -> str:
    return "-" if value is None else f"{1e3 * value:.0f}"


def _summary(console: Console, result) -> None:
    table = Table(title="checkout summary")
    for column in ("step", "arm time s", "max tracking error deg", "final tool error mm / deg"):
        table.add_column(column, justify="left" if column == "step" else "right")
    for step in result.steps:
        final = (f"{1e3 * step.final_position_error:.3f} / {math.degrees(step.final_rotation_error):.4f}"
                 if step.final_position_error is not None else "-")
        table.add_row(step.name, f"{step.duration:.2f}", f"{math.degrees(step.max_tracking_error):.4f}", final)
    console.print(table)
    s = result.stats
    console.print(f"{result.cycles} cycles in {result.wall_time:.1f} s wall; period error median "
                  f"{1e3 * s['period_error_median']:.3f} ms, p99 {1e3 * s['period_error_p99']:.3f} ms, "
                  f"max {1e3 * s['period_error_max']:.3f} ms; execution p99 {1e3 * s['execution_p99']:.3f} ms; "
                  f"overruns {s['overruns']}")
