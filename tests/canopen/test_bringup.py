"""EDS-driven bring-up against our simulated nodes: what is written, what is refused, and
supervision of mapped TPDOs."""
from __future__ import annotations

import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import BusConfig
from spacearm.base.canopen.eds import EdsError
from spacearm.drivers.errors import BootError
from spacearm.drivers.network import ArmNetwork


def _with_node(bus_config: BusConfig, name: str, **update) -> BusConfig:
    nodes = [n.model_copy(update=update) if n.name == name else n for n in bus_config.nodes]
    return bus_config.model_copy(update={"nodes": nodes})


def _boot_refused(net: ArmNetwork, match: str) -> None:
    """Boot must stop with a BootError matching ``match``; the network is closed either way."""
    try:
        with pytest.raises(BootError, match=match):
            net.boot()
    finally:
        net.close()


def test_every_pdo_the_eds_lists_is_configured_explicitly_and_read_back(booted):
    """Nothing assumed from the EDS defaults: used PDOs written and read back, unused disabled;
    the device's own COB-IDs (read over SDO) say so."""
    report = booted.bringup["joint_1"]
    driver = booted.drivers["joint_1"]
    assert report.skipped == [] and report.refused == [] and "1016h" in report.guarding
    used = {(s.kind, s.number): s for s in driver.rpdos + driver.tpdos}
    for kind, comm in (("RPDO", od.RPDO_COMM), ("TPDO", od.TPDO_COMM)):
        for n in range(4):
            cob = booted.sdo_read("joint_1", comm + n, od.PDO_COB_ID)
            spec = used.get((kind, n))
            if spec is None:
                assert cob & od.PDO_COB_ID_INVALID, f"{kind}{n + 1} left enabled"
            else:
                assert cob == spec.cob_id
                assert booted.sdo_read("joint_1", comm + n, od.PDO_TRANSMISSION_TYPE) == od.TRANSMISSION_SYNC
    # the read-back: one COB-ID, one count and every entry per used PDO
    entries = sum(len(s.entries) for s in used.values())
    assert report.sdo_reads >= 3 + 2 * len(used) + entries


def test_a_write_the_device_refuses_names_node_object_and_code(vbus, bus_config, sim):
    _boot_refused(ArmNetwork(vbus, _with_node(bus_config, "joint_2", sdo={"0x605A": 99})),
                  r"node 2 'joint_2' \(joint_drive\): SDO write 0x605A:00 aborted "
                  r"with 0x06090031 \(Value of parameter written too high\)")


def test_sdo_table_naming_a_read_only_object_is_refused(vbus, bus_config, sim):
    _boot_refused(ArmNetwork(vbus, _with_node(bus_config, "joint_2", sdo={"0x6041": 1})),
                  r"node 2 'joint_2'.*\[sdo\] 0x6041: read-only in joint_drive.eds")


def test_missing_or_unparsable_eds_is_one_clear_error(vbus, bus_config, tmp_path):
    with pytest.raises(EdsError, match=r"nowhere.eds: cannot read"):
        ArmNetwork(vbus, _with_node(bus_config, "joint_1", eds=str(tmp_path / "nowhere.eds")))
    bad = tmp_path / "bad.eds"
    bad.write_text("[1000]\nParameterName=x\nDataType=0xZZ\n")
    with pytest.raises(EdsError, match=r"bad.eds: not a valid EDS file"):
        ArmNetwork(vbus, _with_node(bus_config, "joint_1", eds=str(bad)))


def test_mapping_a_non_mappable_object_is_refused_before_boot(vbus, bus_config):
    from spacearm.base.config.bus import PdoLayout
    with pytest.raises(BootError, match=r"node 1 'joint_1'.*TPDO1: object 0x6065:00 'Following error window' "
                                        r"is not PDO-mappable"):
        ArmNetwork(vbus, _with_node(bus_config, "joint_1", pdo=PdoLayout(rpdo=[["0x6040"]],
                                                                         tpdo=[["0x6041", "0x6065"]])))


def test_mapped_tpdo_missing_for_n_syncs_is_a_fault_naming_node_and_pdo(enabled, sim):
    enabled.poll_events()
    sim.node("joint_3").faults.ignore_sync = True
    limit = enabled.config.bus.tpdo_loss_cycles
    for _ in range(limit - 1):
        enabled.cycle(timeout=0.05)
    assert not [e for e in enabled.poll_events() if e.kind == "tpdo_missing"]
    enabled.cycle(timeout=0.05)
    enabled.cycle(timeout=0.05)
    events = [e for e in enabled.poll_events() if e.kind == "tpdo_missing"]
    assert {e.node for e in events} == {"joint_3"}
    assert any(f"TPDO1 (0x{od.TPDO_BASE[0] + 3:03X}) missing for {limit} SYNCs" in e.message for e in events)
    sim.node("joint_3").faults.ignore_sync = False
    enabled.cycle()
    enabled.cycle()
    assert not [e for e in enabled.poll_events() if e.kind == "tpdo_missing"]


