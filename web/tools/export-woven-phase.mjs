#!/usr/bin/env node
// Writes web/lut/woven_phase_32.f32: clothfit's woven phase table (brdf/lut.h DefaultWovenPhase,
// the SAME data the C++ preview reads), 32 x 32 x 9, little-endian float32, stored as a
// (32 * 9) x 32 single-channel image: row j = perceptual r_e at (j + 0.5)/32, column k * 32 + i =
// channel k (beta = kWovenPhaseBetas[k]) at NoV = (i + 0.5)/32.
// Source: clothfit's verified table cache, $CLOTHFIT_TABLE_CACHE or
// ${XDG_CACHE_HOME:-~/.cache}/clothfit/tables/woven-phase-32.bin (written by any clothfit command
// that shades the woven model, e.g. render-preview with a woven preset); its FNV-1a checksum
// is verified here. Usage: node web/tools/export-woven-phase.mjs [cache.bin]
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const cacheDir = process.env.CLOTHFIT_TABLE_CACHE ||
  path.join(process.env.XDG_CACHE_HOME || path.join(os.homedir(), '.cache'), 'clothfit', 'tables');
const src = process.argv[2] || path.join(cacheDir, 'woven-phase-32.bin');
const buf = fs.readFileSync(src);
const nl = buf.indexOf(0x0a);
const header = buf.subarray(0, nl).toString();
const m = /^clothfit-table v1 woven-phase size=(\d+) .*channels=(\d+)$/.exec(header);
if (!m) throw new Error(`${src}: unexpected header '${header}'`);
const n = Number(m[1]), ch = Number(m[2]);
if (ch !== 9) throw new Error(`${src}: expected 9 channels`);
const bytes = n * n * ch * 4;
const body = buf.subarray(nl + 1, nl + 1 + bytes);
if (buf.length !== nl + 1 + bytes + 8) throw new Error(`${src}: size ${buf.length} does not match the header`);
// FNV-1a 64 over the float bytes (brdf/lut.cpp Fnv1a), stored little-endian after them.
let h = 0xcbf29ce484222325n;
for (const b of body) { h ^= BigInt(b); h = (h * 0x100000001b3n) & 0xffffffffffffffffn; }
if (h !== buf.readBigUInt64LE(nl + 1 + bytes)) throw new Error(`${src}: checksum mismatch`);
const f = new Float32Array(body.buffer.slice(body.byteOffset, body.byteOffset + body.length));
const out = new Float32Array(n * n * ch);
for (let j = 0; j < n; ++j) for (let k = 0; k < ch; ++k) for (let i = 0; i < n; ++i) out[j * n * ch + k * n + i] = f[(j * n + i) * ch + k];
const dst = path.join(here, '..', 'lut', `woven_phase_${n}.f32`);
fs.writeFileSync(dst, Buffer.from(out.buffer));
console.log(`wrote ${dst} (${n}x${n}x${ch}) from ${src}`);
