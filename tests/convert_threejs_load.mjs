// `clothfit convert` with weave maps (and, since session 27, with carried colour maps), read
// by three.js r187's OWN loaders (docs/convert.md, "Weave maps in glTF and three.js"): GLTFLoader on <stem>.gltf and the documented
// ObjectLoader + MaterialLoader snippet on <stem>.three.json must give the same
// MeshPhysicalMaterial: base colour factor, the two textures (files, repeat = uv_repeats,
// REPEAT, trilinear, colour spaces, flipY false), anisotropy, rotation, sheen, specular.
// Images are not decoded (node has no DOM: a stub image records its url); the texel values
// are checked by tests/test_convert_weave.cpp.
// Usage: node convert_threejs_load.mjs --clothfit BIN --work DIR [--three DIR]
// Exit 0 pass, 1 fail, 77 skipped (no three.js in web/node_modules and no --three).
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '..');
const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const threeDir = args.three ?? path.join(repo, 'web', 'node_modules', 'three');
if (!fs.existsSync(path.join(threeDir, 'package.json'))) {
  console.log(`skipped: no three.js at ${threeDir}`);
  process.exit(77);
}
let failures = 0;
const fail = (msg) => { console.error(`FAIL: ${msg}`); failures++; };
const near = (a, b, tol, what) => { if (!(Math.abs(a - b) <= tol)) fail(`${what}: ${a} vs ${b} (tol ${tol})`); };

// node stubs: ProgressEvent (FileLoader), document.createElementNS (ImageLoader).
globalThis.ProgressEvent = class { constructor(type, o) { this.type = type; Object.assign(this, o); } };
globalThis.self = globalThis;
globalThis.document = { createElementNS: () => ({
  listeners: {}, addEventListener(t, f) { this.listeners[t] = f; }, removeEventListener() {},
  set src(u) { this._src = u; this.width = 16; this.height = 16;
    setTimeout(() => (fs.existsSync(u) ? this.listeners.load : this.listeners.error)?.call(this, {}), 0); },
  get src() { return this._src; } }) };

const THREE = await import(pathToFileURL(path.join(threeDir, 'build', 'three.module.js')).href);
const { GLTFLoader } = await import(pathToFileURL(path.join(threeDir, 'examples', 'jsm', 'loaders', 'GLTFLoader.js')).href);

const work = path.resolve(args.work ?? 'convert-threejs-test');
fs.rmSync(work, { recursive: true, force: true });
fs.mkdirSync(work, { recursive: true });
const out = path.join(work, 'out');
execFileSync(args.clothfit, ['--quiet', 'convert', path.join(repo, 'tests', 'data', 'convert_weave'),
  '--to', 'threejs,gltf', '--out', out], { stdio: 'inherit' });

// glTF through GLTFLoader (one triangle added so that the parser builds the material).
async function loadGltf(gltfFile, dir) {
  const g = JSON.parse(fs.readFileSync(gltfFile, 'utf8'));
  g.buffers = [{ byteLength: 60, uri: 'data:application/octet-stream;base64,' + Buffer.alloc(60).toString('base64') }];
  g.bufferViews = [{ buffer: 0, byteLength: 36 }, { buffer: 0, byteOffset: 36, byteLength: 24 }];
  g.accessors = [{ bufferView: 0, componentType: 5126, count: 3, type: 'VEC3', min: [0, 0, 0], max: [0, 0, 0] },
    { bufferView: 1, componentType: 5126, count: 3, type: 'VEC2' }];
  g.meshes = [{ primitives: [{ attributes: { POSITION: 0, TEXCOORD_0: 1 }, material: 0 }] }];
  g.nodes = [{ mesh: 0 }]; g.scenes = [{ nodes: [0] }]; g.scene = 0;
  return new Promise((resolve, reject) => new GLTFLoader().parse(JSON.stringify(g), dir + '/', (gl) => {
    let m; gl.scene.traverse((o) => { if (o.material) m = o.material; }); resolve(m);
  }, reject));
}
const gltfFile = path.join(out, 'aniso.gltf');
const gm = JSON.parse(fs.readFileSync(gltfFile, 'utf8')).materials[0];
const fromGltf = await loadGltf(gltfFile, out);

// three.json through the snippet of docs/convert.md.
async function loadThreeJson(file, dir) {
  const json = JSON.parse(fs.readFileSync(file, 'utf8'));
  const objects = new THREE.ObjectLoader().setResourcePath(dir + '/');
  const images = await objects.parseImagesAsync(json.images ?? []);
  const textures = objects.parseTextures(json.textures ?? [], images);
  return new THREE.MaterialLoader().setTextures(textures).parse(json);
}
const fromJson = await loadThreeJson(path.join(out, 'aniso.three.json'), out);

