"""Our master against CANopenNode (a C device stack nobody here wrote) running as its Linux
device `canopend` on real kernel CAN (vcan0; inside the test VM in CI).

The master boots it from its own EDS (DS301_profile.eds: a generic CiA 301 device), configures
heartbeat and PDOs, exchanges process data both ways every SYNC, reads and writes by SDO
(expedited and segmented), receives its EMCY, notices its heartbeat loss when it is killed and
reconfigures it after it restarts. Everything asserted is read back from the device or seen on
the bus. The profile's only objects mappable both ways are the SDO client's COB-IDs (1280h.1/.2):
a value with bit 31 set (client not valid) is accepted by its write check and is harmless, so
RPDO1 writes them and TPDO1 reports them back.
"""
from __future__ import annotations

import signal
import subprocess
import threading
import time

import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import BusConfig, BusSettings, NodeConfig, PdoLayout
from spacearm.drivers.network import ArmNetwork
from hil_tests.conftest import vcan_available
from hil_tests.interop.canopennode import canopend_binary, eds_path

NODE_ID = 4
CLIENT_COB = (0x1280, 1), (0x1280, 2)     # SDO client COB-IDs: rw, mappable both ways
INVALID = 0x8000_0000
ERR_GENERIC_OR_COMM = 0x11      # 1001h bits 0 and 4: the ones CANopenNode leaves OPERATIONAL for


@pytest.fixture(scope="module")
def canopend(tmp_path_factory):
    return canopend_binary(tmp_path_factory.mktemp("canopennode-build"))


class Device:
    """One canopend process on vcan0; start() again after kill() is a power cycle."""

    def __init__(self, binary, workdir):
        self.binary, self.workdir = binary, workdir
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        log = open(self.workdir / "canopend.log", "ab")
        self.proc = subprocess.Popen([str(self.binary), "vcan0", "-i", str(NODE_ID), "-s", f"{self.workdir}/"],
                                     cwd=self.workdir, stdout=log, stderr=subprocess.STDOUT)

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)


class Cycler:
    """The cycle a daemon would run: write, SYNC, read, every sync period, in its own thread."""

    def __init__(self, net: ArmNetwork):
        self.net, self.stop = net, threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self) -> None:
        period = self.net.config.bus.sync_period
        while not self.stop.wait(period):
            self.net.cycle(wait=False)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5)


def _config(eds, time_scale: float) -> BusConfig:
    node = NodeConfig(name="canopennode", node_id=NODE_ID, device="generic", eds=str(eds),
                      heartbeat_period=min(1.0, 0.1 * time_scale),
                      pdo=PdoLayout(rpdo=[["0x1280:1", "0x1280:2"]], tpdo=[["0x1280:1", "0x1280:2"], ["0x1001"]]))
    # SYNC slow enough that a starved emulated VM does not miss one: CANopenNode treats a SYNC
    # later than 1.5 periods (1006h) as a communication error and leaves OPERATIONAL
    bus = BusSettings(sync_period=min(1.0, 0.05 * time_scale), sdo_timeout=min(10.0, 0.5 * time_scale), boot_timeout=min(60.0, 5 * time_scale),
                      master_heartbeat_timeout=min(60.0, 0.5 * time_scale), lockstep_timeout=min(10.0, 0.2 * time_scale))
    return BusConfig(bus=bus, nodes=[node])


def _wait(predicate, seconds: float, what: str):
    print(f"[canopennode] waiting for {what}", flush=True)    # where a slow VM run is (pytest -s)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"{what}: not within {seconds:.0f} s")


def _events(net, kind: str, seen: list):
    seen += net.poll_events()
    return [e for e in seen if e.kind == kind]


def _pdo_round_trip(net, driver, value: int, seconds: float) -> None:
    """RPDO1 carries `value` into 1280h.1; TPDO1 brings back what the device then holds."""
    driver.rpdo_values[CLIENT_COB[0]] = value
    driver.rpdo_values[CLIENT_COB[1]] = value ^ 0x7FF
    _wait(lambda: driver.value(*CLIENT_COB[0]) == value and driver.value(*CLIENT_COB[1]) == value ^ 0x7FF,
          seconds, f"TPDO1 carrying back 0x{value:08X}")


