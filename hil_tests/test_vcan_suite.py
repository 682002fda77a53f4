"""The vcan subset of hil_tests over the real Linux CAN stack.

On a host with vcan0 (or where it can be created) the subset runs directly; on this CI
machine, whose kernel has no CAN support, hil_tests/vm/runner.py boots Debian's kernel under
QEMU (TCG) with virtme-ng and runs it inside. Never skipped in CI: if the VM cannot boot, this
fails and says why. SPACEARM_SKIP_VM=1 skips it on a developer machine (not when CI is set).
"""
from __future__ import annotations

import os

import pytest

from hil_tests.vm import runner

IN_VM = os.environ.get("SPACEARM_IN_VM") == "1"


@pytest.mark.slow
@pytest.mark.timeout(runner.DEFAULT_BUDGET * runner.BUDGET_MAX_SCALE + 120)
def test_scenarios_pass_on_real_socketcan_vcan(record_property):
    if IN_VM:
        pytest.skip("already inside the vcan VM")
    if os.environ.get("SPACEARM_SKIP_VM") == "1" and not os.environ.get("CI"):
        pytest.skip("SPACEARM_SKIP_VM=1 (developer opt-out; never honoured when CI is set)")
    try:
        res = runner.run_suite(budget=runner.machine_budget())
    except runner.VMUnavailable as exc:
        pytest.fail(f"vcan suite cannot run: no vcan0 on this host and the VM cannot start: {exc}")
    where = "directly on this host's vcan0" if res.where == "host" else \
        f"inside a QEMU VM ({res.details.get('kernel_version')})"
    report = (f"vcan suite {where}, {res.seconds:.0f} s: {res.summary or '(no pytest summary)'}; "
              f"{res.passed} passed, {res.failed} failed, {res.errors} errors, {res.skipped} skipped"
              f" [{res.outcome_line()}]")
    print(report)
    record_property("vcan_report", report + (f" -- {res.problem}" if res.problem else ""))
    if not res.ok:
        tail = res.log[-6000:]
        if res.where == "vm":
            tail += "\n---- VM console (tail) ----\n" + res.details.get("console", "")[-3000:]
        pytest.fail(f"{report}{' -- ' + res.problem if res.problem else ''}\n{tail}")
    assert res.passed > 0
