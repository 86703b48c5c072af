// Every glTF that clothfit writes or ships, checked by the Khronos glTF-Validator (npm
// `gltf-validator`, pinned in web/package-lock.json; https://github.com/KhronosGroup/glTF-Validator):
//   - `clothfit convert --to gltf` over a generated catalogue of every input format
//     (datasets/catalogue/generate.py: glTF/.glb, MERL, fabric definitions, presets,
//     SurfaceMaterial, TextureStack) and over tests/data/convert_weave (physical-aniso with its
//     weave maps as PNG textures: KHR_materials_anisotropy, KHR_materials_specular,
//     KHR_materials_sheen, KHR_texture_transform);
//   - the canonical scenes datasets/scenes/*.gltf (scripts/gen-scenes).
// A file passes with no error and no warning. Infos and hints are counted, not failed: a
// material-only glTF (convert's output) has a material no mesh uses (UNUSED_OBJECT), and the
// scenes carry tangents for meshes without a normal map (UNUSED_MESH_TANGENT). An extension
// the validator does not know (UNSUPPORTED_EXTENSION, an info by default) is raised to an
// error, so each extension clothfit writes is checked against its schema, not skipped.
// Usage: node tests/gltf_validate.mjs --clothfit BIN --work DIR [--count N]
// Exit 0 pass, 1 fail, 77 skipped (no web/node_modules/gltf-validator: scripts/install-deps).
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { createRequire } from 'node:module';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '..');
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const validatorDir = path.join(repo, 'web', 'node_modules', 'gltf-validator');
if (!fs.existsSync(path.join(validatorDir, 'package.json'))) {
  console.log(`skipped: no ${validatorDir} (scripts/install-deps runs npm ci in web/)`);
  process.exit(77);
}
if (!args.clothfit) {
  console.error('usage: node tests/gltf_validate.mjs --clothfit BIN --work DIR [--count N]');
  process.exit(1);
}
const validator = createRequire(import.meta.url)(validatorDir);
const work = path.resolve(args.work ?? 'gltf-validate-test');
fs.rmSync(work, { recursive: true, force: true });
fs.mkdirSync(work, { recursive: true });

// Inputs: a catalogue of every format (no deliberately broken items: their refusal is
// tests/test_convert*'s business) and the weave-map case.
const catalogue = path.join(work, 'catalogue');
execFileSync('python3', [path.join(repo, 'datasets', 'catalogue', 'generate.py'), '--out', catalogue,
  '--count', String(Number(args.count ?? 20)), '--no-broken', '--quiet'], { stdio: 'inherit' });
const out = path.join(work, 'out');
execFileSync(args.clothfit, ['--quiet', 'convert', catalogue, path.join(repo, 'tests', 'data', 'convert_weave'),
  '--to', 'gltf', '--out', out], { stdio: 'inherit' });

const list = (dir, re) => fs.readdirSync(dir, { recursive: true })
  .map((f) => path.join(dir, f)).filter((f) => re.test(f) && fs.statSync(f).isFile()).sort();
const scenes = list(path.join(repo, 'datasets', 'scenes'), /\.gltf$/);
const files = [...list(out, /\.(gltf|glb)$/), ...scenes];

// One file through the validator, its external resources (buffers, images) read from disk.
async function validate(file) {
  const dir = path.dirname(file);
  return validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 0,
    severityOverrides: { UNSUPPORTED_EXTENSION: 0 },
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      // convert carries input textures by reference, relative to the output file
      // (docs/convert.md, "Maps and colour spaces"): they must resolve and be valid images.
      fs.readFile(path.resolve(dir, decodeURIComponent(uri)), (e, d) => (e ? reject(e) : resolve(new Uint8Array(d))));
    }),
  });
}

let failures = 0;
// The validator's own checks that it is awake: a converted file, mutated, must come back with
// an error of the given code.
async function selfCheck(file, mutate, code, what) {
  if (!file) { console.error(`FAIL: no converted glTF for the self-check (${what})`); failures++; return; }
  const g = JSON.parse(fs.readFileSync(file, 'utf8'));
  mutate(g);
  const bad = path.join(path.dirname(file), 'self-check.gltf.json');
  fs.writeFileSync(bad, JSON.stringify(g));
  const r = await validate(bad);
  fs.rmSync(bad);
  if (!r.issues.messages.some((m) => m.severity === 0 && m.code === code)) {
    console.error(`FAIL: the validator did not flag ${what} as an error (${code})`);
    failures++;
  }
}
const converted = files.filter((f) => f.startsWith(out));
await selfCheck(converted.find((f) => /KHR_materials_sheen/.test(fs.readFileSync(f, 'utf8'))),
  (g) => { g.materials[0].extensions.KHR_materials_sheen.sheenRoughnessFactor = 2.0; },  // schema: [0, 1]
  'VALUE_NOT_IN_RANGE', 'sheenRoughnessFactor 2.0');
await selfCheck(converted.find((f) => f.endsWith('.gltf')),  // UNSUPPORTED_EXTENSION raised above
  (g) => { g.extensionsUsed = [...(g.extensionsUsed ?? []), 'CLOTHFIT_self_check_unknown']; },
  'UNSUPPORTED_EXTENSION', 'an unknown extension');
let infos = 0;
let images = 0;
const extensions = new Set();
const counts = {};
for (const file of files) {
  const report = await validate(file);
  const is = report.issues;
  for (const e of report.info?.extensionsUsed ?? []) extensions.add(e);
  // Textures read and decoded: an external image resource with a recognised format.
  images += (report.info?.resources ?? []).filter((r) => r.pointer?.startsWith('/images/') &&
    r.storage === 'external' && r.image?.format).length;
  infos += is.numInfos + is.numHints;
  for (const m of is.messages) counts[m.code] = (counts[m.code] ?? 0) + 1;
  if (is.numErrors > 0 || is.numWarnings > 0) {
    failures++;
    console.error(`FAIL: ${path.relative(repo, file).startsWith('..') ? file : path.relative(repo, file)}: ` +
      `${is.numErrors} error(s), ${is.numWarnings} warning(s)`);
    for (const m of is.messages.filter((x) => x.severity <= 1)) {
      console.error(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer ?? ''}: ${m.message}`);
    }
  }
}
console.log(`gltf-validator ${validator.version()}: ${files.length} files (${converted.length} from convert, ` +
  `${files.length - converted.length} scenes, ${images} texture images decoded), ${failures} failure(s); infos/hints ${infos} ` +
  `(${Object.entries(counts).map(([k, v]) => `${k} ${v}`).join(', ') || 'none'}); ` +
  `extensions seen: ${[...extensions].sort().join(', ') || 'none'}`);
// The check must have seen what it is for: material extensions and textures from convert.
for (const e of ['KHR_materials_sheen', 'KHR_materials_anisotropy', 'KHR_materials_specular',
  'KHR_texture_transform']) {
  if (!extensions.has(e)) { console.error(`FAIL: no converted file uses ${e}`); failures++; }
}
if (converted.length < 10) { console.error(`FAIL: only ${converted.length} glTF files from convert`); failures++; }
for (const s of ['drape.gltf', 'sphere.gltf', 'swatch.gltf']) {
  if (!scenes.some((f) => path.basename(f) === s)) { console.error(`FAIL: no datasets/scenes/${s}`); failures++; }
}
if (images < 2) { console.error(`FAIL: only ${images} texture images read and decoded`); failures++; }
process.exit(failures ? 1 : 0);
