"""Which nodes are on a CAN bus, what they are, and how they compare with a bus file.

    found = scan("socketcan:can0")                 # [FoundNode], node-IDs 1..127, bounded time
    diffs = compare(found, bus_config, "socketcan:can0")
    text = starting_bus_file(found, bus_config)

The scan sends no NMT command: one SDO upload of 1000h (device type) to every node-ID at once,
then 1018h.1-4 (identity) to those that answered, each round bounded by ``timeout``.
``compare`` reads every object the node's EDS lists (a device that lacks one aborts) and, for
the objects bring-up writes, writes back the value it just read: an abort there means read-only
on the device although the EDS says writable. PDO objects are never written here.
"""
from __future__ import annotations

import struct
import time
from dataclasses import dataclass, field

import can

from spacearm.base.canopen import od
from spacearm.base.canopen.codes import (ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ABORT_READ_ONLY, SDO_RX_BASE,
                                         SDO_TX_BASE, abort_text)
from spacearm.base.canopen.eds import load_od
from spacearm.base.config.bus import BusConfig, NodeConfig, dump_toml
from spacearm.base.transport import open_bus
from spacearm.drivers.devices import DRIVERS, DeviceDriver

PROFILE_DEVICES = {402: "joint_drive"}    # a device profile this stack has a driver type for
ALL_NODE_IDS = range(1, 128)


@dataclass
class FoundNode:
    node_id: int
    device_type: int
    identity: dict[int, int] = field(default_factory=dict)   # 1018h sub -> value (where it answered)

    @property
    def profile(self) -> int:
        return self.device_type & 0xFFFF

    def describe(self) -> str:
        ident = ", ".join(f"{name} 0x{self.identity[sub]:08X}" for sub, name in
                          ((1, "vendor"), (2, "product"), (3, "revision"), (4, "serial")) if sub in self.identity)
        return f"node {self.node_id}: device type 0x{self.device_type:08X} (CiA {self.profile}){', ' + ident if ident else ''}"


