// The report pages' self-test (docs/report.md, "How the report is built and tested"). Imported
// first by run.js and bench.js (`import "./selftest.js";`), it does nothing unless the page's URL
// has #selftest. Then it collects every window error, unhandled rejection and console.error from
// the start, waits for the page's API (window.avpReport of a run, window.avpBenchReport of a
// bench) to be ready, checks what it drew, and writes a JSON verdict into <pre id="avp-selftest">
// (tests/report_browser.mjs loads the page in headless Chromium and reads it back).
//
// Run page (window.avpReport, contract in docs/report.md): at the last step drawn.voxels ==
// expected.voxels and drawn.frustums == expected.frustums; the WebGL canvas (made with
// preserveDrawingBuffer) is read back and must not be blank; setStep(0) must show one frustum,
// a different voxel count and different pixels. Bench page (window.avpBenchReport): ready, at
// least one scenario and one plot, the plots' elements are in the page, and where the page gives
// expected {scenarios, plots, series, points[]} from its data, what it drew equals it.

const kVerdictId = "avp-selftest";
const kPollMs = 50;
const kReadyTimeoutMs = 30000;
// Fewer pixels than this differing from the background is a blank canvas.
const kMinDrawnPixels = 100;

const errors = [];

function text(value) {
  if (value instanceof Error) return `${value.name}: ${value.message}`;
  if (typeof value === "string") return value;
  try {
    return JSON.stringify(value);
  } catch {
    return String(value);
  }
}

