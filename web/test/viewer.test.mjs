// Node test of web/viewer.html's untrusted-text paths (session 27 audit; web/viewer-ui.js) in a
// small DOM stand-in whose innerHTML / outerHTML / insertAdjacentHTML throw:
//   1. script injection: the menus were built with innerHTML from the query string
//      (?preset=<img onerror=...> ran script). fillSelect makes <option> nodes with the value
//      and label as text; and no file of web/ assigns innerHTML / outerHTML or calls
//      insertAdjacentHTML / document.write (the scan fails on the old viewer.js);
//   4. the file picker: a malformed JSON is an error naming the file (it went to the console
//      only); a woven preset with weave maps, or three.js JSON with images, loads without them
//      and the info-panel notes say they were skipped, why, and how to load them;
//   5. the error panel: the message only (no stack), as text; the stack goes to the console;
//   6. an HDRI missing from the data cache: the message says to run scripts/fetch-data
//      (loadSceneCard in node against web/serve.mjs with an empty $CLOTHFIT_DATA);
//   7. ?shadows= and ?units= values: a bad one names the parameter and the expected form.
// Usage: node web/test/viewer.test.mjs   (exit 77: skipped without web/node_modules)
import assert from 'node:assert/strict';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const web = path.resolve(here, '..');
const repo = path.resolve(web, '..');
if (!fs.existsSync(path.join(web, 'node_modules', 'three', 'package.json'))) {
  console.log('skipped: no web/node_modules (npm ci in web/)');
  process.exit(77);
}
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };

// ---- a DOM stand-in: elements hold text and children; markup setters throw ---------------------
class El {
  constructor(tag, doc) { this.tagName = tag.toUpperCase(); this.ownerDocument = doc; this.children = []; this._text = ''; this.hidden = false; this.value = ''; this.selected = false; }
  get textContent() { return this.children.length ? this.children.map((c) => c.textContent).join('') : this._text; }
  set textContent(t) { this.children = []; this._text = String(t); }
  replaceChildren(...c) { this.children = c; this._text = ''; }
  append(...c) { this.children.push(...c); }
  set innerHTML(_) { throw new Error('innerHTML used'); }
  set outerHTML(_) { throw new Error('outerHTML used'); }
  insertAdjacentHTML() { throw new Error('insertAdjacentHTML used'); }
}
const doc = { createElement: (t) => new El(t, doc), write() { throw new Error('document.write used'); } };
globalThis.document = doc;

const { fillSelect, errorText, showError, clearError, parseShadowsParam, parseUnitsParam, localFileNotes, readLocalPreset } = await import(pathToFileURL(path.join(web, 'viewer-ui.js')).href);

