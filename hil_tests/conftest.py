"""Fixtures for the hardware-in-the-loop suite: the same scenarios over every CAN transport.

``bus_spec`` is parametrised over the transports available here:

* ``virtual:<unique>``                       always (in-process only)
* ``loopback:<unique>@127.0.0.1:<port>``     always; one hub process serves the whole session
                                             (and ``SPACEARM_HUB`` points at it, so a
                                             ``loopback:NAME`` spec in a child reaches it too)
* ``socketcan:vcan0``                        when a ``vcan0`` interface exists (on a PC after
                                             ``modprobe vcan``; inside the test VM it does)

``--transport virtual,loopback`` (or env ``SPACEARM_HIL_TRANSPORTS``) narrows the set; the VM
runs ``-m vcan_vm --transport socketcan``. Everything collected under hil_tests/ is marked
``hil``. Helpers for other tests: ``launch`` (start a subprocess on a bus spec, killed at
teardown), ``open_test_bus`` (open buses closed at teardown), ``peer`` (a second node process,
see base/transport/peer.py), ``time_scale`` (multiply timeouts by it: 15 inside the VM).
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

ALL_TRANSPORTS = ("virtual", "loopback", "socketcan")
IN_VM = os.environ.get("SPACEARM_IN_VM") == "1"
TIME_SCALE = float(os.environ.get("SPACEARM_TIME_SCALE", "15" if IN_VM else "1"))


def vcan_available(name: str = "vcan0") -> bool:
    """True when the SocketCAN interface exists and is up (so tests can use it)."""
    p = Path("/sys/class/net") / name
    if not p.exists():
        return False
    try:
        flags = int((p / "flags").read_text().strip(), 16)
    except (OSError, ValueError):
        return True
    return bool(flags & 0x1)  # IFF_UP


def pytest_addoption(parser):
    parser.addoption("--cpu-load", action="store", type=int,
                     default=int(os.environ.get("SPACEARM_CPU_LOAD", "0") or 0),
                     help="run the whole session beside this many CPU-bound processes (hil_tests/cpu_load.py); "
                          "tests marked under_load get 2 of them in any case")
    parser.addoption("--transport", action="store", default=os.environ.get("SPACEARM_HIL_TRANSPORTS", ""),
                     help="comma list of transports for bus_spec: virtual,loopback,socketcan "
                          "(default: all available here)")


def pytest_configure(config):
    config.addinivalue_line("markers", "hil: hardware-in-the-loop test over a CAN bus")
    config.addinivalue_line("markers", "vcan_vm: part of the short subset run over real SocketCAN inside the test VM")
    config.addinivalue_line("markers", "multiprocess: needs the bus to reach another process (not virtual)")
    config.addinivalue_line("markers", "under_load: runs beside two CPU-bound processes (the suite must hold "
                                       "on a loaded machine)")


_VCAN_REPORTS: list[str] = []


def pytest_runtest_logreport(report):
    """The vcan suite's outcome, a user property of its test: it comes back from an xdist
    worker that way too."""
    _VCAN_REPORTS.extend(value for name, value in report.user_properties if name == "vcan_report")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Show the vcan suite's outcome (VM or direct) in the closing summary, even with -q."""
    report = _VCAN_REPORTS[-1] if _VCAN_REPORTS else None
    if report:
        terminalreporter.write_sep("-", "vcan HIL suite (real SocketCAN)")
        terminalreporter.write_line(report)


def selected_transports(config) -> list[str]:
    raw = config.getoption("--transport") or ""
    wanted = [t.strip() for t in raw.split(",") if t.strip()]
    for t in wanted:
        if t not in ALL_TRANSPORTS:
            raise pytest.UsageError(f"--transport: unknown transport '{t}' (known: {', '.join(ALL_TRANSPORTS)})")
    if not wanted:
        wanted = [t for t in ALL_TRANSPORTS if t != "socketcan" or vcan_available()]
    return wanted


def pytest_generate_tests(metafunc):
    if "bus_spec" in metafunc.fixturenames:
        transports = selected_transports(metafunc.config)
        if "socketcan" in transports and not vcan_available():
            transports = [t for t in transports if t != "socketcan"]
            if not transports:
                raise pytest.UsageError("--transport socketcan: no vcan0 interface here "
                                        "(`modprobe vcan; ip link add dev vcan0 type vcan; ip link set up vcan0`)")
        if metafunc.definition.get_closest_marker("multiprocess"):
            transports = [t for t in transports if t != "virtual"]
        metafunc.parametrize("bus_spec", transports, indirect=True, ids=transports)


def pytest_collection_modifyitems(config, items):
    here = Path(__file__).resolve().parent
    for item in items:
        try:
            inside = Path(str(item.fspath)).resolve().is_relative_to(here)
        except ValueError:
            inside = False
        if inside:
            item.add_marker(pytest.mark.hil)


# --------------------------------------------------------------------------- CPU load
from hil_tests.cpu_load import CpuLoad  # noqa: E402


@pytest.fixture(scope="session", autouse=True)
def session_cpu_load(request):
    """--cpu-load N: the whole session runs beside N CPU-bound processes."""
    count = request.config.getoption("--cpu-load")
    if count <= 0:
        yield None
        return
    with CpuLoad(count) as load:
        yield load


