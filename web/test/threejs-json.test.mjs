// Node test of web/clothfit.js reading `clothfit convert --to threejs` JSON with textures
// (session 27 audit: a physical-aniso .three.json with map and anisotropyMap loaded uniform,
// without a word, although docs/web.md says web/ reads convert's output):
//   - loadClothfitPreset(json) without textures: the slots stay empty, are listed in
//     userData.clothfit.skippedTextures and a console warning names them and how to load them;
//     {textures: null}: the same, without the warning (on purpose);
//   - fetchClothfitPreset(url): the images next to the JSON are loaded (a DOM image stubbed here:
//     it records its URL and loads when the server answers 200) and attached: map (srgb) and
//     anisotropyMap (linear) with convert's repeat, wrap, filters and flipY; any other
//     MaterialLoader slot too (normalMap), and embedded DataTexture images without a DOM;
//   - the seed MeshClothMaterial layout gets its map the same way;
//   - bad images / textures entries are refused naming the field (absolute URL, scheme, "..",
//     an unknown image uuid, an image that does not load);
//   - in node without a DOM, fetchClothfitPreset loads the material without its PNG textures and
//     says why (no DOM to decode them);
//   - with --clothfit BIN: convert's own output for tests/data/convert_weave/aniso.json.
// Usage: node web/test/threejs-json.test.mjs [--clothfit build/bin/clothfit]
//   (exit 77: skipped without web/node_modules)
import assert from 'node:assert/strict';
import { spawnSync } from 'node:child_process';
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
const ci = process.argv.indexOf('--clothfit');
const clothfit = ci > 0 ? process.argv[ci + 1] : null;
const THREE = await import(pathToFileURL(path.join(web, 'node_modules', 'three', 'build', 'three.module.js')).href);
const { loadClothfitPreset, fetchClothfitPreset, fetchThreejsTextures, threejsTextureSlots } = await import(pathToFileURL(path.join(web, 'clothfit.js')).href);
const { startServer } = await import(pathToFileURL(path.join(web, 'serve.mjs')).href);
let checks = 0;
const check = (ok, what) => { assert.ok(ok, what); checks++; };
const warnings = [];
const realWarn = console.warn;
console.warn = (...a) => { const m = a.join(' '); if (m.startsWith('THREE.')) realWarn(...a); else warnings.push(m); };

// A DOM image for three.js's ImageLoader: loads when the server answers 200.
const domStub = { createElementNS: () => ({
  listeners: {}, addEventListener(t, f) { this.listeners[t] = f; }, removeEventListener() {},
  set src(u) {
    this._src = u;
    fetch(u).then((r) => { this.width = 4; this.height = 4; (r.ok ? this.listeners.load : this.listeners.error)?.call(this, {}); },
      () => this.listeners.error?.call(this, {}));
  },
  get src() { return this._src; } }) };

