// Node-side checks of web/clothfit.js that need no browser (run by tests/browser/run.mjs before
// the browser cases; exits non-zero on a failure):
//   - `side` from `clothfit convert --to threejs` (three.js DoubleSide 2 / FrontSide 0) is
//     honoured by loadClothfitPreset for MeshPhysicalMaterial and MeshClothMaterial JSON, and a
//     preset's "side" ('front' | 'double' or 0 / 2) too; without one, three.js's FrontSide stays;
//   - woven presets load as MeshWovenMaterial with the table defaults and reject unknown names;
//     diffuse_roughness (session 18): default 0 (the Lambert program), read, refused naming the
//     field, and the shader's rough-diffuse G(mu) against its hemisphere integral;
//   - the far-field yarn lobe ("woven": {"yarn_lobe"}): program, defines, textures, the port
//     against C++ values (web/test/yarn-lobe-reference.json), bad blocks refused naming the field;
//     the microcylinder lobe (session 19, "model": "sadeghi-microcylinder"): the same, its port
//     against brdf/microcylinder.h EvalSplit (web/test/microcylinder-reference.json) and the
//     generated shader run as JavaScript against the port;
//   - weave maps: web/exr.js reads tests/browser/maps/canvas.weave.exr as OpenImageIO does
//     (oiiotool, when installed), tile means 1, box mips, texture settings, uv_repeats, the
//     anisotropyMap encoding, the preset's "weave_maps" required / refused / fetched;
//   - view-dependent weave maps (session 14): blend weights, weave_maps.view_cosines checks, the
//     bands' data, packing and program, missing view channels (oiiotool, when installed).
// Usage: node tests/browser/unit.mjs [--clothfit build/bin/clothfit --work DIR]
//   with --clothfit, the JSON comes from `clothfit convert --to threejs` itself.
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '..', '..');
// The materials fetch their tables (web/lut/*.f32) by URL: serve file: URLs from disk.
const realFetch = globalThis.fetch;
globalThis.fetch = async (url, ...rest) => {
  const u = String(url);
  if (u.startsWith('file:')) {
    const buf = fs.readFileSync(fileURLToPath(u));
    return { ok: true, status: 200, arrayBuffer: async () => buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.length), json: async () => JSON.parse(buf), text: async () => buf.toString('utf8') };
  }
  return realFetch(url, ...rest);
};
const THREE = await import(pathToFileURL(path.join(repo, 'web', 'node_modules', 'three', 'build', 'three.module.js')).href);
const { loadClothfitPreset, MeshWovenMaterial, MeshClothMaterial, yarnLobeOptions, yarnLobeEval, yarnLobeIbl, microcylinderEvalSplit, lightMapTextureFromExr, lightMapUvBox, applyLightMap } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);

const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) => {
  if (a.startsWith('--')) acc.push([a.slice(2), all[i + 1]]);
  return acc;
}, []));
let checks = 0;
const check = (fn, what) => { fn(); checks++; };
// A yarn-lobe shader (as JS) against the JS port over reference direction pairs: `port` and
// `shader` map (wo, wi) to [T_warp, T_weft]. Relative error max|S - P| / (P_warp + P_weft) per
// lit pair; `beyond` counts pairs over 1e-4 and unlit pairs the shader lights.
const compareLobePairs = (name, pairs, port, shader) => {
  let beyond = 0, lit = 0;
  const rel = [];
  for (const q of pairs) {
    const P = port(q.wo, q.wi), S = shader(q.wo, q.wi), p = P[0] + P[1];
    if (!(p > 0)) { if (S[0] !== 0 || S[1] !== 0) ++beyond; continue; }
    ++lit;
    const d = Math.max(Math.abs(S[0] - P[0]), Math.abs(S[1] - P[1])) / p;
    rel.push(d);
    if (!(d < 1e-4)) ++beyond;
  }
  rel.sort((x, y) => x - y);
  const msg = `${name}: ${lit} lit of ${pairs.length}, median relative ${rel[rel.length >> 1]?.toExponential(1)}, worst ${rel[rel.length - 1]?.toExponential(1)}, ${beyond} beyond 1e-4`;
  return { lit, beyond, msg };
};

const physical = (side) => ({ metadata: { version: 4.6, type: 'Material', generator: 'test' }, type: 'MeshPhysicalMaterial', color: 0x808080, roughness: 0.5, sheen: 1, sheenColor: 0xffffff, sheenRoughness: 0.5, ...(side === undefined ? {} : { side }) });
const cloth = (side) => ({ metadata: { version: 4.6, type: 'Material' }, type: 'MeshClothMaterial', color: 0x808080, sheen: 0xffffff, roughness: 0.6, ...(side === undefined ? {} : { side }) });
check(() => assert.equal(loadClothfitPreset(physical(2)).side, THREE.DoubleSide), 'physical side 2');
check(() => assert.equal(loadClothfitPreset(physical(0)).side, THREE.FrontSide), 'physical side 0');
check(() => assert.equal(loadClothfitPreset(physical()).side, THREE.FrontSide), 'physical no side');
check(() => assert.equal(loadClothfitPreset(cloth(2)).side, THREE.DoubleSide), 'cloth side 2');
check(() => assert.equal(loadClothfitPreset(cloth(0)).side, THREE.FrontSide), 'cloth side 0');
check(() => assert.ok(loadClothfitPreset(cloth(2)) instanceof MeshClothMaterial), 'cloth type');
const preset = (extra) => ({ schema: 'clothfit.preset', version: 1, model: 'standard', parameters: { roughness: 0.5 }, ...extra });
check(() => assert.equal(loadClothfitPreset(preset({ side: 'double' })).side, THREE.DoubleSide), 'preset double');
check(() => assert.equal(loadClothfitPreset(preset({ side: 0 })).side, THREE.FrontSide), 'preset 0');

// Woven.
const w = loadClothfitPreset({ schema: 'clothfit.preset', version: 1, model: 'woven', parameters: { twist: 15 } });
check(() => assert.ok(w instanceof MeshWovenMaterial), 'woven type');
check(() => assert.equal(w.woven.twist, 15), 'woven twist');
check(() => assert.equal(w.woven.forward_scattering, 2), 'woven default beta');
check(() => assert.throws(() => loadClothfitPreset({ schema: 'clothfit.preset', version: 1, model: 'woven', parameters: { twisst: 1 } }), /parameters\.twisst/), 'woven unknown');

