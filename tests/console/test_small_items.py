"""Small console contracts an operator ran into (issue 33): output into a pipe that closes
early, a bad API address, an address beyond loopback, a port in use: each one line with its
code, never a traceback."""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading

import pytest


@pytest.fixture
def fake_daemon():
    """A loopback server answering every request line with a large status (like a real one's
    `status --json`, ~10 kB), standing in for the daemon."""
    server = socket.create_server(("127.0.0.1", 0))
    status = {"state": "enabled", "joints": [{"name": f"j{i}", "q": 0.1 * i, "dq": 0.0, "tau": 0.0, "enabled": True}
                                             for i in range(6)], "events": [{"t": i, "kind": "x", "message": "y" * 80}
                                                                             for i in range(100)]}
    answer = json.dumps({"id": 1, "ok": True, "result": status}).encode() + b"\n"

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                stream = conn.makefile("rwb")
                while stream.readline():
                    stream.write(answer)
                    stream.flush()
    threading.Thread(target=serve, daemon=True).start()
    yield f"tcp:127.0.0.1:{server.getsockname()[1]}"
    server.close()


def spacearm(*args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spacearm.console.main", *args], capture_output=True, text=True,
                          **{"timeout": 120, **kwargs})


def test_status_json_into_a_pipe_that_closes_early_prints_no_traceback(fake_daemon):
    # head reads 600 bytes and exits; the status is larger, so the console writes into a dead pipe
    pipeline = subprocess.run(f"{sys.executable} -m spacearm.console.main status --json --api {fake_daemon} "
                              "| head -c 600", shell=True, capture_output=True, text=True, timeout=120)
    assert len(pipeline.stdout) == 600
    assert pipeline.stderr == "", pipeline.stderr


@pytest.mark.parametrize("address", ["bogus", "tcp:127.0.0.1:notaport"])
def test_a_bad_api_address_is_bad_input_with_its_code(address):
    for args in (["status"], ["oru", "status"], ["jog", "1", "1deg"]):
        done = spacearm(*args, "--api", address)
        assert done.returncode == 2, (args, done.stderr)
        assert done.stderr.startswith("error[bad_argument]: bad API address"), (args, done.stderr)


def test_record_start_into_a_missing_directory_is_refused(tmp_path):
    """The daemon's side of `record start PATH`: a directory that does not exist is bad input,
    refused before any recorder starts (the daemon is never reached: None here)."""
    from spacearm.controller.daemon.command_api import ApiError
    from spacearm.controller.daemon.daemon import RecordingControl
    with pytest.raises(ApiError) as refused:
        RecordingControl(None).start(str(tmp_path / "nonexistent" / "dir" / "x.mcap"))
    assert refused.value.code == "bad_argument" and "no directory" in str(refused.value)
    assert not (tmp_path / "nonexistent").exists()


def test_a_command_sent_to_the_hubs_port_fails_at_once():
    """`stop --api <the hub's port>`: the hub speaks another protocol; it drops a client whose
    first record is not a hello as soon as it can tell (it waited for its 5 s hello deadline)."""
    import time
    from spacearm.base.transport.hub import HELLO_TIMEOUT, LoopbackHub
    hub = LoopbackHub("127.0.0.1", 0)
    threading.Thread(target=hub.serve_forever, daemon=True).start()
    try:
        started = time.monotonic()
        done = spacearm("stop", "--api", f"tcp:127.0.0.1:{hub.port}")
        took = time.monotonic() - started
    finally:
        hub.stop(1.0)
    assert done.returncode == 1 and done.stderr.startswith("error[no_connection]"), done.stderr
    # The interpreter's start is in `took` too; the hub's answer is not the 5 s deadline.
    print(f"stop to the hub's port: {took:.2f} s")
    assert took < HELLO_TIMEOUT, took


def test_the_simulators_refusals_carry_a_code():
    bad_bus = spacearm("sim", "--bus", "bogus:x")
    assert bad_bus.returncode == 2 and bad_bus.stderr.startswith("error[bad_bus]: spacearm sim: bus 'bogus:x'"), \
        bad_bus.stderr
    assert "Traceback" not in bad_bus.stderr and len(bad_bus.stderr.strip().splitlines()) == 1


def test_watch_ends_after_the_refreshes_asked_for_showing_the_state(fake_daemon):
    done = spacearm("watch", "--count", "2", "--rate", "20", "--api", fake_daemon)
    assert done.returncode == 0, done.stderr
    assert "state enabled" in done.stdout and "j5" in done.stdout, done.stdout[-500:]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize("args", [["hub", "--host", "0.0.0.0"], ["hub", "--host", "::"],
                                  ["console-web", "--host", "0.0.0.0"],
                                  ["daemon", "--api", "tcp:0.0.0.0:{port}", "--bus", "loopback:refused", "--no-record"]],
                         ids=lambda a: " ".join(a[:3]))
def test_listening_beyond_loopback_is_refused_in_one_line_exit_2(args):
    """Network rule: 127.0.0.1 / ::1 only. The hub bound 0.0.0.0 with a warning (any host could
    put frames on the arm's bus); the web console and the daemon refused with exit 1, `jog`'s
    bad_argument exits 2. Nothing may listen on the port afterwards either."""
    port = free_port()
    args = [a.format(port=port) for a in args] + (["--port", str(port)] if args[0] != "daemon" else [])
    done = spacearm(*args, timeout=60)
    assert done.returncode == 2, (args, done.returncode, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error[bad_argument]: ") and "loopback" in lines[0], done.stderr
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", port), timeout=5).close()


def test_a_hub_on_a_port_in_use_says_so_with_its_code():
    with socket.create_server(("127.0.0.1", 0)) as taken:
        done = spacearm("hub", "--port", str(taken.getsockname()[1]), timeout=60)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("error[address_in_use]: spacearm hub: 127.0.0.1:") and \
        len(done.stderr.strip().splitlines()) == 1, done.stderr
