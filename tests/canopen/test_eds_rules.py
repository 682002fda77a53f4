"""Our EDS files against an independent reading of CiA 306: our own rule checker
(drivers/eds_rules.py, no canopen), which also catches what canopen.import_od accepts.

(eds-utils 0.3.1 from PyPI also validates every file here with no error, tried by hand; it
is not a test dependency because its wheel installs a top-level `tests` package into
site-packages, which shadows this repository's tests/ and breaks their imports.)"""
from __future__ import annotations

import canopen
import pytest

from spacearm.base.config.bus import EDS_DIR
from spacearm.drivers.eds_rules import check_eds

EDS_FILES = sorted(p.name for p in EDS_DIR.glob("*.eds"))


@pytest.mark.parametrize("name", EDS_FILES)
def test_eds_keeps_the_cia306_rules(name):
    assert check_eds(EDS_DIR / name) == []


def _variant(tmp_path, name: str, old: str, new: str):
    text = (EDS_DIR / name).read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


def test_checker_catches_a_device_type_without_its_profile_objects(tmp_path):
    # the F/T sensor used to claim CiA 404 (0x194) with none of its objects; canopen accepts it
    path = _variant(tmp_path, "ft_sensor.eds", "[1000]\nParameterName=Device type\nObjectType=0x7\n"
                    "DataType=0x0007\nAccessType=ro\nDefaultValue=0x0", "[1000]\nParameterName=Device type\n"
                    "ObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x194")
    canopen.import_od(str(path), 17)
    assert any("claims CiA 404 but lacks 6110h" in p for p in check_eds(path))


def test_checker_catches_missing_device_info_and_dates(tmp_path):
    path = _variant(tmp_path, "joint_drive.eds", "ProductNumber=0x4020001\n", "")
    path.write_text(path.read_text().replace("CreationDate=11-23-2026", "CreationDate=2026-11-23"))
    canopen.import_od(str(path), 1)
    problems = check_eds(path)
    assert "[DeviceInfo] ProductNumber missing" in problems
    assert any(p.startswith("[FileInfo] CreationDate=2026-11-23 is not") for p in problems)


def test_checker_catches_a_default_mapping_of_the_wrong_size(tmp_path):
    path = _variant(tmp_path, "joint_drive.eds", "DefaultValue=0x60410010", "DefaultValue=0x60410020")
    assert any("maps 0x6041:00 with 32 bits, the object has 16" in p for p in check_eds(path))


def test_identity_in_device_info_must_match_1018(tmp_path):
    path = _variant(tmp_path, "end_effector.eds", "VendorNumber=0x5A7", "VendorNumber=0x5A8")
    assert any(p.startswith("[DeviceInfo] VendorNumber=0x5A8 differs from 1018h sub 1") for p in check_eds(path))
