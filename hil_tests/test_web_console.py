"""The browser console end to end: simulator, daemon and web server as separate processes on
the loopback hub, the page in headless Chromium (Debian's /usr/bin/chromium) driven by
Playwright. Loads the page, presimulates a rejected and an accepted joint move, sends it,
checks that the arm moved (daemon state, joint table and 3-D scene), stops a second move
with the STOP button, and saves screenshots next to the test's logs (pytest tmp dir)."""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from hil_tests.conftest import TIME_SCALE
from hil_tests.harness import (CHROMIUM, CHROMIUM_ARGS, StealTimeline, free_port, patient_bus,
                               xfail_if_the_host_stalled_a_vcpu)

pytestmark = [pytest.mark.hil, pytest.mark.slow]


@pytest.fixture
def browser():
    if not Path(CHROMIUM).exists() and not shutil.which(CHROMIUM):
        pytest.skip(f"no Chromium at {CHROMIUM} (Debian package `chromium`, installed by scripts/bootstrap.sh)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright (dev extra) not installed")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


@pytest.fixture
def camera_ring():
    """A frame ring holding one simulated eye-in-hand frame of the marker 300 mm ahead."""
    import numpy as np

    from spacearm.base.vision.frames import ShmFrameRing
    from spacearm.firmware_sim.camera.simulator import CameraSimulator

    frame = CameraSimulator.from_configs(noise_seed=1).render(
        np.array([[1, 0, 0, 0.01], [0, -1, 0, -0.005], [0, 0, -1, 0.30], [0, 0, 0, 1]], float))
    ring = ShmFrameRing.create(frame.image.shape[1], frame.image.shape[0])
    ring.publish(frame.image, frame.timestamp)
    try:
        yield ring
    finally:
        ring.close()


def start_web_stack(loopback_hub, launch, tmp_path, camera_ring, lockstep: bool = False) -> dict:
    bus = loopback_hub.spec(f"web-{os.getpid()}-{time.monotonic_ns()}")
    # lockstep: for tests of what the page shows, not of supervision: the patient bus and
    # the lockstep clock keep a loaded machine's late answers from stopping the arm.
    bus_config = ["--bus-config", str(patient_bus(tmp_path / "bus.toml"))] if lockstep else []
    launch(["-m", "spacearm.console.main", "sim", "--plant", "configs/plant/oru_testbed_nominal.toml", *bus_config],
           bus_spec=bus, ready="nodes ready")
    api = f"tcp:127.0.0.1:{free_port()}"
    # Real time at SCHED_FIFO 50 (the daemon's default, as the README runs it; the harness
    # runs the simulator so too): in lockstep the daemon runs at normal priority, and on a
    # loaded machine its heartbeat producer starved past the drives' 300 ms consumer timeout
    # (EMCY 8130h, a true stop of the drives). bench/bench_web.py measures the page's timing.
    launch(["-m", "spacearm.console.main", "daemon", "--clock", "lockstep" if lockstep else "realtime", "--api", api,
            "--record-dir", str(tmp_path / "runs"), *bus_config],
           bus_spec=bus, ready="spacearm daemon:", timeout=30)
    web = launch(["-m", "spacearm.console.main", "console-web", "--connect", api, "--port", "0",
                  "--camera", camera_ring.name],
                 ready=r"console-web: http://127\.0\.0\.1:\d+/", timeout=30,
                 env={"SPACEARM_LEASE_DIR": str(tmp_path / "lease")})
    text = web.log_paths[0].read_text()
    url = re.search(r"(http://127\.0\.0\.1:\d+/)", text).group(1)
    return {"url": url, "api": api, "artifacts": tmp_path}


@pytest.fixture
def steal():
    """Per-vCPU steal through the test: a stop for silent nodes is judged against it."""
    timeline = StealTimeline()
    yield timeline
    timeline.stop()


@pytest.fixture
def web_stack(loopback_hub, launch, tmp_path, camera_ring, steal):
    return start_web_stack(loopback_hub, launch, tmp_path, camera_ring) | {"steal": steal}


