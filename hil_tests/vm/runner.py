"""Run the vcan subset of hil_tests over real Linux SocketCAN, in a VM when the host has no CAN.

    python -m hil_tests.vm.runner [--direct|--vm] [-- extra pytest args]

Where ``vcan0`` exists on the host (any Linux PC after ``modprobe vcan; ip link add dev vcan0
type vcan; ip link set up vcan0``) the subset runs directly. Otherwise (this CI machine's
kernel has no CONFIG_CAN) it boots Debian's stock kernel (``linux-image-amd64``, which ships
vcan.ko) under QEMU software emulation with virtme-ng, the host filesystem shared read-only
over 9p, creates vcan0 inside, and runs the same pytest subset there with the host's venv:

    pytest hil_tests -m vcan_vm --transport socketcan

Results come back through a writable shared directory (``--rwdir``): the pytest log, a junit
XML file and the exit code. The VM needs: qemu-system-x86, linux-image-amd64, busybox-static
(apt) and virtme-ng (pip, in the dev extra) -- scripts/bootstrap.sh installs them.
"""
from __future__ import annotations

import argparse
import glob
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SUBSET_ARGS = ["-m", "vcan_vm", "--transport", "socketcan"]
DEFAULT_BUDGET = float(os.environ.get("SPACEARM_VM_BUDGET", "1500"))  # kill limit, not the target (~11-13 min)
# That limit was set on a machine where bench/reference_work.py's loop takes 80-90 ms. The VM
# emulates in software, so its run grows with the host's slowness: 952 s against 355 s on this
# machine throttled to a third of its CPU (cgroup quota, 2026-11-29), a 1500 s limit away from
# a kill on a machine a little slower still. The suite scales the limit (machine_budget).
BUDGET_REFERENCE_LOOP = 0.09   # s
BUDGET_MAX_SCALE = 3.0         # a hung VM is still killed within 75 min on the slowest machine


class VMUnavailable(RuntimeError):
    """The VM cannot be started here (missing package, no kernel, ...)."""


@dataclass
class SuiteResult:
    where: str                      # "host" or "vm"
    returncode: int                 # pytest's exit code (or a runner code, see `problem`)
    summary: str                    # pytest's closing line
    tests: int = 0
    passed: int = 0
    failed: int = 0
    errors: int = 0
    skipped: int = 0
    seconds: float = 0.0
    log: str = ""
    problem: str = ""               # set when the suite did not run to the end
    details: dict = field(default_factory=dict)
    outcomes: list[tuple[str, str]] = field(default_factory=list)   # (test, passed|failed|error|skipped: reason)

    def outcome_line(self) -> str:
        """Which test did what, so a skip inside the VM shows by name, not only as a count."""
        return "; ".join(f"{name} {outcome}" for name, outcome in self.outcomes) or "(no per-test results)"

    @property
    def ok(self) -> bool:
        # inside the VM vcan0 exists and everything runs as root: a skip there hides a test
        skips_hide = self.where == "vm" and self.skipped
        return self.returncode == 0 and not self.problem and self.passed > 0 and not (
            self.failed or self.errors or skips_hide)


# ----------------------------------------------------------------------- host checks
def vcan_on_host(name: str = "vcan0") -> bool:
    return Path(f"/sys/class/net/{name}").exists()


def try_create_vcan(name: str = "vcan0") -> bool:
    """Best effort: create vcan0 on the host (root and CONFIG_CAN needed). True if it exists."""
    if vcan_on_host(name):
        return True
    if os.geteuid() != 0 or not shutil.which("ip"):
        return False
    if shutil.which("modprobe"):
        subprocess.run(["modprobe", "vcan"], capture_output=True, timeout=20)
    r = subprocess.run(["ip", "link", "add", "dev", name, "type", "vcan"], capture_output=True, timeout=20)
    if r.returncode != 0:
        return False
    subprocess.run(["ip", "link", "set", "up", name], capture_output=True, timeout=20)
    return vcan_on_host(name)


