// web/sun.js: split a compact sun off an equirect environment into a directional light, a
// line-by-line port of render/scene/sun.cpp (DetectSun; conventions, detection and the
// numbers' reasons in render/scene/sun.h and docs/sun.md). Change both together; the node test
// web/test/sun.test.mjs and the C++ test S10Sun.SharedSyntheticMapMatchesTheRecordedFigures
// check the same synthetic map (tests/data/s10_sun_synthetic.json).
//
// No three.js dependency: web/clothfit.js applies the result (sun-free texture for the PMREM,
// a THREE.DirectionalLight).

export const SUN_DETECT_DEFAULTS = Object.freeze({
  maxRadiusDeg: 3.0,        // angular radius of the window a sun must fit in
  contrast: 10.0,           // T = contrast x the annulus's median luminance
  minPowerFraction: 0.05,   // the sun's share of the map's luminance power
  maxAnnulusExcess: 0.1,    // annulus excess above T / sun excess
  minAnnulusTexels: 8,
});

// Panels (sun mode 'panels', render/scene/sun.h kPanelDetectParams / kMaxPanelLights; why in
// docs/sun.md "Panels"): after the auto sun, detectSun again on the map with everything found so
// far filled, up to MAX_PANEL_LIGHTS times, with a wider window, a lower contrast, no
// compactness test and a lower power share.
export const PANEL_DETECT_PARAMS = Object.freeze({
  maxRadiusDeg: 8.0,
  contrast: 5.0,
  minPowerFraction: 0.02,
  maxAnnulusExcess: Infinity,
  minAnnulusTexels: 8,
});
export const MAX_PANEL_LIGHTS = 8;

const KY = [0.2126, 0.7152, 0.0722];  // Rec.709 luminance
const clean = (x) => (Number.isFinite(x) && x > 0 ? x : 0);
function lowerMedian(v) {
  // Lower median (sorted element (n - 1) / 2), as std::nth_element picks it in the C++.
  const s = Float64Array.from(v).sort();
  return s[(s.length - 1) >> 1];
}

/**
 * Detect (and describe) the sun of an equirect map.
 * data: texels, top row first (rowsBottomUp: bottom row first, as three.js's EXRLoader and
 *   HDRLoader store them), `channels` values per texel (RGB first), read through `decode`
 *   (e.g. THREE.DataUtils.fromHalfFloat for a HalfFloat texture; default: as is).
 *   sunTexels are texel indices into `data` (storage order).
 * Returns {found, summary, powerFraction, annulusExcessRatio, texels, solidAngle, mapDirection,
 *   worldDirection, irradiance, fill, mapPower, sunTexels}; see render/scene/sun.h SunSplit.
 * Light: THREE.DirectionalLight with color = irradiance / max, intensity = max (irradiance at
 *   normal incidence, x the environment intensity), shining FROM worldDirection.
 */
