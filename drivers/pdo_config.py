"""A node's PDO layout from its configuration, checked against its EDS.

The bus file's ``[nodes.pdo]`` table (or, without one, the default layout in the node's
EDS) names the objects; the EDS says whether the device has that many
PDOs, whether each object exists, may be mapped (PDOMapping=1) in that direction (readable
for a TPDO, writable for an RPDO), and how many bits it has. A layout the device cannot take
is a MappingError naming the node, the PDO and the object, before anything is sent.
"""
from __future__ import annotations

from dataclasses import dataclass

import canopen

from spacearm.base.canopen import od
from spacearm.base.config.bus import NodeConfig, parse_object_ref
from spacearm.base.canopen.codes import COB_ID_INVALID, RPDO_BASE, TPDO_BASE
from spacearm.drivers.errors import BootError

MAX_PDO_BITS = 64


class MappingError(BootError):
    """A configured PDO mapping that the device's EDS does not allow."""


@dataclass
class MappedObject:
    index: int
    sub: int
    bits: int
    var: canopen.objectdictionary.ODVariable

    @property
    def size(self) -> int:
        return self.bits // 8

    @property
    def entry(self) -> int:
        """The 32-bit mapping entry written to 16xxh/1Axxh."""
        return (self.index << 16) | (self.sub << 8) | self.bits


@dataclass
class PdoSpec:
    kind: str                    # "RPDO" or "TPDO"
    number: int                  # 0-based (RPDO1 = 0)
    cob_id: int
    entries: list[MappedObject]

    @property
    def length(self) -> int:
        return sum(e.size for e in self.entries)

    @property
    def label(self) -> str:
        return f"{self.kind}{self.number + 1} (0x{self.cob_id:03X})"


def find_var(object_dictionary: canopen.ObjectDictionary, index: int, sub: int):
    """The EDS variable at index:sub, or None when the device does not have it."""
    if index not in object_dictionary:
        return None
    obj = object_dictionary[index]
    if isinstance(obj, canopen.objectdictionary.ODVariable):
        return obj if sub == 0 else None
    try:
        return obj[sub]
    except KeyError:
        return None


def pdo_numbers(object_dictionary: canopen.ObjectDictionary, comm_base: int) -> list[int]:
    """The 0-based numbers of the PDOs of one direction the EDS lists (communication objects)."""
    return sorted(index - comm_base for index in object_dictionary.indices if 0 <= index - comm_base < 512)


def pdo_count(object_dictionary: canopen.ObjectDictionary, comm_base: int) -> int:
    """How many PDOs of a direction the device has."""
    return len(pdo_numbers(object_dictionary, comm_base))


Layout = dict[str, list[tuple[int, int | None, list[tuple[int, int]]]]]   # kind -> (number, COB-ID, objects)


def eds_default_layout(object_dictionary: canopen.ObjectDictionary) -> Layout:
    """The PDO layout the EDS gives by default: the mapping defaults of every PDO whose
    default COB-ID is valid, on that COB-ID (others: left disabled)."""
    out: Layout = {}
    for kind, comm, mapping in (("rpdo", od.RPDO_COMM, od.RPDO_MAP), ("tpdo", od.TPDO_COMM, od.TPDO_MAP)):
        pdos = []
        for n in pdo_numbers(object_dictionary, comm):
            cob = find_var(object_dictionary, comm + n, od.PDO_COB_ID)
            count = find_var(object_dictionary, mapping + n, 0)
            if cob is None or count is None or (cob.default or 0) & COB_ID_INVALID or not count.default:
                continue
            entries = [find_var(object_dictionary, mapping + n, i) for i in range(1, (count.default or 0) + 1)]
            refs = [((e.default or 0) >> 16, ((e.default or 0) >> 8) & 0xFF) for e in entries if e is not None]
            pdos.append((n, (cob.default or 0) & 0x7FF, refs))
        out[kind] = pdos
    return out


def layout_refs(cfg: NodeConfig, object_dictionary: canopen.ObjectDictionary) -> Layout:
    """The node's [nodes.pdo] table, else the layout its EDS defines by default."""
    if cfg.pdo is not None:
        return {kind: [(number - 1, cob_id, [parse_object_ref(r) for r in refs])
                       for number, cob_id, refs in cfg.pdo.entries(kind)]
                for kind in ("rpdo", "tpdo")}
    return eds_default_layout(object_dictionary)


