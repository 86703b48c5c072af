// A small OpenEXR reader for clothfit's own data files (weave maps, render/preview/weave_maps.h),
// plain ES module, browser and node.
//
// Why not three.js's EXRLoader: it only accepts R/G/B/A/Y channel sets ("file contains
// unsupported data channels" for clothfit's `warp`, `weft`, `kd.R`, ...), and it flips the rows
// to bottom-up. This reader returns every channel by name, rows in FILE order (row 0 = the top
// of the image, the first scanline of the data window), as Float32Array.
//
// Supported (what OpenImageIO writes for clothfit, io::WriteExr: scanline, ZIP): single-part
// scanline images, compression NONE, ZIPS (1 line per block) and ZIP (16 lines per block),
// pixel types HALF and FLOAT (UINT is refused). Tiled, deep and multi-part files are refused.
// Format: "OpenEXR File Layout" and "Technical Introduction to OpenEXR" (openexr.com); ZIP blocks
// are zlib streams of the block's bytes reordered (even bytes, then odd) and delta-encoded.

import { unzlibSync } from 'three/addons/libs/fflate.module.js';

const COMPRESSION = ['NONE', 'RLE', 'ZIPS', 'ZIP', 'PIZ', 'PXR24', 'B44', 'B44A', 'DWAA', 'DWAB'];
const PIXEL_TYPES = ['UINT', 'HALF', 'FLOAT'];

function halfToFloat(h) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
  if (e === 0) return s * m * 2 ** -24;
  if (e === 31) return m ? NaN : s * Infinity;
  return s * (1 + m / 1024) * 2 ** (e - 15);
}

// Limits (session 23), as the C++ readers' (render/scene/input_limits.h): the decoded image (width
// x height x channels x 4 bytes of Float32Array) is checked against kMaxImageBytes BEFORE anything
// is allocated, and a ZIP block inflates into a buffer of its expected size + 1, so a forged
// block (a "zip bomb") can neither allocate more nor pass as the right length.
export const EXR_MAX_DECODED_BYTES = 512 * 1024 * 1024;
const MAX_CHANNELS = 64;  // kMaxChannels of the C++ reader
// Names read from the file, in error messages: quoted, control and non-ASCII characters escaped,
// cut to 64 characters (never the untrusted bytes themselves).
const quote = (s) => JSON.stringify(String(s).slice(0, 64)).replace(/[^\x20-\x7e]/g, (c) => `\\u${c.charCodeAt(0).toString(16).padStart(4, '0')}`);

// ZIP / ZIPS block: inflate, undo the delta predictor, de-interleave (OpenEXR ImfZip.cpp layout).
function unzipBlock(bytes, expected) {
  const t = unzlibSync(bytes, { out: new Uint8Array(expected + 1) });
  if (t.length !== expected) throw new Error(`ZIP block inflates to ${t.length > expected ? `more than ${expected}` : t.length} bytes, expected ${expected}`);
  for (let i = 1; i < t.length; ++i) t[i] = (t[i - 1] + t[i] - 128) & 0xff;
  const out = new Uint8Array(t.length);
  const half = (t.length + 1) >> 1;
  for (let i = 0, a = 0, b = half; i < t.length; ++i) out[i] = i & 1 ? t[b++] : t[a++];
  return out;
}

/**
 * Parses an OpenEXR file (ArrayBuffer or typed array). `name` names the file in errors.
 * Returns {width, height, channels: {name: Float32Array(width * height)}, attributes}, row 0 = top.
 */
