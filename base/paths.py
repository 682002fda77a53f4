"""Where the repository's data lives, for modules anywhere in the tree (configuration files are
data in configs/, not installed with the package: spacearm runs from its clone)."""
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
CONFIGS = REPO_ROOT / "configs"
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"