def _upload_all(bus: can.BusABC, requests: list[tuple[int, int, int]], timeout: float) -> dict:
    """Expedited SDO uploads to many nodes at once: {(node, index, sub): value or ('abort', code)}."""
    pending = {}
    for node_id, index, sub in requests:
        bus.send(can.Message(arbitration_id=SDO_RX_BASE + node_id, is_extended_id=False,
                             data=struct.pack("<BHB4x", 0x40, index, sub)))
        pending[(node_id, index, sub)] = True
    out = {}
    deadline = time.monotonic() + timeout
    while pending and (left := deadline - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is None or msg.is_extended_id or msg.is_remote_frame or len(msg.data) != 8:
            continue
        node_id = msg.arbitration_id - SDO_TX_BASE
        command, index, sub = struct.unpack_from("<BHB", msg.data)
        key = (node_id, index, sub)
        if key not in pending:
            continue
        if command == 0x80:
            out[key] = ("abort", struct.unpack_from("<I", msg.data, 4)[0])
        elif command & 0xE3 == 0x43 or command == 0x42:      # expedited, size indicated or not
            size = 4 - ((command >> 2) & 3) if command & 0x01 else 4
            out[key] = int.from_bytes(msg.data[4:4 + size], "little")
        else:
            continue                                           # segmented: not for these objects
        del pending[key]
    return out


def scan(bus_spec: str, node_ids=ALL_NODE_IDS, timeout: float = 0.2) -> list[FoundNode]:
    """The nodes answering an SDO upload of 1000h, with their identity (1018h.1-4)."""
    bus = open_bus(bus_spec)
    try:
        types = _upload_all(bus, [(n, od.DEVICE_TYPE, 0) for n in node_ids], timeout)
        found = {n: FoundNode(n, v) for (n, _, _), v in sorted(types.items()) if isinstance(v, int)}
        idents = _upload_all(bus, [(n, od.IDENTITY, s) for n in found for s in (1, 2, 3, 4)], timeout)
        for (n, _, sub), value in idents.items():
            if isinstance(value, int):
                found[n].identity[sub] = value
        return list(found.values())
    finally:
        bus.shutdown()


def compare(found: list[FoundNode], config: BusConfig, bus_spec: str) -> list[str]:
    """One line per difference between the bus found and the bus file (with each node's EDS);
    SDO answers are awaited for the bus file's sdo_timeout."""
    lines = []
    by_id = {f.node_id: f for f in found}
    for cfg in config.nodes:
        node = by_id.get(cfg.node_id)
        if node is None:
            lines.append(f"{cfg.label}: not found on the bus")
            continue
        lines += _compare_identity(node, cfg)
    for node in found:
        if node.node_id not in {c.node_id for c in config.nodes}:
            lines.append(f"node {node.node_id}: on the bus, not in the bus file ({node.describe()})")
    present = [c for c in config.nodes if c.node_id in by_id]
    if present:
        lines += _compare_objects(present, config, bus_spec, config.bus.sdo_timeout)
    return lines


def _compare_identity(node: FoundNode, cfg: NodeConfig) -> list[str]:
    eds = load_od(cfg.eds_path, cfg.node_id)
    lines = []
    for index, sub, actual in ((od.DEVICE_TYPE, 0, node.device_type),
                               *((od.IDENTITY, s, node.identity.get(s)) for s in (1, 2, 3))):
        var = _var(eds, index, sub)
        if var is None or var.default is None or actual is None:
            continue
        if actual != var.default:
            lines.append(f"{cfg.label}: {var.name} (0x{index:04X}:{sub:02X}) is 0x{actual:08X} on the device, "
                         f"0x{var.default:08X} in {cfg.eds_path.name}")
    return lines


def _compare_objects(nodes: list[NodeConfig], config: BusConfig, bus_spec: str, sdo_timeout: float) -> list[str]:
    import canopen
    from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

    network = canopen.Network()
    network.bus = open_bus(bus_spec)
    network.connect()
    lines = []
    try:
        for cfg in nodes:
            eds = load_od(cfg.eds_path, cfg.node_id)
            remote = canopen.RemoteNode(cfg.node_id, eds)
            remote.sdo.RESPONSE_TIMEOUT = sdo_timeout
            network.add_node(remote)
            written = _written_at_bringup(cfg, config, eds)
            for index in sorted(eds.indices):
                obj = eds[index]
                for var in ([obj] if not hasattr(obj, "subindices") else [obj[s] for s in sorted(obj.subindices)]):
                    where = f"{cfg.label}: 0x{index:04X}:{var.subindex:02X} '{var.name}'"
                    try:
                        data = remote.sdo.upload(index, var.subindex) if var.readable else None
                        if (index, var.subindex) in written and var.writable and data is not None:
                            remote.sdo.download(index, var.subindex, data)
                    except SdoAbortedError as exc:
                        if exc.code in (ABORT_NO_OBJECT, ABORT_NO_SUBINDEX):
                            lines.append(f"{where}: in {cfg.eds_path.name}, the device lacks it "
                                         f"(0x{exc.code:08X})")
                        elif exc.code == ABORT_READ_ONLY:
                            lines.append(f"{where}: writable in {cfg.eds_path.name}, read-only on the device")
                        else:
                            lines.append(f"{where}: 0x{exc.code:08X} {abort_text(exc.code)}")
                    except SdoCommunicationError as exc:
                        lines.append(f"{where}: no answer ({exc})")
    finally:
        network.disconnect()
    return lines


def _written_at_bringup(cfg: NodeConfig, config: BusConfig, eds) -> set[tuple[int, int]]:
    """The objects outside the PDO area that bring-up writes to this node."""
    driver = DRIVERS.get(cfg.device, DeviceDriver)(cfg, config.bus, eds)
    out = {(od.PRODUCER_HEARTBEAT, 0), (od.CONSUMER_HEARTBEAT, 1), (od.COB_ID_SYNC, 0), (od.COMM_CYCLE_PERIOD, 0),
           (od.GUARD_TIME, 0), (od.LIFE_TIME_FACTOR, 0)}
    out |= {(i, s) for i, s, _ in driver.hardware_objects() + driver.config_writes()}
    return out


def _var(eds, index: int, sub: int):
    from spacearm.drivers.pdo_config import find_var
    return find_var(eds, index, sub)


def starting_bus_file(found: list[FoundNode], config: BusConfig | None = None) -> str:
    """A bus file for the nodes found: names, EDS files and settings from ``config`` where it
    has the node-ID, else a CiA 402 drive as a joint_drive; other profiles commented out
    (their device type must be named by hand)."""
    known = {n.node_id: n for n in config.nodes} if config else {}
    lines = ["# Written by `spacearm bus scan`: the nodes found on the bus. Check each one's EDS", ""]
    if config is not None:               # the bus file's [bus] table as it is
        lines += dump_toml(config).split("\n\n[[nodes]]")[0].splitlines()
    else:
        lines.append("[bus]")
    if config is None and any(n.node_id == 127 for n in found):   # the master's heartbeat ID by default
        used = {n.node_id for n in found}
        lines.append(f"master_node_id = {max(i for i in ALL_NODE_IDS if i not in used)}")
    joints = 0
    for node in found:
        cfg = known.get(node.node_id)
        device = cfg.device if cfg else PROFILE_DEVICES.get(node.profile)
        if device == "joint_drive" and cfg is None:
            joints += 1
        name = cfg.name if cfg else (f"joint_{joints}" if device == "joint_drive" else f"node_{node.node_id}")
        prefix = "" if device else "# "
        lines += ["", f"# {node.describe()}", f"{prefix}[[nodes]]", f'{prefix}name = "{name}"',
                  f"{prefix}node_id = {node.node_id}", f'{prefix}device = "{device or "?"}"']
        if cfg is not None and cfg.eds is not None:
            lines.append(f'eds = "{cfg.eds}"')
        elif device:
            lines.append(f'# eds = "..."   # this device\'s own EDS (default: configs/eds/{device}.eds)')
    return "\n".join(lines) + "\n"
