"""Our CANopen master against CiA 402 drives built on `durand` (an independent responder
stack from PyPI), each described by the EDS that durand itself writes."""
from __future__ import annotations

import math

import pytest

from spacearm.base.config.bus import PdoLayout
from spacearm.drivers.errors import BootError
from spacearm.drivers.network import ArmNetwork
from hil_tests.interop.durand_drive import VARIANTS, DurandDrive
from hil_tests.interop.matrix import CHECKS, NODE_ID, bus_config, run_variant



@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_master_boots_enables_moves_and_supervises_durand_drive(variant, tmp_path):
    result = run_variant(variant, tmp_path)
    failed = {c: result.detail.get(c, "not run") for c in CHECKS if not result.passed.get(c)}
    assert not failed, f"{variant}: {failed}"


def test_absent_optional_objects_are_skipped_and_listed(tmp_path):
    result = run_variant("minimal", tmp_path)
    skipped = " ".join(result.skipped)
    for index in ("0x1016", "0x1006", "0x608F", "0x6091", "0x6076", "0x6065", "0x607D", "0x60C2"):
        assert index in skipped


def _net(tmp_path, variant: str, **layout):
    drive = DurandDrive(f"durand-{variant}-{tmp_path.name}", NODE_ID, VARIANTS[variant])
    cfg = bus_config(VARIANTS[variant], drive.write_eds(tmp_path / "d.eds"))
    if layout:
        node = cfg.nodes[0].model_copy(update={"pdo": PdoLayout(**layout)})
        cfg = cfg.model_copy(update={"nodes": [node]})
    return drive, ArmNetwork(f"virtual:durand-{variant}-{tmp_path.name}", cfg)


def test_vendor_objects_are_not_mapped_unless_configured(tmp_path):
    drive, net = _net(tmp_path, "vendor_2000")
    try:
        net.boot()
        mapped = [net.sdo_read("joint_1", 0x1A00 + n, i) >> 16 for n in range(4)
                  for i in range(1, net.sdo_read("joint_1", 0x1A00 + n, 0) + 1)]
        assert mapped and 0x2000 not in mapped and 0x2001 not in mapped
        joint = net.cycle().joints[0]
        assert math.isnan(joint.temperature) and joint.brake_engaged is None   # never its 2000h/2001h
    finally:
        net.close()
        drive.close()


def test_mapping_beyond_the_devices_pdos_is_refused_before_boot(tmp_path):
    with pytest.raises(BootError, match=r"node 5 'joint_1'.*TPDO2: the device has 1 TPDOs"):
        _net(tmp_path, "exact_pdos", rpdo=[["0x6040", "0x607A"]], tpdo=[["0x6041"], ["0x6064"]])


def test_mapping_an_object_the_device_lacks_names_it(tmp_path):
    with pytest.raises(BootError, match=r"TPDO1: object 0x2000:00 does not exist in d.eds"):
        _net(tmp_path, "minimal", rpdo=[["0x6040"]], tpdo=[["0x6041", "0x2000"]])


def test_eds_of_another_device_is_refused_at_boot(tmp_path):
    drive = DurandDrive(f"durand-wrong-{tmp_path.name}", NODE_ID, VARIANTS["minimal"])
    eds = tmp_path / "wrong.eds"
    eds.write_text(drive.eds_text.replace("DefaultValue=3549", "DefaultValue=3550", 1))  # vendor 0xDDD
    net = ArmNetwork(f"virtual:durand-wrong-{tmp_path.name}", bus_config(VARIANTS["minimal"], eds))
    try:
        with pytest.raises(BootError, match=r"Vendor-ID \(0x1018:01\) is 0x00000DDD, the EDS wrong.eds "
                                            r"expects 0x00000DDE"):
            net.boot()
    finally:
        net.close()
        drive.close()
