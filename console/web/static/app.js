// The page: state pushed over one WebSocket, commands and presimulations sent over it.
// It measures its own update latency (cycle -> page) and rate in window.spacearm, which the
// end-to-end test and bench/bench_web.py read.
"use strict";

const DEG = Math.PI / 180;
const $ = id => document.getElementById(id);
const FT_WINDOW = 10;                     // s of force/torque history in the plot

const spacearm = window.spacearm = {
  updates: 0, latencies: [], arrivals: [], lastStatus: null, lastFrames: null,
  presim: null, scene: null, ws: null, replies: new Map(), nextId: 1,
};

function now_mono() { return performance.now() / 1000; }   // s, the page's monotonic clock

// The page's clock against the server's CLOCK_MONOTONIC (the clock of the daemon's `woke_at`),
// NTP-style over the WebSocket: the exchange with the shortest round trip wins. The page's
// wall clock (performance.timeOrigin + now) is no reference: Chromium fixes timeOrigin when the
// page loads and it was seen 2.7 s off the system clock (a latency of -2686.9 ms).
async function syncClock() {
  let best = null;
  for (let i = 0; i < 5; i++) {
    const t0 = performance.now();
    const r = await send("clock");
    const t1 = performance.now();
    if (typeof r.monotonic !== "number") return;
    if (!best || t1 - t0 < best.rtt) best = { rtt: t1 - t0, offset: r.monotonic - (t0 + t1) / 2000 };
  }
  spacearm.clock = best;
}

function send(op, cmd, args) {
  const id = spacearm.nextId++;
  return new Promise(resolve => {
    spacearm.replies.set(id, resolve);
    spacearm.ws.send(JSON.stringify({ op, id, cmd, args: args || {} }));
  });
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  spacearm.ws = ws;
  ws.onopen = () => { setLink(true, "connected"); syncClock(); };
  ws.onclose = () => { setLink(false, "disconnected"); setTimeout(connect, 1000); };
  ws.onmessage = ev => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "state") onState(msg);
    else if (msg.type === "daemon_error") setLink(false, "daemon: " + msg.error);
    else if (msg.id !== undefined && spacearm.replies.has(msg.id)) {
      spacearm.replies.get(msg.id)(msg);
      spacearm.replies.delete(msg.id);
    }
  };
}

function setLink(ok, text) {            // touch the DOM only on a change: each repaint costs CPU
  if (spacearm.link === text) return;
  spacearm.link = text;
  const el = $("link");
  el.textContent = text;
  el.className = "pill " + (ok ? "ok" : "bad");
}

// ---- live state ------------------------------------------------------------------------
const ftHistory = [];

function onState(msg) {
  const arrived = now_mono();
  const s = { ...spacearm.lastStatus, ...msg.status };   // parts left out keep their last value
  spacearm.updates++;
  if (spacearm.clock && typeof msg.status.woke_at === "number") {
    spacearm.latencies.push(arrived + spacearm.clock.offset - msg.status.woke_at);
    if (spacearm.latencies.length > 20000) spacearm.latencies.shift();
  }
  spacearm.arrivals.push(arrived);
  if (spacearm.arrivals.length > 20000) spacearm.arrivals.shift();
  spacearm.lastStatus = s;
  setLink(true, "live");
  if (msg.frames) {
    spacearm.lastFrames = msg.frames;
    if (spacearm.scene) spacearm.scene.setArm(msg.frames);
  }
  if (s.wrench) {
    ftHistory.push([s.time, ...s.wrench]);
    while (ftHistory.length && ftHistory[0][0] < s.time - FT_WINDOW) ftHistory.shift();
  }
  scheduleRender();
}

// Every update is taken in (latency, plot history, arm pose); the tables and the plot are
// redrawn at most 5 times a second and only where a value changed: enough for a person,
// and cheap for a machine that renders the page in software.
const PANEL_INTERVAL = 200;   // ms
let renderPending = false, lastPanels = 0;
function scheduleRender() {
  if (renderPending) return;
  renderPending = true;
  const wait = Math.max(0, lastPanels + PANEL_INTERVAL - performance.now());
  setTimeout(() => requestAnimationFrame(() => {
    renderPending = false;
    lastPanels = performance.now();
    renderStatus(spacearm.lastStatus);
  }), wait);
}

