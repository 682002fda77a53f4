"""A CiA 306 rule checker for EDS/DCF files, independent of the canopen library (which
accepts files that break these rules): standard library only, reading the INI text itself.

    problems = check_eds(path)      # [] when the file keeps every rule below

Rules: [FileInfo] and [DeviceInfo] carry the keys CiA 306 requires, with valid dates and
times; VendorNumber/ProductNumber/RevisionNumber agree with 1018h; the mandatory objects
(1000h, 1001h, 1018h) exist and are listed; every object listed exists and every object is
listed; NrOfRXPDO/NrOfTXPDO count the PDO communication objects; each default PDO mapping
names an existing, mappable object of the stated size; and the device type (1000h) names a
device profile whose mandatory objects are present (402: drives; 0: none claimed).
"""
from __future__ import annotations

import configparser
import re
from datetime import datetime
from pathlib import Path

from spacearm.base.canopen.codes import DATATYPE_BITS

FILE_INFO_KEYS = ("FileName", "FileVersion", "FileRevision", "EDSVersion", "Description", "CreationTime",
                  "CreationDate", "CreatedBy", "ModificationTime", "ModificationDate", "ModifiedBy")
DEVICE_INFO_KEYS = ("VendorName", "VendorNumber", "ProductName", "ProductNumber", "RevisionNumber", "OrderCode",
                    "BaudRate_10", "BaudRate_20", "BaudRate_50", "BaudRate_125", "BaudRate_250", "BaudRate_500",
                    "BaudRate_800", "BaudRate_1000", "SimpleBootUpMaster", "SimpleBootUpSlave", "Granularity",
                    "NrOfRXPDO", "NrOfTXPDO", "LSS_Supported")
MANDATORY = (0x1000, 0x1001, 0x1018)
# device profile number (1000h bits 0..15) -> objects that profile makes mandatory
PROFILE_OBJECTS = {
    0: (),
    402: (0x603F, 0x6040, 0x6041, 0x6502),
    401: (0x6000, 0x6200),           # generic I/O: at least digital inputs/outputs
    404: (0x6110, 0x6112, 0x6130),   # measuring devices: sensor type, operating mode, AI process value
}
_SECTION = re.compile(r"^([0-9A-Fa-f]{4})(sub([0-9A-Fa-f]{1,2}))?$")


def _int(text: str | None) -> int | None:
    if text is None:
        return None
    text = text.strip()
    if "$NODEID" in text.upper():
        text = re.sub(r"(?i)\$NODEID\s*\+?", "", text) or "0"
    try:
        return int(text, 0)
    except ValueError:
        return None


def check_eds(path: str | Path) -> list[str]:
    path = Path(path)
    parser = configparser.ConfigParser(interpolation=None, strict=False)
    parser.optionxform = str           # keys are case-sensitive in our reading
    try:
        parser.read_string(path.read_text(encoding="utf-8", errors="replace"))
    except (OSError, configparser.Error) as exc:
        return [f"{path.name}: cannot be read as INI: {str(exc).splitlines()[0]}"]
    problems: list[str] = []
    p = problems.append
    for section, keys in (("FileInfo", FILE_INFO_KEYS), ("DeviceInfo", DEVICE_INFO_KEYS)):
        if not parser.has_section(section):
            p(f"[{section}] missing")
            continue
        for key in keys:
            if not parser.get(section, key, fallback="").strip():
                p(f"[{section}] {key} missing")
    info = parser["FileInfo"] if parser.has_section("FileInfo") else {}
    for key, fmt in (("CreationDate", "%m-%d-%Y"), ("ModificationDate", "%m-%d-%Y"),
                     ("CreationTime", "%I:%M%p"), ("ModificationTime", "%I:%M%p")):
        value = info.get(key)
        if value:
            try:
                datetime.strptime(value.strip(), fmt)
            except ValueError:
                p(f"[FileInfo] {key}={value} is not {fmt.replace('%', '')}")

    objects: dict[int, dict[int, configparser.SectionProxy]] = {}
    for name in parser.sections():
        m = _SECTION.match(name)
        if m:
            objects.setdefault(int(m.group(1), 16), {})[int(m.group(3), 16) if m.group(2) else -1] = parser[name]

    def var(index: int, sub: int = 0):
        subs = objects.get(index, {})
        if sub in subs:
            return subs[sub]
        return subs.get(-1) if sub == 0 and len(subs) == 1 else None

    listed: set[int] = set()
    for group in ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects"):
        if not parser.has_section(group):
            p(f"[{group}] missing")
            continue
        sec = parser[group]
        n = _int(sec.get("SupportedObjects")) or 0
        for i in range(1, n + 1):
            index = _int(sec.get(str(i)))
            if index is None:
                p(f"[{group}] entry {i} missing")
            elif index not in objects:
                p(f"[{group}] lists 0x{index:04X}, which has no section")
            else:
                listed.add(index)
    for index in MANDATORY:
        if index not in objects:
            p(f"mandatory object 0x{index:04X} missing")
    for index in sorted(set(objects) - listed):
        p(f"object 0x{index:04X} is not listed in a *Objects section")

    dev = parser["DeviceInfo"] if parser.has_section("DeviceInfo") else {}
    for key, sub in (("VendorNumber", 1), ("ProductNumber", 2), ("RevisionNumber", 3)):
        ident = var(0x1018, sub)
        if key in dev and ident is not None and _int(dev[key]) != _int(ident.get("DefaultValue")):
            p(f"[DeviceInfo] {key}={dev[key]} differs from 1018h sub {sub} ({ident.get('DefaultValue')})")
    for key, base in (("NrOfRXPDO", 0x1400), ("NrOfTXPDO", 0x1800)):
        count = sum(1 for index in objects if base <= index < base + 0x200)
        if key in dev and _int(dev[key]) != count:
            p(f"[DeviceInfo] {key}={dev[key]} but the file has {count} such PDOs")

    for base in (0x1600, 0x1A00):
        for index in sorted(i for i in objects if base <= i < base + 0x200):
            count = var(index, 0)
            n = _int(count.get("DefaultValue")) if count is not None else 0
            for sub in range(1, (n or 0) + 1):
                entry_var = var(index, sub)
                entry = _int(entry_var.get("DefaultValue")) if entry_var is not None else None
                if entry is None:
                    p(f"0x{index:04X} sub {sub}: no default mapping entry")
                    continue
                m_index, m_sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
                target = var(m_index, m_sub)
                where = f"0x{index:04X} sub {sub} maps 0x{m_index:04X}:{m_sub:02X}"
                if target is None:
                    p(f"{where}, which does not exist")
                    continue
                if _int(target.get("PDOMapping")) != 1:
                    p(f"{where}, which has PDOMapping=0")
                size = DATATYPE_BITS.get(_int(target.get("DataType")) or 0)
                if size != bits:
                    p(f"{where} with {bits} bits, the object has {size}")

    device_type = var(0x1000)
    value = _int(device_type.get("DefaultValue")) if device_type is not None else None
    if value is None:
        p("1000h has no DefaultValue (device type)")
    else:
        profile = value & 0xFFFF
        required = PROFILE_OBJECTS.get(profile)
        if required is None:
            p(f"device type 0x{value:08X}: profile {profile} is not one this checker knows")
        else:
            missing = [f"{i:04X}h" for i in required if i not in objects]
            if missing:
                p(f"device type 0x{value:08X} claims CiA {profile} but lacks {', '.join(missing)}")
    return problems
