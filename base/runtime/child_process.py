"""Starting this repository's own Python modules as child processes (hub, peers, CAN trace)."""
from __future__ import annotations

import os
import subprocess
import threading
from spacearm.base.paths import REPO_ROOT



def module_env() -> dict[str, str]:
    """This process's environment with the repository first on PYTHONPATH, so that
    `python -m spacearm...` children import this clone's code from any working directory."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO_ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def readline_within(proc: subprocess.Popen, timeout: float) -> str | None:
    """The child's next stdout line, or None if none came within `timeout` s (a reader
    thread: a pipe read cannot time out by itself)."""
    line: list[str] = []
    reader = threading.Thread(target=lambda: line.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout)
    return line[0] if line else None
