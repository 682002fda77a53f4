"""CANopenNode (Apache-2.0, third party, C) as an interop partner: its Linux device ``canopend``
built at test time from the unmodified source in ../shared/third_party/canopennode (never
copied into this repository) into a temporary directory, with nothing but a C compiler and make.

    binary = canopend_binary(workdir)     # $SPACEARM_CANOPEND if set (prebuilt for the VM), else built
    eds = eds_path(binary)                # its own device description, DS301_profile.eds
"""
from __future__ import annotations

import os
import shutil
import subprocess
import tarfile
from pathlib import Path

from spacearm.base.paths import REPO_ROOT

SOURCE = REPO_ROOT.parent / "shared" / "third_party" / "canopennode"     # beside the clone, as ../shared/data
ARCHIVE = "CANopenLinux-064b4c4-CANopenNode-ef9ac3a.tar.gz"
ENV = "SPACEARM_CANOPEND"


class BuildError(RuntimeError):
    """canopend could not be built here (no source, no compiler, make failed)."""


def build(into: Path) -> Path:
    """Unpack and make CANopenLinux in `into`; the path of canopend."""
    archive = SOURCE / ARCHIVE
    if not archive.exists():
        raise BuildError(f"CANopenNode source not found: {archive}")
    missing = [tool for tool in ("cc", "make") if shutil.which(tool) is None]
    if missing:
        raise BuildError(f"cannot build canopend: {', '.join(missing)} missing (scripts/bootstrap.sh installs them)")
    into.mkdir(parents=True, exist_ok=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    result = subprocess.run(["make", "-C", str(into / "CANopenLinux"), f"-j{min(2, os.cpu_count() or 1)}"],
                            capture_output=True, text=True, timeout=600)
    binary = into / "CANopenLinux" / "canopend"
    if result.returncode != 0 or not binary.exists():
        raise BuildError(f"make canopend failed ({result.returncode}): {result.stderr.strip()[-800:]}")
    return binary


def canopend_binary(workdir: Path) -> Path:
    prebuilt = os.environ.get(ENV)
    if prebuilt and Path(prebuilt).is_file():
        return Path(prebuilt)
    return build(workdir / "canopennode")


def eds_path(binary: Path) -> Path:
    """The device description of the example profile canopend is built with."""
    return binary.parent / "CANopenNode" / "example" / "DS301_profile.eds"
