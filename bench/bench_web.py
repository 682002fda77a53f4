"""Browser console: state latency from the control cycle to the page, update rate in the
page, and the daemon's cycle period error with two pages open vs none, in one run.

    .venv/bin/python bench/bench_web.py [--duration 30]

Simulator, daemon (real-time 20 ms cycle, recording every cycle) and web server are
separate processes on the loopback hub; the pages are two tabs of headless Chromium
(Debian /usr/bin/chromium, software WebGL) driven by Playwright. Three phases of
--duration s each: (0) no web server, (1) web server polling with no page, (2) two pages.
Period errors come from the daemon's own recording, split by the phases' daemon times;
latency is measured in the page: arrival time (performance.now, offset to the server's
CLOCK_MONOTONIC by an NTP-style exchange over the WebSocket) minus the cycle's monotonic
`woke_at` from status. Nothing moves during the bench, so a page gets one update a second (it
gets every cycle only while what it shows changes; console/web/server.py).
"""
from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spacearm.console.client import ApiClient  # noqa: E402
from spacearm.controller.recording.mcap_reader import read_recording  # noqa: E402
from spacearm.base.transport.hub import HubProcess  # noqa: E402
from hil_tests.harness import CHROMIUM, CHROMIUM_ARGS, CpuSteal, free_port, stop_group  # noqa: E402


def start(args: list[str], ready: str, log: Path, timeout: float = 60.0) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    handle = open(log, "w")
    proc = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", *args], cwd=ROOT, env=env,
                            stdout=handle, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = log.read_text(errors="replace")
        match = re.search(ready, text)
        if match:
            return proc, match.group(0)
        if proc.poll() is not None:
            raise SystemExit(f"{args[0]} exited: {text[-2000:]}")
        time.sleep(0.05)
    raise SystemExit(f"{args[0]}: not ready within {timeout} s: {log.read_text()[-2000:]}")


stop = stop_group   # hil_tests/harness.py: SIGTERM to the process group, SIGKILL after 10 s


def daemon_time(api: str) -> float:
    with ApiClient(api) as client:
        return float(client.call("status")["time"])


