#!/usr/bin/env node
// Screenshot of web/viewer.html in headless Debian chromium (SwiftShader WebGL2):
//   node web/tools/screenshot.mjs --out docs/viewer-canvas.png --query 'card=...&preset=...'
// (--help: the options; an unknown option is an error: web/test/screenshot-cli.test.mjs).
// The viewer (with shot=1) POSTs its first frame as PNG; the server writes it to --out.
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { startServer } from '../serve.mjs';
import { killChromiumOnExit, stopChromium } from './chromium.mjs';

const USAGE = `Usage: node web/tools/screenshot.mjs [--out FILE] [--query 'card=...&preset=...'] [--timeout S] [--chromium PATH]
  --out FILE       the PNG to write (default viewer.png in the current directory)
  --query Q        web/viewer.html's query string (card, preset, env, sun, shadows, ...; docs/web.md)
  --timeout S      seconds to wait for the first frame (default 180)
  --chromium PATH  the browser (default /usr/bin/chromium)
  -h, --help       print this and exit`;
// The options, checked before anything is started or written: an unknown option, a missing value
// or a bad number is an error (exit 2) naming it.
function parseArgs(argv) {
  const o = { out: 'viewer.png', query: '', timeout: '180', chromium: '/usr/bin/chromium' };
  const fail = (msg) => { console.error(`web/tools/screenshot.mjs: ${msg}\n${USAGE}`); process.exit(2); };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    if (a === '--help' || a === '-h') { console.log(USAGE); process.exit(0); }
    const m = /^--([a-z]+)(?:=(.*))?$/s.exec(a);
    if (!m || !Object.hasOwn(o, m[1])) fail(`unknown ${a.startsWith('-') ? 'option' : 'argument'} ${JSON.stringify(a)}`);
    const v = m[2] ?? argv[++i];
    if (v === undefined || (m[2] === undefined && v.startsWith('--'))) fail(`--${m[1]}: expected a value`);
    o[m[1]] = v;
  }
  const t = Number(o.timeout);
  if (!/^\s*[0-9.eE+]+\s*$/.test(o.timeout) || !Number.isFinite(t) || t <= 0) fail(`--timeout: expected a number of seconds > 0, got ${JSON.stringify(o.timeout)}`);
  if (!o.out) fail('--out: expected a file name');
  if (!fs.existsSync(o.chromium)) fail(`--chromium: ${JSON.stringify(o.chromium)} not found (Debian: apt-get install chromium; or scripts/install-deps)`);
  return { ...o, timeout: t };
}
const opts = parseArgs(process.argv.slice(2));
const out = path.resolve(opts.out);
const query = opts.query;
const timeoutS = opts.timeout;
let done;
const shot = new Promise((r) => { done = r; });
// The page's log is untrusted text (it may quote the query string): control and bidi characters
// are shown escaped, never sent to the terminal as they are.
const printable = (t) => t.replace(/[\u0000-\u0008\u000b-\u001f\u007f-\u009f\u200e\u200f\u202a-\u202e\u2066-\u2069]/g, (c) => `\\u${c.charCodeAt(0).toString(16).padStart(4, '0')}`);
const server = await startServer({ onShot: (png) => done(png), onLog: (m) => console.error(`page: ${printable(m)}`) });
const url = `http://127.0.0.1:${server.address().port}/web/viewer.html?shot=1&${query}`;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-shot-'));
const browser = spawn(opts.chromium, ['--headless=new', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
  '--no-sandbox', '--no-first-run', '--disable-extensions', '--log-level=3', `--user-data-dir=${profile}`, '--window-size=560,640', url],
{ stdio: 'ignore', detached: true });  // its own process group: the renderer and GPU children go with it
killChromiumOnExit(browser, profile);
const timer = setTimeout(() => done(null), timeoutS * 1000);
const png = await shot;
clearTimeout(timer);
if (png) fs.writeFileSync(out, png);
server.close();
const warning = await stopChromium(browser, profile);
if (warning) console.error(`warning: ${warning}`);
if (!png) { console.error('no frame before the timeout'); process.exit(1); }
console.log(`wrote ${out} (${png.length} bytes) from ${url}`);
