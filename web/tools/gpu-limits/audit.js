// web/tools/gpu-limits page (loaded by run-audit.mjs): builds each plan case with web/clothfit.js's
// public API, renders once, and measures the fabric material's linked program (and every other
// program drawn):
//  - active uniforms per STAGE, from two probe programs linked on the same context:
//      vertex stage   = active uniforms of (the real vertex shader + a trivial fragment shader)
//      fragment stage = active uniforms of (the real vertex shader with its main() body emptied +
//                       the real fragment shader)
//    samplers counted per array element; value uniforms counted two ways:
//      naive  = 1 vector per element of float/int/bool/vecN, mat3 = 3, mat4 = 4 (struct members
//               each on their own: getActiveUniform lists every member)
//      packed = the smallest N for which the packing rule of GLSL ES 1.00 Appendix A.7 (the
//               rule WebGL implementations enforce; glsl-count.js fits()) accepts the set, samplers excluded
//  - varyings: the fragment shader's inputs after a small preprocessor (#if/#ifdef/#define), kept
//    when the name is used beyond its declaration; vectors naive (1 per element) and packed (same
//    packer); gl_FragCoord / gl_FrontFacing use noted.
import * as THREE from 'three';
import { loadSceneCard, fetchClothfitPreset, applyLightMap, lightMapTextureFromExr } from '../../clothfit.js';
import { packedRows, varyings } from './glsl-count.js';

const post = (p, body) => fetch(p, { method: 'POST', body });
const log = (m) => post('/log', String(m));
const fsUrl = (p) => (p.startsWith('/') ? `/fs${p}` : p);

// ---- GL type tables ----
let gl;
const T = {};
function initTypes() {
  const v = (name, rows, comps) => { if (gl[name] !== undefined) T[gl[name]] = { name, rows, comps, sampler: false }; };
  const s = (name) => { if (gl[name] !== undefined) T[gl[name]] = { name, sampler: true }; };
  for (const [n, c] of [['FLOAT', 1], ['FLOAT_VEC2', 2], ['FLOAT_VEC3', 3], ['FLOAT_VEC4', 4], ['INT', 1], ['INT_VEC2', 2], ['INT_VEC3', 3], ['INT_VEC4', 4],
    ['BOOL', 1], ['BOOL_VEC2', 2], ['BOOL_VEC3', 3], ['BOOL_VEC4', 4], ['UNSIGNED_INT', 1], ['UNSIGNED_INT_VEC2', 2], ['UNSIGNED_INT_VEC3', 3], ['UNSIGNED_INT_VEC4', 4]]) v(n, 1, c);
  v('FLOAT_MAT2', 2, 4); v('FLOAT_MAT3', 3, 3); v('FLOAT_MAT4', 4, 4);
  v('FLOAT_MAT2x3', 3, 3); v('FLOAT_MAT3x2', 3, 3); v('FLOAT_MAT2x4', 4, 4); v('FLOAT_MAT4x2', 4, 4); v('FLOAT_MAT3x4', 4, 4); v('FLOAT_MAT4x3', 4, 4);
  for (const n of ['SAMPLER_2D', 'SAMPLER_3D', 'SAMPLER_CUBE', 'SAMPLER_2D_SHADOW', 'SAMPLER_2D_ARRAY', 'SAMPLER_2D_ARRAY_SHADOW', 'SAMPLER_CUBE_SHADOW',
    'INT_SAMPLER_2D', 'INT_SAMPLER_3D', 'INT_SAMPLER_CUBE', 'INT_SAMPLER_2D_ARRAY', 'UNSIGNED_INT_SAMPLER_2D', 'UNSIGNED_INT_SAMPLER_3D', 'UNSIGNED_INT_SAMPLER_CUBE', 'UNSIGNED_INT_SAMPLER_2D_ARRAY']) s(n);
}

