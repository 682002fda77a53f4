"""`spacearm sim`: run every simulated node of a bus config as its own process.

    spacearm sim --bus loopback:arm [--plant PLANT.toml] [--bus-config configs/bus/arm.toml]

With `--camera NAME` it renders the eye-in-hand camera into a shared-memory frame ring, and
with `--board FILE` that camera also sees the calibration checkerboard; SIGUSR1 stops the
camera (a fault to inject: frames stop, the nodes go on).
With a `[laser]` section in the plant file it also serves the tool's laser ranger on a
pseudo-terminal and prints "spacearm sim: laser ranger on /dev/pts/N" first.
On a redundant pair (`--bus A+B`), `--fault-file PATH` injects line faults at run time: one
`LINE MODE [LOSS]` per line (LINE: A, B or the line's name, e.g. arm-a or vcan1), re-read when
the file changes (`spacearm bus fault PATH A cut` edits it; README, redundant pairs); every
change prints "spacearm sim: line A (SPEC): MODE".
Prints one line "spacearm sim: N nodes ready on BUS" when all nodes have sent their boot-up
message, then runs until SIGINT/SIGTERM (or --duration seconds).
"""
from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path
from typing import Optional

import typer

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.base.runtime.priority import GIL_SWITCH_INTERVAL, use_fifo

READY_LINE = "spacearm sim: {n} nodes ready on {bus}"
LASER_LINE = "spacearm sim: laser ranger on {port}"   # printed before READY_LINE


CAMERA_LINE = "spacearm sim: camera frames in shared memory {name}"   # printed before READY_LINE


def _refused(exc: Exception) -> int:
    """Bad input (a file, a bus name, an option): the console's one line with its code, exit 2."""
    codes = {"ConfigError": "bad_config", "BusSpecError": "bad_bus"}
    code = next((codes[c.__name__] for c in type(exc).__mro__ if c.__name__ in codes), "bad_argument")
    typer.echo(f"error[{code}]: spacearm sim: {exc}", err=True)
    return 2


def run_sim(bus: str, bus_config: Path = DEFAULT_BUS_CONFIG, plant: Optional[Path] = None,
            duration: Optional[float] = None, stats: bool = False, control_node: Optional[int] = None,
            camera: Optional[str] = None, board: Optional[Path] = None, rt_priority: int = 0,
            time_base: str = "wall", fault_file: Optional[Path] = None) -> int:
    from spacearm.base.config.errors import ConfigError
    from spacearm.base.transport import BusSpecError
    from spacearm.firmware_sim.runner import Simulator

    board_config = None
    if board is not None:
        from spacearm.base.config.board import load_board
        try:
            if not camera:
                raise ValueError("--board needs --camera (the board is only seen through the camera)")
            board_config = load_board(board)
        except (ConfigError, ValueError) as exc:
            return _refused(exc)
    # The nodes answer SYNC on the bus thread while heartbeat and camera threads run.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    if rt_priority:
        problem = use_fifo(rt_priority)      # before the bus and heartbeat threads start
        if problem:
            typer.echo(f"spacearm sim: {problem}", err=True)
    try:
        sim = Simulator(bus, bus_config, plant, control_node, time_base=time_base)
        sim.start()
    except (ConfigError, BusSpecError, ValueError) as exc:
        return _refused(exc)
    except Exception as exc:  # bus cannot be opened etc.
        typer.echo(f"error[no_connection]: spacearm sim: cannot start on {bus}: {exc}", err=True)
        return 1
    watcher = None
    if fault_file is not None:
        if not hasattr(sim.bus, "line_channels"):
            sim.stop()
            return _refused(ValueError(f"--fault-file acts on the lines of a redundant pair; {bus} is one line"))
        watcher = _watch_fault_file(fault_file, sim.bus)
    stop = threading.Event()

    def _stop(signum, frame):
        stop.set()

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            previous[sig] = signal.signal(sig, _stop)
    ring = None
    if camera:
        from spacearm.base.vision.config import load_camera
        from spacearm.base.vision.frames import ShmFrameRing
        cam = load_camera()
        try:
            ring = ShmFrameRing.create(cam.sensor.width, cam.sensor.height, name=camera)
        except FileExistsError:
            sim.stop()
            typer.echo(f"spacearm sim: shared memory {camera!r} exists (another sim running?)", err=True)
            return 1
        service = sim.attach_camera(ring)
        if threading.current_thread() is threading.main_thread():
            # Fault injection: SIGUSR1 and the camera stops delivering frames, the nodes go on
            # (hil_tests/test_web_camera.py: the changeout pauses with camera_stopped).
            previous[signal.SIGUSR1] = signal.signal(signal.SIGUSR1, lambda signum, frame: service.stop())
        if board_config is not None:
            service.show_board(board_config)
        typer.echo(CAMERA_LINE.format(name=ring.name))
    if sim.laser is not None:
        typer.echo(LASER_LINE.format(port=sim.laser.port))
    typer.echo(READY_LINE.format(n=len(sim.nodes), bus=bus))
    try:
        stop.wait(duration)
    finally:
        if watcher is not None:
            watcher.stop()
        sim.stop()
        if ring is not None:
            ring.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if stats:
        typer.echo(f"spacearm sim: {sim.stats}")
    return 0


