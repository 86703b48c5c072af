// Node-side checks of web/clothfit.js that need no browser (run by tests/browser/run.mjs before
// the browser cases; exits non-zero on a failure):
//   - `side` from `clothfit convert --to threejs` (three.js DoubleSide 2 / FrontSide 0) is
//     honoured by loadClothfitPreset for MeshPhysicalMaterial and MeshClothMaterial JSON, and a
//     preset's "side" ('front' | 'double' or 0 / 2) too; without one, three.js's FrontSide stays;
//   - woven presets load as MeshWovenMaterial with the table defaults and reject unknown names.
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
    return { ok: true, status: 200, arrayBuffer: async () => buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.length), json: async () => JSON.parse(buf) };
  }
  return realFetch(url, ...rest);
};
const THREE = await import(pathToFileURL(path.join(repo, 'web', 'node_modules', 'three', 'build', 'three.module.js')).href);
const { loadClothfitPreset, MeshWovenMaterial, MeshClothMaterial } = await import(pathToFileURL(path.join(repo, 'web', 'clothfit.js')).href);

const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) => {
  if (a.startsWith('--')) acc.push([a.slice(2), all[i + 1]]);
  return acc;
}, []));
let checks = 0;
const check = (fn, what) => { fn(); checks++; };

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
console.log(`unit: ${checks} checks passed`);
