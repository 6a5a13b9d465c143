// Small dependency-free line plots in SVG DOM: one line per series with a shaded confidence band,
// axes with ticks and grid, a legend (click a name to hide/show its series) and hover values.
// Shared by the bench report (bench.js) and the run report (run.js). See docs/report.md.
//
//   import { linePlot } from './plot.js';
//   const plot = linePlot(container, {
//     title: 'F1 per view', xLabel: 'fused views', yLabel: 'F1', yMin: 0, yMax: 1,
//     series: [{ name: 'aeplanner', x: [1, 2, 3], y: [0.1, 0.3, 0.5], band: [0.02, 0.03, 0.04] }],
//   });
//   plot.svg; plot.stats(); // {series, points, bands, hidden}
//
// A series' band is either `band` (half-width per point, e.g. a 95 % CI) or `lo` and `hi` (the
// band's ends per point). A non-finite y breaks the line; a non-finite band entry leaves a gap.

const SVG_NS = 'http://www.w3.org/2000/svg';

/** The palette of svg_plot.cpp (matplotlib's tab10), so the SVG files and the page agree. */
export const PALETTE = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2',
  '#7f7f7f', '#bcbd22', '#17becf'];

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG_NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (parent) parent.appendChild(e);
  return e;
}

function finite(v) {
  return typeof v === 'number' && Number.isFinite(v);
}

/** About `count` round tick values covering [lo, hi] (1, 2, 5 x 10^k steps). */
export function niceTicks(lo, hi, count = 5, integer = false) {
  if (!finite(lo) || !finite(hi)) return [];
  if (hi < lo) [lo, hi] = [hi, lo];
  if (hi === lo) {
    const d = lo === 0 ? 1 : Math.abs(lo) * 0.1;
    lo -= d;
    hi += d;
  }
  const raw = (hi - lo) / Math.max(1, count);
  const mag = 10 ** Math.floor(Math.log10(raw));
  let step = mag;
  for (const m of [1, 2, 5, 10]) {
    step = m * mag;
    if (step >= raw) break;
  }
  if (integer) step = Math.max(1, Math.round(step));
  const first = Math.ceil(lo / step - 1e-9) * step;
  const ticks = [];
  for (let t = first; t <= hi + step * 1e-9; t += step) {
    ticks.push(Math.abs(t) < step * 1e-9 ? 0 : Number(t.toPrecision(12)));
  }
  return ticks;
}

/** `v` for a tick or a hover line: up to 3 significant decimals, no trailing zeros. */
export function formatNumber(v, digits = 3) {
  if (!finite(v)) return '–';
  if (Number.isInteger(v)) return String(v);
  const a = Math.abs(v);
  if (a >= 1000 || a < 1e-3) return v.toPrecision(digits);
  return String(Number(v.toFixed(digits)));
}

function bandEnds(s, i) {
  if (Array.isArray(s.lo) && Array.isArray(s.hi)) return [s.lo[i], s.hi[i]];
  if (Array.isArray(s.band)) {
    const b = s.band[i];
    const y = s.y[i];
    if (finite(b) && finite(y)) return [y - b, y + b];
  }
  return [NaN, NaN];
}

function hasBand(s) {
  return (Array.isArray(s.lo) && Array.isArray(s.hi)) || Array.isArray(s.band);
}

/** Runs of consecutive indices where `ok(i)` holds (for lines and bands with gaps). */
function runs(n, ok) {
  const out = [];
  let cur = [];
  for (let i = 0; i < n; ++i) {
    if (ok(i)) {
      cur.push(i);
    } else if (cur.length) {
      out.push(cur);
      cur = [];
    }
  }
  if (cur.length) out.push(cur);
  return out;
}

function checkSpec(spec) {
  if (!spec || !Array.isArray(spec.series)) throw new Error('linePlot: spec.series must be an array');
  spec.series.forEach((s, k) => {
    if (!Array.isArray(s.x) || !Array.isArray(s.y) || s.x.length !== s.y.length) {
      throw new Error(`linePlot: series ${k} (${s.name}) needs x and y of equal length ` +
        `(x ${s.x && s.x.length}, y ${s.y && s.y.length})`);
    }
  });
}

