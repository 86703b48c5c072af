#!/usr/bin/env node
// Writes web/lut/woven_phase_32.f32: clothfit's woven phase table (brdf/lut.h DefaultWovenPhase,
// the SAME data the C++ preview reads), 32 x 32 x 9, little-endian float32, stored as a
// (32 * 9) x 32 single-channel image: row j = perceptual r_e at (j + 0.5)/32, column k * 32 + i =
// channel k (beta = kWovenPhaseBetas[k]) at NoV = (i + 0.5)/32.
// Source: clothfit's verified table cache, woven-phase-32.bin in the cache directory of
// web/tools/table-cache.mjs (written by any clothfit command that shades the woven model, e.g.
// render-preview with a woven preset). Usage: node web/tools/export-woven-phase.mjs [cache.bin]
import { readTableCache, writeLut } from './table-cache.mjs';

const { src, n, ch, f } = readTableCache('woven-phase', 'woven-phase-32.bin', 9, process.argv[2]);
const out = new Float32Array(n * n * ch);
for (let j = 0; j < n; ++j) for (let k = 0; k < ch; ++k) for (let i = 0; i < n; ++i) out[j * n * ch + k * n + i] = f[(j * n + i) * ch + k];
writeLut(`woven_phase_${n}.f32`, out, `${n}x${n}x${ch} from ${src}`);
