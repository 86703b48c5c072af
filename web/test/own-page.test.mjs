// The snippet of docs/web.md "Use it in your own page", run as a user would (session 27): the
// ```html block after the "own-page snippet" marker is written to index.html in a temporary
// folder holding only the files that section says to ship (clothfit.js, exr.js, sun.js, lut/;
// three.js as three/; the preset and its weave maps in presets/), served by web/serve.mjs, and
// loaded in headless Chromium (SwiftShader WebGL2) with a test-only harness script that keeps the
// drawing buffer and posts the canvas once the weave maps have loaded:
//   - the canvas: the sphere is drawn (its centre differs from the background) in the preset's
//     colour (red >= green >= blue, as canvas-demo-woven's base colour);
//   - no page error, and no error text appended by the snippet's catch.
// Usage: node web/test/own-page.test.mjs [--chromium /usr/bin/chromium]
//   (exit 77: skipped without chromium or web/node_modules)
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import zlib from 'node:zlib';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const web = path.resolve(here, '..');
const repo = path.resolve(web, '..');
const ci = process.argv.indexOf('--chromium');
const chromium = ci > 0 ? process.argv[ci + 1] : '/usr/bin/chromium';
if (!fs.existsSync(chromium) || !fs.existsSync(path.join(web, 'node_modules', 'three', 'package.json'))) {
  console.log(`skipped: needs ${chromium} and web/node_modules`);
  process.exit(77);
}
const { startServer } = await import(pathToFileURL(path.join(web, 'serve.mjs')).href);
const { spawnHeadlessChromium, stopChromium } = await import(pathToFileURL(path.join(web, 'tools', 'chromium.mjs')).href);
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };

// The snippet.
const doc = fs.readFileSync(path.join(repo, 'docs', 'web.md'), 'utf8');
const m = /<!-- own-page snippet[^>]*-->\n```html\n([\s\S]*?)\n```/.exec(doc);
check(m !== null, 'docs/web.md has the own-page snippet');
const html = m[1];

// The folder: only what the section says to ship.
const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-own-page-'));
fs.mkdirSync(path.join(dir, 'clothfit', 'lut'), { recursive: true });
for (const f of ['clothfit.js', 'exr.js', 'sun.js']) fs.copyFileSync(path.join(web, f), path.join(dir, 'clothfit', f));
for (const f of fs.readdirSync(path.join(web, 'lut'))) fs.copyFileSync(path.join(web, 'lut', f), path.join(dir, 'clothfit', 'lut', f));
fs.symlinkSync(path.join(web, 'node_modules', 'three'), path.join(dir, 'three'));
fs.mkdirSync(path.join(dir, 'presets'));
for (const f of ['canvas-demo-woven.json', 'canvas-demo-woven.weave.exr']) fs.copyFileSync(path.join(repo, 'docs', 'presets', f), path.join(dir, 'presets', f));
// The harness (test only, a classic script before the snippet's import map; the snippet itself
// is unchanged): WebGL contexts keep their drawing buffer so the canvas can be read after the
// frame; once the preset's weave maps have loaded and 30 more frames have been drawn, the canvas
// is POSTed as PNG (/shot), then the page's visible text (/done); page errors go to /log.
const harness = `<script>
(() => {
  const get = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (type, attrs) { return get.call(this, type, Object.assign({}, attrs, { preserveDrawingBuffer: true })); };
  const post = (p, body) => fetch(p, { method: 'POST', body });
  addEventListener('error', (e) => post('/log', 'error: ' + e.message));
  addEventListener('unhandledrejection', (e) => post('/log', 'unhandled rejection: ' + (e.reason && e.reason.message)));
  let frames = 0;
  const poll = () => {
    const loaded = performance.getEntriesByType('resource').some((r) => r.name.endsWith('.weave.exr'));
    if (loaded && ++frames === 30) {
      document.getElementById('c').toBlob((b) => post('/shot', b).then(() => post('/done', document.body.innerText)), 'image/png');
      return;
    }
    requestAnimationFrame(poll);
  };
  requestAnimationFrame(poll);
})();
</script>
`;
check(/^<!doctype html>\n<meta charset="utf-8">\n/.test(html), 'the snippet starts with the doctype and charset');
fs.writeFileSync(path.join(dir, 'index.html'), html.replace('<meta charset="utf-8">\n', `<meta charset="utf-8">\n${harness}`));