function renderStatus(s) {
  if (!s) return;
  const key = `${s.state}|${s.mode}|${(s.stop || {}).code}`;
  if (key !== spacearm.lastStateKey && spacearm.scene) spacearm.scene.requestRender();   // any state change redraws
  spacearm.lastStateKey = key;
  setText($("state"), s.state);
  setText($("mode"), s.mode || "-");
  setText($("control"), s.control && s.control.held ? s.control.holder : "free");
  const nodes = s.nodes || {}, late = $("nodes-late");   // the simulator/hub/bus answering late
  if (late) {
    late.classList.toggle("hidden", !nodes.level || nodes.level === "ok");
    setText(late, nodes.level && nodes.level !== "ok" ? "NODES LATE: " + nodes.message : "");
  }
  const peers = Object.values(nodes.peers || {}), own = $("peer-timing");   // the simulator's/hub's own reports
  if (own) {
    setText(own, peers.map(p => p.message).join("; "));
    own.classList.toggle("late", peers.some(p => p.level !== "ok"));
  }
  const banner = $("stopreason");
  if (banner.classList.contains("hidden") === !!s.stop_reason) banner.classList.toggle("hidden", !s.stop_reason);
  setText(banner, s.stop_reason ? "PROTECTIVE STOP: " + s.stop_reason + " (reset, then enable)" : "");
  if (s.state === "stopped" && spacearm.scene) spacearm.scene.hideGhost();
  const sent = spacearm.ghostOfSent;       // the ghost of a sent move goes once the move is over:
  if (sent && spacearm.scene) {            // left at the goal it would tint the arm that reached it
    if (s.mode === sent.mode && s.progress < 1) sent.seen = true;
    else if (sent.seen || s.mode === sent.mode || s.state !== "enabled") { spacearm.scene.hideGhost(); spacearm.ghostOfSent = null; }
  }
  const tbody = $("joints").tBodies[0];
  if (tbody.rows.length !== s.joints.length) {
    tbody.innerHTML = s.joints.map(() => "<tr>" + "<td></td>".repeat(6) +
      '<td class="limit"><span></span> <meter min="0" max="1"></meter></td></tr>').join("");
  }
  s.joints.forEach((j, i) => {
    const drive = j.fault ? "FAULT" : j.enabled ? "enabled" : "disabled";
    const cells = [j.name, (j.q / DEG).toFixed(3), (j.q_cmd / DEG).toFixed(3), (j.dq / DEG).toFixed(2),
                   j.tau.toFixed(1), drive];
    cells.forEach((v, k) => setText(tbody.rows[i].cells[k], v));
    if (tbody.rows[i].className !== (j.fault ? "bad" : "")) tbody.rows[i].className = j.fault ? "bad" : "";
    showLimit(tbody.rows[i].cells[6], j);
  });
  setText($("tool-pose"), toolText(s.tool));
  if ($("progress").value !== (s.progress || 0)) $("progress").value = s.progress || 0;
  setText($("progress-text"), s.mode ? `${s.mode} ${(100 * (s.progress || 0)).toFixed(0)} %` : "");
  setText($("task"), s.task ? taskText(s.task) : "");
  const st = s.stats || {};
  const ms = x => (1e3 * (x || 0)).toFixed(2);
  setHtml($("stats"), `cycles ${st.cycles} &middot; period ${(1e3 * s.period).toFixed(1)} ms (${s.clock})<br>` +
    `period error median ${ms(st.period_error_median)} / p99 ${ms(st.period_error_p99)} / max ${ms(st.period_error_max)} ms<br>` +
    `execution median ${ms(st.execution_median)} / p99 ${ms(st.execution_p99)} ms &middot; overruns ${st.overruns} ` +
    `&middot; <span class="pill ${st.level === "ok" ? "ok" : st.level === "warn" ? "warn" : "bad"}">${st.level}</span>`);
  const lat = spacearm.latencies.slice(-250).slice().sort((a, b) => a - b);
  const arr = spacearm.arrivals;
  const rate = arr.length > 50 ? 50 / (arr[arr.length - 1] - arr[arr.length - 51]) : 0;
  setText($("page-stats"), lat.length ?
    `page: ${rate.toFixed(1)} updates/s, latency cycle -> page median ${(1e3 * lat[lat.length >> 1]).toFixed(1)} ms` : "");
  const w = s.wrench || [0, 0, 0, 0, 0, 0];
  setText($("ft-now"), `F ${w.slice(0, 3).map(v => v.toFixed(1)).join(" ")} N \u00b7 T ${w.slice(3).map(v => v.toFixed(2)).join(" ")} N m`);
  drawFt();
  setHtml($("events"), (s.events || []).slice().reverse()
    .map(e => `<li>${e.t.toFixed(2)} s <b>[${esc(e.code || e.kind)}]</b> ${esc(e.message)}</li>`).join(""));
}

