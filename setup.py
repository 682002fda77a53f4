"""The package layout: one import package, `spacearm`, whose rooms stay top-level folders of the
clone (base/, drivers/, firmware_sim/, controller/, offline/, console/). pyproject.toml holds
everything else; this file maps `spacearm.<room>` to its folder, which pyproject's static
configuration cannot express for nested packages found automatically, and builds the
simulator's compiled core (firmware_sim/_simcore.c) where a C compiler is: optional, a machine
without one installs and runs the same results in pure Python (firmware_sim/simcore.py)."""
import sys

from setuptools import Extension, find_namespace_packages, setup
from setuptools.command.build_ext import build_ext

# -ffp-contract=off: no fused multiply-add, so the core's floats are the Python path's bit for bit
SIMCORE = Extension("spacearm.firmware_sim._simcore", ["firmware_sim/_simcore.c"],
                    extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"], optional=True)


class OptionalBuildExt(build_ext):
    """A core that does not build is left out with one line, never a failed install."""

    def run(self):
        try:
            super().run()
        except Exception as exc:   # no compiler, no Python headers
            print(f"spacearm: compiled core not built ({exc}); the pure-Python path runs", file=sys.stderr)

    def build_extension(self, ext):
        try:
            super().build_extension(ext)
        except Exception as exc:
            print(f"spacearm: {ext.name} not built ({exc}); the pure-Python path runs", file=sys.stderr)

ROOMS = ("base", "drivers", "firmware_sim", "controller", "offline", "console")

packages = ["spacearm"]
package_dir = {"spacearm": "spacearm"}
for room in ROOMS:
    package_dir[f"spacearm.{room}"] = room
    packages += [f"spacearm.{room}"] + [f"spacearm.{room}.{sub}" for sub in
                                        find_namespace_packages(room, exclude=["*__pycache__*"])]

setup(packages=packages, package_dir=package_dir, ext_modules=[SIMCORE], cmdclass={"build_ext": OptionalBuildExt})
