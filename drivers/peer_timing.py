"""The master's side of the simulator's and the hub's timing reports (base/canopen/peer_timing.py).

Subscribes to their diagnostics TPDOs and keeps what arrived over a window, with the
monotonic time each report was received; the daemon turns that into "simulator late: N
cycles, max X ms" (controller/daemon/node_timing.py). Real drives on a real bus send no such
reports, and then nothing is shown.
"""
from __future__ import annotations

import threading
import time
from collections import deque

from spacearm.base.canopen import peer_timing
from spacearm.base.canopen.peer_timing import TimingReport

WINDOW = 60.0       # s of reports kept


class PeerTimingListener:
    def __init__(self, network, window: float = WINDOW, device_cob_ids: set[int] = frozenset()):
        """`network`: the canopen.Network of the master (ArmNetwork.network). A report COB-ID
        that a device of the bus already uses (`device_cob_ids`, its PDOs) is not listened to:
        that device's data is not a timing report."""
        self.window = window
        self.malformed = 0
        self._lock = threading.Lock()
        self._reports: dict[str, deque[tuple[float, TimingReport]]] = {
            name: deque() for name in peer_timing.SOURCES.values()}
        for cob_id in set(peer_timing.SOURCES) - set(device_cob_ids):
            network.subscribe(cob_id, self._on_frame)

    def _on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        report = peer_timing.decode(bytes(data))
        if report is None:
            self.malformed += 1
            return
        now = time.monotonic()
        with self._lock:
            kept = self._reports[peer_timing.SOURCES[can_id]]
            kept.append((now, report))
            while kept and kept[0][0] < now - self.window:
                kept.popleft()

    def reports(self) -> dict[str, list[tuple[float, TimingReport]]]:
        """Per source (simulator, hub): (received at, report), oldest first, within the window
        (or the last one, however old: a source that stopped reporting stays visible as silent)."""
        since = time.monotonic() - self.window
        with self._lock:
            return {name: [r for r in kept if r[0] >= since] or list(kept)[-1:] for name, kept in self._reports.items()}
