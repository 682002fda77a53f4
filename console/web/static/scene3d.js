// 3-D scene of the cell with three.js (Debian libjs-three): the measured arm, a ghost arm for
// presimulated motions, the ORU stores, the ORUs and their markers. Kinematics are computed
// by the server (the daemon's model); the page only places meshes at the frames it is sent.
"use strict";

// Render only when something changed, and at most this often: a software-rendered page
// (headless Chromium, remote desktops) must not eat the CPU the control cycle needs.
const MAX_FPS = 15;

function matrixOf(flat) {            // row-major 16 floats -> THREE.Matrix4
  const m = new THREE.Matrix4();
  m.set(...flat);
  return m;
}

class ArmMeshes {
  constructor(scene, nFrames, material, jointMaterial, radius) {
    this.group = new THREE.Group();
    this.links = [];
    this.joints = [];
    const cyl = new THREE.CylinderGeometry(1, 1, 1, 16);
    for (let i = 0; i < nFrames - 1; i++) {
      const link = new THREE.Mesh(cyl, material);
      link.userData.radius = radius;
      this.links.push(link);
      this.group.add(link);
    }
    for (let i = 1; i < nFrames - 1; i++) {       // one drum per joint, along its axis (frame z)
      const drum = new THREE.Mesh(new THREE.CylinderGeometry(radius * 1.5, radius * 1.5, radius * 3.2, 20), jointMaterial);
      drum.matrixAutoUpdate = false;
      this.joints.push(drum);
      this.group.add(drum);
    }
    this.tool = new THREE.Mesh(new THREE.BoxGeometry(0.08, 0.08, 0.04), jointMaterial);
    this.tool.matrixAutoUpdate = false;
    this.group.add(this.tool);
    this.toolAxes = new THREE.AxesHelper(0.12);
    this.toolAxes.matrixAutoUpdate = false;
    this.group.add(this.toolAxes);
    scene.add(this.group);
    this.up = new THREE.Vector3(0, 1, 0);
    this.yToZ = new THREE.Matrix4().makeRotationX(Math.PI / 2);
  }

  update(frames) {
    const p = frames.map(f => new THREE.Vector3(f[3], f[7], f[11]));
    for (let i = 0; i < this.links.length; i++) {
      const link = this.links[i];
      const d = new THREE.Vector3().subVectors(p[i + 1], p[i]);
      const len = d.length();
      link.visible = len > 1e-4;
      if (!link.visible) continue;
      link.position.copy(p[i]).addScaledVector(d, 0.5);
      link.quaternion.setFromUnitVectors(this.up, d.clone().normalize());
      const r = link.userData.radius;
      link.scale.set(r, len, r);
    }
    for (let i = 0; i < this.joints.length; i++) {
      this.joints[i].matrix.copy(matrixOf(frames[i + 1])).multiply(this.yToZ);
    }
    const tool = matrixOf(frames[frames.length - 1]);
    this.tool.matrix.copy(tool).multiply(new THREE.Matrix4().makeTranslation(0, 0, -0.02));
    this.toolAxes.matrix.copy(tool);
  }

  set visible(v) { this.group.visible = v; }
}

