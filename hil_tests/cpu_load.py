"""CPU-bound neighbours for the HIL suite: the real-time stack must hold on a loaded machine.

    with CpuLoad(2):          # two processes spinning at normal priority beside the test
        ...

Each neighbour is a separate process (no GIL shared with the test) running a pure-Python
busy loop at SCHED_OTHER, nice 0: what a build or a browser tab does to the two cores.
They end with the context (SIGKILL to their own ids) or when this process dies (each one
watches its parent), so a crashed test session leaves nothing spinning.
"""
from __future__ import annotations

import os
import subprocess
import sys

from spacearm.base.runtime.priority import use_normal

_SPIN = """
import os, sys
parent = int(sys.argv[1])
n = 0
while True:
    n += 1
    if n % 2_000_000 == 0 and os.getppid() != parent:
        break
"""


class CpuLoad:
    """`count` CPU-bound processes for the duration of a `with` block."""

    def __init__(self, count: int = 2):
        if count < 0:
            raise ValueError(f"cpu load: count must be >= 0, got {count}")
        self.count = count
        self.procs: list[subprocess.Popen] = []

    def start(self) -> "CpuLoad":
        for _ in range(self.count):
            self.procs.append(subprocess.Popen([sys.executable, "-c", _SPIN, str(os.getpid())],
                                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                               stderr=subprocess.DEVNULL, preexec_fn=use_normal))
        return self

    def stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        self.procs.clear()

    def __enter__(self) -> "CpuLoad":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