def find_kernel() -> tuple[str, str]:
    """(vmlinuz path, version) of the newest /boot kernel whose modules include vcan."""
    found = []
    for path in glob.glob("/boot/vmlinuz-*"):
        ver = Path(path).name[len("vmlinuz-"):]
        if glob.glob(f"/lib/modules/{ver}/kernel/drivers/net/can/vcan.ko*"):
            found.append((path, ver))
    if not found:
        raise VMUnavailable("no /boot/vmlinuz-* with a vcan module under /lib/modules: "
                            "`apt-get install linux-image-amd64` (scripts/bootstrap.sh does)")

    def key(item):
        return [int(x) if x.isdigit() else x for x in re.split(r"[.-]", item[1])]

    path, ver = sorted(found, key=key)[-1]
    if not os.access(path, os.R_OK):
        raise VMUnavailable(f"{path} is not readable by this user (Debian installs it 0600): run as root")
    return path, ver


def find_tools() -> dict[str, str]:
    bindir = Path(sys.executable).parent
    vng = bindir / "vng"
    tools = {"vng": str(vng) if vng.exists() else (shutil.which("vng") or "")}
    tools["qemu"] = shutil.which("qemu-system-x86_64") or ""
    tools["busybox"] = shutil.which("busybox") or ("/bin/busybox" if Path("/bin/busybox").exists() else "")
    missing = [f"{k} ({pkg})" for k, pkg in (("vng", "pip: virtme-ng"), ("qemu", "apt: qemu-system-x86"),
                                             ("busybox", "apt: busybox-static")) if not tools[k]]
    if missing:
        raise VMUnavailable("missing for the vcan VM: " + ", ".join(missing) + " -- run scripts/bootstrap.sh")
    return tools


# ----------------------------------------------------------------------- results
_SUMMARY = re.compile(r"^=+ (.+ in [\d.]+s.*) =+$|^(\d+ (passed|failed|error|skipped|deselected).* in [\d.]+s.*)$")


def _summary_line(log: str) -> str:
    for line in reversed(log.splitlines()):
        m = _SUMMARY.match(line.strip())
        if m:
            return (m.group(1) or m.group(2)).strip()
    return ""


def _case_outcome(case: ET.Element) -> tuple[str, str]:
    name = case.get("classname", "").rsplit(".", 1)[-1] + "::" + case.get("name", "?")
    for tag, word in (("failure", "failed"), ("error", "error"), ("skipped", "skipped")):
        found = case.find(tag)
        if found is not None:
            reason = (found.get("message") or "").splitlines()[0][:120] if found.get("message") else ""
            return name, f"{word}: {reason}" if reason else word
    return name, f"passed ({float(case.get('time', 0)):.0f} s)"


def _fill_counts(res: SuiteResult, junit: Path) -> None:
    if junit.exists():
        try:
            root = ET.parse(junit).getroot()
            suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
            for s in suites:
                res.tests += int(s.get("tests", 0))
                res.failed += int(s.get("failures", 0))
                res.errors += int(s.get("errors", 0))
                res.skipped += int(s.get("skipped", 0))
            res.passed = res.tests - res.failed - res.errors - res.skipped
            res.outcomes = [_case_outcome(case) for case in root.iter("testcase")]
            return
        except (ET.ParseError, ValueError):
            pass
    for n, word in re.findall(r"(\d+) (passed|failed|errors?|skipped)", res.summary):
        n = int(n)
        if word == "passed":
            res.passed = n
        elif word == "failed":
            res.failed = n
        elif word.startswith("error"):
            res.errors = n
        else:
            res.skipped = n
    res.tests = res.passed + res.failed + res.errors + res.skipped


# ----------------------------------------------------------------------- runners
def _pytest_cmd(junit: Path, extra: list[str], paths: list[str] | None = None) -> list[str]:
    return [sys.executable, "-m", "pytest", *(paths or ["hil_tests"]), *SUBSET_ARGS, "-p", "no:cacheprovider", "-q", "-rfE",
            f"--junitxml={junit}", *extra]


def descendants(pid: int) -> list[int]:
    """All live descendants of pid (children first found via /proc)."""
    children: dict[int, list[int]] = {}
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            text = Path(stat).read_text()
            ppid = int(text.rsplit(")", 1)[1].split()[1])
            children.setdefault(ppid, []).append(int(Path(stat).parent.name))
        except (OSError, ValueError, IndexError):
            continue
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def _kill_tree(pid: int) -> None:
    for p in [pid] + descendants(pid):
        try:
            os.kill(p, 9)
        except (ProcessLookupError, PermissionError):
            pass