// ---- 1. menus from hostile query strings --------------------------------------------------------
const hostile = ['<img id=pwned src=x onerror="document.title=\'PWNED\'">', '"><script>alert(1)</script>', "' onfocus='x", '&lt;b&gt;&amp;'];
const base = (u) => u.split('/').pop().replace(/\.json$/, '');
for (const h of hostile) {
  const sel = new El('select', doc);
  fillSelect(sel, ['../a/one.json', `../x/${h}.json`], `../x/${h}.json`, base);
  const opts = sel.children;
  check(opts.length === 2 && opts.every((o) => o.tagName === 'OPTION'), `${h}: two <option> nodes`);
  check(opts[1].value === `../x/${h}.json` && opts[1].textContent === base(`../x/${h}.json`) && opts[1].selected && !opts[0].selected, `${h}: value and label kept as text, selected`);
  const cur = new El('select', doc);
  fillSelect(cur, ['card', 'none'], h);  // a current value not in the list is put first
  check(cur.children[0].value === h && cur.children[0].textContent === h && cur.children[0].selected, `${h}: unknown current value first, as text`);
}
// No markup sinks anywhere in web/ (code lines; comments may name them).
const sinks = /\.(innerHTML|outerHTML)\s*\+?=|insertAdjacentHTML\s*\(|document\.write(ln)?\s*\(|createContextualFragment\s*\(/;
const files = fs.readdirSync(web, { recursive: true }).map(String)
  .filter((f) => !f.startsWith('node_modules') && /\.(m?js|html)$/.test(f) && !f.startsWith(`test${path.sep}viewer.test.mjs`));
const offenders = [];
for (const f of files) {
  fs.readFileSync(path.join(web, f), 'utf8').split('\n').forEach((line, i) => {
    const code = line.replace(/^\s*\/\/.*$/, '').replace(/\s\/\/\s.*$/, '');
    if (sinks.test(code)) offenders.push(`web/${f}:${i + 1}`);
  });
}
check(files.some((f) => f === 'viewer.js') && offenders.length === 0, `no innerHTML / outerHTML / insertAdjacentHTML / document.write in web/ (${offenders.join(', ')})`);

// ---- 5. the error panel: the message only, as text ----------------------------------------------
const errors = [];
const realError = console.error, realWarn = console.warn;
console.error = (...a) => errors.push(a);
const panel = new El('div', doc);
panel.hidden = true;
const e = new Error('<b>bad</b> thing');
const shown = showError(panel, e, 'preset file x<y>.json');
check(panel.textContent === 'error: preset file x<y>.json: <b>bad</b> thing' && !panel.hidden && shown === 'preset file x<y>.json: <b>bad</b> thing', `panel text (${panel.textContent})`);
check(!panel.textContent.includes(' at ') && !/viewer\.test\.mjs/.test(panel.textContent), 'no stack in the panel');
check(errors.length === 1 && errors[0].includes(e), 'the error itself (with its stack) on the console');
clearError(panel);
check(panel.hidden && panel.textContent === '', 'clearError');
check(errorText(new TypeError('x')) === 'x' && errorText('plain') === 'plain' && errorText({ type: 'error', target: { src: 'a.png' } }) === 'error event for a.png', 'errorText of errors, strings and events');

// ---- 7. ?shadows= and ?units= -------------------------------------------------------------------
check(parseShadowsParam(null) === undefined && parseShadowsParam('1') === true && parseShadowsParam('true') === true && parseShadowsParam('0') === false && parseShadowsParam('false') === false, 'shadows: 1 / 0 / true / false / absent');
check(JSON.stringify(parseShadowsParam('{"type":"pcf","mapSize":4096}')) === '{"type":"pcf","mapSize":4096}', 'shadows: a JSON object');
const throwsLike = (fn, re, what) => {
  let msg = '';
  try { fn(); } catch (err) { msg = err.message; }
  check(re.test(msg), `${what}: ${JSON.stringify(msg)}`);
};
throwsLike(() => parseShadowsParam('{bad'), /^shadows="\{bad": not JSON \(.*\); expected 1, 0, true, false or a JSON object of shadow settings, e\.g\. shadows=\{"type":"pcf","mapSize":4096\}/, 'shadows={bad');
throwsLike(() => parseShadowsParam('yes'), /^shadows="yes": not JSON/, 'shadows=yes');
throwsLike(() => parseShadowsParam('5'), /^shadows="5": expected 1, 0, true, false or a JSON object/, 'shadows=5');
throwsLike(() => parseShadowsParam('[1]'), /^shadows="\[1\]": expected/, 'shadows=[1]');
check(parseUnitsParam(null) === null && parseUnitsParam('16') === 16, 'units: 16 / absent');
for (const u of ['abc', '0', '1.5', '-3', '']) throwsLike(() => parseUnitsParam(u), /^units=".*": expected a whole number of texture units >= 1/, `units=${u}`);

// ---- 4. the file picker -------------------------------------------------------------------------
const { loadClothfitPreset } = await import(pathToFileURL(path.join(web, 'clothfit.js')).href);
const file = (name, text) => ({ name, text: async () => text });
const rejectsLike = async (p, re, what) => {
  let msg = '';
  try { await p; } catch (err) { msg = err.message; }
  check(re.test(msg), `${what}: ${JSON.stringify(msg)}`);
};
await rejectsLike(readLocalPreset(file('broken.json', '{"schema": "clothfit.preset",'), loadClothfitPreset), /^broken\.json: not JSON \(/, 'malformed JSON names the file');
await rejectsLike(readLocalPreset(file('odd.json', '{"schema":"clothfit.preset","version":1,"model":"nope","parameters":{}}'), loadClothfitPreset), /^odd\.json: loadClothfitPreset: model: unknown/, 'a bad preset names the file and the field');
const wovenText = fs.readFileSync(path.join(repo, 'docs', 'presets', 'canvas-demo-woven.json'), 'utf8');
const wv = await readLocalPreset(file('canvas-demo-woven.json', wovenText), loadClothfitPreset);
check(wv.material.constructor.name === 'MeshWovenMaterial' && wv.material.weaveMaps === null, 'a woven preset with weave maps loads uniform');
check(wv.notes.length === 1 && /^weave maps skipped: canvas-demo-woven\.json names weave maps \(canvas-demo-woven\.weave\.exr\)/.test(wv.notes[0]) &&
  /cannot fetch the files next to it/.test(wv.notes[0]) && /node web\/serve\.mjs/.test(wv.notes[0]) && /viewer\.html\?preset=/.test(wv.notes[0]), `the note says skipped, why and how (${wv.notes[0]})`);
const plain = await readLocalPreset(file('c.json', fs.readFileSync(path.join(repo, 'docs', 'presets', 'canvas-demo-cloth.json'), 'utf8')), loadClothfitPreset);
check(plain.notes.length === 0 && plain.material.isMeshClothMaterial, 'a preset without maps: no note');
const warns = [];
console.warn = (...a) => warns.push(a.join(' '));
const three = { metadata: { version: 4.6, type: 'Material' }, type: 'MeshPhysicalMaterial', color: 0x808080, map: 't', images: [{ uuid: 'i', url: 'x.png' }], textures: [{ uuid: 't', image: 'i' }] };
const tj = await readLocalPreset(file('x.three.json', JSON.stringify(three)), loadClothfitPreset);
console.warn = realWarn;
check(tj.material.map === null && tj.material.userData.clothfit.skippedTextures[0] === 'map' && tj.notes.length === 1 && /^textures skipped: x\.three\.json names 1 image/.test(tj.notes[0]), `three.js JSON: textures skipped, said (${tj.notes[0]})`);
check(warns.length === 0, 'no second warning from the loader (skipped on purpose)');
check(localFileNotes({ weave_maps: { file: '/abs/<b>.exr' } }, 'f.json')[0].includes('(/abs/<b>.exr)'), 'the note quotes the file name as text');

// ---- 6. an HDRI missing from the data cache -----------------------------------------------------
{
  const empty = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-viewer-test-'));
  process.env.CLOTHFIT_DATA = empty;  // before web/serve.mjs is imported: its /hdri/ is empty
  const { startServer } = await import(pathToFileURL(path.join(web, 'serve.mjs')).href);
  const { loadSceneCard, environmentLoadError } = await import(pathToFileURL(path.join(web, 'clothfit.js')).href);
  const server = await startServer();
  const origin = `http://127.0.0.1:${server.address().port}`;
  globalThis.ProgressEvent ??= class { constructor(type, o) { this.type = type; Object.assign(this, o); } };  // three.js FileLoader in node
  doc.baseURI = `${origin}/web/viewer.html`;
  try {
    await rejectsLike(loadSceneCard('../datasets/scenes/sphere.json', { renderer: {} }),
      new RegExp(`^environment "studio": ${origin}/hdri/studio\\.exr not found \\(HTTP 404\\): the HDRI is not in the data cache\\. Run scripts/fetch-data \\(or make data\\)`), 'a missing HDRI: the hint');
  } finally {
    server.close();
    fs.rmSync(empty, { recursive: true, force: true });
  }
  const http404 = Object.assign(new Error('fetch for "u" responded with 404: Not Found'), { response: { status: 404 } });
  check(/not found \(HTTP 404; a path is relative to the scene card\)$/.test(environmentLoadError('maps/room.exr', 'http://h/maps/room.exr', http404)), 'a missing file path: no data-cache hint');
  check(/^environment "studio": u: boom$/.test(environmentLoadError('studio', 'u', new Error('boom'))), 'other failures: the message, named');
}
console.error = realError;
console.log(`viewer: ${checks} checks passed`);
