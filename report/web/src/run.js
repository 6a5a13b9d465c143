// The run report's viewer (report.html of `avp run` / `avp live`, docs/report.md). Bundled with
// three.js at build time (esbuild) and inlined in the page by report::WriteRunReportHtml, next to
// the episode's data (<script type="application/json" id="avp-report-data">, format
// "avp-run-report" version 1: report/src/run_html.cpp).
//
// It shows the map as voxels (coloured by class, instance or confidence), the ground-truth fruit
// (wire spheres: green found, cyan missed: red is the fruit class's colour), every fused view's camera frustum numbered in order,
// and a step slider: the map as the planner saw it after that view, the frustums so far, that
// view's masks and the candidates the planner ranked (coloured by utility, the chosen one
// highlighted), and the F1 / fruits-found curves.
//
// Page API (the contract the browser test and selftest.js use):
//   window.avpReport = {ready, error, steps, step, setStep(k), setColorBy(mode), canvas,
//                       drawn: {voxels, frustums, fruitFound, fruitMissed, candidates},
//                       expected: {voxels, frustums}}
import "./selftest.js";
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { linePlot } from "./plot.js";
import { decodeVoxels, VoxelState, classColor, instanceColor, confidenceColor, utilityColor }
  from "./run_data.js";

const api = {
  ready: false,
  error: null,
  steps: 0,
  step: -1,
  colorBy: "class",
  canvas: null,
  drawn: { voxels: 0, frustums: 0, fruitFound: 0, fruitMissed: 0, candidates: 0 },
  expected: { voxels: 0, frustums: 0 },
  setStep: () => {},
  setColorBy: () => {},
};
window.avpReport = api;

const CSS = `
body { margin: 0; font: 13px/1.35 system-ui, sans-serif; color: #222; background: #fafafa; }
#avp-report { display: grid; grid-template-columns: minmax(0, 1fr) 400px; grid-template-rows: auto
  minmax(420px, 62vh) auto; gap: 8px; padding: 8px; }
#avp-head { grid-column: 1 / 3; }
#avp-head h1 { font-size: 17px; margin: 0 0 4px 0; }
#avp-head .facts span { margin-right: 14px; color: #555; }
#avp-head .facts b { color: #222; font-weight: 600; }
#avp-view { position: relative; background: #fff; border: 1px solid #ddd; min-height: 300px; }
#avp-view canvas { display: block; width: 100%; height: 100%; }
#avp-legend { position: absolute; left: 8px; bottom: 6px; background: rgba(255,255,255,.85);
  padding: 4px 6px; border-radius: 4px; font-size: 12px; }
#avp-legend i { display: inline-block; width: 10px; height: 10px; margin: 0 4px 0 8px;
  vertical-align: -1px; }
#avp-side { overflow: auto; background: #fff; border: 1px solid #ddd; padding: 8px; }
#avp-side h2, #avp-bottom h2 { font-size: 14px; margin: 10px 0 4px 0; }
#avp-controls label { margin-right: 10px; white-space: nowrap; }
#avp-slider { width: 100%; }
#avp-masks img { width: 100%; image-rendering: auto; border: 1px solid #ccc; }
table.avp { border-collapse: collapse; width: 100%; font-size: 12px; }
table.avp td, table.avp th { padding: 1px 4px; text-align: right; border-bottom: 1px solid #eee; }
table.avp td:first-child, table.avp th:first-child { text-align: left; }
table.avp tr.chosen { background: #ffe6f7; font-weight: 600; }
#avp-bottom { grid-column: 1 / 3; background: #fff; border: 1px solid #ddd; padding: 8px;
  display: flex; flex-wrap: wrap; gap: 16px; }
#avp-bottom > div { flex: 1 1 560px; min-width: 0; }
#avp-bottom svg { max-width: 100%; height: auto; }
@media (max-width: 1000px) {
  #avp-report { grid-template-columns: minmax(0, 1fr); grid-template-rows: auto minmax(360px, 60vh)
    auto auto; }
  #avp-head, #avp-bottom { grid-column: 1; }
}
.avp-error { color: #b00; font-weight: 600; }
.avp-muted { color: #777; }
`;

