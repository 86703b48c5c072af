#!/usr/bin/env node
// GPU resource audit of web/clothfit.js's fabric programs: the figures of docs/web.md "Real GPUs:
// float filtering and texture units" (its per-configuration table; session 23).
//
//   nice -n 10 node web/tools/gpu-limits/run-audit.mjs [--work DIR] [--only SUBSTRING]
//        [--timeout SECONDS] [--chromium PATH]
//   node web/tools/gpu-limits/panels-count.mjs    (the "env lights": panels per cached HDRI)
//
// What: for 11 configurations (material x environment x shadows / light map, cases A-K below; the
// docs table quotes A, B, D, F, G, H, J) the fabric's linked program: fragment-stage samplers,
// fragment uniform vectors (naive and packed as GLSL ES 1.00 A.7 says), varyings (packed vectors and components).
// How: it writes the presets, the scene cards (datasets/scenes/drape.json without its visibility
// block, under 4 environments) and plan.json into the work dir, serves the repository, the work dir
// and the HDRI cache with web/serve.mjs (GET /fs/<absolute path>), and runs ONE headless Chromium
// (SwiftShader WebGL2, flags as tests/browser/run.mjs) on audit.html. The page loads each case with
// web/clothfit.js's API (loadSceneCard, fetchClothfitPreset, applyLightMap), renders one frame and
// counts (audit.js): per-stage active uniforms from two probe links of the program's own sources
// (real VS + trivial FS; real VS with main() emptied + real FS), samplers per array element,
// uniform vectors naive (1 per vector, 3 per mat3, 4 per mat4) and packed (the packing rule
// of GLSL ES 1.00 appendix A.7, as WebGL applies it), varyings from the preprocessed fragment shader
// (inputs used beyond their declaration; same packer). SwiftShader's own limits are higher
// (32 samplers, 4096 vectors, 31 varyings), so every program links and can be counted.
// Output in the work dir: results.json (the page's records), report.txt (per-case detail),
// table.md (the table; printed). Wall time 76 s (2 shared cores, nice -n 10).
//
// WebGL2 minimums (WebGL 2.0 exposes OpenGL ES 3.0's; ES 3.0 spec, section 6.2 state tables
// "Implementation Dependent Vertex / Fragment / Aggregate Shader Limits"):
//   MAX_TEXTURE_IMAGE_UNITS 16, MAX_VERTEX_TEXTURE_IMAGE_UNITS 16, MAX_COMBINED_TEXTURE_IMAGE_UNITS 32,
//   MAX_FRAGMENT_UNIFORM_VECTORS 224, MAX_VERTEX_UNIFORM_VECTORS 256, MAX_VARYING_VECTORS 15
//   (MAX_VARYING_COMPONENTS 60, MAX_FRAGMENT_INPUT_COMPONENTS 60, MAX_VERTEX_OUTPUT_COMPONENTS 64).
//
// Needs: chromium, web/node_modules (scripts/install-deps), the HDRIs studio, pmndrs-hall and
// blender-city in $CLOTHFIT_DATA/hdri or ~/.cache/clothfit/hdri (make data); exits 77 without them.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { startServer } from '../../serve.mjs';
import { spawnHeadlessChromium, stopChromium } from '../chromium.mjs';
import { detail, table } from './report.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '..', '..', '..');
const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) => {
  if (a.startsWith('--')) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith('--') ? all[i + 1] : 'true']);
  return acc;
}, []));
const work = path.resolve(args.work ?? fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-gpu-limits-')));
const chromium = args.chromium ?? ['/usr/bin/chromium', '/usr/bin/chromium-browser'].find((p) => fs.existsSync(p));
const timeoutS = Number(args.timeout ?? 400);
const dataDir = process.env.CLOTHFIT_DATA || path.join(os.homedir(), '.cache', 'clothfit');
const hdriDir = path.join(dataDir, 'hdri');

function skip(why) { console.log(`SKIP: ${why}`); process.exit(77); }
if (!chromium) skip('no chromium (scripts/install-deps installs the Debian package)');
if (!fs.existsSync(path.join(repo, 'web', 'node_modules', 'three', 'package.json'))) skip('web/node_modules missing (scripts/install-deps runs npm ci in web/)');
for (const e of ['studio', 'pmndrs-hall', 'blender-city']) {
  if (!fs.existsSync(path.join(hdriDir, `${e}.exr`))) skip(`${hdriDir}/${e}.exr missing (make data / scripts/fetch-data)`);
}
fs.mkdirSync(work, { recursive: true });

// ---- presets (as tests/browser/run.mjs builds them) ----
const preset = (model, parameters, extra = {}) => ({ schema: 'clothfit.preset', version: 1, model, ...extra, parameters });
const lobePreset = (name, over = {}, wovenOver = {}, dropLobe = false) => {
  const j = JSON.parse(fs.readFileSync(path.join(repo, 'web', 'test', `yarn-lobe-${name}.json`), 'utf8'));
  const woven = { ...j.woven, ...wovenOver };
  if (dropLobe) delete woven.yarn_lobe;
  const extra = { woven };
  if (j.weave_maps) {
    const { uri, file, ...wm } = j.weave_maps;
    extra.weave_maps = { ...wm, file: path.join(repo, 'web', 'test', path.basename(uri ?? file)) };
  }
  return preset('woven', { ...j.parameters, ...over }, extra);
};
const PRESETS = {
  // tested presets (s14/s15): far-field yarn lobe + 3 view bands (maps: 2 main + 4 packed view textures)
  'lobe-twill-views': lobePreset('twill-maps-views'),
  'lobe-canvas-views': lobePreset('canvas-maps-views'),
  // + rough diffuse (WOVEN_ROUGH_DIFFUSE: 2 more uniforms)
  'lobe-twill-views-rough': lobePreset('twill-maps-views', { diffuse_roughness: 0.65 }),
  // FIS cannot be combined with the yarn lobe (wovenOptions: yarn_lobe needs ibl split): the same
  // view-band maps with FIS 16 + 16 diffuse taps, albedo-scaled layer, rough diffuse
  'fis-twill-views': lobePreset('twill-maps-views', { diffuse_roughness: 0.65 }, { ibl: 'fis', fis_taps: 16, fis_diffuse_taps: 16, yarn_layer: 'albedo-scaled' }, true),
  'woven-lobe-canvas': lobePreset('canvas'),
  'physical-aniso-maps': preset('physical-aniso', { base_color: [0.0524, 0.1662, 0.0914], roughness: 0.45, metalness: 0, sheen_color: [0.2, 0.3, 0.2],
    sheen_roughness: 0.5, anisotropy_strength: 0.7, anisotropy_rotation: 0, specular_intensity: 1, specular_color: [1, 1, 1] },
  { weave_maps: { file: path.join(repo, 'tests', 'browser', 'maps', 'twill.weave.exr'), size: 64, uv_repeats: 40, anisotropy: 16 } }),
  'cloth-seed': preset('cloth', { base_color: [0.2, 0.25, 0.45], roughness: 0.7 },
    { cloth: { variant: 'seed-threejs', sheen_default: 'sqrt-base-color', subsurface: false, platform: 'desktop' } }),
  'cloth-subsurface': preset('cloth', { base_color: [0.6, 0.5, 0.4], sheen_color: [0.4, 0.4, 0.4], roughness: 0.65, subsurface_color: [0.5, 0.15, 0.1] },
    { cloth: { variant: 'filament', sheen_default: 'explicit', subsurface: true, platform: 'desktop' } }),
};
for (const [n, p] of Object.entries(PRESETS)) fs.writeFileSync(path.join(work, `${n}.json`), JSON.stringify(p, null, 1));

// ---- cards: the drape (spot key, directional fill, point rim) under an environment ----
const drape = JSON.parse(fs.readFileSync(path.join(repo, 'datasets', 'scenes', 'drape.json'), 'utf8'));
const card = (name, env) => {
  const { visibility: _v, ...bare } = drape;
  const c = { ...bare, gltf: path.join(repo, 'datasets', 'scenes', drape.gltf), environment: env };
  const f = path.join(work, `card-${name}.json`);
  fs.writeFileSync(f, JSON.stringify(c, null, 1));
  return f;
};
const CARDS = {
  studio: card('studio', { path: 'studio', intensity: 1, rotation_y_degrees: 0, sun: 'auto' }),          // no sun found: 0 env lights
  'studio-panels': card('studio-panels', { path: 'studio', intensity: 1, rotation_y_degrees: 30, sun: 'panels' }),  // 4 panels
  'hall-panels': card('hall-panels', { path: 'pmndrs-hall', intensity: 1, rotation_y_degrees: 0, sun: 'panels' }),  // 8 panels (panels-count.mjs)
  'city-sun': card('city-sun', { path: 'blender-city', intensity: 0.8, rotation_y_degrees: 60, sun: 'auto' }),   // 1 sun
};
// shadows: the web default type 'basic' at mapSize 512 (the size is a uniform, not a resource;
// small to keep SwiftShader's depth passes cheap)
const SH = { mapSize: 512 };
const CASES = [
  { name: 'A lobe-twill-views | studio | no shadows, no LM (tested case)', preset: 'lobe-twill-views', card: 'studio' },
  { name: 'B lobe-twill-views | studio panels(4) | shadows + LM', preset: 'lobe-twill-views', card: 'studio-panels', shadows: SH, lightMap: true },
  { name: 'C lobe-twill-views | hall panels(8) | LM, no shadows', preset: 'lobe-twill-views', card: 'hall-panels', lightMap: true },
  { name: 'D lobe-twill-views | hall panels(8) | shadows + LM', preset: 'lobe-twill-views', card: 'hall-panels', shadows: SH, lightMap: true },
  { name: 'E lobe-twill-views-rough | hall panels(8) | pcf shadows + LM', preset: 'lobe-twill-views-rough', card: 'hall-panels', shadows: { ...SH, type: 'pcf' }, lightMap: true },
  { name: 'F fis16/16-twill-views-rough-albedo | hall panels(8) | shadows + LM', preset: 'fis-twill-views', card: 'hall-panels', shadows: SH, lightMap: true },
  { name: 'G physical-aniso-maps | hall panels(8) | shadows + LM', preset: 'physical-aniso-maps', card: 'hall-panels', shadows: SH, lightMap: true },
  { name: 'H cloth-seed | hall panels(8) | shadows + LM', preset: 'cloth-seed', card: 'hall-panels', shadows: SH, lightMap: true },
  { name: 'I cloth-subsurface | hall panels(8) | shadows + LM', preset: 'cloth-subsurface', card: 'hall-panels', shadows: SH, lightMap: true },
  { name: 'J woven-lobe-canvas | studio panels(4) | shadows + LM (tested: studio-card-panels)', preset: 'woven-lobe-canvas', card: 'studio-panels', shadows: true, lightMap: true },
  { name: 'K lobe-canvas-views | city sun(1) | shadows + LM', preset: 'lobe-canvas-views', card: 'city-sun', shadows: SH, lightMap: true },
].filter((c) => !args.only || c.name.includes(args.only))
  .map((c) => ({ ...c, presetPath: path.join(work, `${c.preset}.json`), cardPath: CARDS[c.card] }));
fs.writeFileSync(path.join(work, 'plan.json'), JSON.stringify({ hdri_dir: hdriDir, cases: CASES }, null, 1));

// ---- server + one chromium ----
const results = [];
let finish;
const finished = new Promise((r) => { finish = r; });
const t0 = Date.now();
const say = (m) => console.log(`[gpu-limits ${((Date.now() - t0) / 1000).toFixed(1)}s] ${m}`);
const server = await startServer({
  fsRoots: [repo, work, hdriDir],
  onLog: (text) => say(`page: ${text.slice(0, 600)}`),
  onPost: (url, body) => {
    if (url.pathname === '/result') { results.push(JSON.parse(body.toString())); say(`result ${results.length}/${CASES.length + 1}`); }
    else if (url.pathname === '/done') finish(body.toString());
  },
});
const port = server.address().port;
const pageUrl = `http://127.0.0.1:${port}/fs${here}/audit.html?plan=/fs${path.join(work, 'plan.json')}`;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-chromium-'));
const browser = spawnHeadlessChromium(chromium, pageUrl, profile);
let err = '';
browser.stderr.on('data', (d) => { err += d; });
const timer = setTimeout(() => finish('timeout'), timeoutS * 1000);
const outcome = await finished;
clearTimeout(timer);
server.close();
const w = await stopChromium(browser, profile);
if (w) say(`warning: ${w}`);
say(`browser: ${outcome}`);
if (outcome !== 'ok') console.error(err.split('\n').slice(-20).join('\n'));
fs.writeFileSync(path.join(work, 'results.json'), JSON.stringify(results, null, 1));
fs.writeFileSync(path.join(work, 'report.txt'), detail(results));
const md = table(results);
fs.writeFileSync(path.join(work, 'table.md'), md);
console.log(`\n${md}\nwork dir: ${work} (results.json, report.txt, table.md)`);
const failed = results.filter((x) => x.error || (x.fabric && !x.fabric.linked)).length;
process.exit(outcome === 'ok' && !failed && results.length === CASES.length + 1 ? 0 : 1);