// Session 18: the rough diffuse (parameters.diffuse_roughness, brdf/woven.h On / Eo): default 0 =
// Lambert with the old program (no WOVEN_ROUGH_DIFFUSE, the old key), read when given (its own
// program and A, A sigma uniforms), refused as the C++ reader refuses it (the field named), a
// change across 0 recompiles; the shader's s/t and G(mu) (taken from the compiled source and run
// as JavaScript) against the hemisphere integral G(mu) = (1/pi) int s/t cos th_l dw_l.
{
  const rd = (v) => loadClothfitPreset({ schema: 'clothfit.preset', version: 1, model: 'woven', parameters: v === undefined ? {} : { diffuse_roughness: v } });
  const fsrc = '#include <lights_physical_pars_fragment>\n#include <lights_physical_fragment>\n#include <lights_fragment_begin>\n#include <lights_fragment_maps>\n';
  const compile = (m) => { const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: 'void main() {\n#include <project_vertex>\n}' }; m.onBeforeCompile(sh); return sh; };
  const lam = rd(), lam0 = rd(0), rough = rd(0.65);
  check(() => assert.equal(lam.woven.diffuse_roughness, 0), 'woven default diffuse_roughness 0');
  check(() => assert.ok(!lam.roughDiffuse && !lam0.roughDiffuse && rough.roughDiffuse && rough.woven.diffuse_roughness === 0.65), 'diffuse_roughness read');
  check(() => assert.ok(lam.customProgramCacheKey() === 'woven:additive:uniform:split' && lam0.customProgramCacheKey() === 'woven:additive:uniform:split'
    && rough.customProgramCacheKey() === 'woven:additive:uniform:split:rough-diffuse'), 'rough diffuse: its own program key, Lambert the old one');
  const shL = compile(lam), shR = compile(rough);
  // Session 22: the horizon fade applies to directional lights only. The flag is raised around
  // the RE_Direct call of three.js's directional loop alone (the point, spot and area loops keep
  // theirs untouched), and the shader only looks lights up under it.
  {
    const f = shL.fragmentShader;
    const dirLoop = f.slice(f.indexOf('getDirectionalLightInfo( directionalLight, directLight );'));
    const before = f.slice(0, f.indexOf('getDirectionalLightInfo( directionalLight, directLight );'));
    check(() => assert.ok(!f.includes('#include <lights_fragment_begin>') && f.split('wovenDirectional = true;').length === 2
      && /^getDirectionalLightInfo[^]*?wovenDirectional = true;[^]*?RE_Direct\( directLight,[^;]*;\s*wovenDirectional = false;/.test(dirLoop)
      && !before.includes('wovenDirectional = true;') && /if \( wovenDirectional \) \{\s*for \( int k = 0; k < 9;/.test(f)), 'woven: the horizon fade only in the directional-light loop');
  }
  check(() => assert.ok(!shL.fragmentShader.includes('#define WOVEN_ROUGH_DIFFUSE') && shR.fragmentShader.includes('#define WOVEN_ROUGH_DIFFUSE\n')
    && compile(lam0).fragmentShader === shL.fragmentShader), 'WOVEN_ROUGH_DIFFUSE only with sigma > 0');
  const A = 1 / (1 + (0.5 - 2 / (3 * Math.PI)) * 0.65);
  check(() => assert.ok(Math.abs(shR.uniforms.wovenOnA.value - A) < 1e-15 && Math.abs(shR.uniforms.wovenOnB.value - A * 0.65) < 1e-15
    && shL.uniforms.wovenOnA.value === 1 && shL.uniforms.wovenOnB.value === 0), 'rough diffuse uniforms A, A sigma');
  for (const [v, re] of [['0.5', /parameters\.diffuse_roughness: expected a number/], [null, /parameters\.diffuse_roughness: expected a number/],
    [1.5, /parameters\.diffuse_roughness: value 1\.5 outside \[0, 1\]/], [-0.1, /parameters\.diffuse_roughness: value -0\.1 outside/],
    [NaN, /parameters\.diffuse_roughness: not finite/], [Infinity, /parameters\.diffuse_roughness: not finite/]]) {
    check(() => assert.throws(() => rd(v), re), `diffuse_roughness ${v} refused`);
  }
  check(() => assert.throws(() => new MeshWovenMaterial({ diffuse_roughness: 2 }), /MeshWovenMaterial: diffuse_roughness: value 2 outside/), 'material diffuse_roughness refused');
  const m = rd(0), v0 = m.version;
  m.woven.diffuse_roughness = 0.3; m._updateWovenUniforms();
  const v1 = m.version;
  m.woven.diffuse_roughness = 0.5; m._updateWovenUniforms();
  check(() => assert.ok(v1 > v0 && m.version === v1 && m.customProgramCacheKey().endsWith(':rough-diffuse')), 'sigma 0 -> 0.3 recompiles, 0.3 -> 0.5 does not');
  // the shader's functions, in double
  const src = shR.fragmentShader, a = src.indexOf('float wovenOnSOverT('), b = src.indexOf('#endif', a);
  const js = src.slice(a, b)
    .replace(/^float (\w+)\(([^)]*)\) \{/gm, (_, name, ps) => `function ${name}(${ps.replace(/const in float /g, '')}) {`)
    .replace(/^(\s*)float /gm, '$1let ');
  const lib = { max: Math.max, sqrt: Math.sqrt, acos: Math.acos, clamp: (x, lo, hi) => Math.min(Math.max(x, lo), hi), RECIPROCAL_PI: 1 / Math.PI };
  const [sOverT, G] = new Function(...Object.keys(lib), `${js}\nreturn [wovenOnSOverT, wovenOnAlbedoG];`)(...Object.values(lib));
  const integral = (mu) => {  // midpoint rule over (th_l, phi), N x 2N
    const N = 400, sv = Math.sqrt(1 - mu * mu);
    let sum = 0;
    for (let i = 0; i < N; ++i) {
      const th = (i + 0.5) * (Math.PI / 2) / N, cl = Math.cos(th), sl = Math.sin(th);
      for (let j = 0; j < 2 * N; ++j) {
        const lv = mu * cl + sv * sl * Math.cos((j + 0.5) * Math.PI / N);
        sum += sOverT(mu, cl, Math.sqrt((1 + lv) / 2)) * cl * sl;
      }
    }
    return sum * (Math.PI / 2 / N) * (Math.PI / N) / Math.PI;
  };
  const worst = Math.max(...[0.02, 0.2, 0.5, 0.8, 0.99].map((mu) => Math.abs(G(mu) - integral(mu))));
  check(() => assert.ok(worst < 2e-4 && G(1) === 0 && Math.abs(G(0) - (Math.PI / 2 - 2 / 3) / Math.PI) < 1e-15, `G worst ${worst}`), 'shader G(mu) = hemisphere integral of s/t');
}

// Woven options ("woven": yarn_layer, tint_warp, tint_weft): the keys and meaning of the C++
// reader (render/scene/material.cpp), unknown keys and values refused with the field named.
const wp = (woven, model = 'woven') => ({ schema: 'clothfit.preset', version: 1, model, parameters: {}, ...(woven === undefined ? {} : { woven }) });
const wd = loadClothfitPreset(wp());
check(() => assert.equal(wd.yarnLayer, 'additive'), 'woven default yarn layer');
check(() => assert.deepEqual(wd.tintWarp.toArray(), [1, 1, 1]), 'woven default tint');
const wo = loadClothfitPreset(wp({ yarn_layer: 'albedo-scaled', tint_warp: [0.2, 0.5, 1], tint_weft: [1, 0.9, 0.3] }));
check(() => assert.equal(wo.yarnLayer, 'albedo-scaled'), 'woven yarn layer');
check(() => assert.deepEqual(wo.tintWarp.toArray(), [0.2, 0.5, 1]), 'woven tint warp (linear, as given)');
check(() => assert.deepEqual(wo.tintWeft.toArray(), [1, 0.9, 0.3]), 'woven tint weft');
check(() => assert.notEqual(wo.customProgramCacheKey(), wd.customProgramCacheKey()), 'albedo-scaled compiles another program');
check(() => assert.throws(() => loadClothfitPreset(wp({ yarn: 'additive' })), /woven\.yarn: unknown key/), 'woven unknown key');
check(() => assert.throws(() => loadClothfitPreset(wp({ yarn_layer: 'scaled' })), /woven\.yarn_layer/), 'woven bad yarn layer');
check(() => assert.throws(() => loadClothfitPreset(wp({ tint_warp: [1, 1] })), /woven\.tint_warp: expected an array of 3/), 'woven short tint');
check(() => assert.throws(() => loadClothfitPreset(wp({ tint_weft: [1, -0.1, 1] })), /woven\.tint_weft\[1\]: must be >= 0/), 'woven negative tint');
check(() => assert.throws(() => loadClothfitPreset(wp({}, 'cloth')), /woven: only allowed with model "woven"/), 'woven block on cloth');

// IBL options ("woven": ibl, fis_taps, fis_diffuse_taps; docs/web.md "Filtered importance
// sampling"): missing = the split sum (today's program); "fis" compiles another program with the
// tap counts as #defines; bad values refused naming the field.
check(() => assert.equal(wd.ibl, 'split'), 'woven default ibl split');
const wf = loadClothfitPreset(wp({ ibl: 'fis', fis_taps: 8, fis_diffuse_taps: 12 }));
check(() => assert.deepEqual([wf.ibl, wf.fisTaps, wf.fisDiffuseTaps], ['fis', 8, 12]), 'woven fis options');
check(() => assert.deepEqual([loadClothfitPreset(wp({ ibl: 'fis' })).fisTaps, loadClothfitPreset(wp({ ibl: 'fis' })).fisDiffuseTaps], [16, 0]), 'woven fis default taps 16 / 0 (brdf/woven.h)');
check(() => assert.notEqual(wf.customProgramCacheKey(), wd.customProgramCacheKey()), 'fis compiles another program');
check(() => assert.notEqual(wf.customProgramCacheKey(), loadClothfitPreset(wp({ ibl: 'fis', fis_taps: 9, fis_diffuse_taps: 12 })).customProgramCacheKey()), 'tap count is in the program key');
check(() => assert.equal(loadClothfitPreset(wp({ ibl: 'split' })).customProgramCacheKey(), wd.customProgramCacheKey()), 'explicit split = the default program');
{
  // The defines the shader sees (onBeforeCompile on a stand-in of three.js r187's shader).
  const fsrc = '#include <lights_physical_pars_fragment>\n#include <lights_physical_fragment>\n#include <lights_fragment_begin>\n#include <lights_fragment_maps>\n';
  const vsrc = 'void main() {\n#include <project_vertex>\n}';
  const compiled = (m) => { const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: vsrc }; m.onBeforeCompile(sh); return sh.fragmentShader; };
  const ff = compiled(wf), fd = compiled(wd);
  check(() => assert.ok(/#define WOVEN_FIS\n/.test(ff) && /#define WOVEN_FIS_TAPS 8\n/.test(ff) && /#define WOVEN_FIS_DIFFUSE_TAPS 12\n/.test(ff)), 'fis defines');
  check(() => assert.ok(!/#define WOVEN_FIS\n/.test(fd) && !/#define WOVEN_FIS_TAPS /.test(fd) && !/#define WOVEN_FIS_DIFFUSE_TAPS /.test(fd)), 'split: no fis defines');
}
for (const [opt, re] of [[{ ibl: 'FIS' }, /woven\.ibl: expected "split", "fis" or "bent"/], [{ ibl: 1 }, /woven\.ibl: expected/],
  [{ ibl: 'bent', fis_taps: 16 }, /woven\.fis_taps: only allowed with "ibl": "fis"/],
  [{ ibl: 'fis', fis_taps: 0 }, /woven\.fis_taps: must be in \[1, 64\]/], [{ ibl: 'fis', fis_taps: 65 }, /woven\.fis_taps: must be in/],
  [{ ibl: 'fis', fis_taps: 2.5 }, /woven\.fis_taps: expected an integer/], [{ ibl: 'fis', fis_taps: '16' }, /woven\.fis_taps: expected an integer/],
  [{ ibl: 'fis', fis_diffuse_taps: -1 }, /woven\.fis_diffuse_taps: must be in \[0, 64\]/], [{ ibl: 'fis', fis_diffuse_taps: 65 }, /woven\.fis_diffuse_taps: must be in/],
  [{ ibl: 'fis', fis_diffuse_taps: null }, /woven\.fis_diffuse_taps: expected an integer/], [{ fis_tap: 4 }, /woven\.fis_tap: unknown key/],
  [{ fis_taps: 8 }, /woven\.fis_taps: only allowed with "ibl": "fis"/], [{ ibl: 'split', fis_diffuse_taps: 0 }, /woven\.fis_diffuse_taps: only allowed with "ibl": "fis"/]]) {
  check(() => assert.throws(() => loadClothfitPreset(wp(opt)), re), `bad ${JSON.stringify(opt)}`);
}
check(() => assert.throws(() => new MeshWovenMaterial({}, { ibl: 'exact' }), /MeshWovenMaterial: ibl 'exact'/), 'material ibl refused');
check(() => assert.equal(new MeshWovenMaterial({}, { ibl: 'bent' }).customProgramCacheKey(), 'woven:additive:uniform:bent'), 'bent ibl: its own program');
check(() => assert.throws(() => new MeshWovenMaterial({}, { ibl: 'fis', fisTaps: 0 }), /MeshWovenMaterial: fisTaps 0/), 'material taps refused');

// The far-field yarn lobe ("woven": {"yarn_lobe"}; docs/web.md "The far-field yarn lobe"): the
// canvas preset of the browser cases loads with its own program (#defines for the loop bounds),
// uniforms and textures; the double-precision port agrees with the committed C++ values
// (web/test/yarn-lobe-reference.json: fit/yarn_farfield.cpp EvalQuadrature and Table::Ibl at 400
// direction pairs per fabric); a bad block is refused with the field named.
{
  const lobeFile = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'yarn-lobe-canvas.json'), 'utf8'));
  const wl = loadClothfitPreset(lobeFile);
  const yl = wl.yarnLobe;
  check(() => assert.ok(yl && yl.groups.length === 2 && yl.nodes === 16 && yl.ibl.summary.length === 2 * 16 * 32 * 5), 'yarn lobe loaded');
  const key = wl.customProgramCacheKey();
  check(() => assert.match(key, /^woven:additive:uniform:split:yarn-lobe2x16\/16x32\/[0-9a-f]{16}$/), 'yarn lobe: its own program');
  const fsrc = '#include <lights_physical_pars_fragment>\n#include <lights_physical_fragment>\n#include <lights_fragment_begin>\n#include <lights_fragment_maps>\n';
  const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: 'void main() {\n#include <project_vertex>\n}' };
  wl.onBeforeCompile(sh);
  check(() => assert.ok(['WOVEN_YARN_LOBE\n', 'WOVEN_YL_N_THETA 16\n', 'WOVEN_YL_N_PHI 32\n'].every((d) => sh.fragmentShader.includes(`#define ${d}`))), 'yarn lobe defines');
  // session 16: the lobe's constants are in the source (yarnLobeGlsl), 2 groups x 16 node calls
  check(() => assert.ok((sh.fragmentShader.match(/\ts \+= wovenYlStaple\( /g) ?? []).length === 32 && !sh.fragmentShader.includes('@wovenYarnLobe')
    && /^vec2 wovenYarnLobe\( const in vec3 wo, const in vec3 wi \) \{$/m.test(sh.fragmentShader)), 'yarn lobe source generated');
  check(() => assert.ok(sh.uniforms.wovenYlIbl.value.image.width === 64 && sh.uniforms.wovenYlIbl.value.image.height === 32 && sh.uniforms.wovenYlIbl.value.type === THREE.FloatType), 'yarn lobe IBL texture');
  // the IBL texture holds the summary as laid out (entry 4 in the odd texel)
  const it = sh.uniforms.wovenYlIbl.value.image.data, sm = yl.ibl.summary, at = ((1 * 16 + 5) * 32 + 7) * 5;
  check(() => assert.deepEqual([...it.slice(((16 + 5) * 64 + 14) * 4, ((16 + 5) * 64 + 14) * 4 + 5)], [...sm.slice(at, at + 5)]), 'yarn lobe IBL texture layout');
  check(() => assert.ok(!loadClothfitPreset(wp()).customProgramCacheKey().includes('yarn-lobe')), 'no yarn lobe: the old program');
  // setYarnLobe keeps the IBL texture's uniform object a compiled program holds (three.js reuses
  // a program of the same key without onBeforeCompile) and changes its value; other constants
  // (in the source) change the key, the same block gives the same key.
  {
    const ibl = sh.uniforms.wovenYlIbl;
    const other = JSON.parse(JSON.stringify(lobeFile.woven.yarn_lobe));
    other.ibl.summary[0] = 0.123;
    wl.setYarnLobe(other);
    check(() => assert.ok(sh.uniforms.wovenYlIbl === ibl && ibl.value.image.data[0] === Math.fround(0.123) && wl.customProgramCacheKey() === key),
      'setYarnLobe updates the compiled program\'s IBL texture');
    other.groups[0].umax = 15;
    wl.setYarnLobe(other);
    check(() => assert.ok(wl.customProgramCacheKey() !== key && wl.customProgramCacheKey().startsWith('woven:additive:uniform:split:yarn-lobe2x16/16x32/')), 'another lobe: another program');
    wl.setYarnLobe(lobeFile.woven.yarn_lobe);
    check(() => assert.equal(wl.customProgramCacheKey(), key), 'the same lobe: the same program');
  }
  const clone = wl.clone();
  check(() => assert.ok(clone.yarnLobe && clone.customProgramCacheKey() === wl.customProgramCacheKey() && clone._wovenUniforms.wovenYlIbl.value !== wl._wovenUniforms.wovenYlIbl.value), 'yarn lobe survives clone');
  // the port against the C++ quadrature (staple circle, ellipse and hyperbola spines; filament
  // with smoothing, ellipse and hyperbola; 10 groups evaluated as two blocks of 5)
  const ref = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'yarn-lobe-reference.json'), 'utf8'));
  for (const [name, r] of Object.entries(ref.fabrics)) {
    const parts = [];
    for (let i = 0; i < r.block.groups.length; i += 5) parts.push(yarnLobeOptions({ ...r.block, groups: r.block.groups.slice(i, i + 5) }));
    let worst = 0, lit = 0;
    for (const q of r.pairs) {
      const T = parts.map((pp) => yarnLobeEval(pp, q.wo, q.wi)).reduce((a, b) => [a[0] + b[0], a[1] + b[1]]);
      for (let k = 0; k < 2; ++k) {
        if (q.T[k] > 0) ++lit;
        worst = Math.max(worst, Math.abs(T[k] - q.T[k]) / Math.max(Math.abs(q.T[k]), 1e-9));
      }
    }
    check(() => assert.ok(worst < 1e-9 && lit > r.pairs.length / 2, `${name}: worst relative ${worst}, ${lit} lit`), `yarn lobe port = EvalQuadrature (${name})`);
  }
  // session 16: the shader's lobe itself (the generated wovenYarnLobe and its helpers, taken from
  // the compiled fragment source and run as JavaScript, in double, by a few rewrites of the GLSL
  // subset they use) against the port, on the same pairs: the staple's homogeneous-H algebra,
  // the constant band (extent >= w / 2), the filament (smoothing, ellipse, hyperbola) and, with
  // across 0.3 < w / 2 on canvas, the band through atan. The constants are floats, so not 1e-9:
  // relative 1e-4 (of T_warp + T_weft, per lobe), except near a node's |D| = 1 edge (G ~
  // 1 / NoH) at most 1 % of the pairs beyond (measured: worst 4.9e-6, none beyond; --verbose).
  const glslLobe = (block) => {
    const m = loadClothfitPreset(wp({ yarn_lobe: block }));
    const s2 = { uniforms: {}, fragmentShader: fsrc, vertexShader: 'void main() {\n#include <project_vertex>\n}' };
    m.onBeforeCompile(s2);
    const src = s2.fragmentShader, a = src.indexOf('float wovenYlBand('), b = src.indexOf('// Table::Ibl\'s entry');
    let js = src.slice(a, b)
      .replace(/^(float|vec2|vec3|vec4) (\w+)\(([^)]*)\) \{/gm, (_, t, name, ps) => `function ${name}(${ps.replace(/const in (float|vec3|vec4) /g, '')}) {`)
      .replace(/^(\s*)(float|vec2|vec3|vec4) /gm, '$1let ');
    const sum = '\t\tlet H = i + o;';
    assert.equal(js.split(sum).length, 1 + new Set(block.groups.map((g) => g.type)).size);
    js = js.replaceAll(sum, '\t\tlet H = vec3(i.x + o.x, i.y + o.y, i.z + o.z);');
    const vec = (x, ...r) => (r.length ? { x, y: r[0], z: r[1], w: r[2] } : { x, y: x, z: x, w: x });
    const lib = {
      vec2: vec, vec3: vec, vec4: vec, dot: (p, q) => p.x * q.x + p.y * q.y + p.z * q.z, exp: Math.exp, abs: Math.abs, sqrt: Math.sqrt, tan: Math.tan,
      min: Math.min, max: Math.max, atan: (y, x) => (x === undefined ? Math.atan(y) : Math.atan2(y, x)), inversesqrt: (x) => 1 / Math.sqrt(x),
      clamp: (x, lo, hi) => Math.min(Math.max(x, lo), hi), smoothstep: (e0, e1, x) => { const c = Math.min(Math.max((x - e0) / (e1 - e0), 0), 1); return c * c * (3 - 2 * c); },
    };
    const f = new Function(...Object.keys(lib), `${js}\nreturn wovenYarnLobe;`)(...Object.values(lib));
    return (wo, wi) => { const T = f(vec(...wo), vec(...wi)); return [T.x, T.y]; };
  };
  const narrow = (b) => ({ ...b, groups: b.groups.map((g) => ({ ...g, across: 0.3 })) });
  for (const [name, r] of [...Object.entries(ref.fabrics), ['canvas across 0.3', { ...ref.fabrics.canvas, block: narrow(ref.fabrics.canvas.block) }]]) {
    const blocks = [];
    for (let i = 0; i < r.block.groups.length; i += 5) blocks.push({ ...r.block, groups: r.block.groups.slice(i, i + 5) });
    const ports = blocks.map((b) => yarnLobeOptions(b)), shaders = blocks.map(glslLobe);
    const add = (a, b) => [a[0] + b[0], a[1] + b[1]];
    const { lit, beyond, msg } = compareLobePairs(name, r.pairs,
      (wo, wi) => ports.map((pp) => yarnLobeEval(pp, wo, wi)).reduce(add),
      (wo, wi) => shaders.map((sh) => sh(wo, wi)).reduce(add));
    check(() => assert.ok(lit > r.pairs.length / 2 && beyond <= 0.01 * r.pairs.length, msg), `yarn lobe shader = port (${name})`);
    if (args.verbose) console.log(msg);
  }
  for (const q of ref.ibl.pairs) {
    const got = yarnLobeIbl(yl, q.wo);
    check(() => assert.ok([0, 1].every((k) => [got[k].albedo, ...got[k].dir, got[k].roughness].every((x, c) => Math.abs(x - q.ibl[k][c]) < 1e-6))), 'yarn lobe IBL summary = Table::Ibl');
  }
  // bad blocks, the field named
  const lobe = lobeFile.woven.yarn_lobe;
  const bad = (edit) => { const b = JSON.parse(JSON.stringify(lobe)); edit(b); return wp({ yarn_lobe: b }); };
  for (const [edit, re] of [
    [(b) => { b.groups = []; }, /woven\.yarn_lobe\.groups: 0 groups, expected 1 to 16/],
    [(b) => { b.groups = Array(17).fill(b.groups[0]); }, /woven\.yarn_lobe\.groups: 17 groups, expected 1 to 16/],
    [(b) => { b.groups = 'warp'; }, /woven\.yarn_lobe\.groups: expected an array/],
    [(b) => { b.ibl.summary.pop(); }, /woven\.yarn_lobe\.ibl\.summary: 5119 numbers, expected 2 x n_theta x n_phi x 5 = 5120/],
    [(b) => { b.ibl.n_phi = 16; }, /woven\.yarn_lobe\.ibl\.summary: 5120 numbers, expected .* = 2560/],
    [(b) => { b.ibl.summary[17] = null; }, /woven\.yarn_lobe\.ibl\.summary\[17\]: expected a number/],
    [(b) => { b.ibl.summary[3] = 1e31; }, /woven\.yarn_lobe\.ibl\.summary\[3\]: out of float range/],
    [(b) => { b.scale = Infinity; }, /woven\.yarn_lobe\.scale: not finite/],
    [(b) => { b.alpha = NaN; }, /woven\.yarn_lobe\.alpha: not finite/],
    [(b) => { b.groups[1].umax = '24'; }, /woven\.yarn_lobe\.groups\[1\]\.umax: expected a number/],
    [(b) => { b.groups[1].umax = 90; }, /woven\.yarn_lobe\.groups\[1\]\.umax: must be in \(0, 90\)/],
    [(b) => { b.groups[0].width = 3; }, /woven\.yarn_lobe\.groups\[0\]\.umax: width sin\(umax\) must be < length/],
    [(b) => { b.groups[0].type = 'both'; }, /woven\.yarn_lobe\.groups\[0\]\.type: expected "warp" or "weft"/],
    [(b) => { b.groups[0].share = 0; }, /woven\.yarn_lobe\.groups\[0\]\.share: must be in \(0, 1\]/],
    [(b) => { b.groups[0].kappa = -1.5; }, /woven\.yarn_lobe\.groups\[0\]\.kappa/],
    [(b) => { b.groups[0].area_factor = 0.5; }, /woven\.yarn_lobe\.groups\[0\]\.area_factor/],
    [(b) => { delete b.groups[0].along; }, /woven\.yarn_lobe\.groups\[0\]\.along: missing/],
    [(b) => { b.groups[0].extra = 1; }, /woven\.yarn_lobe\.groups\[0\]\.extra: unknown key/],
    [(b) => { b.nodes = 0; }, /woven\.yarn_lobe\.nodes: must be in \[1, 64\]/],
    [(b) => { b.nodes = 65; }, /woven\.yarn_lobe\.nodes: must be in \[1, 64\]/],
    [(b) => { b.nodes = 2.5; }, /woven\.yarn_lobe\.nodes: expected an integer/],
    [(b) => { b.ss = 1; }, /woven\.yarn_lobe\.ss: must be in \[0, 1\)/],
    [(b) => { b.h_width = 0; }, /woven\.yarn_lobe\.h_width: must be in \(0, 1\]/],
    [(b) => { b.beta = -1; }, /woven\.yarn_lobe\.beta: must be >= 0/],
    [(b) => { b.model = 'table'; }, /woven\.yarn_lobe\.model: expected "irawan-far-field"/],
    [(b) => { delete b.ibl; }, /woven\.yarn_lobe\.ibl: missing/],
    [(b) => { b.ibl.n_theta = 1; }, /woven\.yarn_lobe\.ibl\.n_theta: must be in \[2, 64\]/],
    [(b) => { b.table = 1; }, /woven\.yarn_lobe\.table: unknown key/],
  ]) {
    check(() => assert.throws(() => loadClothfitPreset(bad(edit)), re), `bad yarn_lobe ${edit}`);
  }
  check(() => assert.throws(() => loadClothfitPreset(wp({ yarn_layer: 'albedo-scaled', yarn_lobe: lobe })), /woven\.yarn_layer: must be "additive" with a yarn_lobe/), 'yarn lobe needs the additive layer');
  check(() => assert.throws(() => loadClothfitPreset(wp({ ibl: 'fis', yarn_lobe: lobe })), /woven\.ibl: must be "split" with a yarn_lobe/), 'yarn lobe needs the split sum');
  check(() => assert.throws(() => loadClothfitPreset({ ...wp(), woven: { yarn_lobe: null } }), /woven\.yarn_lobe: expected an object/), 'yarn lobe null refused');
  check(() => assert.throws(() => loadClothfitPreset(JSON.stringify(wp({ yarn_lobe: lobe })).replace('"nodes":16', '"nodes":16.0')), /woven\.yarn_lobe\.nodes: expected an integer/), 'nodes 16.0 literal refused');
  check(() => assert.throws(() => new MeshWovenMaterial({}, { yarnLayer: 'albedo-scaled', yarnLobe: lobe }), /MeshWovenMaterial: a yarnLobe needs yarnLayer 'additive'/), 'material: yarn lobe with albedo-scaled refused');
}