class CellScene {
  constructor(container, description) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x0b0e12);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 50);
    this.camera.up.set(0, 0, 1);                 // the arm's base frame is z-up
    this.camera.position.set(2.2, -1.8, 1.4);
    this.controls = new THREE.OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0.3, 0, 0.1);
    this.controls.update();
    this.dirty = true;
    this.lastRender = 0;
    this.controls.addEventListener("change", () => this.requestRender());
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 0.9));
    const sun = new THREE.DirectionalLight(0xffffff, 0.6);
    sun.position.set(2, -3, 4);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(3, 30, 0x335, 0x223);
    grid.rotation.x = Math.PI / 2;
    grid.position.z = -0.5;
    this.scene.add(grid);
    this.scene.add(new THREE.AxesHelper(0.3));
    this.addCell(description);
    const nFrames = description.arm.nq + 2;
    this.arm = new ArmMeshes(this.scene, nFrames,
      new THREE.MeshStandardMaterial({ color: 0xd8d8d0, metalness: 0.3, roughness: 0.5 }),
      new THREE.MeshStandardMaterial({ color: 0x8899aa, metalness: 0.4, roughness: 0.4 }), 0.045);
    const ghostMat = new THREE.MeshStandardMaterial({ color: 0x4f8fff, transparent: true, opacity: 0.35, depthWrite: false });
    this.ghost = new ArmMeshes(this.scene, nFrames, ghostMat, ghostMat, 0.045);
    this.ghost.visible = false;
    this.arm.visible = false;                     // until the first measured state places it
    this.ghostPath = null;
    this.frameCount = 0;
    // Redraw on every size change of the view, not only the window's (a panel reflow resizes
    // the container alone), and whenever the page or the GL context comes back: a resize
    // clears the canvas, and an arm standing still asks for no frame of its own.
    window.addEventListener("resize", () => this.resize());
    if (window.ResizeObserver) new ResizeObserver(() => this.resize()).observe(this.container);
    document.addEventListener("visibilitychange", () => { if (!document.hidden) this.requestRender(); });
    this.renderer.domElement.addEventListener("webglcontextrestored", () => this.requestRender());
    this.resize();
    this.framePending = false;
    this.requestRender();
  }

  // No continuous animation loop: a frame is asked for only when something changed, so an
  // idle page costs nothing (with software WebGL every composited frame costs CPU).
  requestRender() {
    this.dirty = true;
    if (this.framePending) return;
    this.framePending = true;
    const wait = Math.max(0, this.lastRender + 1000 / MAX_FPS - performance.now());
    setTimeout(() => requestAnimationFrame(now => {
      this.framePending = false;
      this.lastRender = now;
      this.dirty = false;
      this.render();
      if (this.ghostPath) this.requestRender();   // the ghost is still playing its motion
    }), wait);
  }

  addCell(d) {
    const storeMat = new THREE.MeshStandardMaterial({ color: 0x6b7b8c, transparent: true, opacity: 0.55 });
    for (const s of d.stores) {
      const g = new THREE.Group();
      g.matrixAutoUpdate = false;
      g.matrix.copy(matrixOf(s.pose));
      const [ix, iy, depth] = s.inner, w = s.wall;
      const parts = [                       // four walls and a floor below the slot opening (z = 0)
        [ix + 2 * w, w, depth, 0, (iy + w) / 2, -depth / 2], [ix + 2 * w, w, depth, 0, -(iy + w) / 2, -depth / 2],
        [w, iy, depth, (ix + w) / 2, 0, -depth / 2], [w, iy, depth, -(ix + w) / 2, 0, -depth / 2],
        [ix + 2 * w, iy + 2 * w, w, 0, 0, -depth - w / 2]];
      for (const [sx, sy, sz, x, y, z] of parts) {
        const box = new THREE.Mesh(new THREE.BoxGeometry(sx, sy, sz), storeMat);
        box.position.set(x, y, z);
        g.add(box);
      }
      g.name = "store:" + s.name;
      this.scene.add(g);
    }
    const oruMat = new THREE.MeshStandardMaterial({ color: 0xc8a050, metalness: 0.5, roughness: 0.4 });
    for (const o of d.orus) {
      const g = new THREE.Group();
      g.matrixAutoUpdate = false;
      g.matrix.copy(matrixOf(o.pose));
      const [sx, sy, h] = o.size, [ax, ay, ah] = o.adapter;
      const body = new THREE.Mesh(new THREE.BoxGeometry(sx, sy, h), oruMat);
      body.position.z = h / 2;
      g.add(body);
      const adapter = new THREE.Mesh(new THREE.BoxGeometry(ax, ay, ah), oruMat);
      adapter.position.z = h + ah / 2;
      g.add(adapter);
      if (d.marker) this.addMarker(g, d.marker, h);
      g.name = "oru:" + o.name;
      this.scene.add(g);
    }
  }

  addMarker(parent, m, top) {
    const plate = new THREE.Mesh(new THREE.BoxGeometry(m.plate_size[0], m.plate_size[1], m.plate_thickness),
      new THREE.MeshStandardMaterial({ color: 0x111111 }));
    plate.position.z = top + m.plate_thickness / 2;
    parent.add(plate);
    const white = new THREE.MeshBasicMaterial({ color: 0xffffff });
    for (const c of m.circles) {
      const dot = new THREE.Mesh(new THREE.CylinderGeometry(m.circle_diameter, m.circle_diameter, 0.001, 16), white);
      dot.rotation.x = Math.PI / 2;
      dot.position.set(c.xyz[0], c.xyz[1], top + m.plate_thickness + c.xyz[2] + 0.0005);
      parent.add(dot);
    }
  }

  resize() {
    const w = this.container.clientWidth, h = this.container.clientHeight;
    if (w === 0 || h === 0) return;           // hidden or collapsed: keep the last size, redraw when it returns
    if (w === this.width && h === this.height) return;
    this.width = w;
    this.height = h;
    this.resizes = (this.resizes || 0) + 1;
    // The drawing buffer follows the container; the canvas's CSS size stays 100 % (style.css),
    // so the size set here never changes the layout it was measured from.
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / Math.max(h, 1);
    this.camera.updateProjectionMatrix();
    if (this.lastRender !== undefined) this.requestRender();
  }

  setArm(frames) {
    const prev = this.armFrames;
    if (prev && prev.length === frames.length && prev.every((f, i) => f.every((v, k) => v === frames[i][k]))) return;
    this.arm.update(frames);
    this.arm.visible = true;
    this.armFrames = frames;
    this.requestRender();
  }

  showGhost(times, frames) {                  // animate the planned motion, then rest at its end
    if (!frames || frames.length === 0) { this.hideGhost(); return; }
    this.ghostPath = { times, frames, start: performance.now() };
    this.ghost.visible = true;
    this.requestRender();
  }

  hideGhost() {                              // called on every status of a stopped arm: a no-op when hidden
    if (!this.ghostPath && !this.ghost.group.visible) return;
    this.ghostPath = null;
    this.ghost.visible = false;
    this.requestRender();
  }

  render() {
    const gp = this.ghostPath;
    if (gp) {
      const duration = gp.times[gp.times.length - 1];
      // play the motion in at most 4 s so long moves stay watchable, then hold the end pose
      const speed = Math.max(1, duration / 4);
      const t = (performance.now() - gp.start) / 1000 * speed;
      let i = gp.times.findIndex(x => x >= t);
      if (i < 0) {                      // played out: rest at the end pose, stop animating
        i = gp.times.length - 1;
        this.ghostPath = null;
      }
      this.ghost.update(gp.frames[i]);
    }
    this.renderer.render(this.scene, this.camera);
    this.frameCount++;
  }
}

window.CellScene = CellScene;
