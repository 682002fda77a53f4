"""Separate processes with the camera in the loop: `spacearm sim --camera NAME` and `spacearm
daemon --camera NAME` (lockstep) on the loopback CAN hub, for the approach and ORU HIL tests."""
from __future__ import annotations

import uuid

from hil_tests.harness import free_port

# slower heartbeats: the simulator renders frames (~0.1 s each) in the nodes' process
BUS_CONFIG = "configs/oru/bus_shared_machine.toml"


def launch_camera_stack(loopback_hub, launch, plant: str, tag: str, procs: dict | None = None) -> tuple[str, str]:
    """Start the simulator (with its camera) and the daemon; returns (api address, camera ring name).
    `procs`, if given, receives the processes as "sim" and "daemon" (to inject faults)."""
    bus = loopback_hub.spec(f"{tag}-{uuid.uuid4().hex[:8]}")
    camera = f"spacearm-cam-{uuid.uuid4().hex[:8]}"
    # The nodes stand in for hardware: SCHED_FIFO 50 as in hil_tests/faults.py (the camera's render
    # thread drops to normal scheduling); at normal priority their heartbeats went silent for
    # 0.66 s on this loaded machine while the renderer ran.
    sim = launch(["-m", "spacearm.console.main", "sim", "--plant", plant, "--camera", camera,
                  "--bus-config", BUS_CONFIG, "--rt-priority", "50", "--time-base", "sync"], bus_spec=bus, ready="nodes ready")
    api = f"tcp:127.0.0.1:{free_port()}"
    daemon = launch(["-m", "spacearm.console.main", "daemon", "--clock", "lockstep", "--api", api, "--no-record",
                     "--camera", camera, "--bus-config", BUS_CONFIG], bus_spec=bus, ready="spacearm daemon:", timeout=30)
    if procs is not None:
        procs.update(sim=sim, daemon=daemon)
    return api, camera
