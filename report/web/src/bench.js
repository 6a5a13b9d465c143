// The bench report page (report.html of an `avp bench` folder, docs/report.md "Bench report"):
// per scenario, F1 (exact and one-voxel tolerant) and the fraction of fruits found per fused view,
// one line per planner with its 95 % interval band (mean and CI over seeds, as summary.csv), the final
// view's table (as summary.md), fruits found per visibility bin (Wilson 95 % intervals, as
// fruits_by_visibility.csv), any other metric per view on demand, and links to every episode's
// run folder. The data is the JSON the C++ writer embeds (report::BenchReportJson) in
// <script type="application/json" id="avp-bench-data">.
//
// window.avpBenchReport = {ready, error, scenarios, plots, expected} (plan: report page contract):
//   scenarios: scenarios drawn; plots: [{scenario, metric, series, points, bands}] one per plot
//   drawn; expected: {scenarios, plots, series (per plot: planners), points (per plot: finite
//   means)} from the data, so a test can compare what was drawn with what should be.
// With #selftest in the URL, selftest.js checks the page after ready (docs/report.md).

// First: with #selftest in the URL it collects errors from the start and checks the page once
// window.avpBenchReport is ready (H4's selftest.js; nothing otherwise).
import './selftest.js';
import { linePlot, formatNumber } from './plot.js';

const state = { ready: false, error: null, scenarios: 0, plots: [], expected: null };
window.avpBenchReport = state;

const CSS = `
body { font: 14px/1.4 system-ui, sans-serif; margin: 0; color: #222; background: #fafafa; }
#avp-bench { max-width: 1400px; margin: 0 auto; padding: 12px 20px 40px; }
h1 { font-size: 22px; margin: 8px 0; }
h2 { font-size: 18px; margin: 28px 0 8px; padding-top: 8px; border-top: 1px solid #ddd; }
h3 { font-size: 15px; margin: 16px 0 6px; }
.facts { color: #444; margin: 4px 0; }
.facts code, td code { background: #eee; padding: 0 3px; border-radius: 3px; }
nav a { margin-right: 12px; }
table { border-collapse: collapse; margin: 6px 0 10px; background: #fff; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: right; white-space: nowrap; }
th { background: #f0f0f0; }
td:first-child, th:first-child { text-align: left; }
.plots { display: flex; flex-wrap: wrap; gap: 8px 16px; }
.plot { background: #fff; border: 1px solid #ddd; padding: 4px; }
.ci { color: #666; }
.failed { color: #b00; }
.verdict-ahead { color: #1a7f37; font-weight: 600; }
.verdict-behind { color: #b00; font-weight: 600; }
.runs td { text-align: left; }
.runs a { margin-right: 8px; }
.muted { color: #777; }
select { font: inherit; }
#avp-error { color: #b00; white-space: pre-wrap; }
`;

function h(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else e.setAttribute(k, v);
  }
  for (const c of children) {
    if (c == null) continue;
    e.appendChild(typeof c === 'string' ? document.createTextNode(c) : c);
  }
  return e;
}

function num(v, digits = 3) {
  return typeof v === 'number' && Number.isFinite(v) ? v.toFixed(digits) : '–';
}

/** "0.512 [0.480, 0.541]" as summary.md writes it (eval::FormatMeanInterval). */
function meanCi(stat, digits = 3, sign = false) {
  if (!stat || stat.mean == null) return '–';
  const f = (v) => (sign && typeof v === 'number' && v >= 0 ? '+' : '') + num(v, digits);
  if (stat.ci_lo == null || stat.ci_hi == null) {
    return `${f(stat.mean)} (n = ${stat.n}, no interval)`;
  }
  return `${f(stat.mean)} [${f(stat.ci_lo)}, ${f(stat.ci_hi)}]`;
}

/** Below this many seeds an interval is marked small (eval::kSmallSample). */
const SMALL_SAMPLE = 5;

function sampleSize(n) {
  return n > 0 && n < SMALL_SAMPLE ? `${n} (small)` : String(n);
}

function table(head, rows, cls) {
  const t = h('table', cls ? { class: cls } : {});
  t.appendChild(h('thead', {}, h('tr', {}, ...head.map((x) => h('th', { text: x })))));
  const body = h('tbody');
  for (const r of rows) {
    body.appendChild(h('tr', {}, ...r.map((x) => (x instanceof Node ? h('td', {}, x) : h('td', {
      text: String(x) })))));
  }
  t.appendChild(body);
  return t;
}