const repeats = 7;  // the fixture's uv_repeats
const ext = gm.extensions;
for (const [name, m] of [['GLTFLoader', fromGltf], ['MaterialLoader', fromJson]]) {
  if (m.type !== 'MeshPhysicalMaterial') fail(`${name}: ${m.type}`);
  for (let c = 0; c < 3; ++c) near(m.color.toArray()[c], gm.pbrMetallicRoughness.baseColorFactor[c], 2e-6, `${name} color[${c}]`);
  near(m.anisotropy, ext.KHR_materials_anisotropy.anisotropyStrength, 1e-12, `${name} anisotropy`);
  near(m.anisotropyRotation, ext.KHR_materials_anisotropy.anisotropyRotation, 1e-12, `${name} anisotropyRotation`);
  near(m.roughness, 0.62, 1e-12, `${name} roughness`);
  near(m.sheenRoughness, 0.55, 1e-12, `${name} sheenRoughness`);
  near(m.specularIntensity, 0.7, 1e-12, `${name} specularIntensity`);
  [0.3, 0.25, 0.2].forEach((v, c) => near(m.sheenColor.toArray()[c] * m.sheen, v, 5e-3, `${name} sheenColor[${c}]`));
  [1.0, 0.8, 0.6].forEach((v, c) => near(m.specularColor.toArray()[c], v, 5e-3, `${name} specularColor[${c}]`));
  for (const [slot, file, cs] of [['map', 'aniso.basecolor.png', THREE.SRGBColorSpace], ['anisotropyMap', 'aniso.anisotropy.png', THREE.NoColorSpace]]) {
    const t = m[slot];
    if (!t) { fail(`${name}: no ${slot}`); continue; }
    const src = t.image?._src ?? t.source?.data?._src;
    if (path.resolve(src ?? '') !== path.join(out, file)) fail(`${name} ${slot}: image ${src}, want ${file}`);
    if (t.repeat.x !== repeats || t.repeat.y !== repeats) fail(`${name} ${slot}: repeat ${t.repeat.toArray()}`);
    if (t.offset.x !== 0 || t.offset.y !== 0 || t.rotation !== 0) fail(`${name} ${slot}: offset/rotation`);
    if (t.wrapS !== THREE.RepeatWrapping || t.wrapT !== THREE.RepeatWrapping) fail(`${name} ${slot}: wrap ${t.wrapS},${t.wrapT}`);
    if (t.minFilter !== THREE.LinearMipmapLinearFilter || t.magFilter !== THREE.LinearFilter) fail(`${name} ${slot}: filters ${t.minFilter},${t.magFilter}`);
    if (t.colorSpace !== cs) fail(`${name} ${slot}: colorSpace ${JSON.stringify(t.colorSpace)}`);
    if (t.flipY !== false) fail(`${name} ${slot}: flipY ${t.flipY}`);
    if (t.channel !== 0) fail(`${name} ${slot}: channel ${t.channel}`);
  }
}
// Session 27 audit, item 2: a glTF with base and sheen colour maps (tests/data/convert_maps).
// The three.json must attach both maps (before, they sat in userData only and `color` held
// fitted / mean(map), drawn as near white), on the same files as the glTF output, with the
// glTF output's texture conventions as GLTFLoader sets them: sRGB, flipY false, REPEAT.
const outMaps = path.join(work, 'out_maps');
execFileSync(args.clothfit, ['--quiet', 'convert', path.join(repo, 'tests', 'data', 'convert_maps'),
  '--to', 'threejs,gltf', '--out', outMaps], { stdio: 'inherit' });
const mapsGltf = await loadGltf(path.join(outMaps, 'velvet.gltf'), outMaps);
const mapsJson = await loadThreeJson(path.join(outMaps, 'velvet.three.json'), outMaps);
const mapsData = JSON.parse(fs.readFileSync(path.join(outMaps, 'velvet.three.json'), 'utf8'));
for (const [slot, file] of [['map', 'albedo.png'], ['sheenColorMap', 'sheen.png']]) {
  const want = path.join(repo, 'tests', 'data', 'convert_maps', 'tex', file);
  for (const [name, m] of [['GLTFLoader', mapsGltf], ['MaterialLoader', mapsJson]]) {
    const t = m[slot];
    if (!t) { fail(`maps ${name}: no ${slot}`); continue; }
    const src = t.image?._src ?? t.source?.data?._src;
    if (path.resolve(src ?? '') !== want) fail(`maps ${name} ${slot}: image ${src}, want ${want}`);
    if (t.colorSpace !== THREE.SRGBColorSpace) fail(`maps ${name} ${slot}: colorSpace ${JSON.stringify(t.colorSpace)}`);
    if (t.flipY !== false) fail(`maps ${name} ${slot}: flipY ${t.flipY}`);
    if (t.wrapS !== THREE.RepeatWrapping || t.wrapT !== THREE.RepeatWrapping) fail(`maps ${name} ${slot}: wrap`);
  }
}
// color is the hex the file states (the factor that multiplies the map), not replaced.
if (mapsJson.color.getHex() !== mapsData.color) fail(`maps MaterialLoader color ${mapsJson.color.getHexString()} vs ${mapsData.color.toString(16)}`);

console.log(failures ? `${failures} failure(s)` : 'three.js GLTFLoader and MaterialLoader read both exports alike');
process.exit(failures ? 1 : 0);