def resolve_layout(cfg: NodeConfig, object_dictionary: canopen.ObjectDictionary) -> tuple[list[PdoSpec], list[PdoSpec]]:
    """(rpdos, tpdos) of a node, each PDO checked against the EDS. Raises MappingError."""
    eds = cfg.eds_path.name
    refs = layout_refs(cfg, object_dictionary)
    out: dict[str, list[PdoSpec]] = {}
    cobs: dict[int, str] = {}
    for kind, comm, bases in (("rpdo", od.RPDO_COMM, RPDO_BASE), ("tpdo", od.TPDO_COMM, TPDO_BASE)):
        name = kind.upper()
        available = pdo_numbers(object_dictionary, comm)
        specs = []
        for n, cob_id, pdo_refs in refs[kind]:
            where = f"{cfg.label}: {name}{n + 1}"
            if n not in available:
                raise MappingError(f"{where}: the device has no {name}{n + 1} (its EDS {eds} lists "
                                   f"{len(available)} {name}s: {_numbers(available)})")
            if cob_id is None:
                if n >= len(bases):
                    raise MappingError(f"{where}: only {name}1..{len(bases)} have pre-defined COB-IDs; "
                                       f"give cob_id in [nodes.pdo]")
                cob_id = bases[n] + cfg.node_id
            if cob_id in cobs:
                raise MappingError(f"{where}: COB-ID 0x{cob_id:03X} already used by {cobs[cob_id]}")
            cobs[cob_id] = f"{name}{n + 1}"
            if len(pdo_refs) > od.MAX_MAPPED:
                raise MappingError(f"{where}: {len(pdo_refs)} objects, at most {od.MAX_MAPPED}")
            entries = []
            for index, sub in pdo_refs:
                ref = f"0x{index:04X}:{sub:02X}"
                var = find_var(object_dictionary, index, sub)
                if var is None:
                    raise MappingError(f"{where}: object {ref} does not exist in {eds}")
                if not var.pdo_mappable:
                    raise MappingError(f"{where}: object {ref} '{var.name}' is not PDO-mappable in {eds}")
                if kind == "tpdo" and not var.readable or kind == "rpdo" and not var.writable:
                    raise MappingError(f"{where}: object {ref} '{var.name}' is "
                                       f"{'not readable' if kind == 'tpdo' else 'not writable'} in {eds}")
                bits = len(var)
                if bits % 8 or bits > MAX_PDO_BITS:
                    raise MappingError(f"{where}: object {ref} '{var.name}' has {bits} bits")
                entries.append(MappedObject(index, sub, bits, var))
            total = sum(e.bits for e in entries)
            if total > MAX_PDO_BITS:
                raise MappingError(f"{where}: {total} bits mapped, a PDO holds {MAX_PDO_BITS}")
            specs.append(PdoSpec(name, n, cob_id, entries))
        out[kind] = specs
    check_required(cfg, out["rpdo"], out["tpdo"])
    return out["rpdo"], out["tpdo"]


def _numbers(available: list[int]) -> str:
    return ", ".join(str(n + 1) for n in available) or "none"


# What each device type's driver cannot work without, per direction (CiA 402 for a drive)
REQUIRED = {"joint_drive": {"rpdo": (od.CONTROLWORD, od.TARGET_POSITION),
                            "tpdo": (od.STATUSWORD, od.POSITION_ACTUAL)}}


def check_required(cfg: NodeConfig, rpdos: list[PdoSpec], tpdos: list[PdoSpec]) -> None:
    for kind, specs in (("rpdo", rpdos), ("tpdo", tpdos)):
        mapped = {e.index for s in specs for e in s.entries}
        for index in REQUIRED.get(cfg.device, {}).get(kind, ()):
            if index not in mapped:
                raise MappingError(f"{cfg.label}: 0x{index:04X} must be mapped to a{'n R' if kind == 'rpdo' else ' T'}"
                                   f"PDO (the {cfg.device} driver runs on it); see [nodes.pdo]")
