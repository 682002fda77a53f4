"""The rooms of the code base and the one direction imports may run between them.

    python -m spacearm.architecture          # the room-level import graph and any violation
    python -m spacearm.architecture --files  # ... with the importing file and line of each edge

In the style of import-linter's layers contract (checked on the source with `ast`, so it needs
nothing installed and sees imports inside functions too): a room may import rooms below it,
never above it, and rooms in one layer (listed together) never import each other.
`tests/architecture/test_layers.py` keeps the tree so.
"""
from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]

# top to bottom; a tuple is one layer of independent rooms
LAYERS: list[tuple[str, ...]] = [
    ("console",),                  # the `spacearm` command, the browser console
    ("offline",),                  # tools that drive the simulator and the controller together
    ("controller",),               # the daemon and the computation it runs
    ("drivers", "firmware_sim"),   # the controller's side and the devices' side of the bus
    ("base",),                     # spatial math, kinematics, config schemas, CANopen tables, transports
]
# inside controller/, the same rule: the daemon on top, the cycle's vocabulary near the bottom
CONTROLLER_LAYERS: list[tuple[str, ...]] = [
    ("daemon",),
    ("oru",),
    ("impedance",),
    ("modes",),
    ("cycle",),
    ("planning", "vision", "calibration", "recording"),
]
ROOMS = [room for layer in LAYERS for room in layer]
# the root package's own modules (this file, __init__) import no room
ROOT_MODULES = ("spacearm",)


@dataclass(frozen=True)
class Import:
    file: str          # path relative to the repository
    line: int
    module: str        # the imported module, as written


@dataclass(frozen=True)
class Violation:
    importer: str      # room (or controller sub-room) of the importing file
    imported: str
    where: Import
    why: str

    def __str__(self) -> str:
        return f"{self.where.file}:{self.where.line}: {self.why} ({self.where.module})"


def room_of_path(path: str) -> str | None:
    """'controller/oru/flow.py' -> 'controller.oru'; 'drivers/network.py' -> 'drivers'."""
    parts = Path(path).with_suffix("").parts
    if not parts:
        return None
    if parts[0] == "spacearm":
        return "spacearm"
    if parts[0] not in ROOMS:
        return None
    if parts[0] == "controller" and len(parts) >= 2 and parts[1] != "__init__":
        return f"controller.{parts[1]}"
    return parts[0]


def room_of_module(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "spacearm":
        return None
    if len(parts) == 1 or parts[1] not in ROOMS:
        return "spacearm"
    if parts[1] == "controller" and len(parts) > 2:
        return f"controller.{parts[2]}"
    return parts[1]


def imports_of(source: str, file: str) -> list[Import]:
    found = []
    for node in ast.walk(ast.parse(source, filename=file)):
        if isinstance(node, ast.Import):
            found += [Import(file, node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append(Import(file, node.lineno, node.module))
    return found


def _rank(room: str) -> tuple[int, int]:
    """(layer index, sub-layer index inside controller); smaller is higher."""
    top, _, sub = room.partition(".")
    layer = next(i for i, names in enumerate(LAYERS) if top in names)
    if top == "controller" and sub:
        known = [i for i, names in enumerate(CONTROLLER_LAYERS) if sub in names]
        return layer, known[0] if known else len(CONTROLLER_LAYERS)
    return layer, -1


def _same_layer(a: str, b: str) -> bool:
    ta, _, sa = a.partition(".")
    tb, _, sb = b.partition(".")
    if ta != tb:
        return any(ta in layer and tb in layer for layer in LAYERS)
    return ta == "controller" and sa != sb and any(sa in layer and sb in layer for layer in CONTROLLER_LAYERS)


def check_import(importer: str, imp: Import) -> Violation | None:
    top = imp.module.split(".")[0]
    if top in ROOMS:
        return Violation(importer, top, imp, f"bare `{top}` import: every module imports `spacearm.{top}`")
    imported = room_of_module(imp.module)
    if imported is None or imported == importer:
        return None
    if importer == "spacearm" or imported == "spacearm":
        return Violation(importer, imported, imp, "the root package and the rooms do not import each other")
    if imported == "controller" or importer == "controller":
        return None     # the controller package's own __init__ and its sub-rooms
    if _same_layer(importer, imported):
        return Violation(importer, imported, imp, f"{importer} and {imported} are independent rooms of one layer")
    if _rank(imported) < _rank(importer):
        return Violation(importer, imported, imp, f"{importer} imports {imported}, a room above it")
    return None


def check_source(path: str, source: str) -> list[Violation]:
    """Violations of one file, given its path in the repository (for a file of no room: bare
    top-level imports only, e.g. tests and benchmarks)."""
    importer = room_of_path(path)
    found = []
    for imp in imports_of(source, path):
        if importer is None:
            top = imp.module.split(".")[0]
            if top in ROOMS:
                found.append(Violation("-", top, imp, f"bare `{top}` import: import `spacearm.{top}`"))
            continue
        violation = check_import(importer, imp)
        if violation is not None:
            found.append(violation)
    return found


def python_files(root: Path = REPO_ROOT) -> list[Path]:
    folders = ROOMS + ["spacearm", "tests", "hil_tests", "bench"]
    return sorted(p for folder in folders for p in (root / folder).rglob("*.py") if "__pycache__" not in p.parts)


def import_graph(root: Path = REPO_ROOT) -> dict[tuple[str, str], list[Import]]:
    graph: dict[tuple[str, str], list[Import]] = defaultdict(list)
    for path in python_files(root):
        rel = path.relative_to(root).as_posix()
        importer = room_of_path(rel)
        if importer is None:
            continue
        for imp in imports_of(path.read_text(), rel):
            imported = room_of_module(imp.module)
            if imported is not None and imported != importer:
                graph[(importer, imported)].append(imp)
    return dict(graph)


def violations(root: Path = REPO_ROOT) -> list[Violation]:
    found = []
    for path in python_files(root):
        rel = path.relative_to(root).as_posix()
        found += check_source(rel, path.read_text())
    return found


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m spacearm.architecture", description=__doc__.splitlines()[0])
    ap.add_argument("--files", action="store_true", help="list the importing file and line of every edge")
    args = ap.parse_args(argv)
    print("layers, top to bottom (a room imports only rooms below it):")
    for layer in LAYERS:
        print("  " + " | ".join(layer))
    print("inside controller/:")
    for layer in CONTROLLER_LAYERS:
        print("  " + " | ".join(layer))
    graph = import_graph()
    by_importer: dict[str, list[str]] = defaultdict(list)
    for (importer, imported), imps in sorted(graph.items()):
        by_importer[importer].append(f"{imported}({len(imps)})")
    print("import graph (room -> rooms it imports, with the number of import statements):")
    for importer in sorted(by_importer):
        print(f"  {importer} -> {', '.join(by_importer[importer])}")
        if args.files:
            for (src, dst), imps in sorted(graph.items()):
                if src == importer:
                    print("      " + "; ".join(f"{i.file}:{i.line} {i.module}" for i in imps))
    found = violations()
    print(f"violations: {len(found)}")
    for v in found:
        print(f"  {v}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
