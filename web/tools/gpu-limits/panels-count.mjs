#!/usr/bin/env node
// Counts the directional lights loadSceneCard's setEnvironment(..., {sun: 'panels'}) adds for each
// cached HDRI ($CLOTHFIT_DATA/hdri or ~/.cache/clothfit/hdri): web/sun.js splitEnvironment on the
// texels three.js's EXRLoader gives (half floats, rows bottom-up), as web/clothfit.js sunSplitFor
// does. The "env lights" of docs/web.md "Real GPUs" (studio 4, pmndrs-hall 8).
//   node web/tools/gpu-limits/panels-count.mjs
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const web = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..', '..');
const THREE = await import(path.join(web, 'node_modules', 'three', 'build', 'three.module.js'));
const { EXRLoader } = await import(path.join(web, 'node_modules', 'three', 'examples', 'jsm', 'loaders', 'EXRLoader.js'));
const { splitEnvironment } = await import(path.join(web, 'sun.js'));
const dir = path.join(process.env.CLOTHFIT_DATA || path.join(os.homedir(), '.cache', 'clothfit'), 'hdri');
if (!fs.existsSync(dir)) { console.log(`SKIP: no ${dir} (make data / scripts/fetch-data)`); process.exit(77); }
let worst = 0;
for (const f of fs.readdirSync(dir).filter((f) => f.endsWith('.exr')).sort()) {
  try {
    const b = fs.readFileSync(path.join(dir, f));
    const r = new EXRLoader().parse(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));
    const channels = r.data.length / (r.width * r.height);
    const s = splitEnvironment(r.data, r.width, r.height, { mode: 'panels', channels, rowsBottomUp: true,
      decode: THREE.DataUtils.fromHalfFloat, encode: THREE.DataUtils.toHalfFloat });
    const n = (s.sun.found ? 1 : 0) + s.panels.length;
    worst = Math.max(worst, n);
    console.log(`${f}\tsun ${s.sun.found ? 1 : 0}\tpanels ${s.panels.length}\t=> ${n} directional lights`);
  } catch (e) { console.log(`${f}\tERROR ${e.message.slice(0, 100)}`); }
}
console.log(`max over the cache: ${worst} directional lights from the environment`);
