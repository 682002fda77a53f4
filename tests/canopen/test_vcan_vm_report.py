"""The vcan VM run's report names each test and what it did: a test skipped inside the VM
(where vcan0 exists and everything runs as root) fails the run instead of hiding in a count."""
from __future__ import annotations

import pytest

from hil_tests.vm import runner
from hil_tests.vm.runner import SuiteResult, _fill_counts

JUNIT = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest" errors="0" failures="0"
skipped="1" tests="2"><testcase classname="hil_tests.test_transport_bus" name="test_frames_both_ways" time="3.2"/>
<testcase classname="hil_tests.interop.test_canopennode_vcan" name="test_master_boots_canopennode" time="0.0">
<skipped type="pytest.skip" message="needs vcan0 (runs inside the test VM)">skip</skipped></testcase>
</testsuite></testsuites>"""


def _result(where: str, tmp_path) -> SuiteResult:
    junit = tmp_path / "junit.xml"
    junit.write_text(JUNIT)
    res = SuiteResult(where, 0, "1 passed, 1 skipped in 4.0s")
    _fill_counts(res, junit)
    return res


def test_a_skip_inside_the_vm_is_named_and_fails_the_run(tmp_path):
    res = _result("vm", tmp_path)
    assert (res.passed, res.skipped) == (1, 1) and not res.ok
    assert res.outcome_line() == ("test_transport_bus::test_frames_both_ways passed (3 s); "
                                  "test_canopennode_vcan::test_master_boots_canopennode skipped: "
                                  "needs vcan0 (runs inside the test VM)")


def test_on_a_host_with_vcan0_a_skip_is_shown_not_fatal(tmp_path):
    assert _result("host", tmp_path).ok


@pytest.mark.parametrize("loop, scale", [(0.045, 1.0), (0.09, 1.0), (0.18, 2.0), (0.36, 3.0)])
def test_the_vms_kill_limit_follows_the_machines_speed(monkeypatch, loop, scale):
    """The VM emulates in software: on a machine whose reference loop takes twice as long the
    run takes about twice as long, and its kill limit grows with it (up to 3x)."""
    import bench.reference_work
    monkeypatch.setattr(bench.reference_work, "reference_loop_seconds", lambda repeats=5: (loop, loop))
    assert runner.machine_budget(1000.0) == pytest.approx(1000.0 * scale)