const METRIC_LABELS = {
  f1: 'voxel F1 (exact)',
  f1_tol: 'voxel F1 (±1 voxel)',
  fruits_found_fraction: 'fraction of fruits found',
  fruits_found: 'fruits found',
};

function metricLabel(m) {
  return METRIC_LABELS[m] || m.replace(/_/g, ' ');
}

function isFraction(metric) {
  return /^(f1|precision|recall)(_tol)?$/.test(metric) || metric === 'fruits_found_fraction' ||
    metric === 'roi_coverage';
}

/** One plot of `metric` per view for a scenario: a series per planner with its 95 % interval. */
function metricPlot(container, data, scenario, metric) {
  const views = data.bench.views;
  const x = Array.from({ length: views }, (_, i) => i + 1);
  const series = [];
  let expectedPoints = 0;
  for (const p of scenario.planners) {
    const pv = p.per_view[metric];
    if (!pv) continue;
    const y = pv.mean.map((v) => (v == null ? NaN : v));
    const lo = pv.ci_lo.map((v) => (v == null ? NaN : v));
    const hi = pv.ci_hi.map((v) => (v == null ? NaN : v));
    expectedPoints += y.filter(Number.isFinite).length;
    const small = p.n < 2 ? ', no interval' : p.n < SMALL_SAMPLE ? ', small' : '';
    const s = { name: `${p.name} (n=${p.n}${small})`, x, y, lo, hi };
    if (metric === 'fruits_found_fraction' && p.per_view.fruits_found && p.per_view.fruits_total) {
      const found = p.per_view.fruits_found.mean;
      const total = p.per_view.fruits_total.mean;
      s.hoverExtra = (i) => ` (${num(found[i], 1)} / ${num(total[i], 1)} fruits)`;
    }
    series.push(s);
  }
  const frac = isFraction(metric);
  const plot = linePlot(container, {
    title: `${scenario.name}: ${metricLabel(metric)}`,
    xLabel: 'fused views',
    yLabel: `${metricLabel(metric)} (mean, 95 % interval)`,
    yMin: frac ? 0 : undefined,
    yMax: frac ? 1 : undefined,
    // As the SVG plots: a fraction's axis is [0, 1] (its intervals stay inside).
    yFixed: frac,
    width: 420,
    height: 300,
    series,
  });
  const stats = plot.stats();
  return { plot, record: { scenario: scenario.name, metric, series: stats.series,
    points: stats.points, bands: stats.bands }, expectedPoints };
}

function header(data) {
  const b = data.bench;
  const root = h('header');
  root.appendChild(h('h1', { text: b.description ? `avp bench: ${b.description}` : 'avp bench' }));
  root.appendChild(h('p', { class: 'facts' },
    `${b.scenarios.length} scenario(s) × ${b.planners.length} planner(s) × ${b.seeds} seed(s), ` +
    `${b.views} fused views, segmenter `, h('code', { text: b.segmenter }),
    `, ${formatNumber(b.voxel_size_m * 1e3)} mm voxels; revision `, h('code', { text: b.revision }),
    `; ${b.seconds == null ? '–' : b.seconds.toFixed(0)} s; ${b.episodes} episodes` +
    (b.failed ? `, ${b.failed} failed (left out of the statistics)` : '') + '.'));
  root.appendChild(h('p', { class: 'facts' },
    'Mean over seeds [95 % interval: a percentile bootstrap of the mean, within the ' +
    "metric's range; none below 2 seeds, \"small\" below 5], as summary.md and summary.csv " +
    'beside this page. ' +
    'found = fruits found / all fruits of the scene. Hover a plot for values; click a legend ' +
    'entry to hide a planner.'));
  const opts = Object.entries(b.run_options || {});
  if (opts.length) {
    root.appendChild(h('p', { class: 'facts' }, 'Run configuration over its defaults: ',
      ...opts.flatMap(([k, v], i) => [i ? ', ' : '', h('code', { text: `${k} = ${v}` })])));
  }
  for (const [p, o] of Object.entries(b.planner_options || {})) {
    root.appendChild(h('p', { class: 'facts' }, `${p} options over its defaults: `,
      ...Object.entries(o).flatMap(([k, v], i) => [i ? ', ' : '', h('code', { text: `${k} = ${v}` })])));
  }
  const nav = h('nav', {}, 'Scenarios: ');
  data.scenarios.forEach((s, i) => nav.appendChild(h('a', { href: `#scenario-${i}`, text: s.name })));
  root.appendChild(nav);
  return root;
}

