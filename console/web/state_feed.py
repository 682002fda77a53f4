"""One status subscription to the daemon, shared by every open page.

A single thread asks the daemon for `status` once per control cycle, timed just after the
cycle has published its snapshot (the daemon reports the monotonic wake-up time of each
cycle, `woke_at`; CLOCK_MONOTONIC is shared by all processes of the machine). Each new cycle
becomes one `StateUpdate` handed to the subscribers; pages that fall behind see only the
newest update, never a backlog. However many pages are open, the daemon sees one client
asking at its own state rate.
"""
from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from spacearm.console.client import ApiClient
from spacearm.console.errors import CommandFailed
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.base.kinematics.forward import frames
from spacearm.base.kinematics.model import KinematicData, KinematicModel

SLOW_KEYS = ("stats", "network", "recording", "control")   # sent at most every SLOW_EVERY updates
SLOW_EVERY = 10
TASK_POLL = 0.5    # s between asks for the ORU task's progress (`oru.status`, answered in the cycle)
TASK_KEYS = ("state", "progress", "stage", "stage_name", "subtask", "subtasks", "subtask_index",
             "title", "algorithm", "holding", "failure", "pause")
PUBLISH_MARGIN = 0.001   # s after the cycle's typical execution time before its snapshot is asked for
RETRY_DELAY = 0.002      # s between asks when the new cycle has not published yet
MAX_RETRIES = 4


@dataclass(frozen=True)
class StateUpdate:
    cycle: int
    cycle_wall_time: float | None   # s since the epoch when the cycle woke (None: daemon too old)
    message: dict[str, Any]         # what the page gets
    status: dict[str, Any]          # the daemon's whole status of this cycle
    text: str = ""                  # the message as JSON, serialised once for every page
    shown: tuple = ()               # what a person sees of it (shown_key): equal keys look the same

    def whole(self) -> "StateUpdate":
        """The same cycle with the whole status (for a page that missed the lean updates)."""
        return StateUpdate(self.cycle, self.cycle_wall_time, self.message, self.status,
                           json.dumps({**self.message, "status": self.status}, separators=(",", ":")), self.shown)


def shown_key(status: dict[str, Any]) -> tuple:
    """What the page shows of a status that moves, at about the resolution it shows it (q and
    targets 1e-5 rad, speeds 1e-4 rad/s, torques and forces 0.01): two statuses with the same
    key look the same to the operator, whatever the cycle counters did in between."""
    def r(value: Any, digits: int) -> Any:
        return round(value, digits) if isinstance(value, (int, float)) else value
    joints = tuple((r(j.get("q"), 5), r(j.get("q_cmd"), 5), r(j.get("dq"), 4), r(j.get("tau"), 2),
                    j.get("enabled"), j.get("fault")) for j in status.get("joints") or ())
    events = status.get("events") or []
    return (status.get("state"), status.get("mode"), r(status.get("progress"), 3), status.get("stop_reason"),
            joints, tuple(r(v, 2) for v in status.get("wrench") or ()), len(events),
            json.dumps(events[-1:], sort_keys=True), json.dumps(status.get("task"), sort_keys=True),
            json.dumps(status.get("control"), sort_keys=True), status.get("end_effector"))


Subscriber = Callable[[StateUpdate], None]


def arm_frames(model: KinematicModel, data: KinematicData, q: list[float]) -> list[list[float]]:
    """base, D-H link frames and tool of configuration q, each a row-major 4x4 as 16 floats."""
    return np.round(frames(model, data, np.asarray(q, float)), 6).reshape(-1, 16).tolist()