@pytest.fixture
def patient_web_stack(loopback_hub, launch, tmp_path, camera_ring, steal):
    return start_web_stack(loopback_hub, launch, tmp_path, camera_ring, lockstep=True) | {"steal": steal}


def wait_for(page, expression: str, timeout: float = 20.0) -> None:
    try:
        page.wait_for_function(expression, timeout=timeout * 1000 * TIME_SCALE)
    except Exception as exc:  # noqa: BLE001 - say what the page showed, not just "timeout"
        seen = page.evaluate("() => ({status: spacearm.lastStatus && {state: spacearm.lastStatus.state, "
                             "mode: spacearm.lastStatus.mode, stop: spacearm.lastStatus.stop_reason, "
                             "events: spacearm.lastStatus.events.slice(-4)}, "
                             "result: document.getElementById('cmd-result').textContent})")
        raise AssertionError(f"page never showed {expression}: {exc.__class__.__name__}; page: {seen}") from None


def status(page) -> dict:
    return page.evaluate("() => spacearm.lastStatus")


def enable(page, stack: dict) -> None:
    """Enable through the page's buttons, once: a stop instead fails with its code (on a loaded
    machine starvation is coded `late_cycle` and does not stop the arm; see report_load)."""
    page.click("#btn-enable")
    wait_for(page, "() => ['enabled', 'stopped'].includes(spacearm.lastStatus.state)")
    assert status(page)["state"] == "enabled", f"arm not enabled: {unexpected_stop(page, stack)}"


def unexpected_stop(page, stack: dict) -> str:
    """The stop's code and message; a stop for silent nodes while the host held a vCPU is the
    machine's, not the stack's, and is reported as such (xfail naming the measured steal)."""
    from spacearm.console.client import ApiClient
    with ApiClient(stack["api"]) as client:
        xfail_if_the_host_stalled_a_vcpu(client.call("status"), stack["steal"])
    return stop_text(page)


def stop_text(page) -> str:
    stop = status(page).get("stop") or {}
    return f"[{stop.get('code')}] {stop.get('message')}" if stop else str(status(page).get("stop_reason"))


def presimulate_accepted(page) -> None:
    """Presimulate the form's command and check that it was accepted."""
    page.evaluate("() => { spacearm.lastPresim = null; }")
    page.click("#btn-presim")
    wait_for(page, "() => spacearm.lastPresim !== null")
    assert page.evaluate("() => spacearm.lastPresim.accepted"), \
        f"presimulation rejected: {page.evaluate('() => spacearm.lastPresim.reason')}"


def send_until(page, stack: dict, done: str) -> None:
    """Send the presimulated command and wait until the JS condition `done` holds; a refusal
    or a protective stop on the way fails the test with its code."""
    page.evaluate("() => { document.getElementById('cmd-result').textContent = ''; }")
    page.click("#btn-send")
    wait_for(page, "() => /^(sent|refused)/.test(document.getElementById('cmd-result').textContent)")
    result = page.text_content("#cmd-result")
    assert result.startswith("sent"), f"command refused: {result}"
    wait_for(page, f"() => ({done}) || spacearm.lastStatus.state === 'stopped'", timeout=30)
    assert page.evaluate(f"() => {done}"), f"stopped before {done}: {unexpected_stop(page, stack)}"


def report_load(stack, record_property) -> dict:
    """What this machine's load did to the daemon during the test, as measured (no retry
    hides it): cycles whose missing data was excused as the controller's own lateness,
    heartbeat checks made after starvation, TPDO waits that timed out, and
    the real-time cycle's overruns and period error (s). Printed and attached to the test
    report (junit properties)."""
    from spacearm.console.client import ApiClient

    status = ApiClient(stack["api"]).call("status")
    network, cycle = status["network"], status["stats"]
    figures = {key: network.get(key) for key in ("late_cycles", "starved_checks", "starved_time", "tpdo_timeouts")}
    figures |= {key: cycle.get(key) for key in ("overruns", "period_error_p99", "period_error_max", "execution_p99")}
    figures["load"] = round(os.getloadavg()[0], 2)
    for key, value in figures.items():
        record_property(key, value)
    print(f"web console under load: {figures}")
    return figures


