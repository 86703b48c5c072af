#!/usr/bin/env node
// Writes web/lut/cloth_dg_128.f32: the cloth DG channel (B) of clothfit's 128 x 128 DFG table,
// little-endian float32, row j = perceptual r at (j + 0.5)/128, column i = NoV at (i + 0.5)/128.
// Source: clothfit's verified table cache (brdf/lut.h CachedDfg), dfg-128.bin in the cache
// directory of web/tools/table-cache.mjs. Usage: node web/tools/export-cloth-dg.mjs [cache.bin]
import { readTableCache, writeLut } from './table-cache.mjs';

const { src, n, ch, f } = readTableCache('dfg', 'dfg-128.bin', 3, process.argv[2]);
const out = new Float32Array(n * n);
for (let j = 0; j < n; ++j) for (let i = 0; i < n; ++i) out[j * n + i] = f[(j * n + i) * ch + 2];
writeLut(`cloth_dg_${n}.f32`, out, `${n}x${n} from ${src}`);
