// Node unit test of web/sun.js (the JS port of render/scene/sun.cpp; docs/sun.md):
//   - the shared synthetic map (tests/data/s10_sun_synthetic.json) gives the C++ figures
//     recorded there (tests/test_s10_sun.cpp checks the same numbers) and the closed form;
//   - the same map stored as half floats (as three.js's EXRLoader delivers it, 4 channels)
//     gives the same split to half precision, and the fill is a half value;
//   - constant, black and weak maps give no sun; bad mode values name the field;
//   - sun mode 'panels' (splitEnvironment): the shared map tests/data/s21_panels_synthetic.json
//     gives the C++ figures of every light recorded there (tests/test_s21_panels.cpp), the split
//     conserves the map's power, and the half-float bottom-up copy splits the same.
// Usage: node web/test/sun.test.mjs   (exits non-zero on a failure)
import assert from 'node:assert/strict';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { detectSun, parseSunMode, splitEnvironment, MAX_PANEL_LIGHTS } from '../sun.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '..', '..');
const spec = JSON.parse(fs.readFileSync(path.join(repo, 'tests', 'data', 's10_sun_synthetic.json'), 'utf8'));
let checks = 0;
const near = (a, b, tol, what) => { assert.ok(Math.abs(a - b) <= tol, `${what}: ${a} vs ${b} (tolerance ${tol})`); checks++; };

// Environment::UvToDirection (the toolkit's equirect convention).
const uvToDir = (u, v) => {
  const phi = (u - 0.5) * 2 * Math.PI, e = (v - 0.5) * Math.PI;
  return [Math.cos(e) * Math.cos(phi), Math.sin(e), Math.cos(e) * Math.sin(phi)];
};
// The map's formula, as in the C++ test (float32 storage).
function synthetic(channels = 3) {
  const { width: W, height: H, map: m } = spec;
  const c = uvToDir(m.u, m.elevation_deg / 180 + 0.5);
  const cosR = Math.cos(m.radius_deg * Math.PI / 180);
  const px = new Float32Array(W * H * channels);
  for (let j = 0; j < H; ++j) {
    for (let i = 0; i < W; ++i) {
      const d = uvToDir((i + 0.5) / W, 1 - (j + 0.5) / H);
      const inDisc = d[0] * c[0] + d[1] * c[1] + d[2] * c[2] >= cosR;
      for (let k = 0; k < 3; ++k) px[(j * W + i) * channels + k] = inDisc ? m.sun[k] : m.sky[k] * (1 + 0.5 * d[1]) + 0.01 * (i % 7);
      if (channels === 4) px[(j * W + i) * 4 + 3] = 1;
    }
  }
  return px;
}

const e = spec.expected;
const px = synthetic();
const s = detectSun(px, spec.width, spec.height, { intensity: spec.intensity, rotationY: spec.rotation_y });
assert.equal(s.found, e.found, s.summary); checks++;
assert.equal(s.texels, e.texels, s.summary); checks++;
for (let k = 0; k < 3; ++k) {
  near(s.irradiance[k], e.irradiance[k], 1e-6 * e.irradiance[k], `irradiance[${k}]`);
  near(s.worldDirection[k], e.world_direction[k], 1e-6, `worldDirection[${k}]`);
  assert.equal(Math.fround(s.fill[k]), Math.fround(e.fill[k]), `fill[${k}]`); checks++;
}
near(s.powerFraction, e.power_fraction, 1e-6, 'powerFraction');
near(s.solidAngle, e.solid_angle, 1e-12, 'solidAngle');
// Closed form: (sun - fill) x the disc texels' solid angle x intensity.
for (let k = 0; k < 3; ++k) near(s.irradiance[k], spec.intensity * (spec.map.sun[k] - s.fill[k]) * e.solid_angle, 1e-9 * s.irradiance[k], `closed form [${k}]`);