// An 8-bit RGB / RGBA PNG (what Chromium writes) -> {width, height, channels, data}.
function readPng(buf) {
  let o = 8, width = 0, height = 0, type = 0;
  const idat = [];
  while (o < buf.length) {
    const len = buf.readUInt32BE(o), kind = buf.toString('latin1', o + 4, o + 8), body = buf.subarray(o + 8, o + 8 + len);
    if (kind === 'IHDR') { width = body.readUInt32BE(0); height = body.readUInt32BE(4); assert.equal(body[8], 8, 'bit depth'); type = body[9]; }
    if (kind === 'IDAT') idat.push(body);
    o += 12 + len;
  }
  const ch = { 2: 3, 6: 4 }[type];
  assert.ok(ch, `PNG colour type ${type}`);
  const raw = zlib.inflateSync(Buffer.concat(idat)), stride = width * ch, data = Buffer.alloc(height * stride);
  for (let y = 0; y < height; ++y) {
    const f = raw[y * (stride + 1)], line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; ++x) {
      const a = x >= ch ? data[y * stride + x - ch] : 0, b = y ? data[(y - 1) * stride + x] : 0, c = x >= ch && y ? data[(y - 1) * stride + x - ch] : 0;
      const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
      const pred = [0, a, b, (a + b) >> 1, pa <= pb && pa <= pc ? a : pb <= pc ? b : c][f];
      data[y * stride + x] = (line[x] + pred) & 255;
    }
  }
  return { width, height, channels: ch, data };
}

const logs = [];
let done, shotPng = null;
const finished = new Promise((r) => { done = r; });
const server = await startServer({
  fsRoots: [dir],
  onShot: (b) => { shotPng = b; },
  onLog: (t) => { logs.push(t); if (/^(error|unhandled rejection)/.test(t)) done(null); },
  onPost: (u, b) => { if (u.pathname === '/done') done(b.toString()); },
});
const url = `http://127.0.0.1:${server.address().port}/fs${dir}/index.html`;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-own-page-profile-'));
const browser = spawnHeadlessChromium(chromium, url, profile, { windowSize: '512,512' });
try {
  const timer = setTimeout(() => done(null), 180000);
  const text = await finished;
  clearTimeout(timer);
  check(text !== null, `the page finished (${logs.join(' | ') || 'timeout'})`);
  check(logs.length === 0, `no page errors (${logs.join(' | ')})`);
  check(!text.includes('clothfit:'), `no error text in the page (${text.trim().slice(0, 300)})`);
  check(shotPng !== null, 'the canvas was captured');
  const png = readPng(shotPng);
  const px = (x, y) => { const i = (y * png.width + x) * png.channels; return [png.data[i], png.data[i + 1], png.data[i + 2]]; };
  // the mean over the sphere's centre (a 40 x 40 box) against the background corner
  const mean = [0, 0, 0];
  for (let y = 236; y < 276; ++y) for (let x = 236; x < 276; ++x) px(x, y).forEach((v, k) => { mean[k] += v / 1600; });
  const bg = px(10, 10);
  console.log(`own-page: centre mean ${mean.map((v) => v.toFixed(1)).join(' ')}, background ${bg.join(' ')}`);
  check(Math.max(...mean.map((v, k) => Math.abs(v - bg[k]))) > 20, 'the sphere is drawn (its centre differs from the background)');
  check(mean[0] >= mean[1] && mean[1] >= mean[2] && mean[0] > 60, 'in the preset\'s colour (red >= green >= blue)');
} finally {
  const warning = await stopChromium(browser, profile);
  if (warning) console.error(`warning: ${warning}`);
  server.close();
  fs.rmSync(dir, { recursive: true, force: true });
}
console.log(`own-page: ${checks} checks passed`);