export function parseExr(buffer, name = 'EXR') {
  const u8 = buffer instanceof Uint8Array ? buffer : new Uint8Array(buffer.buffer ?? buffer, buffer.byteOffset ?? 0, buffer.byteLength);
  const dv = new DataView(u8.buffer, u8.byteOffset, u8.byteLength);
  const fail = (msg) => { throw new Error(`${name}: ${msg}`); };
  if (u8.length < 8 || dv.getUint32(0, true) !== 20000630) fail('not an OpenEXR file (bad magic number)');
  const flags = dv.getUint32(4, true);
  if ((flags & 0xff) !== 2) fail(`OpenEXR version ${flags & 0xff} (2 expected)`);
  if (flags & 0x200) fail('tiled OpenEXR is not supported');
  if (flags & 0x800) fail('deep OpenEXR is not supported');
  if (flags & 0x1000) fail('multi-part OpenEXR is not supported');
  let off = 8;
  const cstr = () => {
    let e = off;
    while (e < u8.length && u8[e] !== 0) ++e;
    if (e >= u8.length) fail('truncated header');
    const s = new TextDecoder().decode(u8.subarray(off, e));
    off = e + 1;
    return s;
  };
  const attributes = {};
  let channels = null, compression = null, dataWindow = null;
  for (;;) {
    const an = cstr();
    if (an === '') break;
    const type = cstr();
    if (off + 4 > u8.length) fail('truncated header');
    const size = dv.getInt32(off, true);
    off += 4;
    const end = off + size;
    if (size < 0 || end > u8.length) fail(`attribute ${quote(an)}: bad size`);
    if (type === 'chlist') {
      channels = [];
      while (off < end && u8[off] !== 0) {
        const cn = cstr();
        if (off + 16 > end) fail(`channel ${quote(cn)}: truncated channel list`);
        const pt = dv.getInt32(off, true);
        const xs = dv.getInt32(off + 8, true), ys = dv.getInt32(off + 12, true);
        off += 16;
        if (xs !== 1 || ys !== 1) fail(`channel ${quote(cn)}: subsampled channels are not supported`);
        if (!(pt in PIXEL_TYPES)) fail(`channel ${quote(cn)}: unknown pixel type ${pt}`);
        if (channels.length >= MAX_CHANNELS) fail(`more than ${MAX_CHANNELS} channels`);
        channels.push({ name: cn, type: PIXEL_TYPES[pt] });
      }
    } else if (type === 'compression') {
      if (size < 1) fail('attribute compression: bad size');
      compression = COMPRESSION[u8[off]] ?? `code ${u8[off]}`;
    } else if (type === 'box2i') {
      if (size < 16) fail(`attribute ${quote(an)}: bad size`);
      const b = [0, 4, 8, 12].map((k) => dv.getInt32(off + k, true));
      attributes[an] = b;
      if (an === 'dataWindow') dataWindow = b;
    } else if (type === 'string') {
      attributes[an] = new TextDecoder().decode(u8.subarray(off, end));
    } else if (type === 'int') {
      attributes[an] = dv.getInt32(off, true);
    } else if (type === 'float') {
      attributes[an] = dv.getFloat32(off, true);
    } else if (type === 'lineOrder') {
      attributes[an] = u8[off];
    }
    off = end;
  }
  if (!channels || !channels.length) fail('no channels');
  if (!dataWindow) fail('no dataWindow');
  const linesPerBlock = { NONE: 1, ZIPS: 1, ZIP: 16 }[compression];
  if (!linesPerBlock) fail(`compression ${compression} is not supported (NONE, ZIPS, ZIP)`);
  for (const c of channels) if (c.type === 'UINT') fail(`channel ${quote(c.name)}: UINT is not supported`);
  if (new Set(channels.map((c) => c.name)).size !== channels.length) fail('a channel name appears twice');
  const [x0, y0, x1, y1] = dataWindow;
  const width = x1 - x0 + 1, height = y1 - y0 + 1;
  if (!(width > 0 && height > 0)) fail('empty data window');
  const decoded = width * height * channels.length * 4;  // exact in double up to 2^53
  if (decoded > EXR_MAX_DECODED_BYTES) fail(`data window ${width} x ${height} with ${channels.length} channels decodes to ${decoded} bytes, over the limit of ${EXR_MAX_DECODED_BYTES} (render/scene/input_limits.h kMaxImageBytes)`);
  const out = {};
  for (const c of channels) out[c.name] = new Float32Array(width * height);
  const bytesPerLine = channels.reduce((s, c) => s + (c.type === 'HALF' ? 2 : 4) * width, 0);
  const nBlocks = Math.ceil(height / linesPerBlock);
  const tableEnd = off + 8 * nBlocks;
  if (tableEnd > u8.length) fail('truncated offset table');
  for (let b = 0; b < nBlocks; ++b) {
    const at = Number(dv.getBigUint64(off + 8 * b, true));
    if (at + 8 > u8.length) fail(`block ${b}: offset past the end of the file`);
    const y = dv.getInt32(at, true), size = dv.getInt32(at + 4, true);
    if (at + 8 + size > u8.length) fail(`block ${b}: truncated`);
    const first = y - y0;
    if (first < 0 || first >= height || first % linesPerBlock) fail(`block ${b}: bad scanline ${y}`);
    const lines = Math.min(linesPerBlock, height - first);
    const expected = lines * bytesPerLine;
    const raw = u8.subarray(at + 8, at + 8 + size);
    // A block that would not shrink is stored uncompressed (OpenEXR rule).
    const data = compression === 'NONE' || size === expected ? raw : unzipBlock(raw, expected);
    const bd = new DataView(data.buffer, data.byteOffset, data.byteLength);
    let p = 0;
    for (let l = 0; l < lines; ++l) {
      const row = (first + l) * width;
      for (const c of channels) {
        const dst = out[c.name];
        if (c.type === 'FLOAT') {
          for (let x = 0; x < width; ++x, p += 4) dst[row + x] = bd.getFloat32(p, true);
        } else {
          for (let x = 0; x < width; ++x, p += 2) dst[row + x] = halfToFloat(bd.getUint16(p, true));
        }
      }
    }
  }
  return { width, height, channels: out, attributes, compression };
}