// Session 19: the microcylinder lobe ("woven": {"yarn_lobe": {"model": "sadeghi-microcylinder"}};
// docs/web.md "The microcylinder lobe"): the double-precision port (microcylinderEvalSplit, also
// through yarnLobeEval) against brdf/microcylinder.h EvalSplit's values
// (web/test/microcylinder-reference.json: velvet, linen and satin as fit/yarn_farfield.cpp
// MicrocylinderDescription builds them, and a made-up fabric with unequal threads, kd 0 and a
// 1-degree surface lobe; random, near-mirror, grazing and along-the-fibre pairs); the shader's
// generated wovenYarnLobe run as JavaScript against the port; the fixtures of the browser cases
// load with their own program; bad blocks are refused with the field named.
{
  const ref = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'microcylinder-reference.json'), 'utf8'));
  const noIbl = { n_theta: 2, n_phi: 3, summary: new Array(60).fill(0) };
  const mcBlock = (threads) => ({ model: 'sadeghi-microcylinder', fabric: 'test', threads, ibl: noIbl });
  for (const [name, r] of Object.entries(ref.fabrics)) {
    const lobe = yarnLobeOptions(mcBlock(r.threads));
    let worst = 0, lit = 0;
    for (const q of r.pairs) {
      const a = microcylinderEvalSplit(lobe, q.wo, q.wi), b = yarnLobeEval(lobe, q.wo, q.wi);
      if (q.out[0] > 0) ++lit;
      for (let k = 0; k < 2; ++k) {
        worst = Math.max(worst, Math.abs(a[k] - q.out[k]) / Math.max(Math.abs(q.out[k]), 1e-300));
        if (a[k] !== b[k]) worst = Infinity;
      }
    }
    check(() => assert.ok(worst < 1e-9 && lit > r.pairs.length / 2, `${name}: worst relative ${worst}, ${lit} lit of ${r.pairs.length}`), `microcylinder port = EvalSplit (${name})`);
    if (args.verbose) console.log(`microcylinder port ${name}: worst relative ${worst.toExponential(1)}, ${lit} lit of ${r.pairs.length}`);
  }
  // The generated GLSL (taken from the compiled fragment source) in double with its float
  // constants, against the port. Relative to the pair's surface + volume, 1e-4 (measured worst
  // in --verbose); the same zeros (below the horizon, masked, behind every tangent).
  const fsrc = '#include <lights_physical_pars_fragment>\n#include <lights_physical_fragment>\n#include <lights_fragment_begin>\n#include <lights_fragment_maps>\n';
  const compiled = (block) => {
    const m = loadClothfitPreset(wp({ yarn_lobe: block }));
    const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: 'void main() {\n#include <project_vertex>\n}' };
    m.onBeforeCompile(sh);
    return { m, sh };
  };
  const mcShaderAsJs = (src) => {
    const a = src.indexOf('// generated by microcylinderGlsl'), b = src.indexOf('// Table::Ibl\'s entry');
    assert.ok(a > 0 && b > a, 'microcylinder source in the program');
    const js = src.slice(a, b)
      .replace(/^(float|vec2|vec3|vec4|void) (\w+)\(([^)]*)\) \{/gm, (_, t, name, ps) => `function ${name}(${ps.replace(/(const in|inout) (float|vec3|vec4) /g, '')}) {`)
      .replace(/^(\s*)(float|vec2|vec3|vec4|bool) /gm, '$1let ');
    const vec = (x, ...r) => (r.length ? { x, y: r[0], z: r[1], w: r[2] } : { x, y: x, z: x, w: x });
    const lib = {
      vec2: vec, vec3: vec, vec4: vec, dot: (p, q) => p.x * q.x + p.y * q.y + p.z * q.z, exp: Math.exp, sqrt: Math.sqrt, asin: Math.asin,
      min: Math.min, max: Math.max, atan: (y, x) => Math.atan2(y, x), clamp: (x, lo, hi) => Math.min(Math.max(x, lo), hi),
    };
    const f = new Function(...Object.keys(lib), `${js}\nreturn wovenYarnLobe;`)(...Object.values(lib));
    return (wo, wi) => { const T = f(vec(...wo), vec(...wi)); return [T.x, T.y]; };
  };
  for (const [name, r] of Object.entries(ref.fabrics)) {
    const block = mcBlock(r.threads), lobe = yarnLobeOptions(block);
    const shader = mcShaderAsJs(compiled(block).sh.fragmentShader);
    const { lit, beyond, msg } = compareLobePairs(name, r.pairs,
      (wo, wi) => microcylinderEvalSplit(lobe, wo, wi), shader);
    check(() => assert.ok(lit > r.pairs.length / 2 && beyond === 0, msg), `microcylinder shader = port (${name})`);
    if (args.verbose) console.log(`microcylinder shader ${msg}`);
  }
  // identical offsets merged: satin's 8 + 1 offsets are 5 + 1 tangent calls
  {
    const { sh } = compiled(mcBlock(ref.fabrics.satin.threads));
    check(() => assert.equal((sh.fragmentShader.match(/^\twovenMcTangent\( /gm) ?? []).length, 6), 'microcylinder: satin has 6 distinct tangents');
  }
  // The browser cases' presets (web/test/yarn-lobe-{velvet,linen,satin}.json, written by
  // `clothfit fit --yarn-lobe preset`): loaded as MeshWovenMaterial with the lobe, own program key,
  // the #defines and the IBL texture of the Irawan lobe, survive clone; a lobe of the other model
  // compiles another program.
  for (const fab of ['velvet', 'linen', 'satin']) {
    const file = path.join(repo, 'web', 'test', `yarn-lobe-${fab}.json`);
    const j = JSON.parse(fs.readFileSync(file, 'utf8'));
    const m = loadClothfitPreset(fs.readFileSync(file, 'utf8'));
    const yl = m.yarnLobe;
    const n = new Set(yl.threads.flatMap((t, k) => (t.a > 0 ? t.offsets.map((o) => `${k}:${o}`) : []))).size;
    check(() => assert.ok(yl.model === 'sadeghi-microcylinder' && yl.threads.length === 2 && yl.ibl.summary.length === 2 * yl.ibl.n_theta * yl.ibl.n_phi * 5), `${fab}: microcylinder lobe loaded`);
    const key = m.customProgramCacheKey();
    check(() => assert.match(key, new RegExp(`^woven:additive:uniform:split:yarn-lobe-mc${n}/${yl.ibl.n_theta}x${yl.ibl.n_phi}/[0-9a-f]{16}$`)), `${fab}: its own program (${key})`);
    const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: 'void main() {\n#include <project_vertex>\n}' };
    m.onBeforeCompile(sh);
    check(() => assert.ok(['WOVEN_YARN_LOBE\n', `WOVEN_YL_N_THETA ${yl.ibl.n_theta}\n`, `WOVEN_YL_N_PHI ${yl.ibl.n_phi}\n`].every((d) => sh.fragmentShader.includes(`#define ${d}`))
      && (sh.fragmentShader.match(/^\twovenMcTangent\( /gm) ?? []).length === n && !sh.fragmentShader.includes('@wovenYarnLobe')
      && (sh.fragmentShader.match(/^vec2 wovenYarnLobe\( /gm) ?? []).length === 1), `${fab}: microcylinder source generated`);
    check(() => assert.ok(sh.uniforms.wovenYlIbl.value.image.width === 2 * yl.ibl.n_phi && sh.uniforms.wovenYlIbl.value.image.height === 2 * yl.ibl.n_theta), `${fab}: IBL texture`);
    // the shader's value at the preset's tints: out[0] in the warp slot, out[1] in the weft slot
    check(() => assert.deepEqual(j.woven.tint_warp, [1, 1, 1]), `${fab}: surface white (tint_warp)`);
    const clone = m.clone();
    check(() => assert.ok(clone.yarnLobe.model === 'sadeghi-microcylinder' && clone.customProgramCacheKey() === key), `${fab}: survives clone`);
    const canvas = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'yarn-lobe-canvas.json'), 'utf8')).woven.yarn_lobe;
    clone.setYarnLobe(canvas);
    check(() => assert.ok(clone.customProgramCacheKey().startsWith('woven:additive:uniform:split:yarn-lobe2x')), `${fab}: Irawan lobe set: the Irawan program`);
    clone.setYarnLobe(j.woven.yarn_lobe);
    check(() => assert.equal(clone.customProgramCacheKey(), key), `${fab}: back to the same program`);
  }
  // bad blocks: each field named (the C++ reader's messages), wrong key counts, escaped keys
  const good = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'yarn-lobe-satin.json'), 'utf8')).woven.yarn_lobe;
  check(() => assert.ok(loadClothfitPreset(wp({ yarn_lobe: good })).yarnLobe.threads[1].offsets.length === 1), 'microcylinder block accepted');
  const bad = (edit) => { const b = JSON.parse(JSON.stringify(good)); edit(b); return wp({ yarn_lobe: b }); };
  const T = 'woven\\.yarn_lobe\\.threads';
  for (const [edit, re] of [
    [(b) => { b.model = 'sadeghi'; }, /woven\.yarn_lobe\.model: expected "irawan-far-field" or "sadeghi-microcylinder"$/],
    [(b) => { delete b.model; }, /woven\.yarn_lobe\.model: missing/],
    [(b) => { b.nodes = 8; }, /woven\.yarn_lobe\.nodes: unknown key \(valid: model, fabric, threads, ibl\)/],
    [(b) => { b['<img src=x>'] = 1; }, /woven\.yarn_lobe\."\\u003cimg src=x\\u003e": unknown key/],
    [(b) => { delete b.threads; }, /woven\.yarn_lobe\.threads: missing/],
    [(b) => { b.fabric = 3; }, /woven\.yarn_lobe\.fabric: expected a string/],
    [(b) => { b.threads = b.threads.slice(0, 1); }, new RegExp(`${T}: expected an array of 2 threads`)],
    [(b) => { b.threads.push(b.threads[0]); }, new RegExp(`${T}: expected an array of 2 threads`)],
    [(b) => { b.threads = { 0: 1 }; }, new RegExp(`${T}: expected an array of 2 threads`)],
    [(b) => { b.threads[1] = [1, 2]; }, new RegExp(`${T}\\[1\\]: expected an object`)],
    [(b) => { b.threads[0].albedo = 0.3; }, new RegExp(`${T}\\[0\\]\\.albedo: unknown key \\(valid: eta, kd, gamma_s, gamma_v, a, volume_scale, offsets\\)`)],
    [(b) => { delete b.threads[1].volume_scale; }, new RegExp(`${T}\\[1\\]\\.volume_scale: missing`)],
    [(b) => { b.threads[0].eta = 1; }, new RegExp(`${T}\\[0\\]\\.eta: expected a number in \\(1, 3\\)`)],
    [(b) => { b.threads[1].eta = 3; }, new RegExp(`${T}\\[1\\]\\.eta: expected a number in \\(1, 3\\)`)],
    [(b) => { b.threads[0].eta = '1.5'; }, new RegExp(`${T}\\[0\\]\\.eta: expected a number, got string`)],
    [(b) => { b.threads[0].kd = -0.1; }, new RegExp(`${T}\\[0\\]\\.kd: expected a number in \\[0, 1\\]`)],
    [(b) => { b.threads[1].kd = null; }, new RegExp(`${T}\\[1\\]\\.kd: expected a number, got null`)],
    [(b) => { b.threads[1].gamma_s = 0; }, new RegExp(`${T}\\[1\\]\\.gamma_s: expected degrees in \\(0, 90\\]`)],
    [(b) => { b.threads[0].gamma_s = 90.5; }, new RegExp(`${T}\\[0\\]\\.gamma_s: expected degrees in \\(0, 90\\]`)],
    [(b) => { b.threads[0].gamma_v = -5; }, new RegExp(`${T}\\[0\\]\\.gamma_v: expected degrees in \\(0, 90\\]`)],
    [(b) => { b.threads[1].a = 1.5; }, new RegExp(`${T}\\[1\\]\\.a: expected a number in \\[0, 1\\]`)],
    [(b) => { b.threads[1].a = 0.2; }, new RegExp(`${T}: a_1 \\+ a_2 must be <= 1`)],
    [(b) => { b.threads[0].volume_scale = 1.2; }, new RegExp(`${T}\\[0\\]\\.volume_scale: expected a number in \\[0, 1\\]`)],
    [(b) => { b.threads[0].offsets = []; }, new RegExp(`${T}\\[0\\]\\.offsets: expected an array of 1 to 64 numbers \\(degrees\\), got 0`)],
    [(b) => { b.threads[1].offsets = Array(65).fill(0); }, new RegExp(`${T}\\[1\\]\\.offsets: expected an array of 1 to 64 numbers \\(degrees\\), got 65`)],
    [(b) => { b.threads[1].offsets = 0; }, new RegExp(`${T}\\[1\\]\\.offsets: expected an array of 1 to 64 numbers \\(degrees\\)$`)],
    [(b) => { b.threads[0].offsets[3] = 91; }, new RegExp(`${T}\\[0\\]\\.offsets\\[3\\]: expected degrees in \\[-90, 90\\]`)],
    [(b) => { b.threads[0].offsets[2] = 'x'; }, new RegExp(`${T}\\[0\\]\\.offsets\\[2\\]: expected a number, got string`)],
    [(b) => { delete b.ibl; }, /woven\.yarn_lobe\.ibl: missing/],
    [(b) => { b.ibl.summary.pop(); }, /woven\.yarn_lobe\.ibl\.summary: \d+ numbers, expected 2 x n_theta x n_phi x 5 = \d+/],
    [(b) => { b.ibl.n_phi = 2; }, /woven\.yarn_lobe\.ibl\.n_phi: must be in \[3, 128\]/],
  ]) {
    check(() => assert.throws(() => loadClothfitPreset(bad(edit)), re), `bad microcylinder yarn_lobe ${edit}`);
  }
  // a_1 + a_2 = 1 exactly (satin) is accepted, up to the C++ reader's 1e-9
  check(() => assert.ok(loadClothfitPreset(bad((b) => { b.threads[1].a = 0.1 + 5e-10; })).yarnLobe), 'a_1 + a_2 <= 1 + 1e-9 accepted');
  // the same text checks as for the Irawan lobe (n_theta 16.0 refused) and its preset rules
  check(() => assert.throws(() => loadClothfitPreset(JSON.stringify(wp({ yarn_lobe: good })).replace('"n_theta":16', '"n_theta":16.0')), /woven\.yarn_lobe\.ibl\.n_theta: expected an integer/), 'microcylinder: n_theta 16.0 literal refused');
  check(() => assert.throws(() => loadClothfitPreset(wp({ ibl: 'fis', yarn_lobe: good })), /woven\.ibl: must be "split" with a yarn_lobe/), 'microcylinder lobe needs the split sum');
}