@pytest.fixture(autouse=True)
def marked_cpu_load(request):
    """Tests marked under_load run beside two CPU-bound processes."""
    if request.node.get_closest_marker("under_load") is None:
        yield None
        return
    with CpuLoad(2) as load:
        yield load


# --------------------------------------------------------------------------- loopback hub
from spacearm.base.runtime.child_process import module_env  # noqa: E402
from spacearm.base.transport.hub import HubProcess  # noqa: E402


@pytest.fixture(scope="session")
def loopback_hub():
    hub = HubProcess(ready_timeout=15.0 * TIME_SCALE, rt_priority=50)
    old = os.environ.get("SPACEARM_HUB")
    os.environ["SPACEARM_HUB"] = hub.address
    try:
        yield hub
    finally:
        if old is None:
            os.environ.pop("SPACEARM_HUB", None)
        else:
            os.environ["SPACEARM_HUB"] = old
        hub.stop()


# --------------------------------------------------------------------------- bus_spec
@pytest.fixture
def bus_spec(request):
    """A bus spec string for the transport this test instance runs on; unique per test where
    the transport allows (virtual, loopback); socketcan:vcan0 is shared."""
    kind = request.param
    unique = f"hil-{uuid.uuid4().hex[:10]}"
    if kind == "virtual":
        return f"virtual:{unique}"
    if kind == "loopback":
        hub = request.getfixturevalue("loopback_hub")
        return hub.spec(unique)
    if kind == "socketcan":
        return "socketcan:vcan0"
    raise AssertionError(kind)


@pytest.fixture
def time_scale() -> float:
    return TIME_SCALE


@pytest.fixture
def open_test_bus():
    """open_test_bus(spec, **kw) -> bus; every bus opened is shut down at teardown."""
    from spacearm.base.transport import open_bus

    opened = []

    def _open(spec: str, **kwargs):
        bus = open_bus(spec, **kwargs)
        opened.append(bus)
        return bus

    yield _open
    for bus in opened:
        try:
            bus.shutdown()
        except Exception:
            pass


SIM_RT_PRIORITY = 50   # as the README runs `spacearm sim` (and the daemon's real-time cycle)


def child_env(extra: dict | None = None) -> dict:
    env = module_env()
    env.setdefault("PYTHONUNBUFFERED", "1")
    if extra:
        env.update(extra)
    return env


@pytest.fixture
def launch(tmp_path):
    """launch(args, bus_spec=None, ready=None, timeout=20, env=None) -> subprocess.Popen

    Starts ``[sys.executable, *args]`` (append ``--bus SPEC`` when bus_spec is given) in the repo
    root with PYTHONPATH and SPACEARM_HUB set; stdout/stderr go to files in tmp_path (paths on
    ``proc.log_paths``). If ``ready`` (a regex) is given, waits until it appears in the
    output, failing after ``timeout`` * time_scale seconds. Every process is terminated, then
    killed, at teardown.

    A simulator (``spacearm.console.main sim``) runs at SCHED_FIFO SIM_RT_PRIORITY unless the
    command names ``--rt-priority``: it stands in for drive firmware, which has its own CPU on
    a real arm; at normal priority the CPU-bound neighbours (--cpu-load) starve its heartbeat
    producer and the controller rightly declares the node lost (a false fault of the test
    set-up, not of the stack).
    """
    procs: list[subprocess.Popen] = []

    def _launch(args, bus_spec: str | None = None, ready: str | None = None, timeout: float = 20.0,
                env: dict | None = None):
        args = [str(a) for a in args]
        if args[:3] == ["-m", "spacearm.console.main", "sim"] and "--rt-priority" not in args:
            args += ["--rt-priority", str(SIM_RT_PRIORITY)]
        cmd = [sys.executable, *args]
        if bus_spec is not None:
            cmd += ["--bus", bus_spec]
        n = len(procs)
        out_path, err_path = tmp_path / f"proc{n}.out", tmp_path / f"proc{n}.err"
        out, err = open(out_path, "w"), open(err_path, "w")
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, stdin=subprocess.DEVNULL, cwd=str(ROOT),
                                env=child_env(env), start_new_session=True)
        out.close()
        err.close()
        proc.log_paths = (out_path, err_path)
        proc.cmd = cmd
        procs.append(proc)
        if ready:
            pattern = re.compile(ready)
            deadline = time.monotonic() + timeout * TIME_SCALE
            while True:
                text = out_path.read_text(errors="replace") + err_path.read_text(errors="replace")
                if pattern.search(text):
                    break
                if proc.poll() is not None:
                    raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode} before "
                                       f"/{ready}/:\n{text[-3000:]}")
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{' '.join(cmd)}: no /{ready}/ within {timeout * TIME_SCALE:.0f} s:\n"
                                       f"{text[-3000:]}")
                time.sleep(0.05)
        return proc

    yield _launch
    for proc in procs:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                proc.terminate()
    for proc in procs:
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                proc.kill()
            proc.wait(5)


@pytest.fixture
def peer():
    """peer(spec, mode, *args) -> spacearm.base.transport.peer.Peer, killed at teardown."""
    from spacearm.base.transport.peer import Peer

    made = []

    def _peer(spec: str, mode: str, *extra: str, timeout: float = 30.0):
        p = Peer(spec, mode, *extra, ready_timeout=20.0 * TIME_SCALE, timeout=timeout * TIME_SCALE)
        made.append(p)
        return p

    yield _peer
    for p in made:
        p.kill()
