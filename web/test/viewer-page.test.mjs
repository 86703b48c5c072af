// Headless-Chromium check of web/viewer.html itself (session 27 audit), the page's DOM read with
// --dump-dom after it has run (SwiftShader WebGL2, the flags of tests/browser/run.mjs):
//   1. ?card=, ?preset=, ?presets= carrying <img onerror="document.title='PWNED'"> do not run
//      script (the title stays, no such element exists; the menus show the text);
//   5. the error panel shows the message without a stack trace;
//   6. the card's HDRI missing from the data cache ($CLOTHFIT_DATA empty): the panel says to run
//      scripts/fetch-data;
//   7. ?shadows={bad and ?units=abc name the parameter and the expected form.
// Usage: node web/test/viewer-page.test.mjs [--chromium /usr/bin/chromium]
//   (exit 77: skipped without chromium or web/node_modules)
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const web = path.resolve(here, '..');
const ci = process.argv.indexOf('--chromium');
const chromium = ci > 0 ? process.argv[ci + 1] : '/usr/bin/chromium';
if (!fs.existsSync(chromium) || !fs.existsSync(path.join(web, 'node_modules', 'three', 'package.json'))) {
  console.log(`skipped: needs ${chromium} and web/node_modules`);
  process.exit(77);
}
const empty = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-viewer-page-'));
process.env.CLOTHFIT_DATA = empty;  // before web/serve.mjs is imported: no HDRIs
const { startServer } = await import(pathToFileURL(path.join(web, 'serve.mjs')).href);
const { killChromiumOnExit, stopChromium } = await import(pathToFileURL(path.join(web, 'tools', 'chromium.mjs')).href);
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };

// The page's DOM once it has settled (virtual time), or '' on a timeout.
async function dumpDom(url, budget = 15000) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-viewer-page-profile-'));
  const browser = spawn(chromium, ['--headless=new', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox',
    '--disable-gpu-sandbox', '--no-first-run', '--no-default-browser-check', '--disable-extensions', '--disable-background-networking',
    '--mute-audio', '--log-level=3', `--user-data-dir=${profile}`, '--window-size=560,640', `--virtual-time-budget=${budget}`, '--dump-dom', url],
  { stdio: ['ignore', 'pipe', 'ignore'], detached: true });
  killChromiumOnExit(browser, profile);
  const chunks = [];
  browser.stdout.on('data', (d) => chunks.push(d));
  const exited = new Promise((r) => { browser.once('exit', r); });
  const timer = new Promise((r) => { setTimeout(r, 120000); });
  await Promise.race([exited, timer]);
  const warning = await stopChromium(browser, profile);
  if (warning) console.error(`warning: ${warning}`);
  return Buffer.concat(chunks).toString('utf8');
}
const between = (html, re) => re.exec(html)?.[1] ?? null;
const errorPanel = (html) => between(html, /<div id="error"[^>]*>([\s\S]*?)<\/div>/);

const server = await startServer();
const page = `http://127.0.0.1:${server.address().port}/web/viewer.html`;
try {
  const evil = (n) => `<img id=pwned${n} src=x onerror="document.title='PWNED'">`;
  const enc = encodeURIComponent;
  // One page at a time, and once more with a longer budget when its error panel is still empty:
  // four browsers at once under a loaded CI machine dumped one page before its error was shown.
  const settled = async (url) => {
    const first = await dumpDom(url);
    return errorPanel(first) ? first : dumpDom(url, 60000);
  };
  const hostile = await settled(`${page}?card=${enc(evil(1))}&presets=${enc(`${evil(2)},${evil(3)}`)}`);
  const shadows = await settled(`${page}?shadows=${enc('{bad')}`);
  const hdri = await settled(`${page}?card=../datasets/scenes/sphere.json`);
  const units = await settled(`${page}?units=abc`);
  // 1. no script from the query string
  check(hostile.includes('<select id="preset">'), `the page was dumped (${hostile.length} bytes)`);
  check(between(hostile, /<title>([^<]*)<\/title>/) === 'clothfit viewer (three.js r187)', `the title is unchanged (${between(hostile, /<title>([^<]*)<\/title>/)})`);
  check(!/<img[^>]*pwned|id="pwned/i.test(hostile), 'no element from the query string');
  check(hostile.includes('&lt;img id=pwned2 src=x onerror="document.title=\'PWNED\'"&gt;</option>'), 'the preset menu shows the text');
  check((hostile.match(/<option [^>]*>&lt;img id=pwned1/g) ?? []).length === 1, 'the scene menu shows the text');
  // 5. message only
  const he = errorPanel(hostile);
  check(he !== null && he.startsWith('error: ') && !/\bat (\S+ )?\(?https?:/.test(he) && !he.includes('viewer.js:'), `the error panel: the message without a stack (${he})`);
  // 7. the parameters
  const se = errorPanel(shadows);
  check(se?.startsWith('error: shadows="{bad": not JSON') && se.includes('expected 1, 0, true, false or a JSON object of shadow settings'), `shadows={bad (${se})`);
  const ue = errorPanel(units);
  check(ue?.startsWith('error: units="abc": expected a whole number of texture units &gt;= 1'), `units=abc (${ue})`);
  // 6. the data cache
  const de = errorPanel(hdri);
  check(de?.startsWith('error: environment "studio": ') && de.includes('not found (HTTP 404): the HDRI is not in the data cache. Run scripts/fetch-data (or make data)'), `missing HDRI (${de})`);
} finally {
  server.close();
  fs.rmSync(empty, { recursive: true, force: true });
}
console.log(`viewer-page: ${checks} checks passed`);
