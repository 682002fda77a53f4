"""The reliability suite's bus: a loopback hub whose frames a test can lose, reorder or black
out, run in a process of its own and steered over its stdin (one JSON request per line, one
JSON answer per line: the answer means the fault is in force).

Every frame of the stack under test passes through this hub. It used to run as a thread of
the test process and share that process's GIL. Late in the suite a pytest worker holds
~260,000 objects, and a full garbage collection there took 100-185 ms (gc callbacks in a
pytest run of tests/diagnosis, 2026-11-29, machine loaded): every frame waited, and the
daemon rightly stopped on "no process data for 5 cycles (all nodes silent too)"
(test_waiting_console_keeps_its_jog_alive failed that way in one CI run of three). A real
bus does not stop when a test collects its garbage; in its own process at SCHED_FIFO 50, as
the daemon and the simulator run, nothing the test does stalls it.

    python -m hil_tests.faulty_hub --seed 1      # prints "port N", then serves requests
"""
from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import threading
import time

from spacearm.base.runtime.child_process import module_env, readline_within
from spacearm.base.runtime.priority import GIL_SWITCH_INTERVAL, use_fifo
from spacearm.base.transport.hub import LoopbackHub

HUB_PRIORITY = 50        # as the daemon and the simulator (spacearm daemon/sim --rt-priority 50)
READY_TIMEOUT = 30.0     # s: a cold start imports python-can and numpy on a loaded machine
ANSWER_TIMEOUT = 10.0    # s: one request; the hub's control thread does nothing else


class FrameFaults:
    """Loss, reordering and blackout of frames, applied by the hub thread to every record."""

    def __init__(self, seed: int):
        self.rng = random.Random(seed)
        self.drop_prob = 0.0
        self.reorder_prob = 0.0
        self.blackout_until = 0.0
        self.dropped = 0
        self.dropped_heartbeats: set[int] = set()   # node IDs whose heartbeat a random loss took
        self.reordered = 0
        self._held: dict[str, bytes] = {}
        self._lock = threading.Lock()

    def filter(self, channel: str, records: list[bytes]) -> list[bytes]:
        if not (self.drop_prob or self.reorder_prob or self.blackout_until or self._held):
            return records
        out: list[bytes] = []
        with self._lock:
            if time.monotonic() < self.blackout_until:
                self.dropped += len(records)
                return []
            for rec in records:
                if self.drop_prob and self.rng.random() < self.drop_prob:
                    self.dropped += 1
                    can_id = int.from_bytes(rec[3:7], "big")     # record: length, type, flags, ID
                    if can_id & 0x780 == 0x700:
                        self.dropped_heartbeats.add(can_id & 0x7F)
                    continue
                held = self._held.pop(channel, None)
                if held is None and self.reorder_prob and self.rng.random() < self.reorder_prob:
                    self._held[channel] = rec       # goes out after the next frame
                    self.reordered += 1
                    continue
                out.append(rec)
                if held is not None:
                    out.append(held)
        return out

    def apply(self, op: str, arg) -> None:
        with self._lock:
            if op == "loss":
                self.drop_prob, self.reorder_prob = float(arg["drop"]), float(arg["reorder"])
            elif op == "blackout":
                self.blackout_until = time.monotonic() + float(arg)
            elif op == "clear":
                self.drop_prob = self.reorder_prob = 0.0
                self.blackout_until = 0.0
            else:
                raise KeyError(f"unknown request {op!r}")

    def counters(self) -> dict:
        with self._lock:
            return {"dropped": self.dropped, "reordered": self.reordered,
                    "dropped_heartbeats": sorted(self.dropped_heartbeats)}


def serve(seed: int) -> int:
    """The hub's process: print its port, then answer requests until stdin closes or "stop"."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    use_fifo(HUB_PRIORITY)    # before the hub thread starts: it inherits the policy
    faults = FrameFaults(seed)
    hub = LoopbackHub("127.0.0.1", 0)
    hub.fault_filter = faults.filter
    hub.start()
    print(f"port {hub.port}", flush=True)
    for line in sys.stdin:
        try:
            request = json.loads(line)
            op, arg = request["op"], request.get("arg")
            if op == "stop":
                break
            if op == "disconnect":
                hub.disconnect(str(arg))
            elif op != "counters":
                faults.apply(op, arg)
            answer = faults.counters()
        except (ValueError, KeyError, TypeError) as exc:
            answer = {"error": f"bad request {line.strip()!r}: {exc}"}
        print(json.dumps(answer), flush=True)
    hub.stop()
    return 0


class FaultyHub:
    """The test's handle on the hub process: `spec(name)` for the stack, fault switches, counters."""

    def __init__(self, seed: int = 1):
        self._proc = subprocess.Popen([sys.executable, "-m", "hil_tests.faulty_hub", "--seed", str(seed)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=module_env())
        line = readline_within(self._proc, READY_TIMEOUT)
        if not line or not line.startswith("port "):
            self.stop()
            raise RuntimeError(f"faulty hub did not start: {line!r}")
        self.port = int(line.split()[1])

    def spec(self, name: str) -> str:
        return f"loopback:{name}@127.0.0.1:{self.port}"

    def _ask(self, op: str, arg=None) -> dict:
        self._proc.stdin.write(json.dumps({"op": op, "arg": arg}) + "\n")
        self._proc.stdin.flush()
        line = readline_within(self._proc, ANSWER_TIMEOUT)
        if not line:
            raise RuntimeError(f"faulty hub did not answer {op!r} (exit code {self._proc.poll()})")
        answer = json.loads(line)
        if "error" in answer:
            raise ValueError(answer["error"])
        return answer

    def set_loss(self, drop: float, reorder: float) -> None:
        """Each frame lost with probability `drop`, held back behind the next with `reorder`."""
        self._ask("loss", {"drop": drop, "reorder": reorder})

    def blackout(self, seconds: float) -> None:
        """Every frame lost for `seconds` from now."""
        self._ask("blackout", seconds)

    def clear(self) -> None:
        self._ask("clear")

    def disconnect(self, channel: str) -> None:
        """Cut every client of `channel` (they reconnect by themselves)."""
        self._ask("disconnect", channel)

    @property
    def dropped(self) -> int:
        return self._ask("counters")["dropped"]

    @property
    def reordered(self) -> int:
        return self._ask("counters")["reordered"]

    @property
    def dropped_heartbeats(self) -> set[int]:
        return set(self._ask("counters")["dropped_heartbeats"])

    def stop(self) -> None:
        if self._proc.poll() is None:
            try:
                self._proc.stdin.write(json.dumps({"op": "stop"}) + "\n")
                self._proc.stdin.close()
                self._proc.wait(5)
            except (OSError, ValueError, subprocess.TimeoutExpired):
                self._proc.kill()
                self._proc.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hil_tests.faulty_hub", description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1, help="seed of the random loss and reordering")
    return serve(parser.parse_args(argv).seed)


if __name__ == "__main__":
    sys.exit(main())