// From the real converter: a glTF with one single-sided and one double-sided material.
if (args.clothfit) {
  const work = path.resolve(args.work ?? fs.mkdtempSync('/tmp/clothfit-unit-'));
  const dir = path.join(work, 'side-src');
  fs.mkdirSync(dir, { recursive: true });
  const mat = (name, ds) => ({ name, doubleSided: ds, pbrMetallicRoughness: { baseColorFactor: [0.5, 0.4, 0.3, 1], roughnessFactor: 0.7, metallicFactor: 0 } });
  fs.writeFileSync(path.join(dir, 'two.gltf'), JSON.stringify({ asset: { version: '2.0' }, materials: [mat('single', false), mat('double', true)] }));
  const out = path.join(work, 'side-out');
  const r = spawnSync(args.clothfit, ['convert', path.join(dir, 'two.gltf'), '--to', 'threejs', '--out', out], { encoding: 'utf8' });
  assert.equal(r.status, 0, `clothfit convert: ${r.stderr}`);
  const files = fs.readdirSync(out, { recursive: true }).map(String).filter((f) => f.endsWith('.json'));
  let seen = 0;
  for (const f of files) {
    const j = JSON.parse(fs.readFileSync(path.join(out, f), 'utf8'));
    if (j?.metadata?.type !== 'Material') continue;
    const single = f.includes('single');
    check(() => assert.equal(j.side, single ? 0 : 2, f), `convert ${f}`);
    check(() => assert.equal(loadClothfitPreset(j).side, single ? THREE.FrontSide : THREE.DoubleSide, f), `load ${f}`);
    seen++;
  }
  assert.ok(seen >= 2, `expected three.js JSON for both materials in ${out}: ${files.join(', ')}`);
}

// Session 24: the preset's parameter values, checked as the C++ reader checks them. Every model
// of `clothfit models --json` is registered in web/ with the same names, sizes, defaults and
// preset ranges (render/scene/material.cpp PresetRange); each bound is accepted and a step past
// it refused, naming the field; wrong types and sizes are refused too.
{
  const { clothfitModels, clothfitModelParameters } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const pre = (model, parameters) => ({ schema: 'clothfit.preset', version: 1, model, parameters });
  const fieldRe = (f) => new RegExp(`parameters\\.${f.replace(/[[\]]/g, '\\$&')}: `);
  if (args.clothfit) {
    const r = spawnSync(args.clothfit, ['models', '--json'], { encoding: 'utf8' });
    assert.equal(r.status, 0, `clothfit models --json: ${r.stderr}`);
    const table = JSON.parse(r.stdout);
    check(() => assert.equal(table.schema, 'clothfit.models'), 'models --json schema');
    for (const [model, { parameters }] of Object.entries(table.models)) {
      check(() => assert.ok(clothfitModels().includes(model), model), `web registers ${model}`);
      const web = clothfitModelParameters(model);
      check(() => assert.deepEqual(web.map((q) => q.name), parameters.map((q) => q.name), model), `${model}: parameter names`);
      for (const q of parameters) {
        const w = web.find((x) => x.name === q.name);
        check(() => assert.equal(w.size, q.size, `${model}.${q.name}`), `${model}.${q.name} size`);
        check(() => assert.deepEqual(w.default, q.default, `${model}.${q.name}`), `${model}.${q.name} default`);
        const [lo, hi] = q.preset_range;
        check(() => assert.ok(Math.abs(w.preset_range[0] - lo) <= 1e-12 * Math.max(1, Math.abs(lo)) && Math.abs(w.preset_range[1] - hi) <= 1e-12 * Math.max(1, Math.abs(hi)), `${model}.${q.name}: web ${w.preset_range}, C++ ${q.preset_range}`), `${model}.${q.name} preset range`);
        // behaviour at the bounds (every component for a colour)
        const val = (x) => (q.size === 1 ? x : Array(q.size).fill(x));
        const eps = (x) => Math.max(1e-9, 1e-6 * Math.abs(x));
        check(() => { loadClothfitPreset(pre(model, { [q.name]: val(lo) })); loadClothfitPreset(pre(model, { [q.name]: val(hi) })); }, `${model}.${q.name} bounds accepted`);
        const f = q.size === 1 ? q.name : `${q.name}[0]`;
        check(() => assert.throws(() => loadClothfitPreset(pre(model, { [q.name]: val(lo - eps(lo)) })), fieldRe(f)), `${model}.${q.name} below refused`);
        check(() => assert.throws(() => loadClothfitPreset(pre(model, { [q.name]: val(hi + eps(hi)) })), fieldRe(f)), `${model}.${q.name} above refused`);
      }
    }
  }
  // the case that was accepted before: a roughness of 7 (three.js clamps it silently)
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { roughness: 7 })), /parameters\.roughness: value 7 outside \[0, 1\]/), 'standard roughness 7 refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('woven', { twist: -91 })), /parameters\.twist: value -91 outside \[-90, 90\]/), 'woven twist -91 refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('woven', { base_color: [0.5, 1.5, 0.5] })), /parameters\.base_color\[1\]: value 1\.5 outside/), 'colour component refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('cloth', { base_color: [0.5, 0.5] })), /parameters\.base_color: expected an array of 3 numbers/), 'short colour refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('cloth', { roughness: '0.5' })), /parameters\.roughness: expected a number, got string/), 'string refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('cloth', { roughness: [0.5] })), /parameters\.roughness: expected a number, got array/), 'array for a scalar refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('physical-aniso', { specular_color: [1, NaN, 1] })), /parameters\.specular_color\[1\]: not finite/), 'NaN refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', [0.5])), /parameters: missing or not an object/), 'parameters array refused');
  check(() => assert.throws(() => loadClothfitPreset({ schema: 'clothfit.preset', version: 1, model: 'standard' }), /parameters: missing or not an object/), 'parameters missing refused (as the C++ reader)');
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', null)), /parameters: missing or not an object/), 'parameters null refused');
  // eslint-disable-next-line no-sparse-arrays
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { base_color: [0.5, , 0.5] })), /parameters\.base_color\[1\]: expected a number, got undefined/), 'a hole in a colour refused');
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { ['x'.repeat(50) + '\u2028\u202e']: 1 })), (e) => /"x{40}"\.\.\.: unknown/.test(e.message)), 'a long name cut, marked');
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { 'a\u2028b\u202ec\u007f': 1 })), (e) => e.message.includes('"a\\u2028b\\u202ec\\u007f"') && !/[\u2028\u202e\u007f]/.test(e.message)), 'separators, bidi overrides and DEL escaped');
  // names inherited from Object.prototype are unknown parameters, and untrusted names and models
  // reach the message quoted and escaped
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { toString: 1 })), /parameters\.toString: unknown for model/), 'toString is unknown');
  check(() => assert.throws(() => loadClothfitPreset(JSON.parse('{"schema": "clothfit.preset", "version": 1, "model": "standard", "parameters": {"__proto__": {"roughness": 7}}}')), /parameters\.__proto__: unknown/), '__proto__ is unknown');
  check(() => assert.throws(() => loadClothfitPreset(pre('standard', { 'a<b>\n': 1 })), (e) => /parameters\."a\\u003cb\\u003e\\n": unknown/.test(e.message) && !/[<>\n]/.test(e.message)), 'unknown name escaped');
  check(() => assert.throws(() => loadClothfitPreset(pre('<img src=x>', {})), (e) => /model: unknown "\\u003cimg src=x\\u003e"/.test(e.message) && !/[<>]/.test(e.message)), 'unknown model escaped');
  check(() => assert.equal(loadClothfitPreset(pre('physical-aniso', { specular_color: [25, 0, 3] })).specularColor.r, 25), 'specular_color up to 25 accepted');
  // session 27: a misspelt top-level field is refused (as the C++ reader), an unknown one kept
  check(() => assert.throws(() => loadClothfitPreset({ ...pre('woven', {}), weave_map: { file: 'x.exr' } }), /weave_map: unknown field; did you mean 'weave_maps'\?/), 'weave_map refused');
  check(() => assert.throws(() => loadClothfitPreset({ ...pre('woven', {}), Woven: {} }), /Woven: unknown field; did you mean 'woven'\?/), 'Woven refused');
  check(() => assert.throws(() => loadClothfitPreset({ ...pre('cloth', {}), paramters: {} }), /did you mean 'parameters'\?/), 'paramters refused');
  check(() => assert.throws(() => loadClothfitPreset({ ...pre('woven', {}), waeve_maps: {} }), /did you mean 'weave_maps'\?/), 'a swap of two letters is one edit');
  check(() => assert.equal(loadClothfitPreset({ ...pre('cloth', {}), future_block: { a: 1 } }).userData.clothfit.future_block.a, 1), 'an unknown field far from every known one is kept');
  check(() => loadClothfitPreset({ ...pre('cloth', {}), size: 1, mode: 2, names: 3, 'mod\u00e9l': 4 }), 'short names refused by case only, non-ASCII keys never (as the C++ reader)');
}