// Half floats, RGBA (what EXRLoader gives three.js by default): a half-rounded copy of the map.
const toHalf = (x) => {  // IEEE binary16, round to nearest even (finite, normal range here)
  const f = new Float32Array([x]), u = new Uint32Array(f.buffer)[0];
  const sign = (u >>> 16) & 0x8000, exp = ((u >>> 23) & 0xff) - 127 + 15, mant = u & 0x7fffff;
  if (exp <= 0) return sign;  // flush tiny values (not in this map)
  let h = sign | (exp << 10) | (mant >>> 13);
  const rest = mant & 0x1fff;
  if (rest > 0x1000 || (rest === 0x1000 && (h & 1))) h += 1;
  return h;
};
const fromHalf = (h) => {
  const s = h & 0x8000 ? -1 : 1, ex = (h >>> 10) & 0x1f, m = h & 0x3ff;
  if (ex === 0) return s * m * 2 ** -24;
  if (ex === 31) return m ? NaN : s * Infinity;
  return s * (1 + m / 1024) * 2 ** (ex - 15);
};
const rgba = synthetic(4);
const half = Uint16Array.from(rgba, toHalf);
const sh = detectSun(half, spec.width, spec.height, { channels: 4, intensity: spec.intensity, rotationY: spec.rotation_y, decode: fromHalf });
assert.equal(sh.found, true, sh.summary); checks++;
assert.equal(sh.texels, e.texels); checks++;
for (let k = 0; k < 3; ++k) {
  near(sh.irradiance[k], e.irradiance[k], 2e-3 * e.irradiance[k], `half irradiance[${k}]`);
  near(sh.worldDirection[k], e.world_direction[k], 1e-3, `half worldDirection[${k}]`);
  assert.equal(fromHalf(toHalf(sh.fill[k])), sh.fill[k], `half fill[${k}] is a half value`); checks++;
}

// No sun: constant, black, weak (1 % of the power).
const W = 256, H = 128;
assert.equal(detectSun(new Float32Array(W * H * 3).fill(0.7), W, H).found, false); checks++;
const black = detectSun(new Float32Array(W * H * 3), W, H);
assert.equal(black.found, false); assert.match(black.summary, /black/); checks++;
const weak = synthetic();
for (let t = 0; t < weak.length; ++t) if (weak[t] >= 1000) weak[t] = weak[t] / 200;  // the disc at ~20
const w = detectSun(weak, spec.width, spec.height);
assert.equal(w.found, false, w.summary); assert.match(w.summary, /too weak/); checks++;

assert.equal(parseSunMode('auto'), 'auto'); checks++;
assert.equal(parseSunMode('panels'), 'panels'); checks++;
assert.throws(() => parseSunMode('maybe', 'environment.sun'), /environment\.sun: expected "auto", "off" or "panels", got "maybe"/); checks++;
console.log(`web/test/sun.test.mjs: ${checks} checks passed (${s.summary})`);
{
  // Bottom-up storage (three.js's EXRLoader): the same split, sun texels as storage indices.
  const { width: W2, height: H2 } = spec;
  const flipped = new Float32Array(px.length);
  for (let j = 0; j < H2; ++j) flipped.set(px.subarray(j * W2 * 3, (j + 1) * W2 * 3), (H2 - 1 - j) * W2 * 3);
  const f = detectSun(flipped, W2, H2, { intensity: spec.intensity, rotationY: spec.rotation_y, rowsBottomUp: true });
  for (let k = 0; k < 3; ++k) near(f.irradiance[k], s.irradiance[k], 1e-12 * s.irradiance[k], `bottom-up irradiance[${k}]`);
  for (const t of f.sunTexels) assert.ok(flipped[t * 3] >= 1000, `bottom-up sun texel ${t}`);
  console.log(`web/test/sun.test.mjs: bottom-up storage checked (${f.sunTexels.length} texels)`);
}