function finalTable(data, scenario) {
  const views = data.bench.views;
  const rows = scenario.planners.map((p) => {
    const f = p.final;
    return [p.name, sampleSize(p.n), meanCi(f.f1), meanCi(f.f1_tol),
      `${num(f.fruits_found.mean, 1)} / ${num(f.fruits_total.mean, 1)}`,
      meanCi(f.fruits_found_fraction), num(f.plan_ms_mean, 0), num(f.episode_s_mean, 2),
      p.failed ? h('span', { class: 'failed', text: String(p.failed) }) : '0'];
  });
  return table(['planner', 'n', `F1 (exact) view ${views}`, 'F1 (±1 voxel)', 'fruits found',
    'found fraction', 'plan ms/step', 'episode s', 'failed'], rows);
}

function visibilitySection(scenario) {
  const out = h('div');
  const v = scenario.visibility;
  if (v && v.fruits > 0) {
    out.appendChild(h('p', {}, 'Fruits by their best visible fraction from a reachable ' +
      'observation view (all seeds): ' + v.levels.map((l, i) =>
      `≥ ${(100 * l).toFixed(0)} %: ${(100 * v.visible[i] / v.fruits).toFixed(1)} %`).join(', ') +
      '.'));
  }
  const first = scenario.planners.find((p) => p.visibility_bins.length);
  const binned = scenario.planners.reduce((a, p) =>
    a + p.visibility_bins.reduce((b, x) => b + x.fruits, 0), 0);
  if (!first || binned === 0) return out;
  out.appendChild(h('h3', { text: 'Fruits found at the final view by best visible fraction' }));
  out.appendChild(h('p', { class: 'muted', text: 'found / fruits over all seeds = fraction ' +
    '[Wilson 95 % interval], as fruits_by_visibility.csv.' }));
  const head = ['planner', ...first.visibility_bins.map((b) =>
    `[${b.lo.toFixed(2)}, ${b.hi.toFixed(2)}${b.hi >= 1 ? ']' : ')'}`)];
  const rows = scenario.planners.map((p) => [p.name, ...p.visibility_bins.map((b) =>
    (b.fruits === 0 ? '–' : `${b.found} / ${b.fruits} = ${num(b.fraction, 2)} ` +
      `[${num(b.ci_lo, 2)}, ${num(b.ci_hi, 2)}]`))]);
  out.appendChild(table(head, rows));
  return out;
}

function perViewTable(data, scenario, metric) {
  const views = data.bench.views;
  const head = ['planner', ...Array.from({ length: views }, (_, i) => String(i + 1))];
  const rows = scenario.planners.map((p) => {
    const pv = p.per_view[metric];
    return [p.name, ...Array.from({ length: views }, (_, i) => (pv ? meanCi({ mean: pv.mean[i],
      ci_lo: pv.ci_lo[i], ci_hi: pv.ci_hi[i], n: pv.n[i] }) : '–'))];
  });
  return table(head, rows);
}

/** The lead planner's paired differences over each other planner (two planners or more). */
function leadTable(data, scenario) {
  const leads = scenario.leads || [];
  if (!leads.length) return null;
  const box = h('div', { class: 'leads' });
  box.appendChild(h('h3', { text: `Lead of ${leads[0].planner}, paired by seed (view ` +
    `${data.bench.views})` }));
  box.appendChild(h('p', { class: 'muted', text: 'Its value minus the other planner\'s on the ' +
    'same seeds, mean [95 % interval]: ahead when the whole F1 interval is above 0, behind ' +
    'when below, tied when it holds 0; as summary.md.' }));
  const rows = leads.map((l) => [l.versus, sampleSize(l.f1.n), meanCi(l.f1, 3, true),
    meanCi(l.found, 3, true), h('span', { class: `verdict-${l.verdict.replace('/', '')}`,
      text: l.verdict })]);
  box.appendChild(table(['versus', 'seeds', 'F1 lead', 'found fraction lead', 'verdict'], rows,
    'lead'));
  return box;
}

