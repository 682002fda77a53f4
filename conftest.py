"""Suite-wide report: wall time beside CPU time (this process and every child it reaped: the
simulators, daemons, hubs and the vcan VM) and the machine's speed, from the reference loop of
bench/reference_work.py timed once at the start. A suite that fits a 3x slower machine is read
off these lines: CPU minutes scale with the machine, wall minutes also with its load."""
from __future__ import annotations

import os
import resource
import time

import pytest

_started: dict[str, float] = {}
_worker_last_report: dict[str, float] = {}     # xdist worker -> wall s of its last test report


def _cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def pytest_sessionstart(session):
    from bench.reference_work import reference_loop_seconds
    _started["wall"], _started["cpu"] = time.monotonic(), _cpu_seconds()
    _started["reference_wall"], _started["reference_cpu"] = reference_loop_seconds(repeats=1)
    _started["load"] = os.getloadavg()[0]


def pytest_runtest_logreport(report):
    # In the controller, a worker's reports carry its gateway: when each worker went idle shows
    # whether the two workers share the suite or one of them is its critical path.
    worker = getattr(getattr(report, "node", None), "gateway", None)
    if worker is not None and "wall" in _started:
        _worker_last_report[worker.id] = time.monotonic() - _started["wall"]


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if "wall" not in _started:
        return
    wall, cpu = time.monotonic() - _started["wall"], _cpu_seconds() - _started["cpu"]
    terminalreporter.write_sep("-", "suite time")
    terminalreporter.write_line(
        f"wall {wall / 60:.1f} min, CPU {cpu / 60:.1f} min (pytest and the children it reaped) on "
        f"{os.cpu_count()} cores; reference loop {1e3 * _started['reference_wall']:.0f} ms wall / "
        f"{1e3 * _started['reference_cpu']:.0f} ms CPU at the start (the slower machine: 320-420 ms); "
        f"load {_started['load']:.1f} at the start, {os.getloadavg()[0]:.1f} at the end")
    if _worker_last_report:
        terminalreporter.write_line("last test report per worker: " + ", ".join(
            f"{worker} {seconds / 60:.1f} min" for worker, seconds in sorted(_worker_last_report.items())))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """With pytest-xdist (the README's test command runs two workers): every HIL test on one
    worker, one after another in file order, while the unit tests share out over both. HIL
    stacks time real motion on 2 cores and must not pile up on each other. The vcan VM stays in
    the HIL group, last. As a scope of its own, started at once beside the HIL tests (tried
    2026-11-30, other load beside it, load 8-12), its two TCG vCPUs starve them: 3 HIL and VM
    tests failed on starvation; not kept until measured on a quiet machine."""
    from xdist.scheduler import LoadScopeScheduling

    class HilInOrder(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return "hil_tests" if nodeid.startswith("hil_tests/") else nodeid

    return HilInOrder(config, log)
