"""The README is executable: every command block marked `<!-- readme-test: NAME -->` (the line
before its ```sh fence) runs as written against a fresh stack, so a README that drifts from
the code fails here.

Each block runs line by line in bash from a scratch directory that sees the clone's `configs/`
(recordings land there, not in the clone), with `spacearm` on PATH from this venv. A line ending
in `&` starts a background process, and the next line waits until that program says it is
ready, as a user would watch for it. Isolation from other stacks on the machine: the hub
address and the API address come from $SPACEARM_HUB / $SPACEARM_API (the commands read them),
and the well-known ports 7440 (API) and 8740 (web console) written in a block are mapped to
free ones. Nothing else of a line is changed.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil_tests.conftest import ROOT, TIME_SCALE, child_env
from hil_tests.harness import free_port, stop_group

pytestmark = pytest.mark.hil

MARK = re.compile(r"<!-- readme-test: ([\w.-]+) -->\s*\n```sh\n(.*?)```", re.S)
# What each background program prints once it serves (the user's cue to type the next line).
READY = {"hub": r"hub listening on|already in use", "sim": r"nodes ready", "daemon": r"spacearm daemon:",
         "console-web": r"console-web: http"}


def readme_blocks(text: str | None = None) -> dict[str, list[str]]:
    text = (ROOT / "README.md").read_text() if text is None else text
    blocks = {}
    for name, body in MARK.findall(text):
        logical = re.sub(r"\s*\\\n\s*", " ", body)       # join continuation lines
        blocks[name] = [line for line in logical.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    return blocks


BLOCKS = readme_blocks()


def test_readme_marks_the_operator_recipes():
    assert {"separate-processes", "oru", "web-console", "diagnosis"} <= set(BLOCKS), sorted(BLOCKS)
    print(f"README blocks run by test_readme_block_runs_as_written: {len(BLOCKS)} ({', '.join(BLOCKS)})")


def test_block_extraction_joins_continuations_and_skips_comments():
    text = "<!-- readme-test: x -->\n```sh\n# note\nspacearm a \\\n    --b 1 &   # bg\nspacearm c\n```\n"
    assert readme_blocks(text) == {"x": ["spacearm a --b 1 &   # bg", "spacearm c"]}


def _command_part(line: str) -> str:
    return re.sub(r"\s+#.*$", "", line).strip()


class Session:
    """One user's terminal: background jobs and foreground commands in one environment."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        (tmp / "configs").symlink_to(ROOT / "configs")
        self.api_port, self.web_port = free_port(), free_port()
        venv_bin = str(Path(sys.executable).parent)
        self.env = child_env({"PATH": venv_bin + os.pathsep + os.environ.get("PATH", ""),
                              "SPACEARM_API": f"tcp:127.0.0.1:{self.api_port}",
                              "SPACEARM_HUB": f"127.0.0.1:{free_port()}",
                              "SPACEARM_LEASE_DIR": str(tmp / "lease")})
        self.jobs: list[subprocess.Popen] = []

    def line(self, text: str) -> str:
        return text.replace("7440", str(self.api_port)).replace("8740", str(self.web_port))

    def background(self, text: str) -> None:
        command = _command_part(text)[:-1].strip()
        program = command.split()[1] if command.startswith("spacearm ") else ""
        log = self.tmp / f"job{len(self.jobs)}.log"
        with open(log, "w") as handle:
            job = subprocess.Popen(["bash", "-c", "exec " + command], cwd=self.tmp, env=self.env,
                                   stdout=handle, stderr=subprocess.STDOUT, start_new_session=True)
        self.jobs.append(job)
        ready = READY.get(program)
        if ready is None:
            return
        deadline = time.monotonic() + 60 * TIME_SCALE
        while not re.search(ready, log.read_text(errors="replace")):
            assert job.poll() is None, f"`{command}` exited: {log.read_text()}"
            assert time.monotonic() < deadline, f"`{command}` not ready: {log.read_text()}"
            time.sleep(0.05)

    def foreground(self, text: str) -> subprocess.CompletedProcess:
        return subprocess.run(["bash", "-e", "-o", "pipefail", "-c", text], cwd=self.tmp, env=self.env,
                              capture_output=True, text=True, timeout=600 * TIME_SCALE)

    def close(self) -> None:
        for job in reversed(self.jobs):
            stop_group(job)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BLOCKS))
def test_readme_block_runs_as_written(name, tmp_path):
    session = Session(tmp_path)
    try:
        for text in BLOCKS[name]:
            line = session.line(text)
            if _command_part(line).endswith("&"):
                session.background(line)
                continue
            result = session.foreground(line)
            logs = "".join(f"\n--- {p.name}\n{p.read_text()[-1500:]}" for p in sorted(tmp_path.glob("job*.log")))
            assert result.returncode == 0, (f"README block {name!r}: `{text}` exited {result.returncode}\n"
                                            f"{result.stdout[-2000:]}{result.stderr[-2000:]}{logs}")
    finally:
        session.close()
