"""The package layout: one import package, `spacearm`, whose rooms stay top-level folders of the
clone (base/, drivers/, firmware_sim/, controller/, offline/, console/). pyproject.toml holds
everything else; this file only maps `spacearm.<room>` to its folder, which pyproject's static
configuration cannot express for nested packages found automatically."""
from setuptools import find_namespace_packages, setup

ROOMS = ("base", "drivers", "firmware_sim", "controller", "offline", "console")

packages = ["spacearm"]
package_dir = {"spacearm": "spacearm"}
for room in ROOMS:
    package_dir[f"spacearm.{room}"] = room
    packages += [f"spacearm.{room}"] + [f"spacearm.{room}.{sub}" for sub in
                                        find_namespace_packages(room, exclude=["*__pycache__*"])]

setup(packages=packages, package_dir=package_dir)