function runsTable(scenario) {
  const rows = [];
  for (const p of scenario.planners) {
    for (const r of p.runs) {
      const links = h('span');
      const folder = `${r.folder}/`;
      if (r.files.includes('report.html')) {
        links.appendChild(h('a', { href: `${folder}report.html`, text: 'report.html' }));
      }
      links.appendChild(h('a', { href: folder, text: 'folder' }));
      for (const f of r.files) {
        if (f === 'report.html' || f === 'avp-state.json') continue;
        links.appendChild(h('a', { href: folder + f, text: f }));
      }
      rows.push([p.name, String(r.seed),
        r.ok ? 'ok' : h('span', { class: 'failed', text: `failed: ${r.status}` }),
        String(r.views), num(r.episode_s, 2), links]);
    }
  }
  const t = table(['planner', 'seed', 'status', 'views', 'episode s', 'run folder'], rows, 'runs');
  return h('details', {}, h('summary', { text: `Episodes (${rows.length}): run folders` }), t);
}

function scenarioSection(data, scenario, index) {
  const sec = h('section', { id: `scenario-${index}` });
  sec.appendChild(h('h2', { text: scenario.name }));
  sec.appendChild(finalTable(data, scenario));
  const lead = leadTable(data, scenario);
  if (lead) sec.appendChild(lead);
  const plots = h('div', { class: 'plots' });
  sec.appendChild(plots);
  for (const metric of ['f1', 'f1_tol', 'fruits_found_fraction']) {
    const box = h('div', { class: 'plot' });
    plots.appendChild(box);
    const r = metricPlot(box, data, scenario, metric);
    state.plots.push(r.record);
    state.expected.points.push(r.expectedPoints);
  }
  sec.appendChild(visibilitySection(scenario));

  // Any metric per view, on demand (not counted in plots: it is redrawn on each choice).
  const others = data.metrics.filter((m) => !['f1', 'f1_tol', 'fruits_found_fraction'].includes(m));
  if (others.length) {
    const box = h('div', { class: 'plot' });
    const select = h('select', {}, ...others.map((m) => h('option', { value: m, text: m })));
    const draw = () => {
      box.textContent = '';
      metricPlot(box, data, scenario, select.value);
      tableBox.textContent = '';
      tableBox.appendChild(perViewTable(data, scenario, select.value));
    };
    const tableBox = h('div');
    const details = h('details', {}, h('summary', { text: 'Other metrics per view' }),
      h('p', {}, 'metric: ', select), box, tableBox);
    select.addEventListener('change', draw);
    details.addEventListener('toggle', () => { if (details.open && !box.firstChild) draw(); });
    sec.appendChild(details);
  }
  sec.appendChild(h('h3', { text: 'F1 (exact) per fused view (mean [95 % interval])' }));
  sec.appendChild(perViewTable(data, scenario, 'f1'));
  sec.appendChild(runsTable(scenario));
  return sec;
}

function render() {
  const dataEl = document.getElementById('avp-bench-data');
  if (!dataEl) throw new Error('no <script id="avp-bench-data"> in the page');
  const data = JSON.parse(dataEl.textContent);
  if (data.format !== 'avp-bench-report') {
    throw new Error(`the embedded data is not an avp bench report (format ${data.format})`);
  }
  document.head.appendChild(h('style', { text: CSS }));
  const root = document.getElementById('avp-bench') || document.body.appendChild(
    h('div', { id: 'avp-bench' }));
  root.textContent = '';
  state.expected = {
    scenarios: data.scenarios.length,
    plots: 3 * data.scenarios.length,
    series: data.bench.planners.length,
    points: [],
  };
  root.appendChild(header(data));
  data.scenarios.forEach((s, i) => {
    root.appendChild(scenarioSection(data, s, i));
    state.scenarios += 1;
  });
}

function start() {
  try {
    render();
    state.ready = true;
  } catch (e) {
    state.error = String((e && e.stack) || e);
    const root = document.getElementById('avp-bench') || document.body;
    root.appendChild(h('pre', { id: 'avp-error', text: `The report could not be drawn: ${state.error}` }));
    console.error(e);
  }
}

if (document.readyState === 'loading') {
  document.addEventListener('DOMContentLoaded', start);
} else {
  start();
}
