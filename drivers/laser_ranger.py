"""pyserial driver of the end-effector laser ranger (protocol in base/laser_ranger_protocol.py).

`measure()` returns metres; a "beam misses" reply raises `NoHit` (not retried: it is a valid
answer); timeouts and garbled replies (bad checksum, wrong format, wrong reply type) are retried
`retries` times and then raise `RangerError`. `average(n)` takes n readings, as the paper's
10 repetitions per configuration.
"""
from __future__ import annotations

from dataclasses import dataclass

import serial

from spacearm.base.laser_ranger_protocol import frame, parse_frame


class RangerError(Exception):
    """No valid reply after the retries (timeout or garbled)."""


class NoHit(Exception):
    """The ranger reports no valid target (beam misses the plane or out of range)."""


@dataclass
class RangerInfo:
    model: str
    min_range: float
    max_range: float
    sigma: float


class LaserRanger:
    def __init__(self, port: str, baudrate: int = 115200, timeout: float = 0.2, retries: int = 3):
        self.serial = serial.Serial(port, baudrate=baudrate, timeout=timeout)
        self.retries = retries
        self.rejected = 0          # garbled / unexpected replies seen (diagnostics)

    def close(self) -> None:
        self.serial.close()

    def __enter__(self) -> "LaserRanger":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _transact(self, body: str, expect: tuple[str, ...]) -> list[str]:
        last = "timeout"
        for _ in range(self.retries + 1):
            self.serial.reset_input_buffer()
            self.serial.write(frame(body))
            line = self.serial.readline()
            if not line:
                last = "timeout"
                continue
            reply = parse_frame(line)
            if reply is None:
                self.rejected += 1
                last = f"garbled reply {line!r}"
                continue
            fields = reply.split(",")
            if fields[0] == "E" and len(fields) == 2 and fields[1] == "NOHIT" and "E" in expect:
                return fields
            if fields[0] not in expect:
                self.rejected += 1
                last = f"unexpected reply {reply!r}"
                continue
            return fields
        raise RangerError(f"{body}: no valid reply after {self.retries + 1} attempts ({last})")

    def ping(self) -> bool:
        return self._transact("PING", ("P",)) == ["P", "OK"]

    def info(self) -> RangerInfo:
        f = self._transact("INFO", ("I",))
        try:
            return RangerInfo(f[1], float(f[2]) * 1e-3, float(f[3]) * 1e-3, float(f[4]) * 1e-3)
        except (IndexError, ValueError):
            raise RangerError(f"malformed INFO reply {f}") from None

    def measure(self) -> float:
        """One distance reading, metres."""
        for _ in range(self.retries + 1):
            f = self._transact("MEAS", ("D", "E"))
            if f[0] == "E":
                raise NoHit("laser ranger: no valid target")
            try:
                return float(f[1]) * 1e-3
            except (IndexError, ValueError):
                self.rejected += 1     # checksum ok but content malformed: ask again
        raise RangerError("MEAS: malformed readings")

    def average(self, n: int = 10) -> float:
        """Mean of n readings (the paper's repetitions per configuration)."""
        return sum(self.measure() for _ in range(n)) / n
