"""A Dask cluster across Linux network namespaces on this machine: the multi-host test bed.

    host (root namespace) --veth--+
                                  |  bridge in the scheduler's namespace: `dask scheduler`
    worker namespace 1   --veth--+
    worker namespace 2   --veth--+

Every address is on a private /24 (10.213.N.0/24, N unused on this machine) that exists only on
the interfaces this module creates, so the cluster's traffic stays inside them. Namespaces,
veth pairs and processes carry a per-run tag; `close()` stops the processes it started (by
process group id) and deletes the namespaces (which deletes their veth ends and the bridge).
Needs root (or CAP_NET_ADMIN + CAP_SYS_ADMIN); `NetnsUnavailable` says why when it cannot.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DASK = str(Path(sys.executable).with_name("dask"))
PORT = 8786


class NetnsUnavailable(Exception):
    pass


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    try:
        out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired) as exc:     # no iproute2, or it hangs
        raise NetnsUnavailable(f"ip {' '.join(args)}: {exc}") from None
    if check and out.returncode != 0:
        raise NetnsUnavailable(f"ip {' '.join(args)}: {out.stderr.strip() or out.returncode}")
    return out


def _free_subnet() -> int:
    used = _ip("-4", "addr", "show").stdout + _ip("-4", "route", "show").stdout
    for third in [20 + (os.getpid() + k) % 200 for k in range(200)]:
        if f"10.213.{third}." not in used:
            return third
    raise NetnsUnavailable("no free 10.213.N.0/24 subnet")


@dataclass
class NetnsCluster:
    workers: int = 2
    tag: str = field(default_factory=lambda: f"{os.getpid() % 100000}")
    namespaces: list[str] = field(default_factory=list)
    host_veth: str | None = None
    processes: list[subprocess.Popen] = field(default_factory=list)
    logs: list[Path] = field(default_factory=list)
    subnet: int = 0
    keep_logs: bool = False          # set when the start failed: the logs say why

    @property
    def scheduler_ip(self) -> str:
        return f"10.213.{self.subnet}.1"

    @property
    def address(self) -> str:
        return f"tcp://{self.scheduler_ip}:{PORT}"

    def worker_ip(self, i: int) -> str:
        return f"10.213.{self.subnet}.{11 + i}"

    def start(self, timeout: float = 90.0) -> "NetnsCluster":
        if os.geteuid() != 0:
            raise NetnsUnavailable("network namespaces need root (ip netns add)")
        try:
            self._network()
            self._processes(timeout)
        except BaseException:
            self.keep_logs = True
            self.close()
            raise
        return self

    def _network(self) -> None:
        self.subnet = _free_subnet()
        net = f"10.213.{self.subnet}"
        sched = f"sa23s{self.tag}"
        self._add_ns(sched)
        _ip("-n", sched, "link", "add", "br0", "type", "bridge")
        _ip("-n", sched, "addr", "add", f"{net}.1/24", "dev", "br0")
        _ip("-n", sched, "link", "set", "br0", "up")
        # the host's leg: its end stays in the root namespace with .254, the other joins the bridge
        self.host_veth = f"sa23h{self.tag}"
        self._veth(self.host_veth, None, sched)
        _ip("addr", "add", f"{net}.254/24", "dev", self.host_veth)
        _ip("link", "set", self.host_veth, "up")
        for i in range(self.workers):
            ns = f"sa23w{i}{self.tag}"
            self._add_ns(ns)
            leg = f"sa23v{i}{self.tag}"
            self._veth(leg, ns, sched)
            _ip("-n", ns, "addr", "add", f"{self.worker_ip(i)}/24", "dev", leg)
            _ip("-n", ns, "link", "set", leg, "up")

    def _add_ns(self, name: str) -> None:
        _ip("netns", "add", name)
        self.namespaces.append(name)
        _ip("-n", name, "link", "set", "lo", "up")

    def _veth(self, name: str, inside: str | None, bridge_ns: str) -> None:
        """veth pair: `name` in namespace `inside` (None: the root namespace), its peer on the bridge."""
        peer = f"{name}p"
        _ip("link", "add", name, "type", "veth", "peer", "name", peer)
        _ip("link", "set", peer, "netns", bridge_ns)
        _ip("-n", bridge_ns, "link", "set", peer, "master", "br0")
        _ip("-n", bridge_ns, "link", "set", peer, "up")
        if inside is not None:
            _ip("link", "set", name, "netns", inside)

    def _spawn(self, ns: str, *args: str) -> subprocess.Popen:
        path = Path("/tmp") / f"{ns}.log"
        self.logs.append(path)
        with open(path, "wb") as log:
            proc = subprocess.Popen(["ip", "netns", "exec", ns, DASK, *args], cwd=ROOT, stdout=log,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        self.processes.append(proc)
        return proc

    def _processes(self, timeout: float) -> None:
        self._spawn(self.namespaces[0], "scheduler", "--host", self.scheduler_ip, "--port", str(PORT),
                    "--no-dashboard", "--no-show")
        self._wait_port(self.scheduler_ip, PORT, timeout)
        for i, ns in enumerate(self.namespaces[1:]):
            self._spawn(ns, "worker", self.address, "--host", self.worker_ip(i), "--nthreads", "1",
                        "--nworkers", "1", "--no-dashboard", "--name", f"netns-worker-{i}")
        from distributed import Client
        with Client(self.address, timeout="30s") as client:
            client.wait_for_workers(self.workers, timeout=timeout)

    def _wait_port(self, host: str, port: int, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(p.poll() is not None for p in self.processes):
                raise NetnsUnavailable(f"dask scheduler exited (log /tmp/{self.namespaces[0]}.log)")
            try:
                with socket.create_connection((host, port), timeout=1):
                    return
            except OSError:
                time.sleep(0.3)
        raise NetnsUnavailable(f"dask scheduler on {host}:{port} did not come up in {timeout} s")

    def kill_worker_host(self, i: int) -> None:
        """SIGKILL everything of worker namespace i (its `dask worker`, nanny and worker process):
        a host that dies mid-trial."""
        os.killpg(self.processes[1 + i].pid, signal.SIGKILL)

    def close(self) -> None:
        for proc in reversed(self.processes):
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGTERM)      # our own session: ip netns exec + dask
                except ProcessLookupError:
                    pass
        for proc in self.processes:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait(5)
        self.processes.clear()
        for ns in reversed(self.namespaces):
            _ip("netns", "del", ns, check=False)
        self.namespaces.clear()
        if not self.keep_logs:
            for path in self.logs:
                path.unlink(missing_ok=True)
        if self.host_veth:   # gone with its peer's namespace; delete in case the move failed
            _ip("link", "del", self.host_veth, check=False)
            self.host_veth = None

    def __enter__(self) -> "NetnsCluster":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