export function detectSun(data, width, height, { channels = 3, intensity = 1, rotationY = 0, decode = null, rowsBottomUp = false, params = {} } = {}) {
  const p = { ...SUN_DETECT_DEFAULTS, ...params };
  const W = width, H = height, n = W * H;
  // t: texel index in the map's convention (top row first); st(t): its index in `data`.
  const st = rowsBottomUp ? (t) => (H - 1 - Math.floor(t / W)) * W + (t % W) : (t) => t;
  const get = decode ? (t, c) => clean(decode(data[st(t) * channels + c])) : (t, c) => clean(data[st(t) * channels + c]);
  const s = {
    found: false, summary: '', powerFraction: 0, annulusExcessRatio: 0, texels: 0, solidAngle: 0,
    mapDirection: [0, 1, 0], worldDirection: [0, 1, 0], irradiance: [0, 0, 0], fill: [0, 0, 0], mapPower: 0, sunTexels: [],
  };
  const dw = new Float64Array(H), cosE = new Float64Array(H), sinE = new Float64Array(H);
  for (let j = 0; j < H; ++j) {
    const eTop = Math.PI / 2 - Math.PI * j / H, eBot = Math.PI / 2 - Math.PI * (j + 1) / H;
    dw[j] = (2.0 * Math.PI / W) * (Math.sin(eTop) - Math.sin(eBot));
    const e = Math.PI / 2 - Math.PI * (j + 0.5) / H;
    cosE[j] = Math.cos(e);
    sinE[j] = Math.sin(e);
  }
  const cosP = new Float64Array(W), sinP = new Float64Array(W);
  for (let i = 0; i < W; ++i) {
    const phi = ((i + 0.5) / W - 0.5) * 2.0 * Math.PI;
    cosP[i] = Math.cos(phi);
    sinP[i] = Math.sin(phi);
  }
  const Y = new Float64Array(n);
  let P = 0, peakY = 0, peak = 0;
  for (let j = 0; j < H; ++j) {
    for (let i = 0; i < W; ++i) {
      const t = j * W + i;
      const y = KY[0] * get(t, 0) + KY[1] * get(t, 1) + KY[2] * get(t, 2);
      Y[t] = y;
      P += y * dw[j];
      if (y > peakY) { peakY = y; peak = t; }
    }
  }
  s.mapPower = P;
  if (!(P > 0)) { s.summary = 'no sun: the map is black'; return s; }
  const pj = Math.floor(peak / W), pi = peak % W;
  const dirOf = (t) => { const j = Math.floor(t / W), i = t % W; return [cosE[j] * cosP[i], sinE[j], cosE[j] * sinP[i]]; };
  const d0 = dirOf(peak);
  const r = p.maxRadiusDeg * Math.PI / 180;
  const cosIn = Math.cos(r), cosOut = Math.cos(Math.min(Math.PI, 2 * r));
  const dp = [0, 0, 0];
  for (let t = 0; t < n; ++t) {
    const d = dirOf(t);
    if (Y[t] >= 0.5 * peakY && d[0] * d0[0] + d[1] * d0[1] + d[2] * d0[2] >= cosIn) for (let k = 0; k < 3; ++k) dp[k] += Y[t] * d[k];
  }
  const dn = Math.sqrt(dp[0] * dp[0] + dp[1] * dp[1] + dp[2] * dp[2]);
  for (let k = 0; k < 3; ++k) dp[k] /= dn;
  const inner = [], ring = [];
  for (let j = 0; j < H; ++j) {
    for (let i = 0; i < W; ++i) {
      const c = cosE[j] * cosP[i] * dp[0] + sinE[j] * dp[1] + cosE[j] * sinP[i] * dp[2];
      const t = j * W + i;
      if (c >= cosIn) inner.push(t);
      else if (c >= cosOut) ring.push(t);
    }
  }
  if (ring.length < p.minAnnulusTexels) {
    s.summary = `no sun: the map is too coarse (${ring.length} texels in the annulus, fewer than ${p.minAnnulusTexels})`;
    return s;
  }
  for (let k = 0; k < 3; ++k) s.fill[k] = lowerMedian(ring.map((t) => get(t, k)));
  const B = lowerMedian(ring.map((t) => Y[t]));
  const T = p.contrast * B;
  const fillY = KY[0] * s.fill[0] + KY[1] * s.fill[1] + KY[2] * s.fill[2];
  const ex = [0, 0, 0], dir = [0, 0, 0];
  let exY = 0, ringEx = 0;
  for (const t of inner) {
    const y = Y[t];
    if (!(y > T)) continue;
    const j = Math.floor(t / W), i = t % W;
    const w = dw[j];
    s.sunTexels.push(st(t));
    s.solidAngle += w;
    for (let k = 0; k < 3; ++k) ex[k] += (get(t, k) - s.fill[k]) * w;
    const wy = (y - fillY) * w;
    exY += wy;
    dir[0] += wy * cosE[j] * cosP[i];
    dir[1] += wy * sinE[j];
    dir[2] += wy * cosE[j] * sinP[i];
  }
  for (const t of ring) if (Y[t] > T) ringEx += (Y[t] - B) * dw[Math.floor(t / W)];
  s.texels = s.sunTexels.length;
  s.powerFraction = exY / P;
  s.annulusExcessRatio = exY > 0 ? ringEx / exY : 0;
  const norm = Math.sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  if (norm > 0) s.mapDirection = [dir[0] / norm, dir[1] / norm, dir[2] / norm];
  const cr = Math.cos(rotationY), sr = Math.sin(rotationY);  // Environment::MapToWorld
  const m = s.mapDirection;
  s.worldDirection = [cr * m[0] + sr * m[2], m[1], -sr * m[0] + cr * m[2]];
  for (let k = 0; k < 3; ++k) s.irradiance[k] = Math.max(0, ex[k]) * intensity;
  const where = `peak ${peakY.toPrecision(4)} at elevation ${(90 - 180 * (pj + 0.5) / H).toFixed(1)} deg, u ${((pi + 0.5) / W).toFixed(3)}; candidate ${s.texels} texels, ${s.solidAngle.toPrecision(3)} sr, power share ${s.powerFraction.toFixed(4)}, annulus excess ratio ${s.annulusExcessRatio.toFixed(3)}`;
  const none = (why) => { s.summary = `no sun: ${why} (${where})`; s.sunTexels = []; return s; };
  if (s.texels === 0 || !(exY > 0) || !(norm > 0)) return none(`nothing above ${T.toPrecision(4)} x the annulus median`);
  if (s.annulusExcessRatio > p.maxAnnulusExcess) return none('not compact');
  if (s.powerFraction < p.minPowerFraction) return none('too weak');
  s.found = true;
  s.summary = `sun: ${where}, E = (${s.irradiance.map((x) => x.toPrecision(4)).join(', ')}), world direction (${s.worldDirection.map((x) => x.toFixed(4)).join(', ')})`;
  return s;
}