function activeUniforms(prog) {
  const out = [];
  const n = gl.getProgramParameter(prog, gl.ACTIVE_UNIFORMS);
  for (let k = 0; k < n; ++k) { const u = gl.getActiveUniform(prog, k); out.push({ name: u.name, t: T[u.type] ?? { name: `0x${u.type.toString(16)}`, rows: 1, comps: 4, sampler: false }, size: u.size }); }
  return out;
}
function summarize(list) {
  const samplers = list.filter((u) => u.t.sampler), values = list.filter((u) => !u.t.sampler);
  return {
    samplers: samplers.reduce((a, u) => a + u.size, 0),
    samplerList: samplers.map((u) => `${u.name.replace(/\[0\]$/, '')}${u.size > 1 ? `[${u.size}]` : ''}:${u.t.name.replace('SAMPLER_', '')}`),
    naiveVectors: values.reduce((a, u) => a + u.t.rows * u.size, 0),
    packedVectors: packedRows(values),
    valueUniforms: values.length,
    biggest: values.map((u) => [u.name, u.t.rows * u.size]).sort((a, b) => b[1] - a[1]).slice(0, 8),
    all: values.map((u) => `${u.name}:${u.t.name}${u.size > 1 ? `x${u.size}` : ''}`),
  };
}
function link(vsSrc, fsSrc) {
  const mk = (type, src) => { const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); return s; };
  const vs = mk(gl.VERTEX_SHADER, vsSrc), fs = mk(gl.FRAGMENT_SHADER, fsSrc);
  const p = gl.createProgram();
  gl.attachShader(p, vs); gl.attachShader(p, fs); gl.linkProgram(p);
  const ok = gl.getProgramParameter(p, gl.LINK_STATUS);
  const info = ok ? '' : `${gl.getProgramInfoLog(p)} | VS: ${gl.getShaderInfoLog(vs)} | FS: ${gl.getShaderInfoLog(fs)}`;
  const list = ok ? activeUniforms(p) : [];
  gl.deleteProgram(p); gl.deleteShader(vs); gl.deleteShader(fs);
  return { ok, info, list };
}
const TRIVIAL_FS = '#version 300 es\nprecision highp float;\nout vec4 clothfitAuditColor;\nvoid main() { clothfitAuditColor = vec4( 1.0 ); }\n';
function emptyMain(src) {
  const i = src.indexOf('void main() {');
  if (i < 0) throw new Error('no main in vertex shader');
  return src.slice(0, i) + 'void main() { gl_Position = vec4( 0.0 ); }\n';
}

function analyzeProgram(wp) {
  const prog = wp.program;
  const [vsObj, fsObj] = [wp.vertexShader, wp.fragmentShader];
  const vsSrc = gl.getShaderSource(vsObj), fsSrc = gl.getShaderSource(fsObj);
  const linked = gl.getProgramParameter(prog, gl.LINK_STATUS);
  const full = summarize(activeUniforms(prog));
  const vProbe = link(vsSrc, TRIVIAL_FS);
  const fProbe = link(emptyMain(vsSrc), fsSrc);
  return {
    cacheKey: wp.cacheKey.length > 200 ? wp.cacheKey.slice(0, 200) + '...' : wp.cacheKey,
    name: wp.name, linked,
    full: { samplers: full.samplers, naiveVectors: full.naiveVectors },
    vertex: vProbe.ok ? summarize(vProbe.list) : { error: vProbe.info.slice(0, 400) },
    fragment: fProbe.ok ? summarize(fProbe.list) : { error: fProbe.info.slice(0, 400) },
    varyings: varyings(fsSrc),
  };
}