def machine_budget(budget: float = DEFAULT_BUDGET) -> float:
    """`budget` scaled by how much longer the reference loop takes here (wall time, median of
    three: load slows the VM as much as a slower CPU does), between 1x and BUDGET_MAX_SCALE."""
    from bench.reference_work import reference_loop_seconds
    wall, _ = reference_loop_seconds(repeats=3)
    return budget * min(BUDGET_MAX_SCALE, max(1.0, wall / BUDGET_REFERENCE_LOOP))


def _run_group(cmd: list[str], budget: float, **kw) -> tuple[str, int, bool]:
    """Run cmd; on timeout (or if we are interrupted) kill it and every descendant (qemu
    included). It stays in our process group, so `timeout`/CI killing our group kills it too.
    Returns (output, returncode, timed_out)."""
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, errors="replace", **kw)
    try:
        out, _ = proc.communicate(timeout=budget)
        return out, proc.returncode, False
    except subprocess.TimeoutExpired:
        _kill_tree(proc.pid)
        try:
            out, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            out = ""
        return out or "", 124, True
    finally:
        if proc.poll() is None:
            _kill_tree(proc.pid)
            proc.wait(10)


def run_direct(extra: list[str] | None = None, budget: float = DEFAULT_BUDGET,
               paths: list[str] | None = None) -> SuiteResult:
    """Run the subset on this host (vcan0 must exist)."""
    with tempfile.TemporaryDirectory(prefix="spacearm-vcan-") as tmp:
        junit = Path(tmp) / "junit.xml"
        t0 = time.monotonic()
        out, rc, timed_out = _run_group(_pytest_cmd(junit, extra or [], paths), budget, cwd=ROOT)
        problem = f"pytest did not finish within {budget:.0f} s" if timed_out else ""
        res = SuiteResult("host", rc, _summary_line(out), seconds=time.monotonic() - t0, log=out, problem=problem)
        _fill_counts(res, junit)
        return res


GUEST_SCRIPT = """#!/bin/sh
# runs inside the VM (as root, host filesystem read-only, {rw} writable)
RW={rw}
echo 1 > $RW/started
echo "[vm] kernel $(uname -r), $(nproc) cpus"
fail() {{ echo "[vm] $1"; echo "$1" > $RW/problem; echo 90 > $RW/rc; exit 90; }}
modprobe vcan || fail "modprobe vcan failed"
for dev in vcan0 vcan1; do    # vcan1: the redundant line of a pair (hil_tests/test_redundancy_hil.py)
  ip link add dev $dev type vcan || fail "ip link add $dev failed"
  ip link set up $dev || fail "ip link set up $dev failed"
done
ip -details link show vcan0 | head -3
cd {root} || fail "cannot cd {root}"
export HOME=/tmp SPACEARM_IN_VM=1 PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 CI="${{CI:-}}"
export PYTHONPATH={pythonpath}
export SPACEARM_CANOPEND={canopend}
export PATH={bindir}:/usr/sbin:/usr/bin:/sbin:/bin
echo "[vm] running: {cmd}"
{cmd} > $RW/pytest.log 2>&1
echo $? > $RW/rc
tail -n 60 $RW/pytest.log
echo "[vm] pytest exit code $(cat $RW/rc)"
"""


def _prebuild_canopend(rw: Path) -> str:
    """CANopenNode's canopend built here, natively (seconds; minutes under the VM's emulation),
    into the shared writable directory. '' when it cannot be: the test builds it itself and
    fails saying why."""
    from hil_tests.interop.canopennode import BuildError, build
    try:
        return str(build(rw / "canopennode"))
    except BuildError as exc:
        print(f"[vm] canopend not prebuilt: {exc}", file=sys.stderr)
        return ""


