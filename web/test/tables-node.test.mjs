// Node test of web/clothfit.js's table loading (session 27 audit): in node, creating a
// MeshClothMaterial crashed the process, because the DG table's fetch of a file: URL was an
// unhandled rejection ("fetch failed ... not implemented"). Now:
//   - in node the tables (web/lut/*.f32) are read from disk: MeshClothMaterial and
//     MeshWovenMaterial are made without any fetch stub, and the tables load;
//   - a table that cannot be read (a copy of clothfit.js without lut/) is reported once on the
//     console, naming the table and the file, the process goes on, and awaiting the table
//     rejects with the same message.
// Usage: node web/test/tables-node.test.mjs   (exit 77: skipped without web/node_modules)
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const web = path.resolve(here, '..');
if (!fs.existsSync(path.join(web, 'node_modules', 'three', 'package.json'))) {
  console.log('skipped: no web/node_modules (npm ci in web/)');
  process.exit(77);
}
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };

// 1. This process, node's own fetch (no stub): the tables load from disk.
const { MeshClothMaterial, MeshWovenMaterial, clothDGTable, wovenPhaseTable } = await import(pathToFileURL(path.join(web, 'clothfit.js')).href);
const cloth = new MeshClothMaterial();
const woven = new MeshWovenMaterial();
const dg = await clothDGTable();
check(dg.image.width === 128 && dg.image.height === 128 && dg.image.data.length === 128 * 128, `cloth DG table read in node (${dg.image.width} x ${dg.image.height})`);
const phase = await wovenPhaseTable();
check(phase.image.height === 32 && phase.image.data.length === 32 * 32 * 9, 'woven phase table read in node');
await new Promise((r) => { setTimeout(r, 0); });
check(cloth._clothUniforms.clothDG.value === dg, 'the material gets the table');
check(woven !== null, 'MeshWovenMaterial made');

// 2. A copy without lut/: reported, not fatal.
const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-tables-'));
try {
  for (const f of ['clothfit.js', 'exr.js', 'sun.js']) fs.copyFileSync(path.join(web, f), path.join(dir, f));
  fs.symlinkSync(path.join(web, 'node_modules'), path.join(dir, 'node_modules'));
  fs.writeFileSync(path.join(dir, 'main.mjs'), `
import { MeshClothMaterial, MeshWovenMaterial, clothDGTable } from './clothfit.js';
new MeshClothMaterial(); new MeshClothMaterial(); new MeshWovenMaterial();
await new Promise((r) => setTimeout(r, 200));
try { await clothDGTable(); console.log('no error'); } catch (e) { console.log('awaited: ' + e.message); }
console.log('still running');
`);
  const r = spawnSync(process.execPath, [path.join(dir, 'main.mjs')], { encoding: 'utf8', timeout: 30000 });
  check(r.status === 0, `a missing table is not fatal (exit ${r.status}; ${r.stderr.slice(0, 300)})`);
  check(r.stdout.includes('still running'), 'the process went on');
  const lines = r.stderr.trim().split('\n');
  const dgLines = lines.filter((l) => l.includes('cloth DG table'));
  const file = path.join(dir, 'lut', 'cloth_dg_128.f32');
  check(dgLines.length === 1 && dgLines[0].startsWith(`clothfit: cloth DG table: cannot read ${file}: ENOENT`), `reported once, naming the table and the file (${JSON.stringify(r.stderr)})`);
  check(lines.filter((l) => l.includes('woven phase table')).length === 1, 'the woven phase table too, once');
  check(!/fetch failed|not implemented|Unhandled|\n\s+at /.test(r.stderr), `no raw fetch error or stack (${JSON.stringify(r.stderr)})`);
  check(r.stdout.includes(`awaited: cloth DG table: cannot read ${file}: ENOENT`), `awaiting the table rejects with the message (${JSON.stringify(r.stdout)})`);
} finally {
  fs.rmSync(dir, { recursive: true, force: true });
}
console.log(`tables-node: ${checks} checks passed`);