// Where a joint stands in its range: the distance to the nearer limit in degrees, and a bar
// over the whole range that turns amber in the outer 10 % and red in the outer 2 %.
function showLimit(cell, j) {
  if (j.q_min === undefined || j.q_max === undefined) return;
  const below = j.q - j.q_min, above = j.q_max - j.q, near = Math.min(below, above);
  setText(cell.firstChild, `${(near / DEG).toFixed(1)} ${below <= above ? "min" : "max"}`);
  const bar = cell.lastChild, span = j.q_max - j.q_min, at = (j.q - j.q_min) / span;
  if (bar.value !== at) bar.value = at;
  const level = near < 0.02 * span ? "bad" : near < 0.1 * span ? "warn" : "";
  if (cell.className !== "limit " + level) cell.className = "limit " + level;
}

function toolText(tool) {               // measured tool pose: m and rad from the daemon, mm and deg here
  if (!tool) return "";
  const [x, y, z] = tool.xyz.map(v => (1000 * v).toFixed(1)), [r, p, w] = tool.rpy.map(v => (v / DEG).toFixed(2));
  return `tool (base frame): x ${x} y ${y} z ${z} mm \u00b7 roll ${r} pitch ${p} yaw ${w} deg`;
}

function taskText(t) {                   // ORU task flow (oru.status): stage, subtask, progress
  if (typeof t !== "object") return String(t);
  const parts = [`ORU task ${t.state}`, t.stage ? `stage ${t.stage} ${t.stage_name || ""}` : null,
    t.subtask ? `subtask ${t.subtask_index + 1}/${t.subtasks}: ${t.title || ""}` : null,
    t.progress !== undefined && t.progress !== null ? `${(100 * t.progress).toFixed(0)} %` : null,
    t.holding ? `holding ${t.holding}` : null, t.failure ? `FAILED: ${t.failure}` : null,
    t.pause ? `PAUSED [${t.pause.code}]: ${t.pause.message}` : null];   // why the flow paused itself
  return parts.filter(Boolean).join(" \u00b7 ");
}

function setText(el, text) { if (el.textContent !== text) el.textContent = text; }
function setHtml(el, html) { if (el._html !== html) { el._html = html; el.innerHTML = html; } }

function esc(text) {
  const d = document.createElement("div");
  d.textContent = text == null ? "" : String(text);
  return d.innerHTML;
}

