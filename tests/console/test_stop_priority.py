"""`spacearm stop` asks for SCHED_FIFO below the control path before it imports the client
(a loaded machine otherwise queues it behind every CPU-bound process); other commands, and
main() called in-process, do not change the caller's scheduling."""
from __future__ import annotations

import sys

import pytest

import spacearm.base.runtime.priority as priority
from spacearm.console import main as console_main


@pytest.fixture
def requests(monkeypatch):
    asked: list[int] = []
    monkeypatch.setattr(priority, "use_fifo", lambda p: asked.append(p))
    return asked


def run(monkeypatch, words: list[str], argv=None) -> None:
    monkeypatch.setattr(sys, "argv", ["spacearm", *words])
    with pytest.raises(SystemExit):
        console_main.main(argv)


def test_stop_asks_for_real_time_priority_below_the_control_path(monkeypatch, requests):
    run(monkeypatch, ["stop", "--api", "tcp:127.0.0.1:9"])     # nothing listens: exits 1, one line
    assert requests == [console_main.STOP_RT_PRIORITY] and 0 < console_main.STOP_RT_PRIORITY < 50


def test_the_setting_turns_it_off_and_a_bad_setting_still_stops(monkeypatch, requests):
    monkeypatch.setenv("SPACEARM_STOP_RT_PRIORITY", "0")
    run(monkeypatch, ["stop", "--api", "tcp:127.0.0.1:9"])
    monkeypatch.setenv("SPACEARM_STOP_RT_PRIORITY", "high")
    run(monkeypatch, ["stop", "--api", "tcp:127.0.0.1:9"])
    assert requests == [0]


def test_other_commands_and_in_process_calls_leave_scheduling_alone(monkeypatch, requests):
    run(monkeypatch, ["status", "--api", "tcp:127.0.0.1:9"])
    run(monkeypatch, [], argv=["stop", "--api", "tcp:127.0.0.1:9"])
    assert requests == []