def shot(page, stack, name: str) -> Path:
    path = stack["artifacts"] / f"web-{name}.png"
    page.screenshot(path=str(path))
    return path


def open_page(web_stack, browser) -> tuple:
    """A page of the console, and the list its script errors land in."""
    page = browser.new_page(viewport={"width": 1500, "height": 950})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(web_stack["url"])
    return page, errors


def test_web_console_presimulates_sends_and_stops(web_stack, browser, record_property):
    page, errors = open_page(web_stack, browser)
    wait_for(page, "() => spacearm.updates > 3 && spacearm.scene && spacearm.scene.armFrames")
    assert page.text_content("#link") == "live"
    wait_for(page, "() => document.querySelectorAll('#joints tbody tr').length === 6")
    assert page.evaluate("() => spacearm.scene.scene.children.filter(o => o.name.startsWith('store:')).length") == 3
    # Camera monitor: the frame with the vision pipeline's marker overlay.
    wait_for(page, "() => { const i = document.querySelector('#camera img'); return i && i.naturalWidth === 680; }")
    shot(page, web_stack, "1-loaded")

    # Motion commands need the lease and an enabled arm; the page asks as a console would.
    page.click("#btn-take")
    wait_for(page, "() => document.getElementById('cmd-result').textContent.includes('taken')")
    enable(page, web_stack)
    start = status(page)
    q_start = [j["q"] for j in start["joints"]]

    # Presimulation rejects a goal outside the joint limits and explains why; nothing is sendable.
    page.check("input[value=move_joints]")
    page.click("#btn-copy-q")
    page.locator(".q-input").nth(0).fill("200")
    page.click("#btn-presim")
    wait_for(page, "() => spacearm.lastPresim && spacearm.lastPresim.accepted === false")
    assert "outside its limits" in page.text_content("#cmd-result")
    assert page.is_disabled("#btn-send")

    # An accepted move shows the ghost along the plan; the operator then sends it.
    target_deg = math.degrees(q_start[0]) + 10.0
    page.locator(".q-input").nth(0).fill(f"{target_deg:.3f}")
    presimulate_accepted(page)
    presim = page.evaluate("() => ({d: spacearm.lastPresim.duration, n: spacearm.lastPresim.frames.length, "
                           "ghost: spacearm.scene.ghost.group.visible, q: spacearm.lastPresim.q})")
    assert presim["ghost"] and presim["n"] > 10 and presim["d"] > 0.5
    assert presim["q"][-1][0] == pytest.approx(math.radians(target_deg), abs=1e-5)
    checks = page.text_content("#checks")
    assert "joint limits" in checks and "arm state" in checks
    time.sleep(0.5)
    shot(page, web_stack, "2-presimulated")
    tool_before = page.evaluate("() => spacearm.scene.armFrames.at(-1).slice()")
    send_until(page, web_stack, f"spacearm.lastStatus.motions_finished > {start['motions_finished']} "
                     "&& spacearm.lastStatus.state === 'enabled'")
    wait_for(page, f"() => Math.abs(spacearm.lastStatus.joints[0].q - {math.radians(target_deg)}) < 2e-3")
    moved = status(page)
    assert moved["state"] == "enabled"
    assert moved["joints"][0]["q"] == pytest.approx(math.radians(target_deg), abs=2e-3)      # daemon state
    wait_for(page, "() => Math.abs(parseFloat(document.querySelector('#joints tbody tr td:nth-child(2)')"
                   f".textContent) - {target_deg}) < 0.1")                                        # joint table
    tool_after = page.evaluate("() => spacearm.scene.armFrames.at(-1).slice()")
    assert math.dist(tool_before[3::4][:3], tool_after[3::4][:3]) > 0.05                        # 3-D scene
    shot(page, web_stack, "3-moved")

    # STOP is one click: a protective stop in the middle of the next (long) move, shown on the page.
    target_deg = math.degrees(q_start[0]) - 150.0
    page.locator(".q-input").nth(0).fill(f"{target_deg:.3f}")
    presimulate_accepted(page)
    send_until(page, web_stack, "spacearm.lastStatus.mode === 'move_joints' && spacearm.lastStatus.progress > 0.02")
    page.click("#btn-stop")
    wait_for(page, "() => spacearm.lastStatus.state === 'stopped'")
    stopped = status(page)
    assert stopped["stop_reason"]
    wait_for(page, "() => document.getElementById('stopreason').textContent.includes('PROTECTIVE STOP')")
    q_stop = stopped["joints"][0]["q"]
    assert math.radians(target_deg) + 0.1 < q_stop < moved["joints"][0]["q"] - 1e-3   # stopped part-way
    shot(page, web_stack, "4-stopped")

    # The page kept up with the daemon's state rate.
    metrics = page.evaluate("""() => {
        const a = spacearm.arrivals.slice(-100), l = spacearm.latencies.slice(-200).sort((x, y) => x - y);
        return {rate: (a.length - 1) / (a[a.length - 1] - a[0]), median: l[l.length >> 1], n: spacearm.updates};
    }""")
    # The page followed the daemon (it kept receiving states); how fast is a figure of this
    # machine's load (Chromium runs at normal priority beside the CPU hogs: median latency
    # 117 ms at load 18), reported here and measured by bench/bench_web.py, not asserted.
    assert metrics["n"] > 100 and metrics["rate"] > 0, metrics
    assert errors == []
    figures = report_load(web_stack, record_property)
    for key in ("rate", "median"):
        record_property(f"page_{key}", metrics[key])
    print(f"page: {metrics['rate']:.1f} states/s (daemon {1 / stopped['period']:.0f}/s), median latency "
          f"{1e3 * metrics['median']:.0f} ms at load {figures['load']}")