// Session 24: environment texels as the C++ reader keeps them (render/scene/environment.cpp):
// negative or non-finite R, G, B set to 0, alpha untouched, for 32-bit and half-float data; the
// counts are texels, as the C++ warning's.
{
  const { clampEnvironmentTexels } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const H = THREE.DataUtils.toHalfFloat;
  const f = new Float32Array([1, -2, 3, -1, /**/ NaN, 0.5, -0.25, 1, /**/ 0, 0, 0, 1, /**/ Infinity, 2, 2, 1]);
  const tf = new THREE.DataTexture(f, 2, 2, THREE.RGBAFormat, THREE.FloatType);
  const sf = clampEnvironmentTexels(tf);
  check(() => assert.deepEqual([sf.negative, sf.nonfinite, sf.mostNegative], [2, 2, -2]), 'float: counts (a texel with NaN and a negative counts in both)');
  check(() => assert.deepEqual([...f], [1, 0, 3, -1, 0, 0.5, 0, 1, 0, 0, 0, 1, 0, 2, 2, 1]), 'float: values (alpha kept)');
  const h = new Uint16Array([H(1), H(-9.0625), H(3), H(1), /**/ 0x7e00, H(0.5), 0x8000, H(1), /**/ H(-3336), H(0), H(0), H(-1), /**/ 0xfc00, H(2), H(2), H(1)]);
  const th = new THREE.DataTexture(h, 2, 2, THREE.RGBAFormat, THREE.HalfFloatType);
  const sh = clampEnvironmentTexels(th);
  check(() => assert.deepEqual([sh.negative, sh.nonfinite, sh.mostNegative], [2, 2, -3336]), 'half: counts (-0 is not negative)');
  check(() => assert.deepEqual([...h].map((x) => THREE.DataUtils.fromHalfFloat(x)), [1, 0, 3, 1, 0, 0.5, -0, 1, 0, 0, 0, -1, 0, 2, 2, 1]), 'half: values (alpha kept)');
  const clean = new Float32Array([0, 1, 2]);
  check(() => assert.deepEqual(clampEnvironmentTexels(new THREE.DataTexture(clean, 1, 1, THREE.RGBFormat, THREE.FloatType)), { negative: 0, nonfinite: 0, mostNegative: 0 }), 'clean map untouched');
}