def _watch_fault_file(path: Path, pair):
    """Line faults from `path` on the simulator's own side of each line: frames it sends there
    do not enter the line and frames there do not reach its nodes (with the controller the only
    other party, a cut line as both see it)."""
    from spacearm.base.transport.line_faults import FaultFileWatcher
    from spacearm.base.transport.redundant import LINE_NAMES

    names = {}
    for i, fault in enumerate(pair.faults):
        names.update({LINE_NAMES[i]: fault, pair.line_channels[i]: fault, pair.specs[i]: fault})
    return FaultFileWatcher(path, names, lambda text: typer.echo(f"spacearm sim: {text}", err=True))


def register(app: typer.Typer) -> None:
    @app.command("sim")
    def sim(
        bus: str = typer.Option(..., "--bus", help="bus spec: virtual:NAME, loopback:NAME, socketcan:vcan0"),
        plant: Optional[Path] = typer.Option(None, "--plant", help="plant TOML (firmware_sim/plant.py schema)"),
        bus_config: Path = typer.Option(DEFAULT_BUS_CONFIG, "--bus-config", help="bus TOML (nodes, heartbeats)"),
        duration: Optional[float] = typer.Option(None, "--duration", help="exit after this many seconds"),
        stats: bool = typer.Option(False, "--stats", help="print frame counters on exit"),
        control_node: Optional[int] = typer.Option(
            None, "--control-node", min=1, max=127,
            help="also serve the fault-injection unit (configs/eds/sim_control.eds) at this node ID (tests)"),
        camera: Optional[str] = typer.Option(
            None, "--camera", help="render the eye-in-hand camera into this shared-memory frame ring "
                                   "(give the daemon the same --camera NAME)"),
        board: Optional[Path] = typer.Option(
            None, "--board", help="also show this calibration checkerboard in the camera's view "
                                  "(e.g. configs/calibration/board.toml; for `spacearm calibrate camera`)"),
        rt_priority: int = typer.Option(
            0, "--rt-priority", min=0, max=99,
            help="SCHED_FIFO priority of the nodes (0: normal scheduling); the HIL benches use 50 so "
                 "the simulated hardware answers SYNC in time on a busy machine"),
        time_base: str = typer.Option(
            "wall", "--time-base",
            help="wall: the drives judge the controller's heartbeat on the clock (real time); sync: on "
                 "SYNC time, beside a `--clock lockstep` daemon, so a stalled or slow lockstep run is "
                 "never a lost controller"),
        fault_file: Optional[Path] = typer.Option(
            None, "--fault-file",
            help='line faults at run time on a redundant pair, re-read when the file changes: lines "LINE MODE '
                 '[LOSS]", LINE A, B or the line\'s name, MODE cut, babble, stuck_dominant, error_passive, '
                 "intermittent or ok (`spacearm bus fault` edits it)"),
    ) -> None:
        """Run the simulated CANopen nodes (6 joint drives, end effector, F/T sensor)."""
        raise typer.Exit(run_sim(bus, bus_config, plant, duration, stats, control_node, camera, board,
                                 rt_priority, time_base, fault_file))