function h(tag, attrs = {}, parent = null, text = null) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== null) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}

function fmt(v, digits = 3) {
  if (typeof v !== "number" || !Number.isFinite(v)) return "–";
  if (Number.isInteger(v)) return String(v);
  return String(Number(v.toPrecision(digits)));
}

/** A sprite with `text` drawn on a canvas (the frustums' numbers), `size` metres tall. */
function textSprite(text, color, size) {
  const c = document.createElement("canvas");
  c.width = 64;
  c.height = 64;
  const ctx = c.getContext("2d");
  ctx.fillStyle = "rgba(255,255,255,0.85)";
  ctx.beginPath();
  ctx.arc(32, 32, 28, 0, Math.PI * 2);
  ctx.fill();
  ctx.fillStyle = color;
  ctx.font = "bold 38px sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(text, 32, 34);
  const tex = new THREE.CanvasTexture(c);
  tex.colorSpace = THREE.SRGBColorSpace;
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: tex, depthTest: false }));
  sprite.scale.set(size, size, 1);
  sprite.renderOrder = 10;
  return sprite;
}

/** The 4x4 matrix of a row-major 3x4 X_WC. */
function poseMatrix(a) {
  const m = new THREE.Matrix4();
  m.set(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11], 0, 0, 0, 1);
  return m;
}

/** A frustum's lines (camera optical frame: x right, y down, z forward) to depth `d`. */
function frustumGeometry(K, d) {
  const w = K ? K.width : 640;
  const hgt = K ? K.height : 480;
  const fx = K ? K.fx : 554;
  const fy = K ? K.fy : 554;
  const cx = K ? K.cx : (w - 1) / 2;
  const cy = K ? K.cy : (hgt - 1) / 2;
  const corner = (u, v) => [((u - cx) / fx) * d, ((v - cy) / fy) * d, d];
  const c = [corner(0, 0), corner(w, 0), corner(w, hgt), corner(0, hgt)];
  const p = [];
  for (let i = 0; i < 4; i++) {
    p.push(0, 0, 0, ...c[i]);
    p.push(...c[i], ...c[(i + 1) % 4]);
  }
  // The image's top edge (a small tick up, -y) shows which way is up.
  const up = [(c[0][0] + c[1][0]) / 2, c[0][1] - 0.15 * Math.abs(c[2][1] - c[0][1]), d];
  p.push(...c[0], ...up, ...up, ...c[1]);
  const g = new THREE.BufferGeometry();
  g.setAttribute("position", new THREE.Float32BufferAttribute(p, 3));
  return g;
}