/**
 * Draws a line plot into `container` (an HTML element) and returns
 * {svg, root, stats(), setHidden(name, hidden), hoverAt(x)}.
 *
 * spec: {title, xLabel, yLabel, series: [{name, x, y, band | lo+hi, color}], xMin, xMax, yMin,
 * yMax (default: from the data, bands included; the range is widened to include them unless
 * yFixed: true, which keeps exactly [yMin, yMax] and clips the rest), integerX (x ticks at whole numbers, default
 * true), width (default 640), height (default 360), format(v) for hover values}.
 */
export function linePlot(container, spec) {
  checkSpec(spec);
  const W = spec.width || 640;
  const H = spec.height || 360;
  const series = spec.series.map((s, k) => ({ ...s, color: s.color || PALETTE[k % PALETTE.length],
    hidden: false }));
  const fmt = spec.format || formatNumber;
  const integerX = spec.integerX !== false;

  // Data ranges (bands included).
  let xlo = Infinity, xhi = -Infinity, ylo = Infinity, yhi = -Infinity;
  for (const s of series) {
    s.x.forEach((x, i) => {
      if (!finite(x)) return;
      xlo = Math.min(xlo, x);
      xhi = Math.max(xhi, x);
      for (const v of [s.y[i], ...bandEnds(s, i)]) {
        if (finite(v)) {
          ylo = Math.min(ylo, v);
          yhi = Math.max(yhi, v);
        }
      }
    });
  }
  if (!finite(xlo)) [xlo, xhi] = [0, 1];
  if (!finite(ylo)) [ylo, yhi] = [0, 1];
  if (finite(spec.xMin)) xlo = spec.xMin;
  if (finite(spec.xMax)) xhi = spec.xMax;
  // yFixed: exactly [yMin, yMax], what lies outside clipped (a fraction's CI past 0 or 1).
  const fixedY = spec.yFixed === true && finite(spec.yMin) && finite(spec.yMax) &&
    spec.yMax > spec.yMin;
  if (fixedY) {
    [ylo, yhi] = [spec.yMin, spec.yMax];
  } else {
    if (finite(spec.yMin)) ylo = Math.min(spec.yMin, ylo);
    if (finite(spec.yMax)) yhi = Math.max(spec.yMax, yhi);
  }
  if (xhi === xlo) [xlo, xhi] = [xlo - 0.5, xhi + 0.5];
  const yTicks = niceTicks(ylo, yhi, 5);
  if (yTicks.length && !fixedY) {
    ylo = Math.min(ylo, yTicks[0]);
    yhi = Math.max(yhi, yTicks[yTicks.length - 1]);
  }
  if (yhi === ylo) yhi = ylo + 1;
  const xTicks = niceTicks(xlo, xhi, Math.min(10, Math.max(2, Math.round(xhi - xlo))), integerX)
    .filter((t) => t >= xlo - 1e-9 && t <= xhi + 1e-9);

  const m = { left: 56, right: 16, top: spec.title ? 30 : 12, bottom: 44 };
  const pw = W - m.left - m.right;
  const ph = H - m.top - m.bottom;
  const X = (x) => m.left + ((x - xlo) / (xhi - xlo)) * pw;
  const Y = (y) => m.top + (1 - (y - ylo) / (yhi - ylo)) * ph;

  const root = document.createElement('div');
  root.className = 'avp-plot';
  root.style.position = 'relative';
  root.style.display = 'inline-block';
  root.style.font = '12px sans-serif';
  const svg = el('svg', { width: W, height: H, viewBox: `0 0 ${W} ${H}`, role: 'img' });
  svg.style.display = 'block';
  root.appendChild(svg);
  if (spec.title) {
    el('title', {}, svg).textContent = spec.title;
    const t = el('text', { x: W / 2, y: 18, 'text-anchor': 'middle', 'font-size': 14,
      'font-weight': 'bold' }, svg);
    t.textContent = spec.title;
  }

  // Grid, axes, ticks.
  const axes = el('g', { class: 'axes', 'font-size': 11, fill: '#333' }, svg);
  for (const t of yTicks) {
    if (t < ylo - 1e-12 || t > yhi + 1e-12) continue;
    el('line', { x1: m.left, x2: m.left + pw, y1: Y(t), y2: Y(t), stroke: '#e4e4e4' }, axes);
    const lab = el('text', { x: m.left - 6, y: Y(t) + 4, 'text-anchor': 'end' }, axes);
    lab.textContent = formatNumber(t);
  }
  for (const t of xTicks) {
    el('line', { x1: X(t), x2: X(t), y1: m.top + ph, y2: m.top + ph + 4, stroke: '#333' }, axes);
    const lab = el('text', { x: X(t), y: m.top + ph + 16, 'text-anchor': 'middle' }, axes);
    lab.textContent = formatNumber(t);
  }
  el('rect', { x: m.left, y: m.top, width: pw, height: ph, fill: 'none', stroke: '#333' }, axes);
  if (spec.xLabel) {
    el('text', { x: m.left + pw / 2, y: H - 8, 'text-anchor': 'middle' }, axes).textContent =
      spec.xLabel;
  }
  if (spec.yLabel) {
    el('text', { x: 14, y: m.top + ph / 2, 'text-anchor': 'middle',
      transform: `rotate(-90 14 ${m.top + ph / 2})` }, axes).textContent = spec.yLabel;
  }

  // Bands first, then lines and markers (so every line is above every band).
  const clipId = `avp-clip-${Math.random().toString(36).slice(2)}`;
  const clip = el('clipPath', { id: clipId }, el('defs', {}, svg));
  // A little past the frame, so a line at the range's end is drawn whole.
  el('rect', { x: m.left - 3, y: m.top - 3, width: pw + 6, height: ph + 6 }, clip);
  const bandLayer = el('g', { class: 'bands', 'clip-path': `url(#${clipId})` }, svg);
  const lineLayer = el('g', { class: 'lines', 'clip-path': `url(#${clipId})` }, svg);
  let bandCount = 0;
  let pointCount = 0;
  // Each series narrower than the one before, so that equal curves stay visible (the later one
  // inside the earlier), as in the SVG files.
  const strokeWidth = (k) => Math.max(1.25, 3.5 - k);
  series.forEach((s, k) => { s.width = strokeWidth(k); });
  for (const s of series) {
    s.nodes = [];
    if (hasBand(s)) {
      for (const r of runs(s.x.length, (i) => finite(s.x[i]) && bandEnds(s, i).every(finite))) {
        const upper = r.map((i) => `${X(s.x[i])},${Y(bandEnds(s, i)[1])}`);
        const lower = r.slice().reverse().map((i) => `${X(s.x[i])},${Y(bandEnds(s, i)[0])}`);
        const p = el('polygon', { points: [...upper, ...lower].join(' '), fill: s.color,
          'fill-opacity': 0.18, stroke: 'none', class: 'band' }, bandLayer);
        p.dataset.series = s.name;
        s.nodes.push(p);
        ++bandCount;
      }
    }
    for (const r of runs(s.x.length, (i) => finite(s.x[i]) && finite(s.y[i]))) {
      const pl = el('polyline', { points: r.map((i) => `${X(s.x[i])},${Y(s.y[i])}`).join(' '),
        fill: 'none', stroke: s.color, 'stroke-width': s.width, class: 'line' }, lineLayer);
      pl.dataset.series = s.name;
      s.nodes.push(pl);
      for (const i of r) {
        const c = el('circle', { cx: X(s.x[i]), cy: Y(s.y[i]), r: s.width * 0.5 + 1.25, fill: s.color,
          class: 'point' }, lineLayer);
        s.nodes.push(c);
        ++pointCount;
      }
    }
  }

  // Legend: an HTML list under the plot; clicking a name hides or shows the series.
  const legend = document.createElement('div');
  legend.className = 'avp-plot-legend';
  legend.style.cssText = 'display:flex;flex-wrap:wrap;gap:4px 14px;margin:2px 0 0 56px;';
  const setHidden = (name, hidden) => {
    for (const s of series) {
      if (s.name !== name) continue;
      s.hidden = hidden;
      for (const n of s.nodes) n.style.display = hidden ? 'none' : '';
      if (s.legendItem) s.legendItem.style.opacity = hidden ? 0.35 : 1;
    }
  };
  for (const s of series) {
    if (!s.name) continue;
    const item = document.createElement('span');
    item.style.cssText = 'cursor:pointer;user-select:none;white-space:nowrap;';
    item.title = 'click to hide or show';
    const swatch = document.createElement('span');
    swatch.style.cssText = `display:inline-block;width:14px;height:${s.width}px;` +
      `background:${s.color};` +
      'vertical-align:middle;margin-right:5px;box-shadow:0 -4px 0 0 ' + s.color + '33, 0 4px 0 0 ' +
      s.color + '33;';
    item.appendChild(swatch);
    item.appendChild(document.createTextNode(s.name));
    item.addEventListener('click', () => setHidden(s.name, !s.hidden));
    s.legendItem = item;
    legend.appendChild(item);
  }
  root.appendChild(legend);

  // Hover: the nearest x with every visible series' value (and band) there.
  const guide = el('line', { y1: m.top, y2: m.top + ph, stroke: '#999', 'stroke-dasharray': '3 3',
    visibility: 'hidden' }, svg);
  const tip = document.createElement('div');
  tip.className = 'avp-plot-tip';
  tip.style.cssText = 'position:absolute;pointer-events:none;display:none;background:#fff;' +
    'border:1px solid #bbb;border-radius:3px;padding:4px 6px;box-shadow:0 1px 4px #0002;' +
    'white-space:nowrap;font:12px sans-serif;z-index:2;';
  root.appendChild(tip);
  const xs = [...new Set(series.flatMap((s) => s.x.filter(finite)))].sort((a, b) => a - b);
  const hoverAt = (x) => {
    if (!xs.length || !finite(x)) {
      guide.setAttribute('visibility', 'hidden');
      tip.style.display = 'none';
      return null;
    }
    let best = xs[0];
    for (const v of xs) if (Math.abs(v - x) < Math.abs(best - x)) best = v;
    const rows = [];
    for (const s of series) {
      if (s.hidden) continue;
      const i = s.x.indexOf(best);
      if (i < 0) continue;
      const [lo, hi] = bandEnds(s, i);
      let text = fmt(s.y[i]);
      if (Array.isArray(s.band) && finite(s.band[i])) text += ` ± ${fmt(s.band[i])}`;
      else if (finite(lo) && finite(hi)) text += ` [${fmt(lo)}, ${fmt(hi)}]`;
      if (s.hoverExtra) text += s.hoverExtra(i);
      rows.push({ name: s.name, color: s.color, text,
        y: finite(s.y[i]) ? Y(s.y[i]) : NaN });
    }
    guide.setAttribute('x1', X(best));
    guide.setAttribute('x2', X(best));
    guide.setAttribute('visibility', 'visible');
    tip.textContent = '';
    const head = document.createElement('div');
    head.style.fontWeight = 'bold';
    head.textContent = `${spec.xLabel || 'x'} ${formatNumber(best)}`;
    tip.appendChild(head);
    for (const r of rows) {
      const line = document.createElement('div');
      const dot = document.createElement('span');
      dot.style.cssText = `display:inline-block;width:8px;height:8px;border-radius:4px;` +
        `background:${r.color};margin-right:5px;`;
      line.appendChild(dot);
      line.appendChild(document.createTextNode(`${r.name}: ${r.text}`));
      tip.appendChild(line);
    }
    tip.style.display = 'block';
    const left = X(best) + 12;
    tip.style.left = `${left + tip.offsetWidth > W ? X(best) - 12 - tip.offsetWidth : left}px`;
    // Away from the values: at the bottom of the frame when they lie in its upper half (the
    // final values of a rising curve), at the top otherwise.
    const ys = rows.map((r) => r.y).filter(finite);
    const upper = ys.length && ys.reduce((a, b) => a + b, 0) / ys.length < m.top + ph / 2;
    tip.style.top = `${upper ? m.top + ph - 4 - tip.offsetHeight : m.top + 4}px`;
    return { x: best, rows };
  };
  const overlay = el('rect', { x: m.left, y: m.top, width: pw, height: ph, fill: 'transparent' },
    svg);
  overlay.addEventListener('mousemove', (ev) => {
    const r = svg.getBoundingClientRect();
    const px = ((ev.clientX - r.left) / r.width) * W;
    hoverAt(xlo + ((px - m.left) / pw) * (xhi - xlo));
  });
  overlay.addEventListener('mouseleave', () => hoverAt(NaN));

  container.appendChild(root);
  return {
    svg,
    root,
    setHidden,
    hoverAt,
    /** What was drawn: series, markers (points), band polygons, hidden series. */
    stats: () => ({ series: series.length, points: pointCount, bands: bandCount,
      hidden: series.filter((s) => s.hidden).length }),
  };
}
