"""Where a console keeps its control lease key between invocations.

One file per daemon address under $XDG_RUNTIME_DIR (or ~/.cache), readable by the user
only: the key is what lets this operator's later commands move the arm.
"""
from __future__ import annotations

import os
import re
from pathlib import Path


def _path(address: str) -> Path:
    base = Path(os.environ.get("SPACEARM_LEASE_DIR")
                or os.environ.get("XDG_RUNTIME_DIR")
                or Path.home() / ".cache")
    return base / "spacearm" / f"lease-{re.sub(r'[^A-Za-z0-9_.-]', '_', address)}"


def load(address: str) -> str | None:
    try:
        return _path(address).read_text().strip() or None
    except OSError:
        return None


def save(address: str, key: str) -> None:
    path = _path(address)
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as handle:
        handle.write(key)


def forget(address: str) -> None:
    _path(address).unlink(missing_ok=True)