@pytest.mark.vcan_vm
def test_master_boots_exchanges_supervises_and_reconfigures_canopennode(canopend, tmp_path, time_scale):
    if not vcan_available():
        pytest.skip("needs vcan0 (runs inside the test VM: hil_tests/test_vcan_suite.py)")
    device = Device(canopend, tmp_path)
    cfg = _config(eds_path(canopend), time_scale)
    net = ArmNetwork("socketcan:vcan0", cfg).connect()
    slow = 10 * time_scale
    seen: list = []
    try:
        device.start()                       # listening once its own boot-up message is out
        _wait(lambda: net.health["canopennode"].nmt_state is not None, slow, "canopend's boot-up message")
        # fresh from the factory it has no stored parameters: canopend reports a memory error
        # (generic error bit) and refuses OPERATIONAL; store once (1010h) and power-cycle it
        net.sdo_write("canopennode", 0x1010, 1, 0x65766173)
        device.kill()
        net.health["canopennode"].nmt_state = None
        device.start()
        _wait(lambda: net.health["canopennode"].nmt_state is not None, slow, "canopend's second boot-up")
        # the daemon's order: boot (no SYNC yet), then its cycle sends SYNC every period.
        # CANopenNode arms its SYNC timeout (1.5 x 1006h) at the first SYNC and its 1016h
        # consumer at the first master heartbeat (sent from connect on): a device that kept
        # OPERATIONAL with error register 0 over the first SYNCs saw neither fire
        driver = net.drivers["canopennode"]
        for key in CLIENT_COB:     # a client COB-ID must carry bit 31 (not valid): never send 0
            driver.rpdo_values[key] = INVALID | 0x100
        net.boot()
        print("[canopennode] booted", flush=True)
        cycler = Cycler(net).__enter__()
        _wait(lambda: net.stats.syncs_sent >= 20, slow, "20 SYNCs")
        assert net.health["canopennode"].nmt_state == od.NMT_STATE_OPERATIONAL
        # its error register by TPDO2: no generic or communication error (a SYNC or 1016h timeout)
        assert driver.value(0x1001, 0, None) is not None and driver.value(0x1001, 0) & ERR_GENERIC_OR_COMM == 0
        assert not [e for e in _events(net, "emcy", seen) if e.code & 0xFF00 == 0x8100]   # no SYNC/HB timeout
        report = net.bringup["canopennode"]
        assert report.refused == [] and "1016h" in report.guarding
        # what the device holds, read back over SDO (expedited uploads)
        assert net.sdo_read("canopennode", 0x1017, 0) == round(cfg.nodes[0].heartbeat_period * 1000)
        assert net.sdo_read("canopennode", 0x1016, 1) == (127 << 16) | round(cfg.bus.master_heartbeat_timeout * 1000)
        assert net.sdo_read("canopennode", 0x1006, 0) == round(cfg.bus.sync_period * 1e6)
        cob = [net.sdo_read("canopennode", 0x1800 + n, 1) & (INVALID | 0x7FF) for n in range(4)]
        assert cob[:2] == [0x184, 0x284]
        assert all(net.sdo_read("canopennode", 0x1800 + n, 1) & INVALID for n in (2, 3))
        assert all(net.sdo_read("canopennode", 0x1400 + n, 1) & INVALID for n in (1, 2, 3))
        assert [net.sdo_read("canopennode", 0x1A00, i) for i in range(3)] == [2, 0x1280_0120, 0x1280_0220]
        assert [net.sdo_read("canopennode", 0x1A01, i) for i in range(2)] == [1, 0x1001_0008]
        assert [net.sdo_read("canopennode", 0x1600, i) for i in range(3)] == [2, 0x1280_0120, 0x1280_0220]
        assert [net.sdo_read("canopennode", index, 2) for index in (0x1400, 0x1800, 0x1801)] == [od.TRANSMISSION_SYNC] * 3
        assert net.sdo_read("canopennode", 0x1005, 0) & 0x7FF == od.SYNC_COB_ID_DEFAULT
        for value in (INVALID | 0x123, INVALID | 0x456, INVALID | 0x7EF):
            _pdo_round_trip(net, driver, value, slow)
        assert net.sdo_read("canopennode", 0x1280, 1) == INVALID | 0x7EF       # the device holds it
        # SDO: a segmented download (forced; every object of this profile fits 4 bytes) read back
        net.remote["canopennode"].sdo.download(0x1017, 0, (250).to_bytes(2, "little"), force_segment=True)
        assert net.sdo_read("canopennode", 0x1017, 0) == 250
        net.sdo_write("canopennode", 0x1017, 0, round(cfg.nodes[0].heartbeat_period * 1000))
        # EMCY: an RPDO one byte short; CANopenNode reports the PDO length error (8210h)
        net.network.send_message(0x204, bytes(7))
        emcy = _wait(lambda: [e for e in _events(net, "emcy", seen) if e.code & 0xFF00 == 0x8200], slow,
                     "EMCY for the short RPDO")
        assert emcy[0].node == "canopennode"
        # killed: its heartbeat is lost
        device.kill()
        lost = _wait(lambda: _events(net, "heartbeat_lost", seen), slow, "heartbeat_lost after kill")
        assert lost[0].node == "canopennode"
        # restarted (power cycle): boot-up -> the master configures it again by itself
        device.start()
        _wait(lambda: _events(net, "reconfigured", seen), slow * 2, "reconfigured after restart")
        assert [e.kind for e in seen].index("bootup") < [e.kind for e in seen].index("reconfigured")
        assert net.bringup["canopennode"].reboots == 1
        assert net.sdo_read("canopennode", 0x1017, 0) == round(cfg.nodes[0].heartbeat_period * 1000)
        assert net.sdo_read("canopennode", 0x1A00, 1) == 0x1280_0120
        _pdo_round_trip(net, driver, INVALID | 0x2AA, slow)
    finally:
        if "cycler" in locals():
            cycler.__exit__()
        net.close()
        device.kill()
