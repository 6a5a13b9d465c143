// The run report's voxel data and colours (docs/report.md, "The data"), without three.js's
// scene: decoding each step's voxel changes, replaying them to any step, and the colour maps.
// Kept free of the DOM so that node can check it (tests/report_browser or by hand).
//
// A step's voxels: {set, removed, set_b64, removed_b64, occupied}. set_b64 holds `set` records
// of 10 bytes, little-endian: dx, dy, dz (u16, the key minus the page's origin_key), class (u8),
// confidence * 255 (u8), instance (u16); removed_b64 holds `removed` records of 6 bytes (dx, dy,
// dz). Applying steps 0..k in order gives the map's occupied voxels after view k + 1.

function bytesOf(b64) {
  if (!b64) return new Uint8Array(0);
  if (typeof atob === "function") {
    const s = atob(b64);
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }
  return new Uint8Array(Buffer.from(b64, "base64"));  // node
}

/** One step's changes as typed arrays: {set, sx, sy, sz, cls, conf, inst, removed, rx, ry, rz}. */
export function decodeVoxels(v) {
  const a = bytesOf(v.set_b64);
  const r = bytesOf(v.removed_b64);
  if (a.length !== v.set * 10) {
    throw new Error(`voxel data: ${a.length} bytes of set records, expected ${v.set} x 10`);
  }
  if (r.length !== v.removed * 6) {
    throw new Error(`voxel data: ${r.length} bytes of removed records, expected ${v.removed} x 6`);
  }
  const da = new DataView(a.buffer, a.byteOffset, a.byteLength);
  const dr = new DataView(r.buffer, r.byteOffset, r.byteLength);
  const out = {
    set: v.set, sx: new Uint16Array(v.set), sy: new Uint16Array(v.set), sz: new Uint16Array(v.set),
    cls: new Uint8Array(v.set), conf: new Uint8Array(v.set), inst: new Uint16Array(v.set),
    removed: v.removed, rx: new Uint16Array(v.removed), ry: new Uint16Array(v.removed),
    rz: new Uint16Array(v.removed),
  };
  for (let i = 0; i < v.set; i++) {
    const o = i * 10;
    out.sx[i] = da.getUint16(o, true);
    out.sy[i] = da.getUint16(o + 2, true);
    out.sz[i] = da.getUint16(o + 4, true);
    out.cls[i] = da.getUint8(o + 6);
    out.conf[i] = da.getUint8(o + 7);
    out.inst[i] = da.getUint16(o + 8, true);
  }
  for (let i = 0; i < v.removed; i++) {
    const o = i * 6;
    out.rx[i] = dr.getUint16(o, true);
    out.ry[i] = dr.getUint16(o + 2, true);
    out.rz[i] = dr.getUint16(o + 4, true);
  }
  return out;
}

const K = 65536;
const keyOf = (x, y, z) => x + K * (y + K * z);

/** The occupied voxels at any step: replays the decoded steps (forward from where it is, or
 *  from the start when going back). */
export class VoxelState {
  constructor(decoded) {
    this.decoded = decoded;
    this.map = new Map();  // key -> class | confidence << 8 | instance << 16
    this.step = -1;
  }
  goTo(k) {
    if (k < this.step) {
      this.map.clear();
      this.step = -1;
    }
    while (this.step < k) {
      const d = this.decoded[++this.step];
      for (let i = 0; i < d.removed; i++) this.map.delete(keyOf(d.rx[i], d.ry[i], d.rz[i]));
      for (let i = 0; i < d.set; i++) {
        this.map.set(keyOf(d.sx[i], d.sy[i], d.sz[i]),
          d.cls[i] | (d.conf[i] << 8) | (d.inst[i] * 65536));
      }
    }
  }
  get size() {
    return this.map.size;
  }
  /** fn(dx, dy, dz, class, confidence 0-255, instance) for every occupied voxel. */
  forEach(fn) {
    for (const [key, v] of this.map) {
      const x = key % K;
      const yz = (key - x) / K;
      const y = yz % K;
      const z = (yz - y) / K;
      fn(x, y, z, v & 0xff, (v >> 8) & 0xff, Math.floor(v / 65536));
    }
  }
}

// Colours write into `out` (an object with setRGB, e.g. THREE.Color) and return it.

/** Per class (SemanticClass order: background, fruit, leaf, stem, support, ground, other). */
const CLASS_RGB = [[0.62, 0.62, 0.62], [0.86, 0.12, 0.10], [0.20, 0.62, 0.17],
  [0.55, 0.36, 0.16], [0.45, 0.45, 0.75], [0.65, 0.55, 0.40], [0.85, 0.65, 0.10]];

export function classColor(cls, out) {
  const c = CLASS_RGB[cls] || [0.3, 0.3, 0.3];
  return out.setRGB(c[0], c[1], c[2]);
}

/** A distinct colour per instance id (golden-ratio hues); grey for none (0). */
export function instanceColor(instance, out) {
  if (!instance) return out.setRGB(0.75, 0.75, 0.75);
  const hue = (instance * 0.618033988749895) % 1;
  return hsl(hue, 0.75, 0.5, out);
}

function hsl(hh, s, l, out) {
  const f = (n) => {
    const k = (n + hh * 12) % 12;
    const a = s * Math.min(l, 1 - l);
    return l - a * Math.max(-1, Math.min(k - 3, 9 - k, 1));
  };
  return out.setRGB(f(0), f(8), f(4));
}

// viridis at 0, .25, .5, .75, 1
const VIRIDIS = [[0.267, 0.005, 0.329], [0.229, 0.322, 0.546], [0.128, 0.567, 0.551],
  [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];

function ramp(stops, t, out) {
  t = Math.max(0, Math.min(1, Number.isFinite(t) ? t : 0));
  const x = t * (stops.length - 1);
  const i = Math.min(stops.length - 2, Math.floor(x));
  const f = x - i;
  const a = stops[i];
  const b = stops[i + 1];
  return out.setRGB(a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, a[2] + (b[2] - a[2]) * f);
}

/** Confidence 0-255 on viridis; light grey for voxels without a class. */
export function confidenceColor(cls, confidence, out) {
  if (!cls) return out.setRGB(0.73, 0.73, 0.73);
  return ramp(VIRIDIS, confidence / 255, out);
}

// Candidates: low utility blue, high utility orange-red (a "coolwarm"-like ramp).
const UTILITY = [[0.23, 0.30, 0.75], [0.55, 0.69, 0.99], [0.87, 0.87, 0.87], [0.96, 0.60, 0.48],
  [0.71, 0.02, 0.15]];

/** t in [0, 1]: the candidate's utility within its step's range. */
export function utilityColor(t, out) {
  return ramp(UTILITY, t, out);
}
