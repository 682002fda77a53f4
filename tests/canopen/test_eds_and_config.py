"""EDS files: generated, loadable by canopen, conformant object set. Bus config schema."""
from __future__ import annotations

import canopen
import pytest

from spacearm.base.config.errors import ConfigError
from spacearm.base.config.loader import load_toml_model
from spacearm.base.canopen import od
from spacearm.base.config.bus import EDS_DIR, BusConfig, load_bus_config
from spacearm.base.canopen.pdo_maps import PDO_MAPS
from spacearm.firmware_sim import eds_builder

DEVICES = ("joint_drive", "end_effector", "ft_sensor")


@pytest.mark.parametrize("device", DEVICES)
def test_eds_file_is_up_to_date_with_builder(device):
    assert (EDS_DIR / f"{device}.eds").read_text() == eds_builder.render(device), \
        "run: .venv/bin/python -m spacearm.firmware_sim.eds_builder"


@pytest.mark.parametrize("device", DEVICES)
def test_eds_has_cia301_objects(device):
    d = canopen.import_od(str(EDS_DIR / f"{device}.eds"), 5)
    for index in (od.DEVICE_TYPE, od.ERROR_REGISTER, od.PREDEFINED_ERROR_FIELD, od.COB_ID_SYNC,
                  od.COMM_CYCLE_PERIOD, od.COB_ID_EMCY, od.CONSUMER_HEARTBEAT, od.PRODUCER_HEARTBEAT,
                  od.IDENTITY):
        assert index in d, f"{device}: 0x{index:04X} missing"
    for n in range(od.N_PDOS):
        for base in (od.RPDO_COMM, od.RPDO_MAP, od.TPDO_COMM, od.TPDO_MAP):
            assert base + n in d
    assert [d[od.IDENTITY][i].default for i in (1,)] == [eds_builder.VENDOR_ID]
    assert d[od.COB_ID_EMCY].default == 0x85                       # $NODEID+0x80
    assert d[od.TPDO_COMM][od.PDO_COB_ID].default == 0x185
    assert not d[od.DEVICE_TYPE].writable and not d[od.ERROR_REGISTER].writable


@pytest.mark.parametrize("device", DEVICES)
def test_pdo_maps_only_use_mappable_objects_that_fit(device):
    d = canopen.import_od(str(EDS_DIR / f"{device}.eds"), 1)
    for kind in ("rpdo", "tpdo"):
        for mapping in PDO_MAPS[device][kind]:
            assert sum(bits for _, _, bits in mapping) <= 64
            for index, sub, bits in mapping:
                var = d[index] if not hasattr(d[index], "subindices") else d[index][sub]
                assert var.pdo_mappable and len(var) == bits
                assert var.writable if kind == "rpdo" else var.readable


def test_joint_eds_has_cia402_scaling_and_modes():
    d = canopen.import_od(str(EDS_DIR / "joint_drive.eds"), 1)
    assert d[od.SUPPORTED_DRIVE_MODES].default & 0x81 == 0x81      # PP and CSP
    assert d[od.POSITION_ENCODER_RESOLUTION][1].default == 1 << 20
    assert d[od.GEAR_RATIO][1].default == 100


def test_arm_bus_config_loads():
    cfg = load_bus_config()
    assert [n.node_id for n in cfg.joints] == [1, 2, 3, 4, 5, 6]
    assert cfg.bus.sync_period == 0.02
    assert abs(cfg.joints[0].joint.increments_per_rad - (1 << 20) * 100 / (2 * 3.141592653589793)) < 1e-6
    assert cfg.node("ft_sensor").ft.force_counts_per_n == 100


def test_bus_config_errors_name_file_and_key(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('[[nodes]]\nname = "a"\nnode_id = 1\ndevice = "joint_drive"\n'
                 '[[nodes]]\nname = "b"\nnode_id = 1\ndevice = "ft_sensor"\n')
    with pytest.raises(ConfigError, match=r"bad.toml: .*node_id 1 used by both 'a' and 'b'"):
        load_toml_model(p, BusConfig)
    p.write_text('[[nodes]]\nname = "a"\nnode_id = 200\ndevice = "joint_drive"\n')
    with pytest.raises(ConfigError, match=r"nodes #1\.node_id"):
        load_toml_model(p, BusConfig)
    p.write_text('[[nodes]]\nname = "a"\nnode_id = 2\ndevice = "gripper"\n')
    with pytest.raises(ConfigError, match=r"nodes #1\.device"):
        load_toml_model(p, BusConfig)
    p.write_text('[[nodes]]\nname = "a"\nnode_id = 2\ndevice = "ft_sensor"\n[nodes.joint]\nlower = 0\n')
    with pytest.raises(ConfigError, match=r"\[joint\] settings given for a ft_sensor node"):
        load_toml_model(p, BusConfig)


def test_eds_with_empty_device_info_numbers_loads(tmp_path):
    """Vendors leave [DeviceInfo] VendorNumber/ProductNumber empty (CANopenNode's example profile
    does); the identity that matters is 1018h, so the file loads."""
    from spacearm.base.canopen.eds import load_od
    from spacearm.base.config.bus import EDS_DIR

    text = (EDS_DIR / "joint_drive.eds").read_text()
    lines = [("VendorNumber=" if line.startswith("VendorNumber=") else
              "ProductNumber=" if line.startswith("ProductNumber=") else line) for line in text.splitlines()]
    path = tmp_path / "vendor.eds"
    path.write_text("\n".join(lines) + "\n")
    od = load_od(path, 3)
    assert od[0x1018][1].default == load_od(EDS_DIR / "joint_drive.eds", 3)[0x1018][1].default
