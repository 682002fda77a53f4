"""Line faults injected at run time through a fault file (`spacearm bus fault` writes it,
`spacearm sim --fault-file` / `spacearm hub --fault-file` read it), judged by what a plain bus
on each line (a third party on the wire) receives from a pair whose faults the file drives."""
from __future__ import annotations

import time
import uuid

import can
import pytest
from typer.testing import CliRunner

from spacearm.base.transport import open_bus
from spacearm.base.transport.line_faults import FaultFileWatcher, LineFault, clear_all, parse_fault_text
from spacearm.console.main import build_app


def received(bus: can.BusABC, wait: float = 0.05) -> list[int]:
    out, deadline = [], time.monotonic() + wait
    while time.monotonic() < deadline:
        msg = bus.recv(0.01)
        if msg is not None:
            out.append(msg.arbitration_id)
    return out


def bus_fault(*args: str):
    return CliRunner().invoke(build_app(["bus"]), ["bus", "fault", *args])


def test_console_command_cuts_and_restores_a_line_the_pair_sends_on(tmp_path):
    tag = uuid.uuid4().hex[:8]
    a, b = f"virtual:ff-a-{tag}", f"virtual:ff-b-{tag}"
    pair, wire_a = open_bus(f"{a}+{b}"), open_bus(a)
    reports: list[str] = []
    path = tmp_path / "faults"
    watcher = FaultFileWatcher(path, {"A": pair.faults[0], f"ff-a-{tag}": pair.faults[0], "B": pair.faults[1]},
                               reports.append)
    frame = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
    try:
        assert bus_fault(str(path), "A", "cut").exit_code == 0
        watcher.poll()
        pair.send(frame)
        assert received(wire_a) == []
        assert bus_fault(str(path), "B", "intermittent", "--loss", "0.3").exit_code == 0
        watcher.poll()
        assert (pair.faults[0].mode, pair.faults[1].mode, pair.faults[1].loss) == ("cut", "intermittent", 0.3)
        assert bus_fault(str(path), "A", "ok").exit_code == 0
        watcher.poll()
        pair.send(frame)
        assert received(wire_a) == [0x080]
        assert path.read_text() == "B intermittent 0.3\n"
        assert [r for r in reports if "line A" in r] == [f"line A ({a}): cut", f"line A ({a}): ok"]
    finally:
        watcher.stop()
        pair.shutdown()
        wire_a.shutdown()
        clear_all()


@pytest.mark.parametrize("args, said", [(("A", "melted"), "unknown line fault 'melted'"),
                                        (("A", "intermittent", "--loss", "1.5"), "not within 0..1"),
                                        (("two words", "cut"), "one word")])
def test_console_command_refuses_bad_input_in_one_line(tmp_path, args, said):
    result = bus_fault(str(tmp_path / "faults"), *args)
    assert result.exit_code == 2 and said in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "faults").exists()


def test_fault_file_text_with_bad_lines_keeps_the_good_ones():
    wanted, problems = parse_fault_text("A cut  # the nominal line\n\nB babble 0.5 extra\nvcan1 melted\nB ok\n")
    assert wanted == {"A": ("cut", None), "B": ("ok", None)}
    assert [p.split(":")[0] for p in problems] == ["3", "4"]


def test_watcher_names_a_line_it_does_not_have(tmp_path):
    path = tmp_path / "faults"
    path.write_text("C cut\n")
    reports: list[str] = []
    watcher = FaultFileWatcher(path, {"A": LineFault("virtual:x")}, reports.append)
    watcher.stop()
    assert len(reports) == 1 and "no line 'C'" in reports[0]
