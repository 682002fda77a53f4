"""`spacearm bus scan`: nodes found by SDO upload, compared with a bus file and its EDS, written
as a starting bus file."""
from __future__ import annotations

import json

from typer.testing import CliRunner

from spacearm.base.config.bus import load_bus_config
from spacearm.console.main import build_app
from spacearm.drivers.bus_scan import compare, scan, starting_bus_file
from hil_tests.interop.durand_drive import VARIANTS, DurandDrive
from hil_tests.interop.matrix import bus_config


def test_scan_finds_every_simulated_node_with_its_identity(vbus, bus_config, sim):
    found = scan(vbus)
    assert [n.node_id for n in found] == sorted(n.node_id for n in bus_config.nodes)
    drives = [n for n in found if n.node_id <= 6]
    assert all(n.profile == 402 and set(n.identity) == {1, 2, 3, 4} for n in drives)
    assert compare(found, bus_config, vbus) == []          # the simulator is what its EDS says


def test_scan_compares_an_overstating_drive_and_writes_a_bus_file_that_loads(tmp_path):
    variant = VARIANTS["overstated"]
    channel = f"scan-{tmp_path.name}"
    drive = DurandDrive(channel, variant.node_id, variant)
    try:
        cfg = bus_config(variant, drive.write_eds(tmp_path / "vendor.eds"))
        # durand answers from Python threads: on a loaded machine an answer may take long, and
        # a late one must not read as a missing object (the timeout only ends a hang)
        cfg = cfg.model_copy(update={"bus": cfg.bus.model_copy(update={"sdo_timeout": 5.0})})
        found = scan(f"virtual:{channel}")
        assert [(n.node_id, n.device_type) for n in found] == [(5, 0x0002_0192)]
        lines = compare(found, cfg, f"virtual:{channel}")
        lacks = {line.split(": ")[1].split(" ")[0] for line in lines if "the device lacks it (0x06020000)" in line}
        assert {"0x1016:01", "0x1006:00", "0x6065:00", "0x6066:00", "0x6072:00", "0x607D:02", "0x60C2:01"} <= lacks, \
            lines
        read_only = {line.split(": ")[1].split(" ")[0] for line in lines if "read-only on the device" in line}
        assert read_only == {"0x608F:01", "0x608F:02", "0x6091:01", "0x6091:02", "0x6076:00"}
        assert len(lines) == len(lacks) + len(read_only)       # nothing else differs
        written = tmp_path / "found.toml"
        written.write_text(starting_bus_file(found, cfg))
        assert [(n.name, n.node_id, n.device) for n in load_bus_config(written).nodes] == [("joint_1", 5, "joint_drive")]
        bare = tmp_path / "bare.toml"
        bare.write_text(starting_bus_file(found))
        assert load_bus_config(bare).nodes[0].device == "joint_drive"
    finally:
        drive.close()


def test_cli_scan_reports_in_one_json_object_and_exits_1_on_differences(vbus, bus_config, sim, tmp_path):
    runner = CliRunner()
    result = runner.invoke(build_app(["bus"]), ["bus", "scan", vbus, "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert len(report["nodes"]) == 8 and report["differences"] == []
    other = bus_config.without("joint_6")
    path = tmp_path / "bus.toml"
    from spacearm.base.config.bus import dump_toml
    path.write_text(dump_toml(other))
    result = runner.invoke(build_app(["bus"]), ["bus", "scan", vbus, "--bus-file", str(path)])
    assert result.exit_code == 1
    assert "node 6: on the bus, not in the bus file" in result.output