class StateFeed:
    def __init__(self, address: str, token: str | None, model: KinematicModel,
                 connect_timeout: float = 5.0):
        self.address = address
        self.token = token
        self.model = model
        self.data = KinematicData(model)
        self.connect_timeout = connect_timeout
        self._subscribers: dict[int, Subscriber] = {}
        self._next_id = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="web-state-feed", daemon=True)
        self.latest: StateUpdate | None = None
        self._last_events: Any = None
        self._last_task: Any = None
        self.task: dict[str, Any] | None = None      # ORU task progress, when the daemon has the task
        self._task_supported = True
        self._task_asked = 0.0
        self.polls = 0              # status requests sent (the daemon's load: one client)
        self.updates = 0            # distinct cycles among them, passed on to the pages
        self.error: str | None = None

    # ---- subscribers -------------------------------------------------------------------
    def subscribe(self, callback: Subscriber) -> int:
        with self._lock:
            self._next_id += 1
            self._subscribers[self._next_id] = callback
            return self._next_id

    def unsubscribe(self, key: int) -> None:
        with self._lock:
            self._subscribers.pop(key, None)

    @property
    def subscriber_count(self) -> int:
        return len(self._subscribers)

    # ---- thread ------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                with ApiClient(self.address, self.token, timeout=self.connect_timeout) as client:
                    self.error = None
                    self._poll(client)
            except CommandFailed as exc:
                self.error = str(exc)
                self._publish_error(self.error)
                self._stop.wait(1.0)   # the daemon is away: try again, slowly

    def _poll(self, client: ApiClient) -> None:
        last_cycle = -1
        while not self._stop.is_set():
            status = client.call("status")
            self.polls += 1
            cycle = status.get("cycle", -1)
            period = float(status.get("period") or 0.02)
            woke_at = status.get("woke_at")
            if cycle == last_cycle:
                # Asked before the cycle published: ask again shortly, then give up on this one.
                retries = getattr(self, "_retries", 0) + 1
                self._retries = retries
                self._stop.wait(RETRY_DELAY if retries < MAX_RETRIES else period / 2)
                continue
            self._retries = 0
            last_cycle = cycle
            self.updates += 1
            self._poll_task(client)
            if self.task is not None:
                status["task"] = self.task
            self._publish(self._update(status))
            if woke_at is None or status.get("clock") == "lockstep":
                self._stop.wait(period)     # no cycle timing to align to: ask at the state rate
            else:
                # The snapshot is published at the end of the cycle's execution.
                execution = float((status.get("stats") or {}).get("execution_median") or 0.0)
                margin = min(max(1.2 * execution + PUBLISH_MARGIN, PUBLISH_MARGIN), period / 2)
                next_ready = woke_at + period + margin
                self._stop.wait(max(0.0, next_ready - time.monotonic()))

    def _poll_task(self, client: ApiClient) -> None:
        """A few times a second: the ORU task's progress, if this daemon runs the task flow."""
        now = time.monotonic()
        if not self._task_supported or now - self._task_asked < TASK_POLL:
            return
        self._task_asked = now
        try:
            answer = client.call("oru.status")
        except CommandFailed as exc:
            if exc.code == ErrorCode.UNKNOWN_COMMAND:
                self._task_supported = False     # a daemon without the ORU task flow
            return
        if isinstance(answer, dict) and answer.get("state") != "idle":
            self.task = {k: answer.get(k) for k in TASK_KEYS}

    def _update(self, status: dict[str, Any]) -> StateUpdate:
        woke_at = status.get("woke_at")
        wall = None if woke_at is None else time.time() - (time.monotonic() - woke_at)
        # Keep each message small (the page pays per byte, 50 times a second): the slowly
        # changing parts ride along every SLOW_EVERY updates, events only when they change;
        # the page keeps the last value of anything left out. `full` has them all.
        full = status
        status = dict(status)
        if self.updates % SLOW_EVERY != 1:
            for key in SLOW_KEYS:
                status.pop(key, None)
        if status.get("task") == self._last_task and self.updates != 1:
            status.pop("task", None)
        else:
            self._last_task = status.get("task")
        if status.get("events") == self._last_events and self.updates != 1:
            status.pop("events", None)
        else:
            self._last_events = status.get("events")
        message: dict[str, Any] = {"type": "state", "status": status, "cycle_wall_time": wall}
        if full.get("joints"):
            message["frames"] = arm_frames(self.model, self.data, [j["q"] for j in full["joints"]])
        return StateUpdate(int(full.get("cycle", -1)), wall, message, full,
                           json.dumps(message, separators=(",", ":")), shown_key(full))

    def _publish(self, update: StateUpdate) -> None:
        self.latest = update
        with self._lock:
            subscribers = list(self._subscribers.values())
        for callback in subscribers:
            callback(update)

    def _publish_error(self, text: str) -> None:
        message = {"type": "daemon_error", "error": text}
        update = StateUpdate(-1, None, message, {}, json.dumps(message))
        with self._lock:
            subscribers = list(self._subscribers.values())
        for callback in subscribers:
            callback(update)
