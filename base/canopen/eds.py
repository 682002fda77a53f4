"""Loading the EDS files of configs/eds/ (cached: the parsed dictionaries are read-only)."""
from __future__ import annotations

import io
import re
from functools import lru_cache
from pathlib import Path

import canopen

from spacearm.base.config.errors import ConfigError


class EdsError(ConfigError):
    """An EDS file that cannot be read or parsed; the message names the file. A ConfigError:
    the commands report it as bad input in one line, whoever loads it first."""


_EMPTY_INFO = re.compile(r"^\s*[A-Za-z_0-9]+\s*=\s*$")


def _without_empty_device_info(text: str) -> str:
    """The text with [DeviceInfo] keys that have no value left out: vendors' EDS files leave
    VendorNumber or ProductNumber empty (CANopenNode's example profile does), and the canopen
    library reads each of those keys as a number. The identity that matters is in 1018h."""
    out, section = [], ""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            section = stripped[1:-1].strip().lower()
        if section == "deviceinfo" and _EMPTY_INFO.match(line):
            continue
        out.append(line)
    return "\n".join(out) + "\n"


@lru_cache(maxsize=None)
def _load(path: str, mtime: float, node_id: int) -> canopen.ObjectDictionary:
    try:
        text = _without_empty_device_info(Path(path).read_text(encoding="utf-8", errors="replace"))
        source = io.StringIO(text)
        source.name = path               # the library picks the format by the name's suffix
        return canopen.import_od(source, node_id)
    except Exception as exc:  # configparser, int(), KeyError ... from inside the library
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise EdsError(f"{path}: not a valid EDS file: {first}") from None


def load_od(path: str | Path, node_id: int) -> canopen.ObjectDictionary:
    """The object dictionary of an EDS with $NODEID resolved for node_id."""
    path = Path(path).resolve()
    try:
        mtime = path.stat().st_mtime
    except OSError as exc:
        raise EdsError(f"{path}: cannot read: {exc.strerror}") from None
    return _load(str(path), mtime, node_id)