async function run() {
  const plan = await (await fetch(new URLSearchParams(location.search).get('plan'))).json();
  const canvas = document.getElementById('c');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true, powerPreference: 'high-performance' });
  gl = renderer.getContext();
  initTypes();
  const errors = [];
  renderer.debug.onShaderError = (g, program, vs, fs) => { errors.push(`${g.getProgramInfoLog(program)}\n${g.getShaderInfoLog(fs)}\n${g.getShaderInfoLog(vs)}`.slice(0, 1500)); };
  const P = (n) => gl.getParameter(gl[n]);
  const limits = Object.fromEntries(['MAX_TEXTURE_IMAGE_UNITS', 'MAX_COMBINED_TEXTURE_IMAGE_UNITS', 'MAX_VERTEX_TEXTURE_IMAGE_UNITS', 'MAX_FRAGMENT_UNIFORM_VECTORS',
    'MAX_VERTEX_UNIFORM_VECTORS', 'MAX_VARYING_VECTORS', 'MAX_VERTEX_OUTPUT_COMPONENTS', 'MAX_FRAGMENT_INPUT_COMPONENTS', 'MAX_VERTEX_ATTRIBS'].map((n) => [n, P(n)]));
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  const env = { version: P('VERSION'), renderer: dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : P('RENDERER'), limits,
    floatLinear: renderer.extensions.has('OES_texture_float_linear'), maxAnisotropy: renderer.capabilities.getMaxAnisotropy(),
    precision: renderer.capabilities.precision, extensions: gl.getSupportedExtensions() };
  await post('/result', JSON.stringify({ env }));
  // a synthetic light map (8 x 8, uv box 0..1): only its presence matters (USE_LIGHTMAP)
  const lmExr = () => ({ width: 8, height: 8, channels: { R: new Float32Array(64).fill(0.1), G: new Float32Array(64).fill(0.1), B: new Float32Array(64).fill(0.1) }, attributes: { 'clothfit:uv_box': '0 0 1 1' } });
  for (const c of plan.cases) {
    const t0 = performance.now();
    errors.length = 0;
    try {
      const sc = await loadSceneCard(fsUrl(c.cardPath), { renderer, shadows: c.shadows ?? false, resolvePath: (p, base) => {
        if (!p.includes('/') && !/\.[A-Za-z0-9]+$/.test(p)) return fsUrl(`${plan.hdri_dir}/${p}.exr`);
        return p.startsWith('/') ? fsUrl(p) : new URL(p, base).href;
      } });
      const material = await fetchClothfitPreset(fsUrl(c.presetPath), { renderer, resolveWeaveMapPath: (f) => fsUrl(f) });
      if (c.lightMap) applyLightMap(material, lightMapTextureFromExr(lmExr()));
      sc.setMaterial(material);
      if (c.shadows) sc.setShadows(c.shadows);
      sc.apply(renderer);
      renderer.setSize(sc.width, sc.height, false);
      renderer.render(sc.scene, sc.camera);
      const px = new Uint8Array(4);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      const lights = { directional: 0, spot: 0, point: 0, castShadow: 0 };
      sc.scene.traverse((o) => { if (o.isDirectionalLight) lights.directional++; if (o.isSpotLight) lights.spot++; if (o.isPointLight) lights.point++; if (o.isLight && o.castShadow) lights.castShadow++; });
      const wp = renderer.properties.get(sc.fabricMeshes[0].material).currentProgram;
      const fabric = analyzeProgram(wp);
      // every other program on the context (the floor / support, depth passes): max samplers only
      const others = renderer.info.programs.filter((p) => p !== wp).map((p) => ({ name: p.name, samplers: summarize(activeUniforms(p.program)).samplers }));
      await post('/result', JSON.stringify({ name: c.name, lights, areaLights: (sc.scene.userData.clothfitAreaLights ?? []).length,
        viewBands: material.viewBands ?? 0, fabric, otherMaxSamplers: Math.max(0, ...others.map((o) => o.samplers)),
        shaderErrors: errors.slice(), ms: Math.round(performance.now() - t0) }));
      material.dispose();
    } catch (e) {
      await post('/result', JSON.stringify({ name: c.name, error: String(e?.stack ?? e).slice(0, 2000), shaderErrors: errors.slice() }));
    }
  }
  await post('/done', 'ok');
}
run().catch(async (e) => { await log(`error: ${e?.stack ?? e}`); await post('/done', 'error'); });