function build(data) {
  const style = document.createElement("style");
  style.textContent = CSS;
  document.head.appendChild(style);
  const root = document.getElementById("avp-report") || h("div", { id: "avp-report" },
    document.body);
  root.textContent = "";

  // ---- Header -------------------------------------------------------------------------------
  const head = h("div", { id: "avp-head" }, root);
  h("h1", {}, head, data.title || "avp run");
  const facts = h("div", { class: "facts" }, head);
  for (const [k, v] of data.facts || []) {
    const s = h("span", {}, facts, `${k}: `);
    h("b", {}, s, v);
  }

  // ---- 3D view ------------------------------------------------------------------------------
  const view = h("div", { id: "avp-view" }, root);
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
  renderer.setClearColor(0xffffff, 1);
  view.appendChild(renderer.domElement);
  api.canvas = renderer.domElement;
  const legend = h("div", { id: "avp-legend" }, view);

  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(45, 1, 0.005, 50);
  camera.up.set(0, 0, 1);  // the robot base frame: z up
  scene.add(new THREE.HemisphereLight(0xffffff, 0x888888, 2.0));
  const sun = new THREE.DirectionalLight(0xffffff, 1.5);
  sun.position.set(1, -1.5, 2);
  scene.add(sun);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;

  const vs = data.voxel_size_m;
  const origin = data.origin_key;
  const steps = data.steps;
  const decoded = steps.map((s) => decodeVoxels(s.voxels));
  const state = new VoxelState(decoded);
  let capacity = 1;
  for (const s of steps) capacity = Math.max(capacity, s.voxels.occupied || 0);

  // Voxels: one instanced cube each.
  const cube = new THREE.BoxGeometry(vs * 0.92, vs * 0.92, vs * 0.92);
  const voxelMaterial = new THREE.MeshLambertMaterial({ color: 0xffffff });
  const voxels = new THREE.InstancedMesh(cube, voxelMaterial, capacity);
  voxels.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
  voxels.setColorAt(0, new THREE.Color(1, 1, 1));
  voxels.count = 0;
  voxels.frustumCulled = false;
  scene.add(voxels);

  // Bounds of everything the map ever holds (for the camera) and the scale of markers.
  const box = new THREE.Box3();
  const keyCenter = (dx, dy, dz, out) =>
    out.set((origin[0] + dx + 0.5) * vs, (origin[1] + dy + 0.5) * vs, (origin[2] + dz + 0.5) * vs);
  {
    const p = new THREE.Vector3();
    for (const d of decoded) {
      for (let i = 0; i < d.set; i++) box.expandByPoint(keyCenter(d.sx[i], d.sy[i], d.sz[i], p));
    }
  }

  // Ground-truth fruit.
  const fruits = Array.isArray(data.fruits) ? data.fruits : [];
  const fruitGroup = new THREE.Group();
  let found = 0;
  let missed = 0;
  for (const f of fruits) {
    if (!Array.isArray(f.center_m) || !(f.radius_m > 0)) continue;
    const g = new THREE.WireframeGeometry(new THREE.SphereGeometry(f.radius_m, 14, 10));
    // Drawn through the leaves (no depth test): a missed fruit is usually a hidden one.
    const line = new THREE.LineSegments(g, new THREE.LineBasicMaterial({
      color: f.found ? 0x12a012 : 0x00b7c7, transparent: true, opacity: 0.7, depthTest: false }));
    line.renderOrder = 5;
    line.position.set(...f.center_m);
    line.userData = f;
    fruitGroup.add(line);
    box.expandByPoint(new THREE.Vector3(...f.center_m));
    if (f.found) found++;
    else missed++;
  }
  scene.add(fruitGroup);

  const size = box.isEmpty() ? 0.5 : Math.max(0.05, box.getSize(new THREE.Vector3()).length());
  const labelSize = Math.max(0.015, size * 0.035);

  // Frustums, numbered in view order, and the path between the views.
  const frustumGroup = new THREE.Group();
  const frustums = [];
  const eyes = [];
  const labelSpots = [];  // where the numbers are, so that two close views' numbers do not overlap
  steps.forEach((s, k) => {
    const cam = s.camera || {};
    const X = poseMatrix(cam.X_WC);
    const K = cam.K;
    let d = Number.isFinite(cam.median_depth_m) ? cam.median_depth_m : size * 0.3;
    d = Math.min(Math.max(d * 0.6, 0.03), Math.max(0.05, size * 0.6));
    const lines = new THREE.LineSegments(frustumGeometry(K, d),
      new THREE.LineBasicMaterial({ color: 0x3060c0 }));
    lines.applyMatrix4(X);
    const label = textSprite(String(k + 1), "#1a3f8a", labelSize);
    const eye = new THREE.Vector3().setFromMatrixPosition(X);
    // A view whose number would cover an earlier one's gets it raised above that one.
    const spot = eye.clone();
    for (let tries = 0; tries < 16 && labelSpots.some((p) => p.distanceTo(spot) < labelSize * 1.2);
      ++tries) {
      spot.z += labelSize * 1.2;
    }
    labelSpots.push(spot);
    label.position.copy(spot);
    const g = new THREE.Group();
    g.add(lines);
    g.add(label);
    frustumGroup.add(g);
    frustums.push({ group: g, lines });
    eyes.push(eye);
    box.expandByPoint(eye);
  });
  scene.add(frustumGroup);
  const pathGeometry = new THREE.BufferGeometry().setFromPoints(eyes);
  const path = new THREE.Line(pathGeometry, new THREE.LineDashedMaterial({
    color: 0x3060c0, dashSize: labelSize * 0.5, gapSize: labelSize * 0.4 }));
  path.computeLineDistances();
  scene.add(path);
  // The camera's planned paths between the views (docs/motion.md), in place of the dashed
  // straight one where the run has them: teal, red with a count where a move touched something.
  let planned = 0;
  steps.forEach((s) => {
    const m = s.motion;
    if (!m || !m.path || m.path.length < 6) return;
    const pts = [];
    for (let i = 0; i + 2 < m.path.length; i += 3) {
      pts.push(new THREE.Vector3(m.path[i], m.path[i + 1], m.path[i + 2]));
    }
    const touched = m.contacts > 0;
    scene.add(new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts),
      new THREE.LineBasicMaterial({ color: touched ? 0xe02020 : 0x1090a0 })));
    if (touched) {
      const mark = textSprite(`${m.contacts} contact${m.contacts > 1 ? "s" : ""}`, "#c01010",
        labelSize * 0.8);
      mark.position.copy(pts[Math.floor(pts.length / 2)]);
      scene.add(mark);
    }
    ++planned;
  });
  path.visible = planned === 0;

  // Candidates of the current step: small spheres coloured by utility; the chosen one larger,
  // magenta, with its viewing direction.
  const candRadius = labelSize * 0.18;
  const candMaxCount = Math.max(1, ...steps.map((s) => (s.plan ? s.plan.kept : 0)));
  const candidates = new THREE.InstancedMesh(new THREE.SphereGeometry(candRadius, 8, 6),
    new THREE.MeshBasicMaterial({ color: 0xffffff }), candMaxCount);
  candidates.setColorAt(0, new THREE.Color(1, 1, 1));
  candidates.count = 0;
  candidates.frustumCulled = false;
  scene.add(candidates);
  const chosen = new THREE.Group();
  const chosenBall = new THREE.Mesh(new THREE.SphereGeometry(candRadius * 2.2, 16, 12),
    new THREE.MeshBasicMaterial({ color: 0xe000b0, wireframe: true }));
  chosen.add(chosenBall);
  const chosenDir = new THREE.ArrowHelper(new THREE.Vector3(1, 0, 0), new THREE.Vector3(),
    labelSize * 2.5, 0xe000b0, labelSize * 0.6, labelSize * 0.35);
  chosen.add(chosenDir);
  chosen.visible = false;
  scene.add(chosen);

  // Camera: look at the map's (and the views') bounds from the first view's side.
  const center = box.isEmpty() ? new THREE.Vector3() : box.getCenter(new THREE.Vector3());
  controls.target.copy(center);
  const from = eyes.length ? eyes[0].clone().sub(center) : new THREE.Vector3(1, -1, 0.6);
  if (from.lengthSq() < 1e-12) from.set(1, -1, 0.6);
  from.normalize().multiplyScalar(size * 1.1);
  from.z = Math.abs(from.z) + size * 0.35;
  camera.position.copy(center).add(from);
  camera.near = Math.max(1e-4, size / 500);
  camera.far = size * 50;
  camera.updateProjectionMatrix();
  controls.update();

  // ---- Side panel ---------------------------------------------------------------------------
  const side = h("div", { id: "avp-side" }, root);
  const ctl = h("div", { id: "avp-controls" }, side);
  const stepLine = h("div", {}, ctl);
  const stepLabel = h("b", {}, stepLine);
  const slider = h("input", { id: "avp-slider", type: "range", min: 0,
    max: Math.max(0, steps.length - 1), step: 1, value: steps.length - 1 }, ctl);
  const opts = h("div", {}, ctl);
  const colorLabel = h("label", {}, opts, "colour by ");
  const colorSelect = h("select", { id: "avp-color-by" }, colorLabel);
  for (const m of ["class", "instance", "confidence"]) h("option", { value: m }, colorSelect, m);
  const toggle = (name, obj, checked = true) => {
    const l = h("label", {}, opts);
    const c = h("input", { type: "checkbox" }, l);
    c.checked = checked;
    l.appendChild(document.createTextNode(` ${name}`));
    c.addEventListener("change", () => {
      for (const o of [].concat(obj)) o.visible = c.checked;
      render();
    });
  };
  toggle("voxels", voxels);
  toggle("fruit", fruitGroup);
  toggle("frustums", [frustumGroup, path]);
  toggle("candidates", [candidates, chosen]);
  const stepInfo = h("div", {}, side);
  h("h2", {}, side, "Masks");
  const masks = h("div", { id: "avp-masks" }, side);
  h("h2", {}, side, "Candidates (next view)");
  const candInfo = h("div", { id: "avp-candidates" }, side);

  // ---- Curves -------------------------------------------------------------------------------
  const bottom = h("div", { id: "avp-bottom" }, root);
  const x = steps.map((s) => s.view);
  const metric = (name) => steps.map((s) => {
    const v = s.metrics ? s.metrics[name] : null;
    return typeof v === "number" ? v : NaN;
  });
  const plots = [];
  const hasMetrics = steps.some((s) => s.metrics && typeof s.metrics.f1 === "number");
  if (hasMetrics) {
    const left = h("div", {}, bottom);
    h("h2", {}, left, "F1 per fused view");
    plots.push(linePlot(left, { title: "", xLabel: "fused views", yLabel: "F1", yMin: 0, yMax: 1,
      width: 560, height: 260, series: [
        { name: "voxel F1 (exact)", x, y: metric("f1") },
        { name: "voxel F1 (±1 voxel)", x, y: metric("f1_tol") },
        { name: "precision", x, y: metric("precision") },
        { name: "recall", x, y: metric("recall") }] }));
    const right = h("div", {}, bottom);
    h("h2", {}, right, "Fruits found per fused view");
    const total = metric("fruits_total");
    const yMax = Math.max(1, ...total.filter(Number.isFinite));
    plots.push(linePlot(right, { title: "", xLabel: "fused views", yLabel: "fruits", yMin: 0,
      yMax, width: 560, height: 260, series: [
        { name: "fruits found", x, y: metric("fruits_found") },
        { name: "fruits observable", x, y: metric("fruits_observable") },
        { name: "fruits in the scene", x, y: total }] }));
  } else {
    h("p", { class: "avp-muted" }, bottom, "No ground truth: no F1 or fruit curves.");
  }
  // Map growth (always there).
  const growth = h("div", {}, bottom);
  h("h2", {}, growth, "Map per fused view");
  plots.push(linePlot(growth, { title: "", xLabel: "fused views", yLabel: "voxels", yMin: 0,
    width: 560, height: 260, series: [
      { name: "occupied voxels", x, y: steps.map((s) => s.occupied_voxels) },
      { name: "target-class voxels", x, y: steps.map((s) => s.target_voxels) }] }));

  // ---- Drawing ------------------------------------------------------------------------------
  const color = new THREE.Color();
  const matrix = new THREE.Matrix4();
  const colorOf = (v) => {
    if (api.colorBy === "instance") return instanceColor(v.instance, color);
    if (api.colorBy === "confidence") return confidenceColor(v.cls, v.confidence, color);
    return classColor(v.cls, color);
  };

  const drawVoxels = () => {
    let i = 0;
    const p = new THREE.Vector3();
    state.forEach((dx, dy, dz, cls, confidence, instance) => {
      keyCenter(dx, dy, dz, p);
      matrix.makeTranslation(p.x, p.y, p.z);
      voxels.setMatrixAt(i, matrix);
      voxels.setColorAt(i, colorOf({ cls, confidence, instance }));
      i++;
    });
    voxels.count = i;
    voxels.instanceMatrix.needsUpdate = true;
    if (voxels.instanceColor) voxels.instanceColor.needsUpdate = true;
    api.drawn.voxels = i;
  };

  const drawLegend = () => {
    legend.textContent = "";
    const item = (c, text) => {
      const i = h("i", {}, legend);
      i.style.background = c;
      legend.appendChild(document.createTextNode(text));
    };
    if (api.colorBy === "class") {
      const present = new Set();
      state.forEach((dx, dy, dz, cls) => present.add(cls));
      for (const c of [...present].sort((a, b) => a - b)) {
        item(`#${classColor(c, color).getHexString()}`,
          c === 0 ? "unlabelled" : (data.classes[c] || `class ${c}`));
      }
    } else if (api.colorBy === "instance") {
      legend.appendChild(document.createTextNode("one colour per map instance; grey: none"));
    } else {
      for (const q of [0.0, 0.5, 1.0]) {
        item(`#${confidenceColor(1, Math.round(q * 255), color).getHexString()}`, fmt(q, 2));
      }
      item("#bbbbbb", "unlabelled");
    }
    if (found + missed > 0) {
      item("#12a012", `found fruit (${found})`);
      item("#00b7c7", `missed fruit (${missed})`);
    }
  };

  const drawCandidates = (s) => {
    const plan = s.plan;
    candidates.count = 0;
    chosen.visible = false;
    api.drawn.candidates = 0;
    candInfo.textContent = "";
    if (!plan) {
      h("p", { class: "avp-muted" }, candInfo, s.view === steps.length ?
        "No plan after the last view." : "No plan at this step.");
      return;
    }
    const c = plan.candidates;
    const n = plan.kept;
    let lo = Infinity, hi = -Infinity;
    for (let i = 0; i < n; i++) {
      if (Number.isFinite(c.utility[i])) {
        lo = Math.min(lo, c.utility[i]);
        hi = Math.max(hi, c.utility[i]);
      }
    }
    for (let i = 0; i < n; i++) {
      matrix.makeTranslation(c.eye[3 * i], c.eye[3 * i + 1], c.eye[3 * i + 2]);
      candidates.setMatrixAt(i, matrix);
      const t = hi > lo ? (c.utility[i] - lo) / (hi - lo) : 1;
      candidates.setColorAt(i, utilityColor(Number.isFinite(t) ? t : 0, color));
    }
    candidates.count = n;
    candidates.instanceMatrix.needsUpdate = true;
    if (candidates.instanceColor) candidates.instanceColor.needsUpdate = true;
    api.drawn.candidates = n;
    const r = plan.chosen_rank;
    if (r >= 0 && r < n) {
      const p = new THREE.Vector3(c.eye[3 * r], c.eye[3 * r + 1], c.eye[3 * r + 2]);
      chosenBall.position.copy(p);
      chosenDir.position.copy(p);
      chosenDir.setDirection(new THREE.Vector3(c.dir[3 * r], c.dir[3 * r + 1], c.dir[3 * r + 2])
        .normalize());
      chosen.visible = candidates.visible;
    }
    h("div", {}, candInfo, `${plan.generated} generated, ${plan.reachable} reachable, ` +
      `${plan.ranked} ranked${plan.kept < plan.ranked ? ` (best ${plan.kept} kept)` : ""}; ` +
      `chosen rank ${r >= 0 ? r + 1 : "none"}${plan.refused_moves ?
        ` after ${plan.refused_moves} refused` : ""}; utility ${fmt(lo)} – ${fmt(hi)}` +
      (plan.status !== "OK" ? `; ${plan.status}` : "") +
      (plan.stop ? `; planner stopped: ${plan.stop_reason}` : ""));
    const m = s.motion;
    if (m && (m.planned || m.contacts !== null)) {
      const contacts = m.contacts === null ? "" : `; ${m.contacts} contact${m.contacts === 1 ? "" :
        "s"}${m.first_contact ? ` (${m.first_contact})` : ""}, the straight line ` +
        `${m.straight_line_contacts}`;
      h("div", {}, candInfo, `move: ${m.planned ? (m.straight ? "straight (free)" :
        "planned around obstacles") : "straight, unchecked"}, ${fmt(m.execution_s)} s` +
        `${m.rejected ? `, ${m.rejected} candidates rejected` : ""}${contacts}`);
    }
    const f = s.moving_frames;
    if (f) {
      h("div", {}, candInfo, `while moving: ${f.fused} frames fused (${f.segmented} with masks` +
        `${f.dropped ? `, ${f.dropped} dropped` : ""}${f.failed ? `, ${f.failed} failed` : ""}), ` +
        `+${f.known_delta} known voxels, +${f.target_delta} fruit voxels; the map took ` +
        `${fmt(f.map_rate_hz)} frames/s`);
    }
    const table = h("table", { class: "avp" }, candInfo);
    const hr = h("tr", {}, table);
    for (const t of ["rank", "utility", "gain", "cost", "source"]) h("th", {}, hr, t);
    const show = new Set();
    for (let i = 0; i < Math.min(n, 12); i++) show.add(i);
    if (r >= 0 && r < n) show.add(r);
    for (const i of [...show].sort((a, b) => a - b)) {
      const tr = h("tr", { class: i === r ? "chosen" : "" }, table);
      const sw = h("td", {}, tr);
      const dot = h("i", {}, sw);
      dot.style.cssText = "display:inline-block;width:8px;height:8px;border-radius:4px;" +
        `margin-right:4px;background:#${utilityColor(hi > lo ? (c.utility[i] - lo) / (hi - lo)
          : 1, color).getHexString()}`;
      sw.appendChild(document.createTextNode(String(i + 1) + (i === r ? " ◀ chosen" : "")));
      h("td", {}, tr, fmt(c.utility[i], 4));
      h("td", {}, tr, fmt(c.gain[i], 4));
      h("td", {}, tr, fmt(c.cost[i], 3));
      h("td", {}, tr, plan.sources[c.source[i]] || "");
    }
  };

  const drawMasks = (s) => {
    masks.textContent = "";
    const img = s.image;
    if (!img) {
      h("p", { class: "avp-muted" }, masks, "No image at this view (the capture failed).");
      return;
    }
    if (img.jpeg) {
      h("img", { src: `data:image/jpeg;base64,${img.jpeg}`, width: img.width,
        height: img.height, alt: `view ${s.view}: masks over the colour image` }, masks);
    }
    if (!img.instances.length) {
      h("p", { class: "avp-muted" }, masks, "No instance masks at this view.");
      return;
    }
    const table = h("table", { class: "avp" }, masks);
    const hr = h("tr", {}, table);
    for (const t of ["instance", "class", "score", "pixels"]) h("th", {}, hr, t);
    img.instances.forEach((m, i) => {
      const tr = h("tr", {}, table);
      const td = h("td", {}, tr);
      const dot = h("i", {}, td);
      dot.style.cssText = `display:inline-block;width:8px;height:8px;margin-right:4px;` +
        `background:${m.color}`;
      td.appendChild(document.createTextNode(`${i + 1} ${m.label || ""}`));
      h("td", {}, tr, m.class);
      h("td", {}, tr, fmt(m.score, 3));
      h("td", {}, tr, String(m.pixels));
    });
  };

  let frame = 0;
  const render = () => {
    if (frame) return;
    frame = requestAnimationFrame(() => {
      frame = 0;
      renderer.render(scene, camera);
    });
  };
  const renderNow = () => renderer.render(scene, camera);

  const resize = () => {
    const w = Math.max(50, view.clientWidth);
    const hh = Math.max(50, view.clientHeight);
    renderer.setSize(w, hh, false);
    camera.aspect = w / hh;
    camera.updateProjectionMatrix();
    renderNow();
  };
  window.addEventListener("resize", resize);
  controls.addEventListener("change", render);

  const setStep = (k) => {
    k = Math.max(0, Math.min(steps.length - 1, Math.round(Number(k))));
    if (!Number.isFinite(k)) return;
    const s = steps[k];
    state.goTo(k);
    drawVoxels();
    let n = 0;
    frustums.forEach((f, i) => {
      f.group.visible = i <= k;
      f.lines.material.color.set(i === k ? 0xff7a00 : 0x3060c0);
      n += i <= k ? 1 : 0;
    });
    pathGeometry.setDrawRange(0, k + 1);
    api.drawn.frustums = n;
    drawCandidates(s);
    drawMasks(s);
    drawLegend();
    stepLabel.textContent = `view ${s.view} of ${steps.length}`;
    slider.value = String(k);
    const m = s.metrics || {};
    const errors = Object.entries(s.errors || {}).map(([w, e]) => `${w}: ${e}`);
    stepInfo.innerHTML = "";
    h("div", {}, stepInfo, `${s.occupied_voxels} occupied voxels (+${s.voxels.set} set, ` +
      `−${s.voxels.removed} removed), ${s.known_voxels} known, ${s.target_voxels} target-class, ` +
      `${s.instances} instances, ${s.masks} masks`);
    if (typeof m.f1 === "number") {
      h("div", {}, stepInfo, `F1 ${fmt(m.f1)} (±1 voxel ${fmt(m.f1_tol)}), fruits found ` +
        `${fmt(m.fruits_found)} of ${fmt(m.fruits_total)}`);
    }
    for (const e of errors) h("div", { class: "avp-error" }, stepInfo, e);
    for (const p of plots) p.hoverAt(s.view);
    api.step = k;
    renderNow();
  };
  const setColorBy = (mode) => {
    if (!["class", "instance", "confidence"].includes(mode)) {
      throw new Error(`setColorBy: unknown mode '${mode}' (class, instance or confidence)`);
    }
    api.colorBy = mode;
    colorSelect.value = mode;
    drawVoxels();
    drawLegend();
    renderNow();
  };
  slider.addEventListener("input", () => setStep(Number(slider.value)));
  colorSelect.addEventListener("change", () => setColorBy(colorSelect.value));
  window.addEventListener("keydown", (e) => {
    if (e.target && e.target.tagName === "INPUT" && e.target.type !== "range") return;
    if (e.key === "ArrowRight") setStep(api.step + 1);
    if (e.key === "ArrowLeft") setStep(api.step - 1);
  });

  api.steps = steps.length;
  api.expected = { voxels: data.expected.voxels, frustums: data.expected.frustums };
  api.drawn.fruitFound = found;
  api.drawn.fruitMissed = missed;
  api.setStep = setStep;
  api.setColorBy = setColorBy;
  resize();
  // #step=N (a view, 1-based) opens the page at that view; the last one otherwise.
  const m = /(?:^#|&)step=(\d+)/.exec(window.location.hash);
  setStep(m ? Number(m[1]) - 1 : steps.length - 1);
}

function fail(e) {
  api.error = e && e.message ? e.message : String(e);
  const root = document.getElementById("avp-report") || document.body;
  const p = document.createElement("p");
  p.className = "avp-error";
  p.textContent = `The report could not be shown: ${api.error}`;
  root.appendChild(p);
  console.error(e);
}

function main() {
  const el = document.getElementById("avp-report-data");
  if (!el) throw new Error("the page has no data (#avp-report-data)");
  const data = JSON.parse(el.textContent);
  if (data.format !== "avp-run-report" || data.version !== 1) {
    throw new Error(`unknown data format ${data.format} version ${data.version}`);
  }
  if (!Array.isArray(data.steps)) throw new Error("the page's data has no steps");
  if (data.steps.length === 0) {
    const root = document.getElementById("avp-report") || document.body;
    root.textContent = `${data.title || "avp run"}: the run fused no view; nothing to show.`;
    api.ready = true;
    return;
  }
  build(data);
  api.ready = true;
}

try {
  main();
} catch (e) {
  fail(e);
}
