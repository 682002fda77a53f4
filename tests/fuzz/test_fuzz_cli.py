"""The console's error contract, walked over every subcommand: bad arguments give exactly one
line on stderr (a JSON object under --json), exit 2 for bad input and 1 for a refused or failed
command, and never a traceback. Runs `spacearm.console.main.main` in-process (what the installed
script calls), plus a few end-to-end cases from the operator's report as real processes."""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import typer
from hypothesis import HealthCheck, given, settings, strategies as st

from spacearm.console.main import app, main

ROOT = Path(__file__).resolve().parents[2]
CLOSED_API = "tcp:127.0.0.1:1"     # nothing listens on port 1: daemon commands fail with exit 1


def leaf_commands() -> list[tuple[list[str], object]]:
    leaves = []

    def walk(command, path: list[str]) -> None:
        if hasattr(command, "commands"):
            for name, sub in command.commands.items():
                walk(sub, path + [name])
        else:
            leaves.append((path, command))

    walk(typer.main.get_command(app), [])
    return leaves


LEAVES = leaf_commands()
IDS = [" ".join(path) for path, _ in LEAVES]


def run(argv: list[str], capsys, monkeypatch) -> tuple[int, str, str]:
    monkeypatch.setenv("SPACEARM_API", CLOSED_API)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out, err = capsys.readouterr()
    code = exit_info.value.code
    return (0 if code is None else int(code)), out, err


def assert_contract(argv: list[str], code: int, err: str, expect: set[int]) -> None:
    assert code in expect, f"spacearm {' '.join(argv)}: exit {code}, stderr {err!r}"
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, f"spacearm {' '.join(argv)}: {len(lines)} lines on stderr: {err!r}"
    if "--json" in argv:
        answer = json.loads(lines[0])
        assert answer["ok"] is False and answer["exit"] == code and answer["error"]
    else:
        assert lines[0].startswith("error")


def has_json(command) -> bool:
    return any("--json" in p.opts for p in command.params)


@pytest.mark.parametrize(("path", "command"), LEAVES, ids=IDS)
def test_unknown_option_is_one_line_exit_2(path, command, capsys, monkeypatch):
    for extra in ([], ["--json"] if has_json(command) else None):
        if extra is None:
            continue
        argv = [*path, "--no-such-option", *extra]
        code, _, err = run(argv, capsys, monkeypatch)
        assert_contract(argv, code, err, {2})


@pytest.mark.parametrize(("path", "command"), LEAVES, ids=IDS)
def test_numbers_that_are_not_numbers_are_one_line_exit_2(path, command, capsys, monkeypatch):
    numeric = [p for p in command.params if p.param_type_name == "option" and p.bare_type() in (int, float)
               and not p.is_flag]
    for param in numeric:
        argv = [*path, param.opts[0], "three"] + (["--json"] if has_json(command) else [])
        code, _, err = run(argv, capsys, monkeypatch)
        assert_contract(argv, code, err, {2})


DAEMON_COMMANDS = [["status"], ["stop"], ["enable"], ["disable"], ["reset"], ["control", "take"],
                   ["control", "release"], ["record", "stop"], ["move", "joints", "ready"],
                   ["move", "joints", "0", "1", "2", "3", "4", "5"], ["move", "pose", "0", "0", "20mm", "0", "0", "0"],
                   ["jog", "1", "3deg"]]


@pytest.mark.parametrize("argv", DAEMON_COMMANDS, ids=" ".join)
@pytest.mark.parametrize("as_json", [False, True])
def test_no_daemon_is_one_line_exit_1(argv, as_json, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("SPACEARM_LEASE_DIR", str(tmp_path))
    argv = argv + (["--json"] if as_json else [])
    code, _, err = run(argv, capsys, monkeypatch)
    assert_contract(argv, code, err, {1})
    assert ("no_connection" in err)


@pytest.mark.parametrize("argv", [
    ["move", "joints", "0", "1x", "0", "0", "0", "0"], ["move", "pose", "0", "0", "2furlongs", "0", "0", "0"],
    ["jog", "1", "3degs"], ["jog", "1", "3deg", "--no-wait"], ["config", "check", "configs/arm/nope.toml"],
    ["config", "check", "configs/arm/nope.toml", "--json"], ["export", "README.md", "--csv", "/dev/null"],
    ["export", "README.md", "--csv", "/dev/null", "--json"], ["kin", "fk", "configs/arm/nope.toml"],
    ["daemon", "--clock", "sundial"], ["daemon", "--period", "5"],
], ids=" ".join)
def test_bad_values_are_one_line_exit_2(argv, capsys, monkeypatch):
    code, _, err = run(argv, capsys, monkeypatch)
    assert_contract(argv, code, err, {2})


TOKENS = st.sampled_from(["0", "-1", "1e309", "nan", "3deg", "x", "", "--json", "--api", "tcp:127.0.0.1:1",
                          "--speed", "0", "ready", "--frame", "sideways", "\x00", "ü", "99", "1.5furlong"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(command=st.sampled_from(DAEMON_COMMANDS + [["move", "joints"], ["move", "pose"], ["jog"], ["control"]]),
       tokens=st.lists(TOKENS, max_size=6))
def test_random_arguments_to_operator_commands_keep_the_contract(command, tokens, capsys, monkeypatch):
    argv = [*command, *tokens]
    code, _, err = run(argv, capsys, monkeypatch)
    if code == 0:           # e.g. `--help` never drawn; anything that succeeds needs no daemon
        return
    if code == 2 and not err.strip().startswith(("error", "{")):
        return              # `spacearm move` alone prints its help (asked for nothing)
    assert code in (1, 2) and "Traceback" not in err
    line = err.strip().splitlines()
    assert len(line) == 1, err
    if "--json" in argv and line[0].startswith("{"):
        assert json.loads(line[0])["ok"] is False


# ---- as real processes: the operator's report, item 6 ---------------------------------------

def spacearm(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "spacearm.console.main", *args], capture_output=True,
                          text=True, cwd=ROOT, timeout=timeout)


def one_line(result: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in result.stderr, result.stderr
    lines = [l for l in result.stderr.splitlines() if l.startswith(("error", "{"))]
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_daemon_with_a_bad_bus_spec_is_one_line_exit_2():
    result = spacearm("daemon", "--bus", "bogus:xyz", "--no-record", "--api", "tcp:127.0.0.1:0")
    assert result.returncode == 2 and "error[bad_bus]" in one_line(result)


def test_daemon_on_a_used_api_port_is_one_line_exit_1():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = spacearm("daemon", "--bus", "virtual:nobody", "--no-record", "--api", f"tcp:127.0.0.1:{port}")
    assert result.returncode == 1 and "error[api_address]" in one_line(result)


def test_console_pointed_at_something_that_is_not_a_daemon():
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()

        def answer() -> None:
            connection, _ = server.accept()
            with connection:
                connection.recv(4096)
                connection.sendall(b"HTTP/1.0 200 OK\r\n\r\nhello\n")
        threading.Thread(target=answer, daemon=True).start()
        result = spacearm("status", "--json", "--api", f"tcp:127.0.0.1:{server.getsockname()[1]}")
    assert result.returncode == 1
    assert json.loads(one_line(result))["code"] == "bad_answer"


def test_diagnose_on_a_file_that_is_not_mcap(tmp_path):
    bad = tmp_path / "run.mcap"
    bad.write_text("not a recording\n")
    result = spacearm("diagnose", str(bad), "--report", str(tmp_path / "report"))
    assert result.returncode == 2 and "error" in one_line(result)