def test_web_console_refuses_foreign_pages_and_lease_smuggling(patient_web_stack, browser):
    web_stack = patient_web_stack
    url = web_stack["url"]
    request = urllib.request.Request(url + "api/info", headers={"Origin": "http://evil.example"})
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(request, timeout=5)
    assert refused.value.code == 403
    with urllib.request.urlopen(url + "api/info", timeout=5) as answer:
        assert json.load(answer)["daemon"] == web_stack["api"]

    page = browser.new_page()
    page.goto(url)
    wait_for(page, "() => spacearm.updates > 5")
    # A command outside the console's set is refused by the server; a lease in the page's
    # arguments is dropped (the page never holds one), so without control nothing moves.
    reply = page.evaluate("() => send('command', 'record.start', {path: '/tmp/x.mcap'})")
    assert not reply["ok"] and "unknown command" in reply["error"]
    reply = page.evaluate("() => send('command', 'enable', {lease: 'forged'})")
    # The server used the operator's own lease, as `spacearm enable` would.
    assert reply["ok"], reply
    reply = page.evaluate("() => send('command', 'jog', {joint: 9, delta: 0.1})")
    assert not reply["ok"] and "not a joint" in reply["error"]       # the daemon validates


def test_presimulation_uses_the_daemons_planner_and_checks():
    """No browser: the checks the page shows, from the same planner and limits as the daemon."""
    import numpy as np

    from spacearm.console.web.presim import Presimulator
    from spacearm.base.config.arm import load_arm_config
    from spacearm.base.kinematics.model import KinematicModel

    model = KinematicModel.from_config(load_arm_config("configs/arm/oru_testbed_6dof.toml"))
    presim = Presimulator(model, 0.02)
    q = [-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
         -0.22888135613941607, 1.2827321288823015]          # the arm's "ready" posture
    idle = {"state": "enabled", "mode": "hold", "progress": 1.0,
            "joints": [{"q": v, "q_cmd": v} for v in q]}

    ok = presim.run("jog", {"joint": 2, "delta": 0.1}, idle)
    assert ok.accepted and ok.reason is None
    assert ok.q[0] == pytest.approx(q, abs=1e-6) and ok.q[-1][1] == pytest.approx(q[1] + 0.1, abs=1e-6)
    assert len(ok.frames) == len(ok.times) and len(ok.frames[0]) == model.nq + 2

    beyond = presim.run("move_joints", {"q": [4.0, *q[1:]]}, idle)
    assert not beyond.accepted and "outside its limits" in beyond.reason and beyond.frames == []

    far = presim.run("move_pose", {"xyz": [3.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]}, idle)
    assert not far.accepted and "reach" in far.reason
    assert [c.name for c in far.checks if not c.ok] == ["reachability"]

    step = presim.run("move_pose", {"xyz": [0.0, 0.0, 0.02], "rpy": [0.0, 0.0, 0.0], "frame": "tool"}, idle)
    assert step.accepted, step.reason
    tool = np.array(step.frames[-1][-1]).reshape(4, 4)
    start = np.array(step.frames[0][-1]).reshape(4, 4)
    assert np.linalg.norm(tool[:3, 3] - (start[:3, 3] + 0.02 * start[:3, 2])) < 1e-4   # 20 mm along tool z

    stopped = presim.run("jog", {"joint": 1, "delta": 0.1}, {**idle, "state": "stopped", "stop_reason": "x"})
    assert not stopped.accepted and "reset first" in stopped.reason and stopped.frames   # ghost still shown

    bad = presim.run("jog", {"joint": "1", "delta": 0.1}, idle)
    assert not bad.accepted and bad.checks[0].name == "arguments"
    assert not presim.run("record.start", {}, idle).accepted


