"""The command API: JSON lines, loopback only unless exposed with a token, bad input refused."""
from __future__ import annotations

import json
import socket

import pytest

from spacearm.controller.daemon.command_api import ApiAddress, ApiError, CommandServer, MAX_REQUEST_BYTES
from spacearm.controller.daemon.leases import ControlLease, LeaseError


class Echo:
    def __init__(self):
        self.calls = []
        self.closed = []

    def __call__(self, session, cmd, args):
        if cmd == "fail":
            raise ApiError("nope")
        self.calls.append((session.id, cmd, args))
        return {"cmd": cmd, "args": args}

    def on_close(self, session):
        self.closed.append(session.id)


@pytest.fixture
def served():
    echo = Echo()
    server = CommandServer(ApiAddress("tcp", "127.0.0.1", 0), echo, echo.on_close)
    server.start()
    yield server, echo
    server.stop()


def talk(port, *lines, token=None):
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        stream = sock.makefile("rwb")
        answers = []
        for line in lines:
            stream.write(line if isinstance(line, bytes) else line.encode())
            stream.write(b"\n")
            stream.flush()
            answers.append(json.loads(stream.readline()))
        return answers


def test_request_and_answer_round_trip(served):
    server, echo = served
    [answer] = talk(server.bound_port, json.dumps({"id": 7, "cmd": "status", "args": {"x": 1}}))
    assert answer == {"id": 7, "ok": True, "result": {"cmd": "status", "args": {"x": 1}}}


@pytest.mark.parametrize(("line", "error"), [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "must be a JSON object"),
    ('{"id": 1}', "cmd must be a non-empty string"),
    ('{"id": 1, "cmd": 5}', "cmd must be a non-empty string"),
    ('{"id": 1, "cmd": "move", "args": [1]}', "args must be a JSON object"),
    ('{"id": [1], "cmd": "x"}', "id must be an integer or a string"),
    ('{"id": 2, "cmd": "fail"}', "nope"),
])
def test_malformed_requests_get_clear_errors_and_reach_no_handler(served, line, error):
    server, echo = served
    [answer] = talk(server.bound_port, line)
    assert answer["ok"] is False and error in answer["error"]
    assert echo.calls == []


def test_huge_request_is_refused_and_connection_dropped(served):
    server, echo = served
    with socket.create_connection(("127.0.0.1", server.bound_port), timeout=5) as sock:
        sock.sendall(b'{"cmd": "' + b"x" * (MAX_REQUEST_BYTES + 10) + b'"}\n')
        answer = json.loads(sock.makefile("rb").readline())
    assert answer["ok"] is False and "longer than" in answer["error"]
    assert echo.calls == []


def test_non_loopback_address_needs_explicit_expose_and_token():
    echo = Echo()
    with pytest.raises(ApiError, match="not loopback"):
        CommandServer(ApiAddress("tcp", "0.0.0.0", 0), echo, echo.on_close)
    with pytest.raises(ApiError, match="needs a token"):
        CommandServer(ApiAddress("tcp", "0.0.0.0", 0), echo, echo.on_close, expose=True)


def test_token_is_required_when_set():
    echo = Echo()
    server = CommandServer(ApiAddress("tcp", "127.0.0.1", 0), echo, echo.on_close,
                           expose=True, token="s3cret")
    server.start()
    try:
        [denied] = talk(server.bound_port, '{"id": 1, "cmd": "status"}')
        assert denied["ok"] is False and "token" in denied["error"]
        [wrong] = talk(server.bound_port, '{"id": 1, "cmd": "status", "token": "guess"}')
        assert wrong["ok"] is False
        [ok] = talk(server.bound_port, '{"id": 1, "cmd": "status", "token": "s3cret"}')
        assert ok["ok"] is True
    finally:
        server.stop()
    assert [c[1] for c in echo.calls] == ["status"]


def test_unix_socket_is_private_to_the_user(tmp_path):
    echo = Echo()
    path = tmp_path / "api.sock"
    server = CommandServer(ApiAddress("unix", path=str(path)), echo, echo.on_close)
    server.start()
    try:
        assert (path.stat().st_mode & 0o777) == 0o600
        with socket.socket(socket.AF_UNIX) as sock:
            sock.settimeout(5)
            sock.connect(str(path))
            sock.sendall(b'{"id": 1, "cmd": "ping"}\n')
            assert json.loads(sock.makefile("rb").readline())["ok"] is True
    finally:
        server.stop()
    assert not path.exists()


def test_api_address_parsing():
    assert ApiAddress.parse("tcp:127.0.0.1:7440") == ApiAddress("tcp", "127.0.0.1", 7440)
    assert ApiAddress.parse("unix:/tmp/x.sock").path == "/tmp/x.sock"
    assert not ApiAddress.parse("tcp:10.0.0.5:7440").is_loopback
    with pytest.raises(ApiError):
        ApiAddress.parse("carrier-pigeon")


def test_one_console_holds_control_at_a_time():
    lease = ControlLease()
    key = lease.take("alice@console")
    lease.require(key)
    with pytest.raises(LeaseError, match="held by 'alice@console'"):
        lease.take("bob@console")
    with pytest.raises(LeaseError, match="may only watch"):
        lease.require("not-the-key")
    with pytest.raises(LeaseError):
        lease.release("not-the-key")
    lease.release(key)
    assert not lease.held
    lease.require(lease.take("bob@console"))


def test_the_holder_taking_control_again_keeps_it_and_others_are_still_refused():
    lease = ControlLease()
    key = lease.take("alice@vm /dev/pts/1 pid 10")
    assert lease.take("alice@vm /dev/pts/2 pid 11", key) == key      # the same operator, another terminal
    assert lease.holder == "alice@vm /dev/pts/1 pid 10"
    with pytest.raises(LeaseError, match="held by 'alice@vm /dev/pts/1 pid 10'"):
        lease.take("bob@vm web console :8740 page 1", "a-guessed-key")
    with pytest.raises(LeaseError):
        lease.take("bob@vm /dev/pts/3 pid 12")
    lease.release(key)
    assert lease.take("bob@vm /dev/pts/3 pid 12", key) != key         # a released key is worth nothing


def test_out_of_range_arguments_are_explained_in_the_operators_words():
    from spacearm.controller.daemon.api_handlers import JogArgs, _parse
    with pytest.raises(ApiError) as refused:
        _parse(JogArgs, {"joint": 1, "delta": 2.0})
    assert str(refused.value) == "delta: 2.0 is out of range: allowed range [-1.5708, 1.5708] rad"
    assert "Input should be" not in str(refused.value)
