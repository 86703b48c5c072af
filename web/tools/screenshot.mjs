#!/usr/bin/env node
// Screenshot of web/viewer.html in headless Debian chromium (SwiftShader WebGL2):
//   node web/tools/screenshot.mjs --out docs/viewer-canvas.png --query 'card=...&preset=...'
// The viewer (with shot=1) POSTs its first frame as PNG; the server writes it to --out.
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { startServer } from '../serve.mjs';
import { killChromiumOnExit, stopChromium } from './chromium.mjs';

const arg = (k, d) => { const i = process.argv.indexOf(`--${k}`); return i > 0 ? process.argv[i + 1] : d; };
const out = path.resolve(arg('out', 'viewer.png'));
const query = arg('query', '');
const timeoutS = Number(arg('timeout', 180));
let done;
const shot = new Promise((r) => { done = r; });
const server = await startServer({ onShot: (png) => done(png), onLog: (m) => console.error(`page: ${m}`) });
const url = `http://127.0.0.1:${server.address().port}/web/viewer.html?shot=1&${query}`;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-shot-'));
const browser = spawn(arg('chromium', '/usr/bin/chromium'), ['--headless=new', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
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