READY = [-0.28806419791259463, 1.5707963267948966, -3.294079780986511, 1.9521648103310305,
         -0.22888135613941607, 1.2827321288823015]     # configs/arm/oru_testbed_6dof.toml [postures]


# ---- what the screen shows -------------------------------------------------------------------
# The 3-D view's pixels as Chromium composited them (a screenshot, not the canvas's own
# buffer): the arm's links are a light grey (0xd8d8d0 lit), the ghost a translucent blue
# (0x4f8fff); the background, the grid, the stores (blue-grey) and the ORUs (gold) are neither.

def view_pixels(page):
    """The 3-D view's region of a screenshot, as an (h, w, 3) RGB array."""
    import cv2
    import numpy as np
    box = page.locator("#viewport").bounding_box()
    png = page.screenshot(clip=box)
    bgr = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    return bgr[:, :, ::-1].astype(int)


def arm_mask(rgb):
    """Light, unsaturated pixels: the measured arm's links (and the markers' white dots)."""
    return (rgb.min(axis=2) > 90) & (rgb.max(axis=2) - rgb.min(axis=2) < 24)


def ghost_mask(rgb):
    """Clearly blue pixels: the presimulated ghost (and the two z axes' lines)."""
    return (rgb[:, :, 2] > 70) & (rgb[:, :, 2] > rgb[:, :, 0] + 40)


