"""The console's side of control: enable waits for the drives and explains a refusal; the
holder's identity names user, host, terminal or web session and pid."""
from __future__ import annotations

import os

import pytest

from spacearm.console.control import holder_identity, wait_enabled
from spacearm.console.errors import CommandFailed


class FakeDaemon:
    def __init__(self, states: list[dict]):
        self.states = states

    def call(self, cmd: str, **args) -> dict:
        assert cmd == "status"
        return self.states.pop(0) if len(self.states) > 1 else self.states[0]


def test_enable_waits_until_every_drive_is_enabled():
    daemon = FakeDaemon([{"state": "enabling"}, {"state": "enabling"}, {"state": "enabled"}])
    assert wait_enabled(daemon, timeout=5.0)["state"] == "enabled"


def test_a_drive_that_never_enables_is_explained_with_what_to_do():
    daemon = FakeDaemon([{"state": "enabling"}, {"state": "stopped", "stop": {
        "code": "enable_timeout", "message": "joints not enabled within 2 s: joint_3"}}])
    with pytest.raises(CommandFailed) as failed:
        wait_enabled(daemon, timeout=5.0)
    assert failed.value.code == "enable_timeout"
    assert "joint_3" in str(failed.value) and "restart" in str(failed.value)


def test_the_holder_names_the_terminal_or_web_session_and_the_pid():
    assert holder_identity("web console :8740 page 1f").endswith(f"web console :8740 page 1f pid {os.getpid()}")
    assert "@" in holder_identity() and f"pid {os.getpid()}" in holder_identity()
