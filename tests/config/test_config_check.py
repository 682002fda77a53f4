"""`spacearm config check`: each kind of file with its own schema, a bus file against its EDS."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from spacearm.base.config.bus import BusConfig, NodeConfig, PdoEntry, PdoLayout, dump_toml, load_bus_config
from spacearm.base.config.errors import ConfigError
from spacearm.console.commands.config import check_file, file_kind

ROOT = Path(__file__).resolve().parents[2]
FILES = {"arm": "configs/arm/ur10.toml", "bus": "configs/bus/arm.toml", "plant": "configs/plant/ur10_nominal.toml",
         "scene": "configs/scene/oru_testbed.toml", "campaign": "configs/campaigns/approach.toml"}


@pytest.mark.parametrize("kind", sorted(FILES))
def test_each_kind_is_recognised_and_validated(kind, tmp_path):
    path = ROOT / FILES[kind]
    assert file_kind(path) == kind
    copy = tmp_path / "anywhere.toml"           # not in its configs/<kind>/ folder: told by its keys
    copy.write_text(path.read_text())
    if kind != "plant":
        assert file_kind(copy) == kind
    assert check_file(path, kind)["text"]


def _bus_with(tmp_path, pdo: PdoLayout) -> Path:
    base = load_bus_config()
    node = base.node("joint_1").model_copy(update={"pdo": pdo})
    path = tmp_path / "bus.toml"
    path.write_text(dump_toml(BusConfig(bus=base.bus, nodes=[node])))
    return path


def test_bus_file_pdo_numbers_and_cob_ids_round_trip_and_are_checked_against_the_eds(tmp_path):
    layout = PdoLayout(rpdo=[["0x6040", "0x607A"]],
                       tpdo=[PdoEntry(number=3, cob_id=0x3E1, objects=["0x6041", "0x6064"])])
    path = _bus_with(tmp_path, layout)
    assert load_bus_config(path).node("joint_1").pdo == layout
    assert check_file(path, "bus")["nodes"] == 1
    beyond = _bus_with(tmp_path, PdoLayout(rpdo=[["0x6040", "0x607A"]],
                                           tpdo=[PdoEntry(number=9, cob_id=0x3E1, objects=["0x6041", "0x6064"])]))
    with pytest.raises(ConfigError, match=r"node 1 'joint_1' \(joint_drive\): TPDO9: the device has no TPDO9 "
                                          r"\(its EDS joint_drive.eds lists 4 TPDOs: 1, 2, 3, 4\)"):
        check_file(beyond, "bus")
    no_cob = _bus_with(tmp_path, PdoLayout(rpdo=[["0x6040", "0x607A"]],
                                           tpdo=[PdoEntry(number=4, objects=["0x6041", "0x6064"])]))
    check_file(no_cob, "bus")                   # PDO4 has a pre-defined COB-ID


def test_pdo_given_twice_is_refused():
    with pytest.raises(ValueError, match="TPDO1 given twice"):
        PdoLayout(tpdo=[["0x6041"], PdoEntry(number=1, objects=["0x6064"])])


def test_cli_checks_a_bus_file_and_names_each_bad_file_in_one_line(tmp_path):
    bad = tmp_path / "bad_bus.toml"
    bad.write_text((ROOT / FILES["bus"]).read_text().replace("node_id = 2\n", "node_id = 200\n", 1))
    result = subprocess.run([sys.executable, "-m", "spacearm.console.main", "config", "check",
                             FILES["bus"], FILES["plant"], str(bad)], capture_output=True, text=True, cwd=ROOT,
                            timeout=120)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    out = result.stdout.splitlines()
    assert out[0] == f"{FILES['bus']}: ok (bus: 8 nodes (IDs 1, 2, 3, 4, 5, 6, 16, 17), every PDO layout fits its EDS)"
    assert out[1].startswith(f"{FILES['plant']}: ok (plant: ") and len(out) == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error[bad_config]: {bad}: nodes #2.node_id")
