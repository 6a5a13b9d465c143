// The report pages in a real browser (issue 17; docs/report.md, "How the report is built and
// tested"). Writes a short `avp run` (or a small `avp bench`) with the built avp, loads its
// report.html from disk in Debian's headless Chromium (WebGL through SwiftShader; no network: every
// host name resolves to nothing) with #selftest, so that the page's selftest.js checks what it drew
// and writes a JSON verdict into <pre id="avp-selftest">. Fails on a console error, an uncaught
// exception, a WebGL or network error, a blank canvas, voxel / frustum counts that differ from
// the run's record.json, a step slider that changes nothing, or a bench page whose scenarios
// differ from summary.csv.
//
// Usage: node report_browser.mjs --avp <avp> --page run|bench --out <scratch dir>
//                                [--chromium <chromium>] [--timeout-s 45]
//
// Chromium is driven over --remote-debugging-pipe (the DevTools protocol on file descriptors 3
// and 4; no port is opened) rather than with --dump-dom and --virtual-time-budget: a page that
// renders every animation frame never exhausts a virtual time budget, and the protocol gives each
// console message's level (the stderr log writes them all as INFO).

import { execFileSync, spawn } from "node:child_process";
import { accessSync, constants, existsSync, mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { delimiter, join } from "node:path";
import { pathToFileURL } from "node:url";

function arg(name, fallback) {
  const i = process.argv.indexOf(name);
  if (i < 0 || i + 1 >= process.argv.length) {
    if (fallback !== undefined) return fallback;
    console.error(`report_browser: missing ${name} <value>`);
    process.exit(2);
  }
  return process.argv[i + 1];
}

const avp = arg("--avp");
const page = arg("--page");
const outDir = arg("--out");
const timeoutMs = Number(arg("--timeout-s", "45")) * 1000;
if (page !== "run" && page !== "bench") {
  console.error(`report_browser: --page must be run or bench, got '${page}'`);
  process.exit(2);
}

function findChromium() {
  const given = arg("--chromium", "");
  if (given) return given;
  for (const dir of (process.env.PATH || "").split(delimiter)) {
    for (const name of ["chromium", "chromium-browser"]) {
      const p = join(dir, name);
      try {
        accessSync(p, constants.X_OK);
        return p;
      } catch {
        // next
      }
    }
  }
  return null;
}

const chromium = findChromium();
if (!chromium || !existsSync(chromium)) {
  console.error("report_browser: Debian's chromium is not installed (the report's browser test " +
                "needs it); run scripts/setup");
  process.exit(1);
}

let failures = 0;
function check(ok, what) {
  console.log(`${ok ? "ok  " : "FAIL"} ${what}`);
  if (!ok) failures++;
}

// A short episode: 3 views of 160x120 pixels (the report draws the same things at any size).
const kCamera = ["camera.width=160", "camera.height=120", "camera.fx=154", "camera.fy=154",
                 "camera.cx=79.5", "camera.cy=59.5"].flatMap((kv) => ["--set", kv]);
const folder = join(outDir, page);
rmSync(folder, { recursive: true, force: true });  // a fresh folder each time
const t0 = Date.now();
function runAvp(args) {
  try {
    execFileSync(avp, args, { stdio: ["ignore", "ignore", "inherit"], timeout: 60000 });
  } catch (e) {
    console.error(`report_browser: ${avp} ${args.join(" ")} failed (${e.status ?? e.signal})`);
    process.exit(1);
  }
}
if (page === "run") {
  runAvp(["run", "--scenario", "tomato-multiple-clusters", "--seed", "0", "--views",
          "3", ...kCamera, "--out", folder]);
} else {
  runAvp(["bench", "--scenarios", "tomato-multiple-clusters", "--planners", "avp-nbv,predefined",
          "--seeds", "2", "--views", "3", ...kCamera, "--out", folder]);
}
const report = join(folder, "report.html");
console.log(`report_browser: ${page} folder written in ${((Date.now() - t0) / 1000).toFixed(1)} s: ` +
            report);
if (!existsSync(report)) {
  console.error(`report_browser: ${report} was not written`);
  process.exit(1);
}

// ---- Chromium over the DevTools protocol ------------------------------------------------------
const profile = mkdtempSync(join(tmpdir(), "avp-report-browser-"));
const flags = [
  "--headless=new",
  // root in a container: no user namespaces for Chromium's sandbox
  "--no-sandbox",
  // WebGL without a GPU: ANGLE on SwiftShader (the software Vulkan/GL Chromium ships); since
  // Chromium 137 SwiftShader WebGL needs this explicit opt-in
  "--use-angle=swiftshader",
  "--enable-unsafe-swiftshader",
  "--remote-debugging-pipe",
  `--user-data-dir=${profile}`,
  "--window-size=800,600",
  // offline: nothing resolves, nothing is fetched in the background
  "--host-resolver-rules=MAP * ~NOTFOUND",
  "--no-first-run",
  "--no-default-browser-check",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--disable-extensions",
  "about:blank",
];
const browser = spawn(chromium, flags, {
  stdio: ["ignore", "ignore", "pipe", "pipe", "pipe"],
  detached: true,  // its own process group: killed as a whole
  env: { ...process.env, DBUS_SESSION_BUS_ADDRESS: "disabled:" },
});
let stderrTail = "";
browser.stderr.on("data", (d) => {
  stderrTail = (stderrTail + d.toString()).slice(-4000);
});
const exited = new Promise((resolve) => browser.on("exit", (code, signal) => resolve({ code, signal })));
function killBrowser() {
  try {
    process.kill(-browser.pid, "SIGKILL");
  } catch {
    // already gone
  }
}
const watchdog = setTimeout(() => {
  console.error(`report_browser: no verdict after ${timeoutMs / 1000} s; killing Chromium`);
  console.error(`Chromium's last log lines:\n${stderrTail}`);
  killBrowser();
  process.exit(1);
}, timeoutMs);

const toBrowser = browser.stdio[3];
const fromBrowser = browser.stdio[4];
let nextId = 1;
const pending = new Map();
const messages = [];  // {level, text}
let buffered = Buffer.alloc(0);
fromBrowser.on("data", (chunk) => {
  buffered = Buffer.concat([buffered, chunk]);
  for (let end = buffered.indexOf(0); end >= 0; end = buffered.indexOf(0)) {
    const msg = JSON.parse(buffered.subarray(0, end).toString("utf8"));
    buffered = buffered.subarray(end + 1);
    if (msg.id !== undefined && pending.has(msg.id)) {
      const { resolve, reject, method } = pending.get(msg.id);
      pending.delete(msg.id);
      if (msg.error) reject(new Error(`${method}: ${msg.error.message}`));
      else resolve(msg.result);
    } else if (msg.method) {
      onEvent(msg.method, msg.params);
    }
  }
});
function send(method, params = {}, sessionId = undefined) {
  const id = nextId++;
  const msg = { id, method, params };
  if (sessionId) msg.sessionId = sessionId;
  toBrowser.write(JSON.stringify(msg) + "\0");
  return new Promise((resolve, reject) => pending.set(id, { resolve, reject, method }));
}

function remoteText(o) {
  if (o.type === "string") return o.value;
  if (o.value !== undefined) return JSON.stringify(o.value);
  return o.description || o.type;
}
function onEvent(method, p) {
  if (method === "Runtime.consoleAPICalled") {
    messages.push({ level: p.type, text: p.args.map(remoteText).join(" ") });
  } else if (method === "Runtime.exceptionThrown") {
    const d = p.exceptionDetails;
    messages.push({ level: "exception",
                    text: `${d.text} ${d.exception?.description || ""} (${d.url || ""}:${d.lineNumber})` });
  } else if (method === "Log.entryAdded") {
    const e = p.entry;
    messages.push({ level: `${e.source}-${e.level}`, text: `${e.text}${e.url ? ` (${e.url})` : ""}` });
  }
}
// Errors: console.error/assert, uncaught exceptions, the browser's own errors (network,
// security, ...), and WebGL's complaints (logged as warnings: "WebGL: INVALID_OPERATION ...",
// "GL_INVALID_...").
function isError(m) {
  if (m.level === "error" || m.level === "assert" || m.level === "exception") return true;
  if (m.level.endsWith("-error")) return true;
  return /WebGL|GL_INVALID|GL ERROR/i.test(m.text);
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

const url = `${pathToFileURL(report).href}#selftest`;
let verdict = null;
const tLoad = Date.now();
try {
  const { targetInfos } = await send("Target.getTargets");
  let target = targetInfos.find((t) => t.type === "page");
  if (!target) target = await send("Target.createTarget", { url: "about:blank" });
  const { sessionId } = await send("Target.attachToTarget",
                                   { targetId: target.targetId, flatten: true });
  await send("Runtime.enable", {}, sessionId);
  await send("Log.enable", {}, sessionId);
  await send("Page.enable", {}, sessionId);
  await send("Page.navigate", { url }, sessionId);
  for (;;) {
    const { result } = await send("Runtime.evaluate", {
      expression: "(document.getElementById('avp-selftest') || {}).textContent || ''",
      returnByValue: true,
    }, sessionId);
    if (result.value) {
      verdict = JSON.parse(result.value);
      break;
    }
    await sleep(200);
  }
  await send("Browser.close").catch(() => {});
} catch (e) {
  console.error(`report_browser: DevTools protocol: ${e.message}`);
  console.error(`Chromium's last log lines:\n${stderrTail}`);
  failures++;
}
const loadSeconds = (Date.now() - tLoad) / 1000;
const exit = await Promise.race([exited, sleep(5000).then(() => null)]);
if (!exit) killBrowser();
clearTimeout(watchdog);
rmSync(profile, { recursive: true, force: true });
if (!verdict) process.exit(1);

// ---- Judging -----------------------------------------------------------------------------------
console.log(`report_browser: ${page} page checked in ${loadSeconds.toFixed(1)} s; verdict: ` +
            JSON.stringify(verdict));
for (const m of messages) console.log(`  console [${m.level}] ${m.text}`);
const errors = messages.filter(isError);
check(errors.length === 0, `no console error, exception, WebGL or network error (${errors.length})`);
check(verdict.errors.length === 0,
      `no error the page collected (${verdict.errors.length}: ${verdict.errors.join(" | ")})`);
check(verdict.failures.length === 0,
      `the page's self-test passed (${verdict.failures.join(" | ") || "no failures"})`);
check(verdict.ready === true, "the page became ready");
check(verdict.page === page, `the page is a ${page} report (${verdict.page})`);

if (page === "run") {
  const record = JSON.parse(readFileSync(join(folder, "record.json"), "utf8"));
  const steps = record.steps;
  const last = steps[steps.length - 1];
  check(verdict.steps === steps.length, `steps: page ${verdict.steps}, record.json ${steps.length}`);
  check(verdict.last?.drawn?.voxels === last.occupied_voxels,
        `voxels drawn at the last step: ${verdict.last?.drawn?.voxels}, record.json's last ` +
        `occupied_voxels ${last.occupied_voxels}`);
  check(verdict.last?.drawn?.frustums === record.views_fused,
        `frustums drawn at the last step: ${verdict.last?.drawn?.frustums}, views fused ` +
        `${record.views_fused}`);
  check(verdict.first?.drawn?.voxels === steps[0].occupied_voxels,
        `voxels drawn at step 0: ${verdict.first?.drawn?.voxels}, record.json's first ` +
        `occupied_voxels ${steps[0].occupied_voxels}`);
  check(verdict.first?.drawn?.frustums === 1,
        `frustums drawn at step 0: ${verdict.first?.drawn?.frustums}`);
  check(verdict.last?.pixels >= 100 && verdict.first?.pixels >= 100,
        `non-blank canvas ${verdict.canvas?.width}x${verdict.canvas?.height}: ` +
        `${verdict.last?.pixels} pixels drawn at the last step, ${verdict.first?.pixels} at step 0`);
  check(verdict.changed_pixels > 0, `the step slider changes ${verdict.changed_pixels} pixels`);
} else {
  const rows = readFileSync(join(folder, "summary.csv"), "utf8").trim().split("\n");
  const column = rows[0].split(",").indexOf("scenario");
  const scenarios = new Set(rows.slice(1).map((r) => r.split(",")[column])).size;
  check(verdict.scenarios === scenarios,
        `scenarios: page ${verdict.scenarios}, summary.csv ${scenarios}`);
  check(verdict.plots >= 1, `plots drawn: ${verdict.plots} (svg ${verdict.svg}, tables ` +
        `${verdict.tables})`);
}
console.log(failures === 0 ? "report_browser: PASS" : `report_browser: ${failures} failure(s)`);
process.exit(failures === 0 ? 0 : 1);