/** "auto" | "off" | "panels" (a scene card's environment.sun); anything else throws naming the field. */
export function parseSunMode(value, field = 'environment.sun') {
  if (value === 'auto' || value === 'off' || value === 'panels') return value;
  throw new Error(`${field}: expected "auto", "off" or "panels", got ${JSON.stringify(value)}`);
}

/**
 * The split of a map in a sun mode (render/scene/sun.cpp SplitEnvironmentSun): the auto sun,
 * then ('panels') up to MAX_PANEL_LIGHTS panels, each detected on the map with the earlier
 * sources filled. Arguments as detectSun's; `encode` maps a fill value to the storage type
 * (THREE.DataUtils.toHalfFloat for a HalfFloat texture; default: as is).
 * Returns {sun, panels, lights, summary, data}: `sun` = detectSun's result, `panels` the panels
 * found (detectSun results), `lights` = the found ones in light order (the sun, then the panels),
 * `data` = a copy of the texels with every light's texels set to its fill (null when nothing
 * was found, or mode 'off').
 */
export function splitEnvironment(data, width, height, { mode = 'auto', channels = 3, intensity = 1, rotationY = 0, decode = null, encode = null, rowsBottomUp = false } = {}) {
  parseSunMode(mode, 'sun mode');
  const out = { sun: null, panels: [], lights: [], summary: 'no sun: off', data: null };
  if (mode === 'off') return out;
  const opts = { channels, intensity, rotationY, decode, rowsBottomUp };
  let cur = data;
  const take = (split) => {
    if (cur === data) cur = data.slice();
    const fill = split.fill.map((x) => (encode ? encode(x) : x));
    for (const t of split.sunTexels) for (let k = 0; k < 3; ++k) cur[t * channels + k] = fill[k];
    out.lights.push(split);
  };
  out.sun = detectSun(cur, width, height, opts);
  out.summary = out.sun.summary;
  if (out.sun.found) take(out.sun);
  if (mode === 'panels') {
    let stop = '';
    for (let k = 0; k < MAX_PANEL_LIGHTS; ++k) {
      const p = detectSun(cur, width, height, { ...opts, params: PANEL_DETECT_PARAMS });
      if (!p.found) { stop = p.summary; break; }
      out.panels.push(p);
      take(p);
    }
    out.summary += `; panels: ${out.panels.length}`;
    out.panels.forEach((p, k) => { out.summary += `; panel ${k + 1}: ${p.summary.replace(/^sun: /, '')}`; });
    if (stop && out.panels.length < MAX_PANEL_LIGHTS) out.summary += `; then ${stop}`;
  }
  if (out.lights.length) out.data = cur;
  return out;
}