const work = fs.mkdtempSync(path.join(os.tmpdir(), 'clothfit-threejs-json-'));
const server = await startServer({ fsRoots: [work] });
const base = `http://127.0.0.1:${server.address().port}/fs${work}/`;
try {
  // convert's layout (tests/data/convert_weave, docs/convert.md "Loading the three.js JSON")
  fs.writeFileSync(path.join(work, 'w.basecolor.png'), 'png');
  fs.writeFileSync(path.join(work, 'w.anisotropy.png'), 'png');
  fs.writeFileSync(path.join(work, 'w.normal.png'), 'png');
  const tex = (uuid, image, colorSpace, name) => ({ uuid, image, name, colorSpace, anisotropy: 16, channel: 0, flipY: false, generateMipmaps: true,
    magFilter: 1006, minFilter: 1008, mapping: 300, offset: [0, 0], repeat: [7, 7], center: [0, 0], rotation: 0, wrap: [1000, 1000] });
  const physical = {
    metadata: { version: 4.6, type: 'Material', generator: 'clothfit convert' }, type: 'MeshPhysicalMaterial', name: 'w',
    color: 0xc5b093, roughness: 0.62, metalness: 0, sheen: 1, sheenColor: 0x95887c, sheenRoughness: 0.55, anisotropy: 0.6, anisotropyRotation: 0.3, side: 2,
    map: 'kd-t', anisotropyMap: 'an-t', normalMap: 'n-t',
    images: [{ uuid: 'kd-i', url: 'w.basecolor.png' }, { uuid: 'an-i', url: 'w.anisotropy.png' }, { uuid: 'n-i', url: 'w.normal.png' }],
    textures: [tex('kd-t', 'kd-i', 'srgb', 'weave kd'), tex('an-t', 'an-i', '', 'weave anisotropy'), tex('n-t', 'n-i', '', 'normal')],
  };
  fs.writeFileSync(path.join(work, 'w.three.json'), JSON.stringify(physical));
  check(JSON.stringify(threejsTextureSlots(physical).map(([k]) => k)) === '["map","anisotropyMap","normalMap"]', 'the texture slots found');

  // 1. loadClothfitPreset alone: skipped, said
  warnings.length = 0;
  const bare = loadClothfitPreset(physical);
  check(bare.type === 'MeshPhysicalMaterial' && bare.map === null && bare.anisotropyMap === null && bare.normalMap === null, 'no textures given: slots empty');
  check(JSON.stringify(bare.userData.clothfit.skippedTextures) === '["map","anisotropyMap","normalMap"]', `skippedTextures (${bare.userData.clothfit.skippedTextures})`);
  check(warnings.length === 1 && /textures not loaded \(map, anisotropyMap, normalMap\)/.test(warnings[0]) && /fetchClothfitPreset\(url\)/.test(warnings[0]), `one warning naming the slots and the loader (${warnings[0]})`);
  check(Math.abs(bare.anisotropy - 0.6) < 1e-12 && bare.side === THREE.DoubleSide, 'the rest of the material as before');
  warnings.length = 0;
  const quiet = loadClothfitPreset(physical, { textures: null });
  check(quiet.map === null && quiet.userData.clothfit.skippedTextures.length === 3 && warnings.length === 0, '{textures: null}: skipped on purpose, no warning');

  // 2. fetchClothfitPreset with a DOM: attached
  globalThis.document = domStub;
  warnings.length = 0;
  const m = await fetchClothfitPreset(`${base}w.three.json`, { maxAnisotropy: 8 });
  for (const [slot, file, cs] of [['map', 'w.basecolor.png', THREE.SRGBColorSpace], ['anisotropyMap', 'w.anisotropy.png', THREE.NoColorSpace], ['normalMap', 'w.normal.png', THREE.NoColorSpace]]) {
    const t = m[slot];
    check(t?.isTexture, `${slot} attached`);
    check(t.image?._src === `${base}${file}`, `${slot}: image ${t.image?._src}`);
    check(t.colorSpace === cs && t.repeat.x === 7 && t.repeat.y === 7 && t.wrapS === THREE.RepeatWrapping && t.minFilter === THREE.LinearMipmapLinearFilter && t.flipY === false, `${slot}: texture settings`);
    check(t.anisotropy === 8, `${slot}: anisotropy clamped to the renderer's max (${t.anisotropy})`);
  }
  check(m.userData.clothfit.skippedTextures === undefined && warnings.length === 0, `nothing skipped, no warning (${warnings})`);

  // 3. the seed's MeshClothMaterial layout with a map
  const seed = { metadata: { version: 4.6, type: 'Material' }, type: 'MeshClothMaterial', color: 0x808080, sheen: 0xffffff, roughness: 0.6,
    map: 'kd-t', images: [physical.images[0]], textures: [physical.textures[0]] };
  fs.writeFileSync(path.join(work, 'seed.meshcloth.json'), JSON.stringify(seed));
  const sm = await fetchClothfitPreset(`${base}seed.meshcloth.json`);
  check(sm.isMeshClothMaterial && sm.map?.image?._src === `${base}w.basecolor.png`, 'MeshClothMaterial layout: map attached');
  warnings.length = 0;
  check(loadClothfitPreset(seed).userData.clothfit.skippedTextures?.[0] === 'map' && warnings.length === 1, 'MeshClothMaterial layout: skipped and said without textures');

  // 4. embedded image data (three.js DataTexture JSON): no DOM needed
  delete globalThis.document;
  const embedded = { ...physical, map: undefined, anisotropyMap: undefined, normalMap: undefined, roughnessMap: 'r-t',
    images: [{ uuid: 'r-i', url: { data: [0, 64, 128, 255], width: 2, height: 2, type: 'Uint8Array' } }],
    textures: [{ ...tex('r-t', 'r-i', '', 'roughness'), format: THREE.RedFormat }] };
  const em = await fetchClothfitPreset(`data:application/json,${encodeURIComponent(JSON.stringify(embedded))}`);
  check(em.roughnessMap?.isDataTexture && em.roughnessMap.image.width === 2 && em.roughnessMap.image.data[3] === 255, 'embedded DataTexture image loaded without a DOM');

  // 5. node without a DOM: PNG textures skipped, said why
  warnings.length = 0;
  const nd = await fetchClothfitPreset(`${base}w.three.json`);
  check(nd.map === null && nd.userData.clothfit.skippedTextures.length === 3, 'no DOM: loaded without the PNG textures');
  check(warnings.length === 1 && /no DOM to decode PNG \/ JPEG images/.test(warnings[0]) && /images\[0\]\.url/.test(warnings[0]), `no DOM: the warning says why (${warnings[0]})`);

  // 6. bad entries refused naming the field (and the JSON's URL)
  globalThis.document = domStub;
  const bad = async (patch, re, what) => {
    const f = `bad-${checks}.three.json`;
    fs.writeFileSync(path.join(work, f), JSON.stringify({ ...physical, ...patch }));
    let msg = '';
    try { await fetchClothfitPreset(`${base}${f}`); } catch (e) { msg = e.message; }
    check(re.test(msg) && msg.startsWith(`${base}${f}: `), `${what}: ${JSON.stringify(msg)}`);
  };
  const img0 = (url) => ({ images: [{ uuid: 'kd-i', url }, ...physical.images.slice(1)] });
  await bad(img0('/etc/passwd'), /images\[0\]\.url: "\/etc\/passwd" must be relative/, 'absolute image URL');
  await bad(img0('http://example.com/x.png'), /images\[0\]\.url: .* must be relative/, 'image URL with a scheme');
  await bad(img0('../x.png'), /images\[0\]\.url: .*escapes/, 'image URL leaving the directory');
  await bad(img0(42), /images\[0\]\.url: expected a URL relative to the JSON/, 'image URL not a string');
  await bad(img0('missing.png'), /images\[0\]\.url: cannot load .*missing\.png/, 'image that does not load');
  await bad({ textures: [{ ...physical.textures[0], image: 'nope' }] }, /textures\[0\]\.image: "?nope"? is not the uuid of an entry of "images"/, 'unknown image uuid');
  await bad({ images: 'x' }, /images: expected an array/, 'images not an array');

  // 7. convert's own output
  if (clothfit) {
    const out = path.join(work, 'convert');
    const r = spawnSync(clothfit, ['--quiet', 'convert', path.join(repo, 'tests', 'data', 'convert_weave', 'aniso.json'), '--to', 'threejs', '--out', out], { encoding: 'utf8' });
    check(r.status === 0, `clothfit convert: ${r.stderr}`);
    const cm = await fetchClothfitPreset(`${base}convert/aniso.three.json`);
    check(cm.map?.image?._src === `${base}convert/aniso.basecolor.png` && cm.anisotropyMap?.image?._src === `${base}convert/aniso.anisotropy.png`, 'convert\'s aniso.three.json: map and anisotropyMap attached');
    check(cm.map.colorSpace === THREE.SRGBColorSpace && cm.anisotropyMap.colorSpace === THREE.NoColorSpace && cm.map.repeat.x === 7, 'convert\'s textures: colour spaces and repeat');
  } else console.log('threejs-json: no --clothfit: convert\'s own output not checked');
} finally {
  server.close();
  fs.rmSync(work, { recursive: true, force: true });
  console.warn = realWarn;
}
console.log(`threejs-json: ${checks} checks passed`);
