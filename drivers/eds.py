"""Loading the EDS files of configs/eds/ (cached: the parsed dictionaries are read-only)."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import canopen


@lru_cache(maxsize=None)
def _load(path: str, mtime: float, node_id: int) -> canopen.ObjectDictionary:
    return canopen.import_od(path, node_id)


def load_od(path: str | Path, node_id: int) -> canopen.ObjectDictionary:
    """The object dictionary of an EDS with $NODEID resolved for node_id."""
    path = Path(path).resolve()
    return _load(str(path), path.stat().st_mtime, node_id)
