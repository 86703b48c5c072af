#!/usr/bin/env node
// Writes web/lut/cloth_dg_128.f32: the cloth DG channel (B) of clothfit's 128 x 128 DFG table,
// little-endian float32, row j = perceptual r at (j + 0.5)/128, column i = NoV at (i + 0.5)/128.
// Source: clothfit's verified table cache (brdf/lut.h CachedDfg), $CLOTHFIT_TABLE_CACHE or
// ${XDG_CACHE_HOME:-~/.cache}/clothfit/tables/dfg-128.bin, which any clothfit command that
// shades a real-time model (e.g. render-preview) writes. Usage: node web/tools/export-cloth-dg.mjs [cache.bin]
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const cacheDir = process.env.CLOTHFIT_TABLE_CACHE ||
  path.join(process.env.XDG_CACHE_HOME || path.join(os.homedir(), '.cache'), 'clothfit', 'tables');
const src = process.argv[2] || path.join(cacheDir, 'dfg-128.bin');
const buf = fs.readFileSync(src);
const nl = buf.indexOf(0x0a);
const header = buf.subarray(0, nl).toString();
const m = /^clothfit-table v1 dfg size=(\d+) .*channels=(\d+)$/.exec(header);
if (!m) throw new Error(`${src}: unexpected header '${header}'`);
const n = Number(m[1]), ch = Number(m[2]);
if (ch !== 3) throw new Error(`${src}: expected 3 channels`);
const body = buf.subarray(nl + 1, nl + 1 + n * n * ch * 4);
const f = new Float32Array(body.buffer.slice(body.byteOffset, body.byteOffset + body.length));
const out = new Float32Array(n * n);
for (let j = 0; j < n; ++j) for (let i = 0; i < n; ++i) out[j * n + i] = f[(j * n + i) * ch + 2];
const dst = path.join(here, '..', 'lut', `cloth_dg_${n}.f32`);
fs.writeFileSync(dst, Buffer.from(out.buffer));
console.log(`wrote ${dst} (${n}x${n}) from ${src}`);
