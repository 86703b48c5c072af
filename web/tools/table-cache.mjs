// Shared by web/tools/export-*.mjs: reads one of clothfit's verified table-cache files and writes
// a web/lut/*.f32 file. Cache: $CLOTHFIT_TABLE_CACHE or ${XDG_CACHE_HOME:-~/.cache}/clothfit/tables
// (written by any clothfit command that shades the model, e.g. render-preview). File layout
// (brdf/lut.cpp): one header line "clothfit-table v1 <kind> size=<n> ... channels=<c>", then
// n * n * c little-endian float32 (row-major, channels interleaved), then their FNV-1a 64
// checksum, little-endian; the size and the checksum are verified here.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const lutDir = path.join(path.dirname(fileURLToPath(import.meta.url)), '..', 'lut');
export const tableCacheDir = process.env.CLOTHFIT_TABLE_CACHE ||
  path.join(process.env.XDG_CACHE_HOME || path.join(os.homedir(), '.cache'), 'clothfit', 'tables');

// -> { src, n, ch, f: Float32Array(n * n * ch) }; throws naming the file on any mismatch.
export function readTableCache(kind, fileName, channels, src = undefined) {
  src = src || path.join(tableCacheDir, fileName);
  const buf = fs.readFileSync(src);
  const nl = buf.indexOf(0x0a);
  const header = buf.subarray(0, nl).toString();
  const m = new RegExp(`^clothfit-table v1 ${kind} size=(\\d+) .*channels=(\\d+)$`).exec(header);
  if (!m) throw new Error(`${src}: unexpected header '${header}'`);
  const n = Number(m[1]), ch = Number(m[2]);
  if (ch !== channels) throw new Error(`${src}: expected ${channels} channels`);
  const bytes = n * n * ch * 4;
  if (buf.length !== nl + 1 + bytes + 8) throw new Error(`${src}: size ${buf.length} does not match the header`);
  const body = buf.subarray(nl + 1, nl + 1 + bytes);
  // FNV-1a 64 over the float bytes (brdf/lut.cpp Fnv1a).
  let h = 0xcbf29ce484222325n;
  for (const b of body) { h ^= BigInt(b); h = (h * 0x100000001b3n) & 0xffffffffffffffffn; }
  if (h !== buf.readBigUInt64LE(nl + 1 + bytes)) throw new Error(`${src}: checksum mismatch`);
  return { src, n, ch, f: new Float32Array(body.buffer.slice(body.byteOffset, body.byteOffset + body.length)) };
}

// Writes web/lut/<name> (little-endian float32) and says so.
export function writeLut(name, data, what) {
  const dst = path.join(lutDir, name);
  fs.writeFileSync(dst, Buffer.from(data.buffer, data.byteOffset, data.byteLength));
  console.log(`wrote ${dst} (${what})`);
}