function drawFt() {
  const c = $("ft"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  if (ftHistory.length < 2) return;
  const t1 = ftHistory[ftHistory.length - 1][0], t0 = t1 - FT_WINDOW;
  const colors = ["#e74c3c", "#2ecc71", "#3498db", "#f39c12", "#9b59b6", "#1abc9c"];
  let fmax = 1, tmax = 0.1;
  for (const r of ftHistory) {
    for (let k = 1; k <= 3; k++) fmax = Math.max(fmax, Math.abs(r[k]));
    for (let k = 4; k <= 6; k++) tmax = Math.max(tmax, Math.abs(r[k]));
  }
  const half = c.height / 2;
  g.strokeStyle = "#333"; g.beginPath(); g.moveTo(0, half / 2); g.lineTo(c.width, half / 2);
  g.moveTo(0, 1.5 * half); g.lineTo(c.width, 1.5 * half); g.stroke();
  for (let k = 1; k <= 6; k++) {
    const top = k <= 3, scale = (top ? fmax : tmax) * 1.1, mid = top ? half / 2 : 1.5 * half;
    g.strokeStyle = colors[k - 1]; g.beginPath();
    ftHistory.forEach((r, i) => {
      const x = (r[0] - t0) / FT_WINDOW * c.width, y = mid - r[k] / scale * (half / 2);
      i ? g.lineTo(x, y) : g.moveTo(x, y);
    });
    g.stroke();
  }
  g.fillStyle = "#99a";
  g.fillText(`fx fy fz  \u00b1${fmax.toFixed(1)} N`, 4, 10);
  g.fillText(`tx ty tz  \u00b1${tmax.toFixed(2)} N m`, 4, half + 10);
}

// ---- commands ----------------------------------------------------------------------------
function kind() { return document.querySelector("input[name=kind]:checked").value; }

function commandArgs() {
  const speed = parseFloat($("speed").value);
  const k = kind();
  if (k === "jog") return { joint: parseInt($("jog-joint").value, 10), delta: parseFloat($("jog-delta").value) * DEG, speed };
  if (k === "move_joints") {
    return { q: [...document.querySelectorAll(".q-input")].map(el => parseFloat(el.value) * DEG), speed };
  }
  const mm = id => parseFloat($(id).value) / 1000, deg = id => parseFloat($(id).value) * DEG;
  return { xyz: [mm("pose-x"), mm("pose-y"), mm("pose-z")], rpy: [deg("pose-roll"), deg("pose-pitch"), deg("pose-yaw")],
           frame: $("pose-frame").value, speed };
}

function showResult(text, error) {
  const el = $("cmd-result");
  el.textContent = text;
  el.className = error ? "error" : "";
}

async function presimulate() {
  const cmd = kind(), args = commandArgs();
  $("btn-send").disabled = true;
  const r = await send("presim", cmd, args);
  spacearm.ghostOfSent = null;
  spacearm.presim = r;
  spacearm.lastPresim = r;
  $("checks").innerHTML = r.checks.map(c => `<li class="${c.ok ? "pass" : "fail"}"><b>${esc(c.name)}</b>: ${esc(c.detail)}</li>`).join("");
  if (r.accepted) {
    spacearm.scene && spacearm.scene.showGhost(r.times, r.frames);
    showResult(`presimulated: ${cmd}, ${r.duration.toFixed(2)} s; check the ghost, then send`, false);
  } else {
    spacearm.scene && (r.frames.length ? spacearm.scene.showGhost(r.times, r.frames) : spacearm.scene.hideGhost());
    showResult("rejected: " + r.reason, true);
  }
  $("btn-send").disabled = !r.accepted;
  $("btn-replay").disabled = !r.frames.length;
  return r;
}

async function sendPresimulated() {
  const p = spacearm.presim;
  if (!p || !p.accepted) return;
  $("btn-send").disabled = true;
  const r = await send("command", p.cmd, p.args);
  if (r.ok) {
    showResult(`sent: ${r.result.mode} started (${r.result.duration.toFixed(2)} s)`, false);
    spacearm.ghostOfSent = { mode: r.result.mode, seen: false };
    if (p.cmd === "jog") keepAliveWhileJogging();
  } else {
    showResult("refused by the daemon: " + r.error, true);
  }
  spacearm.presim = null;
  return r;
}

function keepAliveWhileJogging() {      // a jog is a dead-man command: the page must be heard
  const timer = setInterval(() => {
    const s = spacearm.lastStatus;
    if (!s || s.mode !== "jog" || s.state !== "enabled" || s.progress >= 1) { clearInterval(timer); return; }
    spacearm.ws.send(JSON.stringify({ op: "keepalive" }));
  }, 200);
}

async function simple(cmd) {
  const r = await send("command", cmd, {});
  showResult(r.ok ? `${cmd}: ${JSON.stringify(r.result)}` : `${cmd} refused: ${r.error}`, !r.ok);
  return r;
}

function invalidatePresim() {           // edited values: the old presimulation no longer applies
  spacearm.presim = null;
  $("btn-send").disabled = true;
}

function setupForms(desc) {
  const n = desc.arm.nq;
  // The point-to-point form starts at the arm file's "ready" posture (where Cartesian work is
  // possible), with one preset button per named posture (`move joints NAME` at the terminal).
  const postures = desc.postures || {};
  const start = postures.ready || postures.home || desc.arm.joint_names.map(() => 0);
  $("joint-inputs").innerHTML = desc.arm.joint_names.map((name, i) =>
    `<input class="q-input" type="number" step="1" value="${(start[i] / DEG).toFixed(3)}" title="${esc(name)}">`).join(" ");
  $("posture-buttons").innerHTML = Object.keys(postures).map(p =>
    `<button class="small posture" data-posture="${esc(p)}" title="Fill in the ${esc(p)} posture">${esc(p)}</button>`).join(" ");
  document.querySelectorAll("button.posture").forEach(b => b.onclick = () => {
    const q = postures[b.dataset.posture];
    document.querySelectorAll(".q-input").forEach((el, i) => { el.value = (q[i] / DEG).toFixed(3); });
    invalidatePresim();
  });
  $("jog-joint").max = n;
  document.querySelectorAll("input[name=kind]").forEach(el => el.addEventListener("change", () => {
    for (const k of ["jog", "move_joints", "move_pose"]) $("form-" + k).classList.toggle("hidden", k !== kind());
    invalidatePresim();
  }));
  document.querySelectorAll("#command-panel input, #command-panel select").forEach(el =>
    el.addEventListener("input", invalidatePresim));
  $("btn-copy-q").onclick = () => {
    const s = spacearm.lastStatus;
    if (s) document.querySelectorAll(".q-input").forEach((el, i) => { el.value = (s.joints[i].q / DEG).toFixed(3); });
    invalidatePresim();
  };
  $("btn-copy-pose").onclick = () => {
    const f = spacearm.lastFrames;
    if (!f) return;
    const T = f[f.length - 1];
    const yaw = Math.atan2(T[4], T[0]), pitch = Math.asin(-Math.max(-1, Math.min(1, T[8]))), roll = Math.atan2(T[9], T[10]);
    $("pose-frame").value = "base";
    [["pose-x", T[3] * 1000], ["pose-y", T[7] * 1000], ["pose-z", T[11] * 1000],
     ["pose-roll", roll / DEG], ["pose-pitch", pitch / DEG], ["pose-yaw", yaw / DEG]]
      .forEach(([id, v]) => { $(id).value = v.toFixed(2); });
    invalidatePresim();
  };
  $("btn-presim").onclick = presimulate;
  $("btn-send").onclick = sendPresimulated;
  $("btn-replay").onclick = () => { const p = spacearm.lastPresim; if (p) spacearm.scene.showGhost(p.times, p.frames); };
  $("btn-stop").onclick = () => simple("stop");
  $("btn-reset").onclick = () => simple("reset");
  $("btn-enable").onclick = () => simple("enable");
  $("btn-disable").onclick = () => simple("disable");
  $("btn-take").onclick = () => simple("control.take");
  $("btn-release").onclick = () => simple("control.release");
}

function setupCamera(camera) {
  if (!camera) return;                     // the "no camera" panel stays
  const img = new Image();
  img.alt = "eye-in-hand camera";
  // Until the first frame has decoded (in lockstep the camera renders only during the
  // approaches) the panel says so; an <img> without a picture shows a broken-image icon.
  $("camera").innerHTML = '<div class="nocam">waiting for the first camera frame</div>';
  // Each new frame shown: [page s, camera frame number, the ORU task line at the time, its
  // decoded width in px] (what the operator saw during which subtask; the web HIL test reads
  // it). Counted once decoded: a frame replaced before it loaded was never on the screen.
  spacearm.cameraFrames = [];
  const shown = (seq, width) => {
    const f = spacearm.cameraFrames, last = f[f.length - 1];
    if (last && last[1] === seq) return;
    if (img.parentNode !== $("camera")) { $("camera").innerHTML = ""; $("camera").appendChild(img); }
    f.push([performance.now() / 1000, seq, $("task").textContent, width]);
    if (f.length > 5000) f.shift();
  };
  let previous = null, latest = -1;
  const next = async () => {
    try {
      // `after`: the server answers 204 while the camera has no newer frame (a still camera
      // costs the page no decode)
      const r = await fetch(`/api/camera.png?after=${latest}&t=${Date.now()}`, { cache: "no-store" });
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      if (r.status === 204) { setTimeout(next, 200); return; }
      const seq = parseInt(r.headers.get("X-Frame-Seq") || "0", 10);
      latest = seq;
      const url = URL.createObjectURL(await r.blob());
      img.onload = () => shown(seq, img.naturalWidth);
      img.src = url;
      if (previous) URL.revokeObjectURL(previous);   // shown or abandoned: either way done with
      previous = url;
      setTimeout(next, 200);
    } catch (err) {
      setTimeout(next, 1000);
    }
  };
  next();
}

async function main() {
  const desc = await (await fetch("/api/scene")).json();
  setupForms(desc);
  $("scene-info").textContent = `${desc.arm.name} \u00b7 scene ${desc.scene}`;
  if (window.THREE) {
    try {
      spacearm.scene = new CellScene($("viewport"), desc);
    } catch (err) {
      $("viewer-error").textContent = "3-D view unavailable: " + err;
      $("viewer-error").classList.remove("hidden");
    }
  } else {
    $("viewer-error").textContent = "three.js missing: run scripts/bootstrap.sh (Debian libjs-three)";
    $("viewer-error").classList.remove("hidden");
  }
  setupCamera(desc.camera);
  connect();
}

main();
