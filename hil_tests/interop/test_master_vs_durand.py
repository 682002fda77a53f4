"""Our CANopen master against CiA 402 drives built on `durand` (an independent responder
stack from PyPI), each described by the EDS that durand itself writes."""
from __future__ import annotations

import math

import pytest

from spacearm.base.config.bus import PdoLayout
from spacearm.console.status_view import status_lines
from spacearm.drivers.errors import BootError
from spacearm.drivers.network import ArmNetwork
from hil_tests.interop.durand_drive import OVERSTATED_ABSENT, OVERSTATED_READ_ONLY, VARIANTS, DurandDrive
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


def _net(tmp_path, variant: str, strict: bool = False, **layout):
    v = VARIANTS[variant]
    drive = DurandDrive(f"durand-{variant}-{tmp_path.name}", v.node_id, v)
    cfg = bus_config(v, drive.write_eds(tmp_path / "d.eds"), strict=strict)
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
    with pytest.raises(BootError, match=r"node 5 'joint_1'.*TPDO2: the device has no TPDO2 \(its EDS d.eds lists 1 TPDOs: 1\)"):
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


def _entries(spec) -> list[int]:
    return [e.entry for e in spec.entries]


@pytest.mark.parametrize("variant", ["stored_other", "factory_empty", "high_pdos"])
def test_device_holds_the_configured_pdos_after_boot_whatever_it_held_before(variant, tmp_path):
    """Read from the drive itself (its own dictionary) and over SDO: every used PDO as the bus
    file says, synchronous, on its COB-ID; every other PDO disabled; data both ways."""
    drive, net = _net(tmp_path, variant)
    try:
        net.boot()
        driver = net.drivers["joint_1"]
        used = {(s.kind, s.number + 1): s for s in driver.rpdos + driver.tpdos}
        rpdos, tpdos = drive.variant.pdos
        for kind, count, comm in (("RPDO", rpdos, 0x1400), ("TPDO", tpdos, 0x1800)):
            for number in range(1, count + 1):
                cob, transmission, mapping = drive.held_pdo(kind, number)
                spec = used.get((kind, number))
                if spec is None:
                    assert cob & 0x8000_0000, f"{variant}: {kind}{number} left enabled (0x{cob:08X})"
                    continue
                assert (cob, transmission, mapping) == (spec.cob_id, 1, _entries(spec)), f"{kind}{number}"
                assert net.sdo_read("joint_1", comm + number - 1, 1) == spec.cob_id
        if variant == "high_pdos":
            assert {k: s.cob_id for k, s in used.items()} == {("RPDO", 6): 0x4E2, ("TPDO", 7): 0x3E1}
        net.enable_all(max_cycles=20)
        state = net.move_to([0.2], 0.3)
        assert abs(state.joints[0].position - 0.2) < 1e-5                       # TPDO in
        assert drive.od.read(0x607A, 0) == round(0.2 * (1 << 20) * 100 / (2 * math.pi))   # RPDO out
    finally:
        net.close()
        drive.close()


def test_overstated_eds_boot_lists_every_refusal_and_uses_the_fallbacks(tmp_path):
    drive, net = _net(tmp_path, "overstated")
    try:
        net.boot()
        report = net.bringup["joint_1"]
        refused = " ".join(report.refused)
        for index in OVERSTATED_ABSENT:
            assert f"0x{index:04X}" in refused and "0x06020000" in refused
        for index in OVERSTATED_READ_ONLY:
            assert f"0x{index:04X}" in refused and "0x06010002" in refused
        assert "1016h refused" in report.guarding and report.master_following_error
        assert "0x608F:01=131072" in report.read_only and "0x6091:01=160" in report.read_only
        shown = "\n".join(status_lines({"state": "disabled", "bringup": {"joint_1": vars(report)}}))   # `status`
        assert [line for line in shown.splitlines() if line.startswith("joint_1: 0x")] == \
            [f"joint_1: {text}" for text in report.refused]
        assert "joint_1: read-only, the device's value used: 0x608F:01=131072" in shown
        net.enable_all(max_cycles=20)
        net.poll_events()
        drive.stalled = True            # the motor stops following: only the master can notice
        joint = net.drivers["joint_1"].settings
        n = round(joint.following_error_timeout / net.config.bus.sync_period) + 5
        net.move_to([0.05], 0.05, settle_cycles=n)
        events = [e for e in net.poll_events() if e.kind == "following_error"]
        assert len(events) == 1 and events[0].code == 0x8611 and "supervised by the master" in events[0].message
    finally:
        net.close()
        drive.close()


def test_strict_node_stops_the_boot_at_the_first_refusal(tmp_path):
    drive, net = _net(tmp_path, "overstated", strict=True)
    try:
        with pytest.raises(BootError, match=r"node 5 'joint_1'.*SDO write 0x1016:01 aborted with 0x06020000"):
            net.boot()
    finally:
        net.close()
        drive.close()


def test_verify_configuration_skips_a_configured_device_and_catches_a_changed_one(tmp_path):
    drive, net = _net(tmp_path, "verify")
    try:
        net.boot()
        first = net.bringup["joint_1"]
        assert not first.verified and first.sdo_writes > 20 and drive.stores == 1
        stamp = (drive.od.read(0x1020, 1), drive.od.read(0x1020, 2))
        assert stamp != (0, 0) and stamp[1] < 86_400_000
        net.boot()                                     # reset communication: the drive kept it all
        second = net.bringup["joint_1"]
        assert second.verified and second.sdo_writes == 0 and drive.stores == 1
        state = net.enable_all(max_cycles=20)
        assert state.all_enabled
    finally:
        net.close()
    # another layout for the same drive: its stamp no longer matches, so it is configured again
    cfg = bus_config(drive.variant, tmp_path / "d.eds")
    node = cfg.nodes[0].model_copy(update={"pdo": PdoLayout(rpdo=[["0x6040", "0x607A"]],
                                                            tpdo=[["0x6041", "0x6064"], ["0x6061"]])})
    net = ArmNetwork(f"virtual:durand-verify-{tmp_path.name}", cfg.model_copy(update={"nodes": [node]}))
    try:
        net.boot()
        third = net.bringup["joint_1"]
        assert not third.verified and drive.stores == 2
        assert drive.held_pdo("TPDO", 2)[2] == [0x6061_0008]
        assert (drive.od.read(0x1020, 1), drive.od.read(0x1020, 2)) != stamp
    finally:
        net.close()
        drive.close()


def test_a_drive_that_keeps_another_mapping_than_written_is_a_boot_error(tmp_path):
    """Read-back: a drive that acknowledges the mapping writes but keeps its own layout."""
    drive, net = _net(tmp_path, "minimal")
    original = drive.od.write

    def stubborn(index, subindex, value, downloaded=False):
        if index == 0x1A00 and subindex == 2 and downloaded:
            value = 0x606C_0020                       # keeps velocity where position was written
        return original(index, subindex, value, downloaded)

    drive.od.write = stubborn
    try:
        with pytest.raises(BootError, match=r"node 5 'joint_1'.*TPDO1 \(0x185\): mapping entry 2 read back "
                                            r"0x606C0020 \(0x1A00:02\), written 0x60640020"):
            net.boot()
    finally:
        net.close()
        drive.close()