def phase_stats(cycles: list[dict], t0: float, t1: float, load: float, steal: float) -> dict:
    inside = [c for c in cycles if t0 <= c["t"] < t1]
    err = np.array([c["period_error"] for c in inside]) * 1e3
    numbers = np.array([c["cycle"] for c in inside])
    skipped = int(np.sum(np.diff(numbers) - 1)) if len(numbers) > 1 else 0
    return {"load": load, "steal": steal, "n": len(inside), "median": float(np.median(err)), "p99": float(np.percentile(err, 99)),
            "max": float(err.max()), "skipped": skipped,
            "execution_p99": float(np.percentile([c["execution"] for c in inside], 99)) * 1e3}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="s per phase")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    work = Path(tempfile.mkdtemp(prefix="bench_web_"))
    hub = HubProcess(ready_timeout=15.0, rt_priority=50)
    bus = hub.spec(f"bench-web-{os.getpid()}")
    api = f"tcp:127.0.0.1:{free_port()}"
    procs = []
    try:
        sim, _ = start(["sim", "--bus", bus, "--plant", "configs/plant/oru_testbed_nominal.toml", "--rt-priority", "50"],
                       "nodes ready", work / "sim.log")
        procs.append(sim)
        daemon, line = start(["daemon", "--bus", bus, "--api", api, "--record-dir", str(work / "runs")],
                             r"spacearm daemon:.*recording (\S+\.mcap)", work / "daemon.log")
        procs.append(daemon)
        recording = re.search(r"recording (\S+\.mcap)", line).group(1)
        time.sleep(3.0)                                          # let the start-up settle
        bounds = [daemon_time(api)]
        steal = CpuSteal()
        time.sleep(args.duration)                                # phase 0: no web server
        bounds.append(daemon_time(api))
        loads = [os.getloadavg()[0]]
        steals = [steal.fraction()]
        web, line = start(["console-web", "--connect", api, "--port", "0"],
                          r"http://127\.0\.0\.1:\d+/", work / "web.log")
        procs.append(web)
        url = line
        time.sleep(2.0)
        bounds.append(daemon_time(api))
        steal.fraction()
        time.sleep(args.duration)                                # phase 1: server, no page
        bounds.append(daemon_time(api))
        loads.append(os.getloadavg()[0])
        steals.append(steal.fraction())
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            pages = [browser.new_page(viewport={"width": 1400, "height": 900}) for _ in range(2)]
            for page in pages:
                page.goto(url)
                page.wait_for_function("() => spacearm.updates > 20 && spacearm.scene", timeout=60000)
            time.sleep(2.0)
            for page in pages:
                page.evaluate("() => { spacearm.latencies = []; spacearm.arrivals = []; }")
            bounds.append(daemon_time(api))
            steal.fraction()
            t_wall = time.monotonic()
            time.sleep(args.duration)                            # phase 2: two pages open
            bounds.append(daemon_time(api))
            loads.append(os.getloadavg()[0])
            steals.append(steal.fraction())
            wall = time.monotonic() - t_wall
            seen = [page.evaluate("() => ({lat: spacearm.latencies, arr: spacearm.arrivals})") for page in pages]
            browser.close()
        import urllib.request
        import json
        with urllib.request.urlopen(url + "api/info", timeout=5) as answer:
            info = json.load(answer)
    finally:
        for proc in reversed(procs):
            stop(proc)
        hub.stop()

    cycles = [m.data for m in read_recording(recording).topic("/cycle")]
    none = phase_stats(cycles, bounds[0], bounds[1], loads[0], steals[0])
    server = phase_stats(cycles, bounds[2], bounds[3], loads[1], steals[1])
    two = phase_stats(cycles, bounds[4], bounds[5], loads[2], steals[2])
    lat = np.concatenate([np.array(s["lat"]) for s in seen]) * 1e3
    rates = [(len(s["arr"]) - 1) / (s["arr"][-1] - s["arr"][0]) for s in seen if len(s["arr"]) > 1]
    daemon_rate = two["n"] / wall       # cycles the daemon ran per wall-clock second (skips excluded)
    rows = [
        ("state latency cycle -> page, median", f"{np.median(lat):.1f} ms ({len(lat)} updates, 2 pages)", "< 20 ms",
         np.median(lat) < 20),
        ("state latency cycle -> page, p99", f"{np.percentile(lat, 99):.1f} ms", "< 60 ms", np.percentile(lat, 99) < 60),
        ("update rate in the page, nothing moving (each of 2)", " / ".join(f"{r:.1f}/s" for r in rates)
         + f" (daemon ran {daemon_rate:.1f} cycles/s; idle pages get 1/s)", "", ""),
        ("server: status requests per state update", f"{info['status_polls'] / info['state_updates']:.2f} "
         f"({info['status_polls']} requests, {info['state_updates']} cycles), one connection for all pages", "", ""),
    ]
    for name, s in (("no web server", none), ("server, no page", server), ("two pages open", two)):
        rows.append((f"period error {name}: median / p99 / max",
                     f"{s['median']:.3f} / {s['p99']:.3f} / {s['max']:.2f} ms, {s['skipped']} skipped, "
                     f"exec p99 {s['execution_p99']:.2f} ms, load {s['load']:.1f}, "
                     f"steal {100 * s['steal']:.1f} %", "", ""))
    ratio = two["p99"] / none["p99"] if none["p99"] > 0 else float("nan")
    rows.append(("period error p99 ratio two pages / none", f"{ratio:.2f}", "<= 1.5", ratio <= 1.5))
    rows.append(("period error median ratio two pages / none", f"{two['median'] / none['median']:.2f}", "", ""))
    print(f"machine: {platform.platform()} | {os.cpu_count()} cores | python {platform.python_version()} | "
          f"load {os.getloadavg()[0]:.2f} | {args.duration:.0f} s per phase | Chromium software WebGL")
    width = max(len(r[0]) for r in rows)
    print(f"{'figure':<{width}}  {'measured':<72}  {'target':<9}  result")
    for figure, measured, target, ok in rows:
        result = "" if ok == "" else ("pass" if ok else "FAIL")
        print(f"{figure:<{width}}  {measured:<72}  {target:<9}  {result}")
    print("load: 1-minute load average of this 2-core machine at the end of each phase (other jobs included); "
          "steal: CPU time the hypervisor gave to other guests during the phase")


if __name__ == "__main__":
    main()
