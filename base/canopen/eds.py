"""Loading the EDS files of configs/eds/ (cached: the parsed dictionaries are read-only)."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import canopen

from spacearm.base.config.errors import ConfigError


class EdsError(ConfigError):
    """An EDS file that cannot be read or parsed; the message names the file. A ConfigError:
    the commands report it as bad input in one line, whoever loads it first."""


@lru_cache(maxsize=None)
def _load(path: str, mtime: float, node_id: int) -> canopen.ObjectDictionary:
    try:
        return canopen.import_od(path, node_id)
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