function installCollectors() {
  window.addEventListener("error", (e) => {
    const where = e.filename ? ` (${e.filename}:${e.lineno}:${e.colno})` : "";
    errors.push(`window error: ${e.message || text(e.error)}${where}`);
  });
  window.addEventListener("unhandledrejection", (e) => {
    errors.push(`unhandled rejection: ${text(e.reason)}`);
  });
  const consoleError = console.error.bind(console);
  console.error = (...args) => {
    errors.push(`console.error: ${args.map(text).join(" ")}`);
    consoleError(...args);
  };
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Two animation frames (the page renders on the next frame after a change), or 200 ms when the
// page gets no frames.
function frames() {
  return new Promise((resolve) => {
    let done = false;
    const finish = () => {
      if (!done) {
        done = true;
        resolve();
      }
    };
    requestAnimationFrame(() => requestAnimationFrame(finish));
    setTimeout(finish, 200);
  });
}

async function waitReady(name) {
  const t0 = performance.now();
  for (;;) {
    const api = window[name];
    if (api && (api.ready || api.error)) return api;
    if (performance.now() - t0 > kReadyTimeoutMs) return api || null;
    await sleep(kPollMs);
  }
}

function count(value) {
  if (Array.isArray(value)) return value.length;
  if (value && typeof value === "object") return Object.keys(value).length;
  return Number(value);
}

// The 3D view's canvas: the one the page names (api.canvas), else the largest canvas.
function viewCanvas(api) {
  if (api && api.canvas instanceof HTMLCanvasElement) return api.canvas;
  let best = null;
  for (const c of document.querySelectorAll("canvas")) {
    if (!best || c.width * c.height > best.width * best.height) best = c;
  }
  return best;
}

// Reads the canvas back through a 2D canvas. The background is the most frequent colour; drawn is
// how many pixels differ from it.
function snapshot(canvas) {
  const w = canvas.width;
  const h = canvas.height;
  if (w === 0 || h === 0) return { width: w, height: h, drawn: 0, pixels: new Uint32Array(0) };
  const copy = document.createElement("canvas");
  copy.width = w;
  copy.height = h;
  const ctx = copy.getContext("2d", { willReadFrequently: true });
  ctx.drawImage(canvas, 0, 0);
  const pixels = new Uint32Array(ctx.getImageData(0, 0, w, h).data.buffer.slice(0));
  const histogram = new Map();
  for (const p of pixels) histogram.set(p, (histogram.get(p) || 0) + 1);
  let background = 0;
  let most = -1;
  for (const [p, n] of histogram) {
    if (n > most) {
      most = n;
      background = p;
    }
  }
  return { width: w, height: h, drawn: pixels.length - most, background, pixels };
}

function changedPixels(a, b) {
  if (a.pixels.length !== b.pixels.length) return Math.max(a.pixels.length, b.pixels.length);
  let n = 0;
  for (let i = 0; i < a.pixels.length; i++) n += a.pixels[i] !== b.pixels[i] ? 1 : 0;
  return n;
}

function drawnCopy(api) {
  const d = api.drawn || {};
  return {
    voxels: d.voxels,
    frustums: d.frustums,
    fruitFound: d.fruitFound,
    fruitMissed: d.fruitMissed,
    candidates: d.candidates,
  };
}

async function testRun(api, verdict, fail, mark) {
  const steps = Number(api.steps);
  verdict.steps = steps;
  verdict.expected = { voxels: api.expected?.voxels, frustums: api.expected?.frustums };
  if (!(steps >= 1)) {
    fail(`steps is ${api.steps}, expected at least 1`);
    return;
  }
  const canvas = viewCanvas(api);
  if (!canvas) {
    fail("no canvas in the page");
    return;
  }
  // The last step (the page opens there; set it anyway).
  api.setStep(steps - 1);
  await frames();
  const last = snapshot(canvas);
  verdict.canvas = { width: last.width, height: last.height };
  verdict.last = { step: api.step, drawn: drawnCopy(api), pixels: last.drawn };
  mark("last");
  if (api.step !== steps - 1) fail(`setStep(${steps - 1}) left step at ${api.step}`);
  if (verdict.last.drawn.voxels !== verdict.expected.voxels) {
    fail(`last step draws ${verdict.last.drawn.voxels} voxels, expected ${verdict.expected.voxels}`);
  }
  if (verdict.last.drawn.frustums !== verdict.expected.frustums) {
    fail(`last step draws ${verdict.last.drawn.frustums} frustums, ` +
         `expected ${verdict.expected.frustums}`);
  }
  if (last.drawn < kMinDrawnPixels) {
    fail(`blank canvas: ${last.drawn} of ${last.width}x${last.height} pixels differ from the ` +
         "background");
  }
  // The first step: the map after view 1 and its frustum.
  api.setStep(0);
  await frames();
  const first = snapshot(canvas);
  verdict.first = { step: api.step, drawn: drawnCopy(api), pixels: first.drawn };
  verdict.changed_pixels = changedPixels(last, first);
  mark("first");
  if (api.step !== 0) fail(`setStep(0) left step at ${api.step}`);
  if (verdict.first.drawn.frustums !== 1) {
    fail(`step 0 draws ${verdict.first.drawn.frustums} frustums, expected 1`);
  }
  if (steps > 1 && verdict.first.drawn.voxels === verdict.last.drawn.voxels) {
    fail(`setStep(0) did not change the voxel count (${verdict.first.drawn.voxels})`);
  }
  if (steps > 1 && verdict.changed_pixels === 0) fail("setStep(0) did not change the canvas");
  if (first.drawn < kMinDrawnPixels) fail(`blank canvas at step 0: ${first.drawn} pixels drawn`);
  // Each colouring must draw without errors (the canvas is not read again: reading it back costs
  // a frame of software rendering).
  if (typeof api.setColorBy === "function") {
    api.setStep(steps - 1);
    for (const mode of ["instance", "confidence", "class"]) {
      api.setColorBy(mode);
      await frames();
    }
    mark("color_by");
  } else {
    fail("setColorBy is not a function");
  }
}

async function testBench(api, verdict, fail) {
  verdict.scenarios = count(api.scenarios);
  verdict.plots = count(api.plots);
  verdict.svg = document.querySelectorAll("svg").length;
  verdict.tables = document.querySelectorAll("table").length;
  verdict.canvases = [];
  for (const c of document.querySelectorAll("canvas")) verdict.canvases.push(snapshot(c).drawn);
  if (!(verdict.scenarios >= 1)) fail(`scenarios is ${text(api.scenarios)}, expected at least 1`);
  if (!(verdict.plots >= 1)) fail(`plots is ${text(api.plots)}, expected at least 1`);
  if (verdict.svg + verdict.canvases.length === 0) fail("no plot (svg or canvas) in the page");
  if (verdict.canvases.some((n) => n < kMinDrawnPixels)) fail("a blank plot canvas");
  // What the page says it should draw (from its data) against what it drew, where it says.
  const expected = api.expected;
  if (expected && typeof expected === "object") {
    verdict.expected = expected;
    if (expected.scenarios !== undefined && verdict.scenarios !== count(expected.scenarios)) {
      fail(`scenarios drawn ${verdict.scenarios}, expected ${text(expected.scenarios)}`);
    }
    if (expected.plots !== undefined && verdict.plots !== count(expected.plots)) {
      fail(`plots drawn ${verdict.plots}, expected ${text(expected.plots)}`);
    }
    if (Array.isArray(api.plots)) {
      api.plots.forEach((plot, i) => {
        const name = `plot ${i} (${plot.scenario} ${plot.metric})`;
        if (Array.isArray(expected.points) && plot.points !== expected.points[i]) {
          fail(`${name} draws ${plot.points} points, expected ${expected.points[i]}`);
        }
        if (typeof expected.series === "number" && plot.series !== expected.series) {
          fail(`${name} draws ${plot.series} series, expected ${expected.series}`);
        }
        if (!(plot.points >= 1)) fail(`${name} draws no point`);
      });
    }
  }
}

function writeVerdict(verdict) {
  let pre = document.getElementById(kVerdictId);
  if (!pre) {
    pre = document.createElement("pre");
    pre.id = kVerdictId;
    document.body.appendChild(pre);
  }
  pre.textContent = JSON.stringify(verdict);
}

async function selftest() {
  const verdict = { ok: false, page: null, failures: [], errors, ms: {} };
  const t0 = performance.now();
  const mark = (what) => {
    verdict.ms[what] = Math.round(performance.now() - t0);
  };
  const fail = (what) => verdict.failures.push(what);
  try {
    // Which page: the first API object that appears.
    while (!window.avpReport && !window.avpBenchReport &&
           performance.now() - t0 < kReadyTimeoutMs) {
      await sleep(kPollMs);
    }
    const name = window.avpReport ? "avpReport" : window.avpBenchReport ? "avpBenchReport" : null;
    verdict.page = name === "avpReport" ? "run" : name === "avpBenchReport" ? "bench" : null;
    if (!name) {
      fail("neither window.avpReport nor window.avpBenchReport was defined");
    } else {
      const api = await waitReady(name);
      mark("ready");
      verdict.ready = Boolean(api && api.ready);
      if (api && api.error) fail(`page error: ${api.error}`);
      if (!verdict.ready) {
        fail(`window.${name} not ready after ${kReadyTimeoutMs} ms`);
      } else if (name === "avpReport") {
        await testRun(api, verdict, fail, mark);
      } else {
        await testBench(api, verdict, fail);
      }
    }
  } catch (e) {
    fail(`selftest threw ${text(e)}${e && e.stack ? `\n${e.stack}` : ""}`);
  }
  await frames();
  verdict.ok = verdict.failures.length === 0 && errors.length === 0;
  writeVerdict(verdict);
}

if (typeof window !== "undefined" && /(^|[#&])selftest(&|$)/.test(window.location.hash)) {
  installCollectors();
  // After the page's own module code (the importer) has run.
  setTimeout(() => {
    selftest();
  }, 0);
}