def test_status_lists_the_optional_objects_a_node_lacks(vbus, bus_config, sim):
    from spacearm.console.status_view import status_lines
    from spacearm.base.config.bus import PdoLayout
    # the simulated node 1 is the standard drive: its identity differs from the compact EDS
    _boot_refused(ArmNetwork(vbus, _with_node(bus_config, "joint_1", eds="joint_drive_compact.eds",
                                              pdo=PdoLayout(rpdo=[["0x6040", "0x607A"]], tpdo=[["0x6041", "0x6064"]]))),
                  r"Product code .* is 0x04020001, the EDS joint_drive_compact.eds")
    lines = status_lines({"state": "idle", "bringup": {"joint_4": {"skipped": ["0x1016:01 not in the EDS"]},
                                                       "joint_1": {"skipped": []}}})
    assert "absent optional objects (skipped at bring-up): joint_4 0x1016:01" in lines


def test_a_drive_layout_without_the_controlword_is_refused(vbus, bus_config):
    from spacearm.base.config.bus import PdoLayout
    with pytest.raises(BootError, match=r"node 3 'joint_3'.*0x6040 must be mapped to an RPDO"):
        ArmNetwork(vbus, _with_node(bus_config, "joint_3", pdo=PdoLayout(rpdo=[["0x607A"]], tpdo=[["0x6041", "0x6064"]])))


def test_dcf_parameter_values_are_written_at_boot(vbus, bus_config, sim, tmp_path):
    from spacearm.base.config.bus import EDS_DIR
    text = (EDS_DIR / "joint_drive.eds").read_text()
    section = "[6067]\nParameterName=Position window\n"
    assert section in text
    dcf = tmp_path / "joint_2.dcf"
    dcf.write_text(text.replace(section, section + "ParameterValue=4242\n"))
    net = ArmNetwork(vbus, _with_node(bus_config, "joint_2", eds=str(dcf)))
    try:
        net.boot()
        assert sim.node("joint_2").get(od.POSITION_WINDOW) == 4242
        assert sim.node("joint_1").get(od.POSITION_WINDOW) != 4242
    finally:
        net.close()


def _guarded_eds(tmp_path):
    """joint_drive.eds with node guarding (100Ch/100Dh) instead of a heartbeat producer."""
    from spacearm.base.config.bus import EDS_DIR
    text = (EDS_DIR / "joint_drive.eds").read_text()
    start = text.index("[1017]\n")
    end = text.index("\n\n", start) + 2
    guarding = ("[100C]\nParameterName=Guard time\nObjectType=0x7\nDataType=0x0006\nAccessType=rw\n"
                "DefaultValue=0x0\nPDOMapping=0\n\n[100D]\nParameterName=Life time factor\nObjectType=0x7\n"
                "DataType=0x0005\nAccessType=rw\nDefaultValue=0x0\nPDOMapping=0\n\n")
    path = tmp_path / "joint_drive_guarded.eds"
    path.write_text(text[:start] + guarding + text[end:])
    return path


def test_a_node_with_only_node_guarding_is_polled_and_its_loss_detected(vbus, bus_config, tmp_path):
    from spacearm.firmware_sim.runner import Simulator
    cfg = _with_node(bus_config, "joint_3", eds=str(_guarded_eds(tmp_path)))
    sim = Simulator(vbus, cfg).start()
    net = ArmNetwork(vbus, cfg)
    try:
        net.boot()
        report = net.bringup["joint_3"]
        assert report.node_guarding and "node guarding" in report.guarding
        assert sim.node("joint_3").get(od.GUARD_TIME) == 100 and sim.node("joint_3").get(od.LIFE_TIME_FACTOR) == 3
        assert net.enable_all().all_enabled
        net.poll_events()
        sim.node("joint_3").faults.heartbeat_stopped = True     # it stops answering the guarding RTRs
        import time
        lost, deadline = [], time.monotonic() + 1.0
        while not lost and time.monotonic() < deadline:
            time.sleep(0.02)
            lost = [e for e in net.poll_events() if e.kind == "heartbeat_lost"]
        assert [e.node for e in lost] == ["joint_3"]
    finally:
        net.close()
        sim.stop()


def test_a_guarding_answer_that_does_not_toggle_is_reported_not_taken_for_loss(vbus, bus_config, tmp_path,
                                                                             monkeypatch):
    import time
    from spacearm.firmware_sim.runner import Simulator
    cfg = _with_node(bus_config, "joint_3", eds=str(_guarded_eds(tmp_path)))
    sim = Simulator(vbus, cfg).start()
    net = ArmNetwork(vbus, cfg)
    try:
        net.boot()
        net.poll_events()
        time.sleep(0.5)                                       # several polls, each answer toggled
        assert net.stats.guard_toggle_errors == 0
        node = sim.node("joint_3")
        answer = node.on_guard_request

        def stuck_toggle():                                   # a node repeating its last answer
            answer()
            node._guard_toggle ^= 0x80
        monkeypatch.setattr(node, "on_guard_request", stuck_toggle)
        deadline = time.monotonic() + 10.0
        events = []
        while not events and time.monotonic() < deadline:
            time.sleep(0.05)
            events = [e for e in net.poll_events() if e.kind == "guard_toggle"]
        assert events and events[0].node == "joint_3" and net.stats.guard_toggle_errors >= 1
        assert net.health["joint_3"].alive                     # answered: not a lost node
    finally:
        net.close()
        sim.stop()