{
  // Sun mode 'panels' on the shared map of tests/data/s21_panels_synthetic.json.
  const ps = JSON.parse(fs.readFileSync(path.join(repo, 'tests', 'data', 's21_panels_synthetic.json'), 'utf8'));
  const { width: W3, height: H3 } = ps;
  const centres = ps.sources.map((q) => ({ ...q, c: uvToDir(q.u, q.elevation_deg / 180 + 0.5), cosR: Math.cos(q.radius_deg * Math.PI / 180) }));
  const map = (channels) => {  // the C++ test's SourcesMap
    const out = new Float32Array(W3 * H3 * channels);
    for (let j = 0; j < H3; ++j) {
      for (let i = 0; i < W3; ++i) {
        const d = uvToDir((i + 0.5) / W3, 1 - (j + 0.5) / H3);
        const hit = centres.find((q) => d[0] * q.c[0] + d[1] * q.c[1] + d[2] * q.c[2] >= q.cosR);
        for (let k = 0; k < 3; ++k) out[(j * W3 + i) * channels + k] = hit ? hit.radiance[k] : ps.sky[k] * (1 + 0.5 * d[1]) + 0.01 * (i % 7);
        if (channels === 4) out[(j * W3 + i) * 4 + 3] = 1;
      }
    }
    return out;
  };
  const m3 = map(3);
  const opts = { intensity: ps.intensity, rotationY: ps.rotation_y };
  const sp = splitEnvironment(m3, W3, H3, { ...opts, mode: 'panels' });
  assert.equal(sp.sun.found, ps.expected_sun, sp.summary); checks++;
  assert.equal(sp.lights.length, ps.expected.length, sp.summary); checks++;
  sp.lights.forEach((l, n) => {
    const x = ps.expected[n];
    assert.equal(l.texels, x.texels, `panels light ${n} texels`); checks++;
    for (let k = 0; k < 3; ++k) {
      near(l.irradiance[k], x.irradiance[k], 1e-6 * x.irradiance[k], `panels light ${n} irradiance[${k}]`);
      near(l.worldDirection[k], x.world_direction[k], 1e-6, `panels light ${n} worldDirection[${k}]`);
      assert.equal(Math.fround(l.fill[k]), Math.fround(x.fill[k]), `panels light ${n} fill[${k}]`); checks++;
    }
  });
  // auto finds the sun only; off nothing; the input is not modified.
  const au = splitEnvironment(m3, W3, H3, { ...opts, mode: 'auto' });
  assert.equal(au.lights.length, ps.expected_sun ? 1 : 0, au.summary); checks++;
  assert.equal(splitEnvironment(m3, W3, H3, { ...opts, mode: 'off' }).data, null); checks++;
  assert.deepEqual(m3, map(3)); checks++;
  // Power: the split map's + every light's luminance excess (stored units) = the map's.
  const power = (px, ch = 3) => {
    let p = 0;
    for (let j = 0; j < H3; ++j) {
      const dw = (2 * Math.PI / W3) * (Math.sin(Math.PI / 2 - Math.PI * j / H3) - Math.sin(Math.PI / 2 - Math.PI * (j + 1) / H3));
      for (let i = 0; i < W3; ++i) { const t = (j * W3 + i) * ch; p += (0.2126 * px[t] + 0.7152 * px[t + 1] + 0.0722 * px[t + 2]) * dw; }
    }
    return p;
  };
  const eLum = sp.lights.reduce((a, l) => a + (0.2126 * l.irradiance[0] + 0.7152 * l.irradiance[1] + 0.0722 * l.irradiance[2]) / ps.intensity, 0);
  near(power(sp.data) + eLum, power(m3), 1e-9 * power(m3), 'panels power identity');
  // Half floats, RGBA, bottom-up (what three.js's EXRLoader gives): the same lights to half precision.
  const m4 = map(4);
  const flipped = new Float32Array(m4.length);
  for (let j = 0; j < H3; ++j) flipped.set(m4.subarray(j * W3 * 4, (j + 1) * W3 * 4), (H3 - 1 - j) * W3 * 4);
  const hb = splitEnvironment(Uint16Array.from(flipped, toHalf), W3, H3, { ...opts, mode: 'panels', channels: 4, rowsBottomUp: true, decode: fromHalf, encode: toHalf });
  assert.equal(hb.lights.length, sp.lights.length, hb.summary); checks++;
  hb.lights.forEach((l, n) => {
    for (let k = 0; k < 3; ++k) {
      near(l.irradiance[k], sp.lights[n].irradiance[k], 2e-3 * sp.lights[n].irradiance[k], `half bottom-up light ${n} irradiance[${k}]`);
      near(l.worldDirection[k], sp.lights[n].worldDirection[k], 1e-3, `half bottom-up light ${n} worldDirection[${k}]`);
    }
  });
  // The limit: ten boxes give MAX_PANEL_LIGHTS panels.
  const ten = new Float32Array(W3 * H3 * 3);
  const boxes = Array.from({ length: 10 }, (_, k) => ({ c: uvToDir((k + 0.5) / 10, 12 / 180 + 0.5), cosR: Math.cos(4 * Math.PI / 180), L: 20 + k }));
  for (let j = 0; j < H3; ++j) for (let i = 0; i < W3; ++i) {
    const d = uvToDir((i + 0.5) / W3, 1 - (j + 0.5) / H3);
    const hit = boxes.find((q) => d[0] * q.c[0] + d[1] * q.c[1] + d[2] * q.c[2] >= q.cosR);
    for (let k = 0; k < 3; ++k) ten[(j * W3 + i) * 3 + k] = hit ? hit.L : ps.sky[k] * (1 + 0.5 * d[1]) + 0.01 * (i % 7);
  }
  const tp = splitEnvironment(ten, W3, H3, { mode: 'panels' });
  assert.equal(tp.panels.length, MAX_PANEL_LIGHTS, tp.summary); checks++;
  console.log(`web/test/sun.test.mjs: panels checked (${sp.lights.length} lights on the shared map; ${checks} checks in all)`);
}
