"""Simulated end-effector laser ranger on a pseudo-terminal (os.openpty).

Protocol: base/laser_ranger_protocol.py (ASCII lines, NMEA-style checksum), 115200 8N1 nominal.

The true distance comes from a callable (None = the beam misses, e.g. not on the plane).
Readings get N(0, sigma) noise (0.2 mm by default, as in the laser-ranger paper). Fault injection
for driver tests: garble (flip a byte of the reply), drop (no reply), both as probabilities.
"""
from __future__ import annotations

import os
import select
import threading
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np
from pydantic import Field

from spacearm.base.config.loader import StrictModel
from spacearm.base.laser_ranger_protocol import frame, parse_frame

MODEL = "SIM-LR1"


@dataclass
class RangerConfig:
    sigma: float = 0.2e-3          # m
    min_range: float = 0.05        # m
    max_range: float = 5.0         # m
    garble_prob: float = 0.0
    drop_prob: float = 0.0
    seed: int = 0


class LaserRangerSim:
    """Serves the protocol on the master side of a pty; `port` is the slave device path."""

    def __init__(self, distance: Callable[[], Optional[float]], config: RangerConfig | None = None):
        self.distance = distance
        self.config = config or RangerConfig()
        self.rng = np.random.default_rng(self.config.seed)
        self.master, self.slave = os.openpty()
        self.port = os.ttyname(self.slave)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="laser-ranger-sim", daemon=True)
        self.requests = 0

    def __enter__(self) -> "LaserRangerSim":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        import tty
        tty.setraw(self.slave)      # no echo, no line editing: a serial line, not a terminal
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass

    # ------------------------------------------------------------------------------ server
    def reply_to(self, body: Optional[str]) -> str:
        c = self.config
        if body is None:
            return "E,BADCS"
        if body == "PING":
            return "P,OK"
        if body == "INFO":
            return f"I,{MODEL},{c.min_range * 1e3:.0f},{c.max_range * 1e3:.0f},{c.sigma * 1e3:.3f}"
        if body == "MEAS":
            h = self.distance()
            if h is None or not np.isfinite(h) or not (c.min_range <= h <= c.max_range):
                return "E,NOHIT"
            return f"D,{(h + self.rng.normal(0.0, c.sigma)) * 1e3:.3f}"
        return "E,UNKNOWN"

    def _serve(self) -> None:
        buf = b""
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.05)
            if not r:
                continue
            try:
                chunk = os.read(self.master, 256)
            except OSError:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                if not line.strip():
                    continue
                self.requests += 1
                body = parse_frame(line) if line.strip().startswith(b"$") else None
                out = frame(self.reply_to(body))
                if self.rng.random() < self.config.drop_prob:
                    continue
                if self.rng.random() < self.config.garble_prob:
                    i = int(self.rng.integers(1, len(out) - 4))
                    out = out[:i] + bytes([out[i] ^ 0x15]) + out[i + 1:]
                os.write(self.master, out)


class LaserTarget(StrictModel):
    """Plant-file section `[laser]`: a ranger on the tool (beam along tool +z from the tool
    origin) aimed at a plane n.p + f = 0 in the base frame; the simulator serves it on a pty."""
    plane: tuple[float, float, float, float] = Field(description="n_x, n_y, n_z, f of the true plane (m)")
    sigma: float = Field(default=0.2e-3, ge=0.0, le=0.01, description="m, reading noise (1 sigma)")
    min_range: float = Field(default=0.05, ge=0.0, le=100.0, description="m")
    max_range: float = Field(default=5.0, gt=0.0, le=100.0, description="m")
    seed: int = 0

    def ranger_config(self) -> RangerConfig:
        return RangerConfig(sigma=self.sigma, min_range=self.min_range, max_range=self.max_range,
                            seed=self.seed)


def tool_plane_distance(tool_pose: Callable[[], np.ndarray], normal, offset: float
                        ) -> Callable[[], Optional[float]]:
    """Distance source: along tool +z from the tool origin to the plane n.p + f = 0 (eq. 10 of
    the laser-ranger paper), None when the beam points away from the plane."""
    n = np.asarray(normal, float)

    def distance() -> Optional[float]:
        T = tool_pose()
        nb = float(T[:3, 2] @ n)
        if abs(nb) < 1e-9:
            return None
        h = -(float(T[:3, 3] @ n) + offset) / nb
        return h if h > 0 else None
    return distance


def arm_plane_distance(model, x_true: np.ndarray, normal, offset: float,
                       joint_angles: Callable[[], np.ndarray]) -> Callable[[], Optional[float]]:
    """Distance source from the true arm as a calibration ErrorModel at x_true."""
    return tool_plane_distance(
        lambda: model.poses(x_true[: model.n_params], np.atleast_2d(joint_angles()))[0], normal, offset)