def colours(rgb) -> int:
    import numpy as np
    return len(np.unique(rgb.reshape(-1, 3) // 8, axis=0))


def assert_arm_drawn(page, stack, name: str):
    """Screenshot the view and check it shows the arm; returns the arm's pixel mask."""
    rgb = view_pixels(page)
    import cv2
    cv2.imwrite(str(stack["artifacts"] / f"view-{name}.png"), rgb[:, :, ::-1].astype("uint8"))
    mask = arm_mask(rgb)
    h, w = mask.shape
    # At least ~0.2 % of the view (a link 300 px long and 10 wide is 3000 px of 900 x 750).
    assert mask.sum() > 0.002 * h * w, (f"{name}: the 3-D view shows no arm ({mask.sum()} arm-coloured px of "
                                        f"{h}x{w}, {colours(rgb)} colours); see view-{name}.png")
    assert colours(rgb) > 20, f"{name}: the 3-D view is (nearly) one flat colour"
    return mask


def chromium_cpu() -> dict[str, float]:
    """CPU time (s) used so far by this test's Chromium processes, by kind: renderer, gpu,
    other helpers and the browser process (Chromium runs below this process: Playwright's driver)."""
    ticks = os.sysconf("SC_CLK_TCK")
    children: dict[int, list] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append((int(entry), cmdline, (int(fields[11]) + int(fields[12])) / ticks))
    usage: dict[str, float] = {}
    todo = [os.getpid()]
    while todo:
        for pid, cmdline, cpu in children.get(todo.pop(), []):
            todo.append(pid)
            if "chrom" not in cmdline.split(" ", 1)[0]:
                continue
            kind = re.search(r"--type=(\S+)", cmdline)
            kind = "browser" if kind is None else kind.group(1) if kind.group(1) in ("renderer", "gpu-process") else "other"
            usage[kind] = usage.get(kind, 0.0) + cpu
    return usage


IDLE_CPU_LIMIT = 0.05     # of one core, the renderer, with nothing moving (issue 33)


@pytest.mark.timeout(900)   # ~4 min at load 19 on 2 cores (the suite's default is 300 s)
def test_the_3d_view_shows_the_arm_at_two_sizes_moving_stopped_and_its_ghost(patient_web_stack, browser, record_property):
    """The pixels the operator sees: the arm in the 3-D view at two window sizes, after a
    resize, while still (and the page's idle CPU), with the ghost of a presimulated move,
    while moving and after. Fails on a page whose canvas feeds back into its layout (it grew
    out of the window: a black view) or that redraws with nothing moving."""
    web_stack = patient_web_stack
    page, errors = open_page(web_stack, browser)         # 1500 x 950
    wait_for(page, "() => spacearm.updates > 3 && spacearm.scene && spacearm.scene.armFrames")
    time.sleep(1.0)
    assert_arm_drawn(page, web_stack, "1-large")

    page.set_viewport_size({"width": 1000, "height": 650})
    time.sleep(1.0)
    small = assert_arm_drawn(page, web_stack, "2-small")
    # The canvas fills its container and stays that size (no layout feedback), inside the window.
    size = "() => { const c = spacearm.scene.renderer.domElement, v = spacearm.scene.container; " \
           "return [c.clientWidth, c.clientHeight, c.width, c.height, v.clientWidth, v.clientHeight, " \
           "v.getBoundingClientRect().bottom]; }"
    before = page.evaluate(size)
    drawn, resized = page.evaluate("() => [spacearm.scene.frameCount, spacearm.scene.resizes]")

    # Nothing moving for a while: no redraw of the 3-D view, and the page's renderer is idle.
    cpu0, t0 = chromium_cpu(), time.monotonic()
    time.sleep(10.0)
    cpu1, t1 = chromium_cpu(), time.monotonic()
    idle = {kind: (cpu1.get(kind, 0.0) - cpu0.get(kind, 0.0)) / (t1 - t0) for kind in cpu1}
    after = page.evaluate(size)
    # (A banner coming or going, "NODES LATE" on a loaded machine, may resize the view; but
    # never beyond the window, and the canvas always matches its container.)
    for sizes in (before, after):
        assert sizes[0] == sizes[2] == sizes[4] and sizes[1] == sizes[3] == sizes[5] and sizes[6] <= 650, sizes
    redraws, resizes = page.evaluate(f"() => [spacearm.scene.frameCount - {drawn}, spacearm.scene.resizes - {resized}]")
    print(f"idle page: CPU of a core {', '.join(f'{k} {100 * v:.1f} %' for k, v in sorted(idle.items()))}; "
          f"{redraws} redraws of the 3-D view in {t1 - t0:.1f} s ({resizes} resizes); load {os.getloadavg()[0]:.1f}")
    for kind, value in idle.items():
        record_property(f"idle_cpu_{kind}", round(value, 4))
    assert redraws <= resizes, f"the 3-D view redrew {redraws} times with nothing moving ({resizes} resizes)"
    assert idle.get("renderer", 0.0) <= IDLE_CPU_LIMIT, f"idle page renderer CPU {100 * idle['renderer']:.1f} % of a core"

    page.set_viewport_size({"width": 1400, "height": 900})
    time.sleep(1.0)
    assert_arm_drawn(page, web_stack, "3-resized-back")

    # The ghost of a presimulated move shows over the arm; then the arm moves and comes to rest.
    page.click("#btn-take")
    wait_for(page, "() => document.getElementById('cmd-result').textContent.includes('taken')")
    enable(page, web_stack)
    blue_before = ghost_mask(view_pixels(page)).sum()
    # The point-to-point form starts at the arm file's ready posture (Cartesian work possible),
    # with a preset button per named posture.
    page.check("input[value=move_joints]")
    q_inputs = "() => [...document.querySelectorAll('.q-input')].map(e => parseFloat(e.value))"
    assert page.evaluate(q_inputs) == pytest.approx([math.degrees(q) for q in READY], abs=1e-3)
    assert page.locator("button.posture").all_text_contents() == ["home", "ready"]
    page.click("button.posture[data-posture=home]")
    assert page.evaluate(q_inputs) == pytest.approx([0.0, 90.0, -90.0, 0.0, -90.0, 0.0], abs=1e-3)
    page.click("button.posture[data-posture=ready]")
    page.fill("#speed", "0.3")                        # a move long enough to be seen under way
    presimulate_accepted(page)
    time.sleep(5.0)                                   # the ghost has played its motion (<= 4 s) and rests at the goal
    ghost = view_pixels(page)
    blue = ghost_mask(ghost).sum()
    assert blue > blue_before + 300, f"no ghost in the 3-D view: {blue_before} -> {blue} blue px"
    still = assert_arm_drawn(page, web_stack, "4-ghost")
    page.click("#btn-send")
    wait_for(page, "() => spacearm.lastStatus.mode === 'move_joints' && spacearm.lastStatus.progress > 0.2 "
                   "|| spacearm.lastStatus.state === 'stopped'")
    moving = assert_arm_drawn(page, web_stack, "5-moving")
    wait_for(page, "() => spacearm.lastStatus.progress >= 1 && spacearm.lastStatus.mode !== 'move_joints' "
                   "|| spacearm.lastStatus.state === 'stopped'", timeout=60)
    assert status(page)["state"] == "enabled", f"stopped during the move: {stop_text(page)}"
    time.sleep(1.0)
    rest = assert_arm_drawn(page, web_stack, "6-at-ready")
    # The ghost of the move went with the move: left at the goal it would tint the arm blue.
    blue_rest = ghost_mask(view_pixels(page)).sum()
    assert blue_rest < blue_before + 300, f"the ghost outlived its move: {blue_before} -> {blue_rest} blue px"
    # The state at a glance: the tool pose in mm and deg, each joint's distance to its limits.
    wait_for(page, "() => document.getElementById('tool-pose').textContent.includes('mm')")
    glance = page.evaluate("() => ({tool: spacearm.lastStatus.tool, text: document.getElementById('tool-pose').textContent, "
                           "limits: [...document.querySelectorAll('#joints td.limit')].map(td => td.textContent.trim())})")
    assert f"x {1e3 * glance['tool']['xyz'][0]:.1f}" in glance["text"], glance
    assert len(glance["limits"]) == 6 and all(t.endswith(("min", "max")) for t in glance["limits"]), glance
    # What the screen shows moved: the arm's pixels differ between still, moving and at rest.
    def changed(a, b):            # (a banner coming or going shifts the view by a few px)
        h, w = min(a.shape[0], b.shape[0]), min(a.shape[1], b.shape[1])
        return (a[:h, :w] ^ b[:h, :w]).sum()
    assert changed(still, moving) > 500 and changed(moving, rest) > 500, (changed(still, moving), changed(moving, rest))
    assert small.shape != rest.shape
    assert errors == []