def run_in_vm(extra: list[str] | None = None, budget: float = DEFAULT_BUDGET, memory: str = "2G",
              cpus: int | None = None, echo: bool = False, paths: list[str] | None = None) -> SuiteResult:
    """Boot the VM and run the subset inside; never raises for test failures, only returns."""
    kernel, ver = find_kernel()
    tools = find_tools()
    cpus = cpus or min(2, os.cpu_count() or 1)
    rw = Path(tempfile.mkdtemp(prefix="spacearm-vm-"))
    try:
        junit = rw / "junit.xml"
        inner = " ".join(shlex.quote(a) for a in _pytest_cmd(junit, extra or [], paths))
        script = rw / "guest.sh"
        # the host's PYTHONPATH after this tree: whatever made this tree's code win here wins inside too
        host_path = filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))
        pythonpath = os.pathsep.join(dict.fromkeys([str(ROOT), *host_path]))
        script.write_text(GUEST_SCRIPT.format(rw=shlex.quote(str(rw)), root=shlex.quote(str(ROOT)),
                                              pythonpath=shlex.quote(pythonpath),
                                              bindir=shlex.quote(str(Path(sys.executable).parent)), cmd=inner,
                                              canopend=shlex.quote(_prebuild_canopend(rw))))
        script.chmod(0o755)
        cmd = [tools["vng"], "--run", kernel, "--force-9p", "--memory", memory, "--cpus", str(cpus),
               "--rwdir", str(rw), "--exec", f"sh {shlex.quote(str(script))}"]
        if os.environ.get("SPACEARM_VM_KVM") != "1":
            cmd.insert(3, "--disable-kvm")  # stock guests do not boot under this host's KVM; TCG does
        env = dict(os.environ)
        env["PATH"] = str(Path(tools["vng"]).parent) + os.pathsep + env.get("PATH", "")
        t0 = time.monotonic()
        problem = ""
        console, vng_rc, timed_out = _run_group(cmd, budget, cwd=ROOT, env=env)
        if timed_out:
            problem = f"the VM run did not finish within {budget:.0f} s (killed)"
        seconds = time.monotonic() - t0
        log = (rw / "pytest.log").read_text(errors="replace") if (rw / "pytest.log").exists() else ""
        rc_text = (rw / "rc").read_text().strip() if (rw / "rc").exists() else ""
        if not problem and (rw / "problem").exists():
            problem = "inside the VM: " + (rw / "problem").read_text().strip()
        if not problem and not (rw / "started").exists():
            problem = f"the VM did not boot (vng exit code {vng_rc})"
        if not problem and not rc_text:
            problem = f"pytest inside the VM did not report an exit code (vng exit code {vng_rc})"
        rc = int(rc_text) if rc_text.isdigit() else (vng_rc or 1)
        res = SuiteResult("vm", rc, _summary_line(log), seconds=seconds, log=log, problem=problem,
                          details={"kernel": kernel, "kernel_version": ver, "console": console[-6000:],
                                   "command": " ".join(shlex.quote(c) for c in cmd)})
        _fill_counts(res, junit)
        if echo:
            print(console[-6000:])
        return res
    finally:
        shutil.rmtree(rw, ignore_errors=True)


def run_suite(extra: list[str] | None = None, mode: str = "auto", budget: float = DEFAULT_BUDGET,
              paths: list[str] | None = None) -> SuiteResult:
    """mode: auto (direct when vcan0 can be had on the host, else VM), direct, vm."""
    if mode == "direct" or (mode == "auto" and try_create_vcan()):
        return run_direct(extra, budget, paths)
    return run_in_vm(extra, budget, paths=paths)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hil_tests.vm.runner", description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--direct", action="store_const", dest="mode", const="direct")
    g.add_argument("--vm", action="store_const", dest="mode", const="vm")
    ap.add_argument("--budget", type=float, default=DEFAULT_BUDGET, help="seconds for the whole run")
    ap.add_argument("--paths", default="", help="comma list of test paths (default: hil_tests)")
    ap.add_argument("extra", nargs="*", help="extra pytest arguments (after --)")
    args = ap.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # run the cleanup (kills the VM)
    try:
        res = run_suite(args.extra, args.mode or "auto", args.budget,
                        [p for p in args.paths.split(",") if p] or None)
    except VMUnavailable as exc:
        print(f"vcan suite: cannot start the VM: {exc}", file=sys.stderr)
        return 3
    # the head keeps the tests' own progress lines (-s) and the first failure, the tail the summary
    print(res.log if len(res.log) <= 12000 else res.log[:4000] + "\n[...]\n" + res.log[-8000:])
    if res.where == "vm" and (res.problem or res.returncode):
        print("---- VM console (tail) ----\n" + res.details.get("console", "")[-4000:])
    print(f"vcan suite ({res.where}, {res.seconds:.0f} s): {res.summary or '(no pytest summary)'}"
          f"{' -- ' + res.problem if res.problem else ''}\n  per test: {res.outcome_line()}")
    return 0 if res.ok else (res.returncode or 1)


if __name__ == "__main__":
    sys.exit(main())