// ---- weave maps (web/exr.js, weaveMapsFromExr; the C++ side is render/preview/weave_maps.*) ----
{
  const { parseExr } = await import(pathToFileURL(path.join(repo, 'web', 'exr.js')).href);
  const { weaveMapsFromExr, anisotropyFromWeave, fetchClothfitPreset, weaveMapUrl, weaveMapUriUrl, presetIntegerLiterals } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const exrPath = path.join(here, 'maps', 'canvas.weave.exr');
  const buf = fs.readFileSync(exrPath);
  const img = parseExr(buf, exrPath);
  check(() => assert.deepEqual([img.width, img.height, Object.keys(img.channels).sort().join(',')], [64, 64, 'kd.B,kd.G,kd.R,warp,weft']), 'exr channels');
  check(() => assert.equal(Number(img.attributes['clothfit:uv_repeats']), 60), 'exr uv_repeats metadata');
  // An independent decoder (OpenImageIO's oiiotool, if installed) on a few texels: same values,
  // row 0 = the image's top row.
  const oiio = spawnSync('oiiotool', ['--dumpdata', exrPath], { encoding: 'utf8' });
  if (oiio.status === 0) {
    const px = new Map();
    for (const line of oiio.stdout.split('\n')) {
      const m = /Pixel \((\d+), (\d+)\): (.*)$/.exec(line);
      if (m) px.set(`${m[1]},${m[2]}`, m[3].trim().split(/\s+/).map(Number));
    }
    for (const [x, y] of [[0, 0], [5, 0], [0, 1], [17, 40], [63, 63], [31, 2]]) {
      const ref = px.get(`${x},${y}`);  // oiiotool order: warp weft kd.R kd.G kd.B
      ['warp', 'weft', 'kd.R', 'kd.G', 'kd.B'].forEach((c, k) => check(() => assert.ok(Math.abs(img.channels[c][y * 64 + x] - ref[k]) <= 1e-8 * Math.max(1, ref[k]), `${c} at (${x}, ${y}): ${img.channels[c][y * 64 + x]} vs oiiotool ${ref[k]}`), 'exr vs oiiotool'));
    }
  } else {
    console.log('unit: oiiotool not found, EXR cross-check skipped');
  }
  const maps = weaveMapsFromExr(buf, { field: { uv_repeats: 60 }, name: exrPath });
  check(() => assert.equal(maps.levels.length, 7), 'mip count 64 -> 1');
  for (let c = 0; c < 5; ++c) {
    let mean = 0;
    for (let t = 0; t < 64 * 64; ++t) mean += maps.levels[0][t * 5 + c];
    check(() => assert.ok(Math.abs(mean / 4096 - 1) < 1e-6, `channel ${c} tile mean ${mean / 4096}`), 'tile mean 1');
    check(() => assert.ok(Math.abs(maps.levels[6][c] - 1) < 1e-6, `1x1 mip ${maps.levels[6][c]}`), '1x1 mip = mean');
  }
  // level 1 texel (3, 5) = the box average of level-0 texels (6..7, 10..11), in float32.
  const at = (l, s, i, j, c) => maps.levels[l][(j * s + i) * 5 + c];
  check(() => assert.equal(at(1, 32, 3, 5, 1), Math.fround(0.25 * (at(0, 64, 6, 10, 1) + at(0, 64, 7, 10, 1) + at(0, 64, 6, 11, 1) + at(0, 64, 7, 11, 1)))), 'box mip');
  check(() => assert.equal(maps.weightsTexture.mipmaps.length, 7), 'texture mip chain');
  check(() => assert.equal(maps.weightsTexture.flipY, false), 'no flip');
  check(() => assert.equal(maps.weightsTexture.wrapS, THREE.RepeatWrapping), 'repeat');
  check(() => assert.equal(maps.kdTexture.minFilter, THREE.LinearMipmapLinearFilter), 'trilinear');
  check(() => assert.equal(maps.uvTransform.elements[0], 60), 'uv transform scale');
  check(() => assert.equal(weaveMapsFromExr(buf, { field: {} }).uvRepeats, 60), 'uv_repeats from the file');
  check(() => assert.equal(weaveMapsFromExr(buf, { field: { uv_repeats: 12 } }).uvRepeats, 12), 'preset uv_repeats wins');
  check(() => assert.throws(() => weaveMapsFromExr(buf, { field: { uv_repeats: -1 }, name: 'x.exr' }), /x\.exr: weave maps: weave_maps\.uv_repeats/), 'bad uv_repeats');
  check(() => assert.throws(() => parseExr(new Uint8Array(16), 'junk.exr'), /junk\.exr: not an OpenEXR file/), 'bad exr');
  const an = anisotropyFromWeave(new Float32Array([3, 1, 1, 1, 1, 1, 3, 1, 1, 1, 0, 0, 1, 1, 1, 2, 2, 1, 1, 1]), 2);
  check(() => assert.deepEqual(Array.from(an), [1, 0.5, 0.5, 1, 0.5, 1, 0.5, 1, 1, 0.5, 0, 1, 1, 0.5, 0, 1]), 'anisotropy encoding');
  const wpm = (extra) => ({ schema: 'clothfit.preset', version: 1, model: 'woven', parameters: {}, weave_maps: { file: exrPath, uv_repeats: 60 }, ...extra });
  check(() => assert.throws(() => loadClothfitPreset(wpm()), /weave_maps: the preset names weave maps/), 'maps required');
  check(() => assert.equal(loadClothfitPreset(wpm(), { weaveMaps: null }).weaveMaps, null), 'uniform on purpose');
  check(() => assert.equal(loadClothfitPreset(wpm(), { weaveMaps: maps }).weaveMaps, maps), 'woven maps attached');
  check(() => assert.throws(() => loadClothfitPreset({ ...wpm(), model: 'standard' }, { weaveMaps: maps }), /weave_maps: not used by model 'standard'/), 'maps refused on standard');
  const pa = loadClothfitPreset({ ...wpm(), model: 'physical-aniso', parameters: { anisotropy_strength: 0.5 } }, { weaveMaps: maps });
  check(() => assert.ok(pa.map === maps.kdTexture && pa.anisotropyMap && pa.anisotropyMap.repeat.x === 60 && pa.map.repeat.y === 60), 'physical-aniso map + anisotropyMap');
  check(() => assert.equal(weaveMapUrl('/abs/dir/x.weave.exr', 'http://h/p/x.json'), 'http://h/p/x.weave.exr'), 'absolute file -> next to the preset');
  check(() => assert.equal(weaveMapUrl('maps/x.exr', 'http://h/p/x.json'), 'http://h/p/maps/x.exr'), 'relative file');
  // s9-aniso: weave_maps.anisotropy -> texture.anisotropy of every map (1 without the key),
  // clamped to the renderer's max; 0, 17, 2.5, "x" refused naming the field, and a literal 16.0
  // in the preset's text too (as the C++ reader, nlohmann is_number_integer).
  check(() => assert.equal(maps.weightsTexture.anisotropy, 1), 'anisotropy default 1');
  const m16 = weaveMapsFromExr(buf, { field: { anisotropy: 16 } });
  check(() => assert.ok(m16.weightsTexture.anisotropy === 16 && m16.kdTexture.anisotropy === 16 && m16.anisotropyTexture().anisotropy === 16), 'anisotropy 16 on every map');
  check(() => assert.equal(weaveMapsFromExr(buf, { field: { anisotropy: 16 }, maxAnisotropy: 4 }).kdTexture.anisotropy, 4), 'anisotropy clamped to the renderer max');
  for (const bad of [0, 17, 2.5, 'x', -1]) {
    check(() => assert.throws(() => weaveMapsFromExr(buf, { field: { anisotropy: bad }, name: 'a.exr' }), /weave_maps\.anisotropy: expected an integer in \[1, 16\]/), `bad anisotropy ${bad}`);
  }
  check(() => assert.throws(() => loadClothfitPreset('{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {"anisotropy": 1.0}, "weave_maps": {"file": "m.exr", "source": {"texels": 64.0}, "anisotropy": 16.0}}', { weaveMaps: null }), /weave_maps\.anisotropy: expected an integer/), 'anisotropy 16.0 literal refused');
  check(() => assert.ok(loadClothfitPreset('{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {"anisotropy": 1.0}, "weave_maps": {"file": "m.exr", "source": {"anisotropy": 2.0}, "anisotropy": 16}}', { weaveMaps: null })), 'a float "anisotropy" elsewhere is not the maps\' key');
  check(() => assert.throws(() => loadClothfitPreset('{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {}, "woven": {"ibl": "fis", "fis_taps": 16.0}}'), /loadClothfitPreset: woven\.fis_taps: expected an integer/), 'fis_taps 16.0 literal refused');
  check(() => assert.throws(() => loadClothfitPreset('{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {}, "woven": {"ibl": "fis", "fis_diffuse_taps": 1e1}}'), /woven\.fis_diffuse_taps: expected an integer/), 'fis_diffuse_taps 1e1 literal refused');
  check(() => assert.equal(loadClothfitPreset('{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {}, "woven": {"ibl": "fis", "fis_taps": 16}}').fisTaps, 16), 'fis_taps 16 accepted');
  // The literal check follows the key path (session 9 review): nested objects, braces inside
  // strings and earlier keys of the same name do not hide or fake a match.
  check(() => assert.throws(() => presetIntegerLiterals('{"weave_maps": {"source": {"a": {"b": 1}}, "file": "a}b.exr", "anisotropy": 16.0}}'), /weave_maps\.anisotropy: expected an integer/), 'anisotropy 16.0 after a two-level object and a "}" in a string');
  check(() => assert.throws(() => presetIntegerLiterals('{"x": {"weave_maps": {"anisotropy": 4}}, "weave_maps": {"anisotropy": 16.0}}'), /weave_maps\.anisotropy/), 'anisotropy 16.0 after a nested "weave_maps"');
  check(() => assert.doesNotThrow(() => presetIntegerLiterals('{"provenance": {"fis_taps": 2.5, "woven": {"fis_taps": 1.5}}, "woven": {"fis_taps": 16}, "a": [{}, "woven", 1.5]}')), 'fis_taps floats at other paths are not checked');
  check(() => assert.throws(() => presetIntegerLiterals('{"woven": {"note": "q\\"}", "fis_taps": 1e1}}'), /woven\.fis_taps/), 'an escaped quote in a string');
  check(() => assert.throws(() => weaveMapsFromExr(buf, { field: { anisotropy: '\u202e'.repeat(200) } }), (e) => e.message.endsWith('got string')), 'a bad anisotropy value is named by type, not echoed');
  const mapsWork = fs.mkdtempSync('/tmp/clothfit-unit-maps-');
  const presetFile = path.join(mapsWork, 'woven-maps-unit.json');
  fs.writeFileSync(presetFile, JSON.stringify(wpm()));
  const fm = await fetchClothfitPreset(pathToFileURL(presetFile).href, { resolveWeaveMapPath: (f) => pathToFileURL(f).href });
  check(() => assert.ok(fm.weaveMaps && fm.weaveMaps.uvRepeats === 60), 'fetchClothfitPreset loads the maps');
  fs.writeFileSync(presetFile, JSON.stringify(wpm()).replace('"uv_repeats":60', '"uv_repeats":60,"anisotropy":16.0'));
  await assert.rejects(fetchClothfitPreset(pathToFileURL(presetFile).href, { resolveWeaveMapPath: (f) => pathToFileURL(f).href }), /woven-maps-unit\.json: weave_maps\.anisotropy: expected an integer/);
  fs.writeFileSync(presetFile, JSON.stringify(wpm()).replace('"uv_repeats":60', '"uv_repeats":60,"anisotropy":8'));
  const fa = await fetchClothfitPreset(pathToFileURL(presetFile).href, { resolveWeaveMapPath: (f) => pathToFileURL(f).href, maxAnisotropy: 16 });
  check(() => assert.equal(fa.weaveMaps.kdTexture.anisotropy, 8), 'fetchClothfitPreset: the preset\'s anisotropy');
  fs.writeFileSync(presetFile, JSON.stringify(wpm({ weave_maps: { file: exrPath, glint_file: exrPath } })));
  await assert.rejects(fetchClothfitPreset(pathToFileURL(presetFile).href, { resolveWeaveMapPath: (f) => pathToFileURL(f).href }), /woven-maps-unit\.json: weave_maps\.glint_file/);
  // "uri" first (docs/preset-format.md "Weave maps: `uri` and `file`"): relative to the preset,
  // never through resolveWeaveMapPath; a decoy "file" must not be read.
  check(() => assert.equal(weaveMapUriUrl('x.weave.exr', 'http://h/p/x.json'), 'http://h/p/x.weave.exr'), 'uri next to the preset');
  check(() => assert.equal(weaveMapUriUrl('m/../x.exr', 'http://h/p/x.json'), 'http://h/p/x.exr'), 'uri with an inner ..');
  for (const [bad, why] of [['../x.exr', /escapes the preset's directory/], ['a/../../x.exr', /escapes/], ['/etc/x.exr', /must be relative/],
    ['http://evil/x.exr', /must be relative/], ['data:,x', /must be relative/], ['a\\b.exr', /backslash/], ['a/%2e%2e/%2e%2e/x.exr', /percent/i], ['.%2e/x.exr', /percent/i], ['a\u0001.exr', /control character/], ['', /non-empty/], [7, /non-empty string/]]) {
    check(() => assert.throws(() => weaveMapUriUrl(bad, 'http://h/p/x.json'), (e) => /^weave_maps\.uri: /.test(e.message) && why.test(e.message) && !/[\u0000-\u001f]/.test(e.message)), `bad uri ${JSON.stringify(bad)}`);
  }
  fs.copyFileSync(exrPath, path.join(mapsWork, 'moved.weave.exr'));
  fs.writeFileSync(presetFile, JSON.stringify(wpm({ weave_maps: { uri: 'moved.weave.exr', file: '/nonexistent/decoy.weave.exr', uv_repeats: 60 } })));
  const fu = await fetchClothfitPreset(pathToFileURL(presetFile).href, { resolveWeaveMapPath: () => { throw new Error('resolveWeaveMapPath asked for a uri'); } });
  check(() => assert.ok(fu.weaveMaps && fu.weaveMaps.uvRepeats === 60 && fu.weaveMaps.size === maps.size), 'fetchClothfitPreset loads the maps by uri, not file');
  fs.writeFileSync(presetFile, JSON.stringify(wpm({ weave_maps: { uri: '../escape.weave.exr', uv_repeats: 60 } })));
  await assert.rejects(fetchClothfitPreset(pathToFileURL(presetFile).href), /woven-maps-unit\.json: weave_maps\.uri: "\.\.\/escape\.weave\.exr" escapes/);
  checks++;
  checks++;
  fs.rmSync(mapsWork, { recursive: true, force: true });
}
// ---- view-dependent weave maps (session 14; docs/web.md "View-dependent weave maps") ----------
// web/test/yarn-lobe-twill-maps-views.{json,weave.exr}: the twill lobe maps plus 3 view bands
// (view{k}.*, clothfit:view_cosines). The blend weights, the preset's view_cosines checked as the
// C++ reader checks them (render/preview/weave_maps.cpp LoadPresetWeaveMaps), the bands' data and
// packing, the program (a preset without view_cosines compiles the old program), missing channels.
{
  const { weaveMapsFromExr, weaveMapViewCosines, weaveMapViewWeights, fetchClothfitPreset } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const { parseExr } = await import(pathToFileURL(path.join(repo, 'web', 'exr.js')).href);
  const GL = [0.8872983346207417, 0.5, 0.1127016653792583];
  // Blend weights: exact at the nodes, linear between, clamped outside, sum 1; the hat functions
  // over the ascending nodes (piecewise-linear interpolation: a linear f is reproduced inside).
  for (const [i, c] of GL.entries()) check(() => assert.deepEqual(weaveMapViewWeights(GL, c), GL.map((_, k) => (k === i ? 1 : 0))), `view weights exact at node ${i}`);
  for (const [x, want] of [[1, [1, 0, 0]], [0.95, [1, 0, 0]], [0.05, [0, 0, 1]], [0, [0, 0, 1]], [-0.3, [0, 0, 1]], [1.7, [1, 0, 0]], [NaN, [0, 0, 1]]]) {
    check(() => assert.deepEqual(weaveMapViewWeights(GL, x), want), `view weights clamped at ${x}`);
  }
  check(() => assert.deepEqual(weaveMapViewWeights(GL, (GL[0] + GL[1]) / 2).map((w) => +w.toFixed(12)), [0.5, 0.5, 0]), 'view weights: midpoint of bands 0 and 1');
  check(() => assert.deepEqual(weaveMapViewWeights(GL, 0.3).map((w) => +w.toFixed(12)), [0, +((0.3 - GL[2]) / (GL[1] - GL[2])).toFixed(12), +((GL[1] - 0.3) / (GL[1] - GL[2])).toFixed(12)]), 'view weights: between bands 1 and 2');
  {
    let worst = 0, worstLin = 0;
    const f = (c) => 2 * c - 0.3;  // linear: reproduced exactly between the nodes
    for (let i = 0; i <= 1000; ++i) {
      const x = i / 1000, w = weaveMapViewWeights(GL, x);
      worst = Math.max(worst, Math.abs(w.reduce((a, b) => a + b, 0) - 1));
      if (w.some((v) => v < 0 || v > 1)) worst = Infinity;
      if (x >= GL[2] && x <= GL[0]) worstLin = Math.max(worstLin, Math.abs(w.reduce((a, v, k) => a + v * f(GL[k]), 0) - f(x)));
    }
    check(() => assert.ok(worst < 1e-15 && worstLin < 1e-14, `sum ${worst}, linear ${worstLin}`), 'view weights: in [0, 1], sum 1, linear interpolation');
    const eight = [1, 0.9, 0.75, 0.6, 0.4, 0.3, 0.2, 0.1];
    check(() => assert.deepEqual(weaveMapViewWeights(eight, 0.7).map((v) => +v.toFixed(12)), [0, 0, +(2 / 3).toFixed(12), +(1 / 3).toFixed(12), 0, 0, 0, 0]), 'view weights: 8 bands');
  }
  // The preset's view_cosines (2..8 numbers, strictly decreasing, in (0, 1]).
  check(() => assert.deepEqual(weaveMapViewCosines({ view_cosines: GL }), GL), 'view_cosines accepted');
  check(() => assert.equal(weaveMapViewCosines({ uri: 'x.exr' }), null), 'no view_cosines: null');
  check(() => assert.deepEqual(weaveMapViewCosines({ view_cosines: [1, 0.5] }), [1, 0.5]), 'view_cosines 1 is allowed');
  for (const [bad, why] of [[[0.5, 0.8, 0.1], /\[1\]: 0\.8 is not below \[0\] 0\.5 \(expected strictly decreasing\)/], [[0.5, 0.5], /\[1\]: 0\.5 is not below/],
    [[0.8, 0.5, 0], /\[2\]: 0 is not in \(0, 1\]/], [[1.2, 0.5], /\[0\]: 1\.2 is not in \(0, 1\]/], [[0.5, -0.1], /\[1\]: -0\.1 is not in/], [[0.5], /1 numbers, expected 2 to 8/],
    [[0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1], /9 numbers, expected 2 to 8/], [[], /0 numbers/], [[0.8, '0.5'], /\[1\]: expected a finite number, got string/],
    [[0.8, null], /\[1\]: expected a finite number, got null/], ['0.8 0.5', /expected an array of 2 to 8 numbers, got string/], [null, /got null/], [{ 0: 0.8, 1: 0.5 }, /expected an array/]]) {
    check(() => assert.throws(() => weaveMapViewCosines({ view_cosines: bad }), (e) => /^loadClothfitPreset: weave_maps\.view_cosines: /.test(e.message) && why.test(e.message)), `bad view_cosines ${JSON.stringify(bad)}`);
    check(() => assert.throws(() => loadClothfitPreset({ schema: 'clothfit.preset', version: 1, model: 'woven', parameters: {}, weave_maps: { uri: 'm.exr', view_cosines: bad } }, { weaveMaps: null }), /loadClothfitPreset: weave_maps\.view_cosines: /), `bad view_cosines ${JSON.stringify(bad)} (loadClothfitPreset)`);
  }
  // The bands: data as the C++ reader makes them (renormalised, box mips), packed 5 K channels
  // into ceil(5 K / 4) RGBA textures with the main maps' settings.
  const viewsExr = path.join(repo, 'web', 'test', 'yarn-lobe-twill-maps-views.weave.exr'), plainExr = path.join(repo, 'web', 'test', 'yarn-lobe-twill-maps.weave.exr');
  const viewsPreset = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', 'yarn-lobe-twill-maps-views.json'), 'utf8'));
  const vbuf = fs.readFileSync(viewsExr), vimg = parseExr(vbuf, viewsExr);
  check(() => assert.equal(vimg.attributes['clothfit:view_cosines'], GL.join(' ')), 'views EXR: clothfit:view_cosines');
  check(() => assert.deepEqual(viewsPreset.weave_maps.view_cosines, GL), 'views preset: view_cosines');
  const vm = weaveMapsFromExr(vbuf, { field: viewsPreset.weave_maps, name: 'views.exr' });
  check(() => assert.ok(vm.viewCosines.length === 3 && vm.viewLevels.length === 3 && vm.viewTextures.length === 4), 'views: 3 bands, 4 packed textures');
  {
    let worstMean = 0, worstPack = 0;
    for (let k = 0; k < 3; ++k) {
      const l0 = vm.viewLevels[k][0];
      for (let c = 0; c < 5; ++c) {
        let mean = 0;
        for (let t = 0; t < 4096; ++t) mean += l0[t * 5 + c];
        worstMean = Math.max(worstMean, Math.abs(mean / 4096 - 1));
        const src = vimg.channels[`view${k}.${['warp', 'weft', 'kd.R', 'kd.G', 'kd.B'][c]}`];
        let raw = 0;
        for (let t = 0; t < 4096; ++t) raw += src[t];
        raw /= 4096;
        for (const t of [0, 77, 2048, 4095]) if (l0[t * 5 + c] !== Math.fround(src[t] / raw)) worstPack = Infinity;
        const g = 5 * k + c, tex = vm.viewTextures[g >> 2];
        for (let l = 0; l < 7; ++l) {
          const lv = vm.viewLevels[k][l], data = tex.mipmaps[l].data;
          for (let t = 0; t < lv.length / 5; t += 7) worstPack = Math.max(worstPack, Math.abs(data[t * 4 + (g & 3)] - lv[t * 5 + c]));
        }
      }
      check(() => assert.equal(vm.viewLevels[k][1][(3 * 32 + 5) * 5 + 1], Math.fround(0.25 * (vm.viewLevels[k][0][(6 * 64 + 10) * 5 + 1] + vm.viewLevels[k][0][(6 * 64 + 11) * 5 + 1] + vm.viewLevels[k][0][(7 * 64 + 10) * 5 + 1] + vm.viewLevels[k][0][(7 * 64 + 11) * 5 + 1]))), `band ${k}: box mip`);
    }
    check(() => assert.ok(worstMean < 1e-6 && worstPack === 0, `mean ${worstMean}, packing ${worstPack}`), 'views: bands renormalised to tile mean 1, packed texel for texel');
    check(() => assert.ok(vm.viewTextures[3].mipmaps[0].data[3] === 1 && vm.viewTextures[3].mipmaps[6].data[3] === 1), 'views: unused packed component is 1');
    check(() => assert.ok(vm.viewTextures.every((t) => t.mipmaps.length === 7 && t.anisotropy === 16 && t.wrapS === THREE.RepeatWrapping && t.wrapT === THREE.RepeatWrapping
      && t.minFilter === THREE.LinearMipmapLinearFilter && t.magFilter === THREE.LinearFilter && t.flipY === false && t.generateMipmaps === false
      && t.format === THREE.RGBAFormat && t.type === THREE.FloatType)), 'views: texture settings = the main maps\'');
  }
  // The material: its own program (key, #defines), uniforms; the NoV of the unperturbed normal.
  const vmat = loadClothfitPreset(viewsPreset, { weaveMaps: vm });
  check(() => assert.equal(vmat.viewBands, 3), 'material: 3 view bands');
  check(() => assert.match(vmat.customProgramCacheKey(), /^woven:additive:maps-views3:split:yarn-lobe4x16\/16x32\/[0-9a-f]{16}$/), 'views: their own program key');
  {
    const sh = { uniforms: {}, fragmentShader: THREE.ShaderChunk.meshphysical_frag, vertexShader: THREE.ShaderChunk.meshphysical_vert };
    vmat.onBeforeCompile(sh);
    const f = sh.fragmentShader;
    check(() => assert.ok(f.includes('#define WOVEN_VIEW_BANDS 3\n') && f.includes('#define WOVEN_VIEW_TEXTURES 4\n') && f.includes('uniform sampler2D wovenViewMaps[ WOVEN_VIEW_TEXTURES ];')), 'views: defines and samplers');
    check(() => assert.ok(!f.includes('texture2D( wovenWeaveWeights') && (f.match(/texture2D\( wovenViewMaps\[ \d \]/g) ?? []).length === 4), 'views: the bands replace the main maps\' read');
    check(() => assert.ok(f.includes('dot( nonPerturbedNormal, ( isOrthographic ) ? vec3( 0.0, 0.0, 1.0 ) : normalize( vViewPosition ) )')
      && f.indexOf('vec3 nonPerturbedNormal') < f.indexOf('wovenNoVView') && f.indexOf('#include <normal_fragment_maps>') < f.indexOf('wovenNoVView')), 'views: NoV from the normal before the normal map');
    check(() => assert.ok(sh.uniforms.wovenViewMaps.value.length === 4 && sh.uniforms.wovenViewMaps.value[2] === vm.viewTextures[2] && sh.uniforms.wovenViewCosines.value.join(' ') === GL.join(' ')), 'views: uniforms');
    // band 1's kd.G is packed channel 5 + 3 = 8: texture 2, x
    // (the last vec3( before three.js's lights_fragment_begin, which the horizon fade inlines)
    check(() => assert.ok(/wovenVW\[ 1 \] \* wovenVT2\.x/.test(f.slice(0, f.indexOf('vec3 geometryPosition = - vViewPosition;')).split('vec3(').pop())), 'views: band 1 kd.G = texture 2 .x');
    const clone = vmat.clone();
    check(() => assert.ok(clone.viewBands === 3 && clone.customProgramCacheKey() === vmat.customProgramCacheKey() && clone._wovenUniforms.wovenViewMaps.value.length === 4), 'views survive clone');
  }
  // Extra view channels without view_cosines: ignored, the old maps and the old program.
  const { view_cosines: _vc, ...plainField } = viewsPreset.weave_maps;
  const pm = weaveMapsFromExr(vbuf, { field: plainField }), om = weaveMapsFromExr(fs.readFileSync(plainExr), { field: plainField });
  check(() => assert.ok(pm.viewCosines === null && pm.viewTextures === null), 'view channels without view_cosines: ignored');
  check(() => assert.ok(pm.levels.every((lv, l) => lv.every((x, i) => x === om.levels[l][i]))), 'view channels without view_cosines: the main maps as the 5-channel file\'s');
  {
    const plainPreset = { ...viewsPreset, weave_maps: plainField };
    const a = loadClothfitPreset(plainPreset, { weaveMaps: pm }), b = loadClothfitPreset(plainPreset, { weaveMaps: om });
    const comp = (mat) => { const sh = { uniforms: {}, fragmentShader: THREE.ShaderChunk.meshphysical_frag, vertexShader: THREE.ShaderChunk.meshphysical_vert }; mat.onBeforeCompile(sh); return sh; };
    const sa = comp(a), sb = comp(b);
    check(() => assert.ok(/^woven:additive:maps:split:yarn-lobe4x16\/16x32\/[0-9a-f]{16}$/.test(a.customProgramCacheKey()) && sa.fragmentShader === sb.fragmentShader && !sa.fragmentShader.includes('WOVEN_VIEW')), 'without view_cosines: the old program');
  }
  // The maps given must carry the bands the preset names (and only then).
  check(() => assert.throws(() => loadClothfitPreset(viewsPreset, { weaveMaps: pm }), /weave_maps\.view_cosines: the preset names 3 view bands, the weave maps given carry none/), 'preset bands, maps without');
  check(() => assert.throws(() => loadClothfitPreset({ ...viewsPreset, weave_maps: plainField }, { weaveMaps: vm }), /the preset names no view bands, the weave maps given carry 3/), 'maps with bands, preset without');
  // The file must carry the cosines and every channel the preset's cosines imply.
  check(() => assert.throws(() => weaveMapsFromExr(fs.readFileSync(plainExr), { field: viewsPreset.weave_maps, name: 'plain.exr' }), /plain\.exr: weave maps: no clothfit:view_cosines metadata/), 'no view bands in the file');
  check(() => assert.throws(() => weaveMapsFromExr(vbuf, { field: { ...viewsPreset.weave_maps, view_cosines: [0.8872983346207417, 0.5] }, name: 'v.exr' }), /v\.exr: weave maps: clothfit:view_cosines names 3 view bands, the preset's weave_maps\.view_cosines 2/), 'band count differs');
  check(() => assert.throws(() => weaveMapsFromExr(vbuf, { field: { ...viewsPreset.weave_maps, view_cosines: [0.887, 0.5, 0.1127016653792583] }, name: 'v.exr' }), /differs from the preset's weave_maps\.view_cosines at \[0\]/), 'cosines differ');
  check(() => assert.throws(() => weaveMapsFromExr(vbuf, { field: { ...viewsPreset.weave_maps, view_cosines: [0.5, 0.9] }, name: 'v.exr' }), /loadClothfitPreset: weave_maps\.view_cosines: \[1\]/), 'bad cosines refused by weaveMapsFromExr');
  const oiio = spawnSync('oiiotool', ['--help'], { encoding: 'utf8' });
  if (!oiio.error) {
    const work = fs.mkdtempSync('/tmp/clothfit-unit-views-');
    const all = Object.keys(vimg.channels);
    for (const drop of ['view1.kd.G', 'view0.warp', 'view2.kd.B']) {
      const out = path.join(work, `no-${drop}.weave.exr`);
      const r = spawnSync('oiiotool', [viewsExr, '--ch', ['warp', 'weft', 'kd.R', 'kd.G', 'kd.B', ...[0, 1, 2].flatMap((k) => ['warp', 'weft', 'kd.R', 'kd.G', 'kd.B'].map((c) => `view${k}.${c}`))].filter((c) => c !== drop).join(','), '-d', 'float', '-o', out], { encoding: 'utf8' });
      check(() => assert.equal(r.status, 0, r.stderr), `oiiotool drops ${drop}`);
      const dimg = parseExr(fs.readFileSync(out), out);
      check(() => assert.ok(!dimg.channels[drop] && Object.keys(dimg.channels).length === all.length - 1 && dimg.attributes['clothfit:view_cosines'] === GL.join(' ')), `${drop} dropped, metadata kept`);
      const re = new RegExp(`no-${drop.replace(/\./g, '\\.')}\\.weave\\.exr: weave maps: no channel ${drop.replace(/\./g, '\\.')} \\(weave_maps\\.view_cosines names 3 view bands`);
      check(() => assert.throws(() => weaveMapsFromExr(fs.readFileSync(out), { field: viewsPreset.weave_maps, name: out }), re), `missing channel ${drop} refused`);
      // fetched: the error names the preset's URL and the channel
      fs.writeFileSync(path.join(work, 'p.json'), JSON.stringify({ ...viewsPreset, weave_maps: { ...viewsPreset.weave_maps, uri: path.basename(out) } }));
      await assert.rejects(fetchClothfitPreset(pathToFileURL(path.join(work, 'p.json')).href), new RegExp(`p\\.json: .*no channel ${drop.replace(/\./g, '\\.')}`));
      checks++;
    }
    fs.rmSync(work, { recursive: true, force: true });
  } else {
    console.log('unit: oiiotool not found, missing-view-channel checks skipped');
  }
  // fetched as a whole (uri next to the preset): the bands are read
  const fv = await fetchClothfitPreset(pathToFileURL(path.join(repo, 'web', 'test', 'yarn-lobe-twill-maps-views.json')).href);
  check(() => assert.ok(fv.viewBands === 3 && fv.weaveMaps.viewTextures.length === 4), 'fetchClothfitPreset reads the view bands');
}
// ---- shadows (session 13): shadowOptions validation, fitted shadow cameras ------------------
{
  const { shadowOptions, fitShadowCamera, SHADOW_DEFAULTS } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  check(() => assert.equal(shadowOptions(undefined), null), 'shadows off by default');
  check(() => assert.equal(shadowOptions(false), null), 'shadows false');
  check(() => assert.deepEqual(shadowOptions(true), { ...SHADOW_DEFAULTS }), 'shadows true = defaults');
  check(() => assert.deepEqual(shadowOptions({ type: 'pcf', mapSize: 4096 }), { ...SHADOW_DEFAULTS, type: 'pcf', mapSize: 4096 }), 'shadows override');
  for (const [bad, why] of [[{ typ: 'pcf' }, /shadows\.typ: unknown field/], [{ type: 'pcfsoft' }, /removed in three\.js r187/], [{ type: 'x' }, /shadows\.type: expected one of/],
    [{ mapSize: 2048.5 }, /mapSize: expected an integer/], [{ mapSize: 32 }, /mapSize: expected a number in \[64, 8192\]/], [{ bias: 'a' }, /bias: expected a number/],
    [{ normalBias: NaN }, /normalBias/], [{ fit: 'floor' }, /fit: expected 'fabric' or 'scene'/], ['yes', /expected true, false or an object/], [[1], /expected true, false or an object/]]) {
    check(() => assert.throws(() => shadowOptions(bad), why), `bad shadows ${JSON.stringify(bad)}`);
  }
  // Fitted cameras: every receiver corner inside the shadow frustum, every caster corner in
  // front of its near plane (directional: depth >= near; spot: inside the cone too when the
  // receivers are), for a light from a slanted direction.
  const receivers = new THREE.Box3(new THREE.Vector3(-0.5, 0, -0.45), new THREE.Vector3(0.5, 0.72, 0.49));
  const casters = new THREE.Box3(new THREE.Vector3(-2, 0, -2), new THREE.Vector3(2, 0.72, 2));
  const corners = (b) => [0, 1, 2, 3, 4, 5, 6, 7].map((i) => new THREE.Vector3(i & 1 ? b.max.x : b.min.x, i & 2 ? b.max.y : b.min.y, i & 4 ? b.max.z : b.min.z));
  const inFrustum = (light, p) => {
    light.shadow.updateMatrices(light);
    const q = p.clone().applyMatrix4(light.shadow.camera.matrixWorldInverse).applyMatrix4(light.shadow.camera.projectionMatrix);
    return Math.abs(q.x) <= 1 && Math.abs(q.y) <= 1 && q.z >= -1 && q.z <= 1;
  };
  const dir = new THREE.DirectionalLight();
  dir.position.set(0, 0, 0); dir.add(dir.target); dir.target.position.set(0.3, -0.8, -0.5); dir.updateMatrixWorld(true);
  fitShadowCamera(dir, receivers, casters, 2048);
  check(() => assert.ok(corners(receivers).every((p) => inFrustum(dir, p))), 'directional: receivers inside the fitted frustum');
  check(() => assert.ok(dir.shadow.camera.right - dir.shadow.camera.left < 2), 'directional: the frustum frames the receivers, not the floor');
  const view = dir.shadow.camera.matrixWorldInverse;
  check(() => assert.ok(corners(casters).every((p) => -p.clone().applyMatrix4(view).z >= dir.shadow.camera.near)), 'directional: casters behind the near plane');
  // s24 texelBias: the depth bias is at least texelBias texels of world depth (normalised by this
  // camera's depth range); the normalised bias stays when it is the larger; 0 = unchanged
  {
    const cam = dir.shadow.camera, texel = (cam.right - cam.left) / 2048, range = cam.far - cam.near;
    dir.shadow.bias = -0.001;
    fitShadowCamera(dir, receivers, casters, 2048, 8);
    check(() => assert.ok(Math.abs(dir.shadow.bias * range + 8 * texel) < 1e-12 * range && dir.shadow.bias < -0.001), `directional: texelBias 8 -> ${(-dir.shadow.bias * range * 1000).toFixed(3)} mm = 8 texels`);
    dir.shadow.bias = -0.5;
    fitShadowCamera(dir, receivers, casters, 2048, 8);
    check(() => assert.equal(dir.shadow.bias, -0.5), 'directional: a larger normalised bias is kept');
    dir.shadow.bias = -0.001;
    fitShadowCamera(dir, receivers, casters, 2048, 0);
    check(() => assert.equal(dir.shadow.bias, -0.001), 'directional: texelBias 0 leaves the bias');
    check(() => assert.deepEqual(shadowOptions({ texelBias: 0 }), { ...SHADOW_DEFAULTS, texelBias: 0 }), 'texelBias option');
    check(() => assert.throws(() => shadowOptions({ texelBias: -1 }), /shadows\.texelBias: expected a number in \[0, 64\]/), 'texelBias range');
    check(() => assert.throws(() => shadowOptions({ toString: 1 }), /shadows\.toString: unknown field/), 'shadow option names from Object.prototype are unknown');
  }
  const spot = new THREE.SpotLight(0xffffff, 1, 0, 0.5);
  spot.position.set(-1.2, 2, 1.4); spot.add(spot.target); spot.target.position.set(0, 0, -1);
  spot.lookAt(0, 0.3, 0); spot.updateMatrixWorld(true);
  fitShadowCamera(spot, receivers, casters, 2048);
  check(() => assert.ok(spot.shadow.focus > 0 && spot.shadow.focus <= 1), 'spot: focus in (0, 1]');
  check(() => assert.ok(corners(receivers).every((p) => inFrustum(spot, p))), 'spot: receivers inside the fitted frustum');
  const point = new THREE.PointLight(0xffffff, 1, 0);
  point.position.set(0.4, 1.2, -1.2); point.updateMatrixWorld(true);
  fitShadowCamera(point, receivers, casters, 1024);
  check(() => assert.ok(point.shadow.camera.near > 0 && point.shadow.camera.near < casters.distanceToPoint(point.position) &&
    corners(receivers).every((p) => p.distanceTo(point.position) < point.shadow.camera.far)), 'point: near before the casters, far past the receivers');
}
// The scene card's light map (s13-lm; docs/web.md "The light map"): the texture's conventions,
// its uv box, the material's light map, and the routing into MeshClothMaterial / MeshWovenMaterial's
// IBL diffuse (the stand-in shader as above, with three.js r187's real lights_fragment_maps).
{
  const w = 4, h = 2, ch = (f) => Float32Array.from({ length: w * h }, (_, t) => f(t));
  const img = { width: w, height: h, channels: { R: ch((t) => t), G: ch((t) => 10 + t), B: ch((t) => 20 + t) }, attributes: { 'clothfit:uv_box': '0 0.2 1.3 1.2' } };
  const t = lightMapTextureFromExr(img, { name: 'unit.lm.exr' });
  check(() => assert.ok(t.isDataTexture && t.type === THREE.FloatType && t.format === THREE.RGBAFormat && t.flipY === false && t.generateMipmaps === false
    && t.magFilter === THREE.LinearFilter && t.minFilter === THREE.LinearFilter && t.wrapS === THREE.ClampToEdgeWrapping && t.wrapT === THREE.ClampToEdgeWrapping
    && t.colorSpace === THREE.NoColorSpace && t.channel === 0), 'light map texture settings');
  // row 0 of the file is data row 0 (t = 0 = glTF v0): texel (i=1, j=1) = file texel 5
  check(() => assert.deepEqual([...t.image.data.slice(5 * 4, 6 * 4)], [5, 15, 25, 1]), 'light map rows in file order, A = 1');
  check(() => assert.ok(Math.abs(t.offset.x) < 1e-12 && Math.abs(t.offset.y + 0.2) < 1e-12 && Math.abs(t.repeat.x - 1 / 1.3) < 1e-12 && Math.abs(t.repeat.y - 1) < 1e-12), 'light map offset / repeat from the uv box');
  // the texture matrix maps the uv box onto [0, 1]^2
  t.updateMatrix();
  const m = t.matrix.elements, at = (u, v) => [m[0] * u + m[3] * v + m[6], m[1] * u + m[4] * v + m[7]];
  check(() => assert.ok(at(0, 0.2).every((x) => Math.abs(x) < 1e-7) && at(1.3, 1.2).every((x) => Math.abs(x - 1) < 1e-7)), 'light map matrix: uv box -> [0, 1]');
  check(() => assert.deepEqual(lightMapUvBox('0 0 1.29999995 1.29999995'), [0, 0, 1.29999995, 1.29999995]), 'uv box parse');
  for (const bad of [undefined, '0 0 1', '0 0 0 1', '0 1 1 0', '0 0 1 x']) check(() => assert.throws(() => lightMapTextureFromExr({ ...img, attributes: { 'clothfit:uv_box': bad } }, { name: 'bad.exr' }), /bad\.exr: clothfit:uv_box/), `bad uv box ${bad}`);
  check(() => assert.throws(() => lightMapTextureFromExr({ ...img, channels: { R: img.channels.R, G: img.channels.G } }), /no channel B/), 'light map needs RGB');
  check(() => assert.throws(() => lightMapTextureFromExr({ ...img, channels: { ...img.channels, G: ch((t) => (t === 3 ? -1 : 0)) } }), /texel 3 channel G is negative/), 'light map: negative texel refused');
  check(() => assert.deepEqual(lightMapTextureFromExr(img, { uvBox: [0, 0, 2, 2] }).userData.clothfit.uvBox, [0, 0, 2, 2]), 'uv box override');
  const std = loadClothfitPreset(preset({}));
  const v0 = std.version;
  check(() => assert.ok(applyLightMap(std, t) === t && std.lightMap === t && std.lightMapIntensity === 1 && std.version > v0), 'applyLightMap: material.lightMap, intensity 1, recompiled');
  check(() => assert.ok(applyLightMap(std, null) === null && std.lightMap === null), 'applyLightMap(null) removes it');
  check(() => assert.throws(() => applyLightMap(new THREE.MeshBasicMaterial(), t), /MeshStandardMaterial/), 'applyLightMap: fabric materials only');
  const fsrc = THREE.ShaderChunk.meshphysical_frag;
  for (const [who, mat] of [['cloth', new MeshClothMaterial({})], ['woven', loadClothfitPreset(wp())]]) {
    const sh = { uniforms: {}, fragmentShader: fsrc, vertexShader: THREE.ShaderChunk.meshphysical_vert };
    mat.onBeforeCompile(sh);
    const f = sh.fragmentShader;
    check(() => assert.ok(!f.includes('#include <lights_fragment_maps>') && !f.includes('irradiance += lightMapIrradiance;') && f.includes('clothfitLightMapIrradiance += lightMapIrradiance;')
      && f.indexOf('vec3 clothfitLightMapIrradiance = vec3( 0.0 );') < f.indexOf(who === 'cloth' ? 'void RE_IndirectSpecular_Cloth' : 'void RE_IndirectSpecular_Woven')), `${who}: the light map goes to the IBL diffuse, not to three.js's irradiance`);
    // without USE_LIGHTMAP the routing is preprocessed away: every added line is inside #ifdef USE_LIGHTMAP
    const added = f.split('\n').filter((l) => l.includes('clothfitLightMapIrradiance'));
    check(() => assert.ok(added.length >= 3), `${who}: routing lines present`);
  }
}
// ---- s23: real GPUs (docs/web.md "Real GPUs"): float filtering and sampler counting ----------
{
  const { floatTexturesFilterable, programSamplerCount, weaveMapsFromExr } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const fakeRenderer = (has) => ({ extensions: { has: (n) => (n === 'OES_texture_float_linear' ? has : true) } });
  check(() => assert.equal(floatTexturesFilterable(fakeRenderer(true)), true), 'float filterable: the renderer says yes');
  check(() => assert.equal(floatTexturesFilterable(fakeRenderer(false)), false), 'float filterable: the renderer says no');
  check(() => assert.equal(floatTexturesFilterable(undefined), true), 'float filterable without a renderer in node: 32-bit, as before');
  const buf = fs.readFileSync(path.join(repo, 'tests', 'browser', 'maps', 'canvas.weave.exr'));
  const types = (m) => [m.weightsTexture.type, m.kdTexture.type, m.anisotropyTexture().type];
  check(() => assert.ok(types(weaveMapsFromExr(buf, { field: {}, renderer: fakeRenderer(false) })).every((t) => t === THREE.HalfFloatType)), 'weave maps: half floats on a context without OES_texture_float_linear');
  check(() => assert.ok(types(weaveMapsFromExr(buf, { field: {}, renderer: fakeRenderer(true) })).every((t) => t === THREE.FloatType)), 'weave maps: 32-bit floats on a context with it');
  check(() => assert.ok(types(weaveMapsFromExr(buf, { field: {}, renderer: fakeRenderer(false), halfFloat: false })).every((t) => t === THREE.FloatType)), 'weave maps: halfFloat false forces 32-bit');
  const n = 4, R = new Float32Array(n * n).fill(2), big = new Float32Array(n * n).fill(1e6);
  const lm = { width: n, height: n, channels: { R, G: R, B: big }, attributes: { 'clothfit:uv_box': '0 0 1 1' } };
  const half = lightMapTextureFromExr(lm, { renderer: fakeRenderer(false) });
  check(() => assert.ok(half.type === THREE.HalfFloatType && THREE.DataUtils.fromHalfFloat(half.image.data[0]) === 2 && THREE.DataUtils.fromHalfFloat(half.image.data[2]) === 65504), 'light map: half floats, values above 65504 clamped to it');
  check(() => assert.equal(lightMapTextureFromExr(lm, { renderer: fakeRenderer(true) }).type, THREE.FloatType), 'light map: 32-bit floats on a context with the extension');
  // programSamplerCount on a fake context: samplers of every WebGL2 type counted with their array
  // size, other uniforms not, a failed link null.
  const GL = { LINK_STATUS: 0x8b82, ACTIVE_UNIFORMS: 0x8b86 };
  const fakeGl = (linked, uniforms) => ({ ...GL, getProgramParameter: (p, k) => (k === GL.LINK_STATUS ? linked : uniforms.length), getActiveUniform: (p, i) => uniforms[i] });
  const u = (type, size = 1) => ({ type, size });
  const samplerTypes = [0x8b5e, 0x8b5f, 0x8b60, 0x8b62, 0x8dc1, 0x8dc4, 0x8dc5, 0x8dca, 0x8dcb, 0x8dcc, 0x8dcf, 0x8dd2, 0x8dd3, 0x8dd4, 0x8dd7];
  check(() => assert.equal(programSamplerCount(fakeGl(true, samplerTypes.map((t) => u(t))), {}), 15), 'every WebGL2 sampler type counted');
  check(() => assert.equal(programSamplerCount(fakeGl(true, [u(0x8b5e, 4), u(0x8b51), u(0x8b5c), u(0x1406, 9)]), {}), 4), 'a sampler array counts its size; vec3, mat4, float do not count');
  check(() => assert.equal(programSamplerCount(fakeGl(false, [u(0x8b5e)]), {}), null), 'a failed link: null');
}
// ---- s23: web/exr.js on hostile files (validate before allocating; no echo of file bytes) -------
{
  const { parseExr, EXR_MAX_DECODED_BYTES } = await import(pathToFileURL(path.join(repo, 'web', 'exr.js')).href);
  const zlib = await import('node:zlib');
  // A scanline EXR built by hand (OpenEXR file layout): header attributes, offset table, blocks.
  const exr = ({ width, height, channels = ['R'], compression = 0, blocks = null, names = channels }) => {
    const parts = [];
    const u32 = (v) => { const b = Buffer.alloc(4); b.writeUInt32LE(v >>> 0); return b; };
    const i32 = (v) => { const b = Buffer.alloc(4); b.writeInt32LE(v); return b; };
    const attr = (name, type, data) => parts.push(Buffer.from(`${name}\0${type}\0`, 'latin1'), i32(data.length), data);
    parts.push(u32(20000630), u32(2));
    attr('channels', 'chlist', Buffer.concat([...names.map((n) => Buffer.concat([Buffer.from(`${n}\0`, 'latin1'), i32(2), Buffer.alloc(4), i32(1), i32(1)])), Buffer.from([0])]));
    attr('compression', 'compression', Buffer.from([compression]));
    attr('dataWindow', 'box2i', Buffer.concat([i32(0), i32(0), i32(width - 1), i32(height - 1)]));
    parts.push(Buffer.from([0]));
    const head = Buffer.concat(parts);
    const bl = blocks ?? [];
    let at = head.length + 8 * bl.length;
    const table = [], data = [];
    for (const [y, bytes] of bl) {
      const o = Buffer.alloc(8); o.writeBigUInt64LE(BigInt(at)); table.push(o);
      data.push(i32(y), i32(bytes.length), bytes); at += 8 + bytes.length;
    }
    return new Uint8Array(Buffer.concat([head, ...table, ...data]));
  };
  const ok = parseExr(exr({ width: 2, height: 1, blocks: [[0, Buffer.from(new Float32Array([1.5, 2]).buffer)]] }), 'ok.exr');
  check(() => assert.deepEqual([...ok.channels.R], [1.5, 2]), 'hand-built EXR reads back');
  // a data window of 2^30 x 2^30: refused before any Float32Array is made, naming the file and the limit
  check(() => assert.throws(() => parseExr(exr({ width: 2 ** 30, height: 2 ** 30 }), 'huge.exr'), (e) => /^huge\.exr: data window 1073741824 x 1073741824 with 1 channels decodes to \d+ bytes, over the limit of 536870912/.test(e.message)), 'huge data window refused before allocating');
  check(() => assert.equal(EXR_MAX_DECODED_BYTES, 512 * 1024 * 1024), 'the C++ kMaxImageBytes');
  // a ZIPS block that inflates to 1 MB where one 4-pixel FLOAT line (16 bytes) is expected
  const bomb = zlib.deflateSync(Buffer.alloc(1 << 20));
  check(() => assert.throws(() => parseExr(exr({ width: 4, height: 1, compression: 2, blocks: [[0, bomb]] }), 'bomb.exr'), /ZIP block inflates to more than 16 bytes, expected 16/), 'oversized ZIP block refused');
  check(() => assert.throws(() => parseExr(exr({ width: 4, height: 1, compression: 2, blocks: [[0, zlib.deflateSync(Buffer.alloc(8))]] }), 'short.exr'), /ZIP block inflates to 8 bytes, expected 16/), 'short ZIP block refused');
  // a channel name with control and bidi characters: quoted and escaped in the message, never echoed
  const evil = 'x\u001b[31m\u202e';
  let msg = '';
  try { parseExr(exr({ width: 1, height: 1, names: [evil], channels: [evil], compression: 9 }), 'evil.exr'); } catch (e) { msg = e.message; }
  try { parseExr(exr({ width: 1, height: 1, names: [evil, evil] }), 'evil.exr'); } catch (e) { msg += ` | ${e.message}`; }
  check(() => assert.ok(msg.includes('a channel name appears twice') && !/[\u0000-\u001f\u007f-\uffff]/.test(msg)), `no raw control bytes in the messages (${JSON.stringify(msg)})`);
  check(() => assert.throws(() => parseExr(exr({ width: 1, height: 1 }).subarray(0, 26), 'cut.exr'), /cut\.exr: truncated header/), 'truncated header named');
}
// ---- s23: bounded downloads (web/clothfit.js fetchBounded; data: URLs, which node's fetch reads) --
{
  const { fetchBounded, FETCH_LIMITS } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);
  const url = `data:application/octet-stream;base64,${Buffer.alloc(300, 1).toString('base64')}`;
  const got = await fetchBounded(url, 300, 'test file');
  check(() => assert.ok(got instanceof Uint8Array && got.length === 300 && got[299] === 1), 'fetchBounded: a body at the limit is read whole');
  let err = '';
  try { await fetchBounded(url, 299, 'test file'); } catch (e) { err = e.message; }
  check(() => assert.match(err, /test file (of 300 bytes, )?over the limit of 299/), `fetchBounded: one byte over the limit is refused (${err.slice(-80)})`);
  check(() => assert.ok(FETCH_LIMITS.json === 16 << 20 && FETCH_LIMITS.image === 512 << 20), 'the C++ kMaxJsonFileBytes and kMaxImageFileBytes');
}
console.log(`unit: ${checks} checks passed`);
