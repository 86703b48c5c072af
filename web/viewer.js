// web/viewer.html: a scene card + a clothfit preset in three.js r187, with orbit controls and
// environment / preset switching. Query: card, preset, presets (comma list), env, sun (auto |
// off | panels: the environment's sun, and with panels its softboxes, as directional lights,
// docs/sun.md; default: the preset's fit.env_sun when it names a mode (a preset fitted with
// `--env-sun panels` is drawn with its panels, as `clothfit evaluate` draws it), else the card's
// environment.sun, else auto), shot (=1: POST the first finished frame as PNG to /shot, for
// web/tools/screenshot.mjs), shadows (1 | 0 | a JSON object of shadow settings; session 13),
// units (N: keep the shadow maps within N texture units, as on such a GPU; session 23).
// Untrusted text (the query string, file names, preset contents, error messages) reaches the page
// only as text (web/viewer-ui.js); errors show their message in the error panel, the stack goes
// to the console (session 27).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { loadSceneCard, fetchClothfitPreset, loadClothfitPreset } from './clothfit.js';
import { fillSelect, showError, clearError, parseShadowsParam, parseUnitsParam, readLocalPreset } from './viewer-ui.js';

const q = new URLSearchParams(location.search);
const CARDS = ['../datasets/scenes/sphere.json', '../datasets/scenes/drape.json', '../datasets/scenes/swatch.json'];
const cardUrl = q.get('card') ?? CARDS[0];
const presets = (q.get('presets') ?? q.get('preset') ?? '../docs/presets/twill-handpicked-cloth.json').split(',');
const presetUrl = q.get('preset') ?? presets[0];
const info = document.getElementById('info');
const errorPanel = document.getElementById('error');
const canvas = document.getElementById('c');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: q.has('shot') });

const base = (u) => u.split('/').pop().replace(/\.json$/, '');

async function main() {
  fillSelect(document.getElementById('card'), CARDS, cardUrl, base);
  fillSelect(document.getElementById('preset'), presets, presetUrl, base);
  // shadows=1: three.js shadow maps with web/clothfit.js's defaults (SHADOW_DEFAULTS); a JSON
  // object overrides fields (?shadows={"type":"pcf","mapSize":4096}); 0: off; absent: the card's
  // visibility.shadows. A bad value names the parameter and the expected form.
  const shadows = parseShadowsParam(q.get('shadows'));
  const units = parseUnitsParam(q.get('units'));
  const names = await fetch('/hdri/index.json').then((r) => (r.ok ? r.json() : [])).catch(() => []);
  fillSelect(document.getElementById('env'), ['card', 'none', ...names.filter((n) => typeof n === 'string')], q.get('env') ?? 'card');
  const sc = await loadSceneCard(cardUrl, { renderer, shadows });
  // units=N: budget the shadow maps as on a GPU with N texture units (docs/web.md "Real GPUs";
  // the budget only: this GPU still links what it can)
  if (units !== null) sc.samplerLimit = units;
  sc.apply(renderer);
  renderer.setSize(Math.max(sc.width, 512), Math.max(sc.width, 512) * sc.height / sc.width);
  sc.camera.aspect = sc.width / sc.height;
  sc.camera.updateProjectionMatrix();
  const controls = new OrbitControls(sc.camera, canvas);
  // Orbit about the fabric's centre.
  const box = new THREE.Box3();
  for (const m of sc.fabricMeshes) box.expandByObject(m);
  box.getCenter(controls.target);
  controls.update();

  let material = null;
  // notes: lines about what the preset lost (a local file's weave maps or textures)
  const setPreset = (m, notes = []) => {
    material?.dispose();
    material = m;
    sc.setMaterial(m);
    const p = m.userData.clothfit;
    infoBase.textContent = `${sc.card.description ?? ''}\nmodel ${p.model}${p.cloth ? ` (${p.cloth.variant}${p.cloth.subsurface ? ', subsurface' : ''})` : ''}: ${JSON.stringify(p.parameters)}\n` +
      // a far-field yarn lobe is summarised (its IBL table is thousands of numbers)
      (p.woven ? `woven options ${JSON.stringify({ ...p.woven, yarn_lobe: undefined })} (ibl ${m.ibl ?? 'split'}${m.ibl === 'fis' ? `, ${m.fisTaps} + ${m.fisDiffuseTaps} taps` : ''})\n` : '') +
      (m.weaveMaps ? `weave maps ${m.weaveMaps.size} x ${m.weaveMaps.size}, uv_repeats ${m.weaveMaps.uvRepeats}, anisotropy ${m.weaveMaps.anisotropy}${m.viewBands ? `, ${m.viewBands} view bands blended by NoV (cosines ${m.weaveMaps.viewCosines.map((c) => c.toFixed(3)).join(' ')})` : ''}\n` : '') +
      (m.yarnLobe ? `far-field yarn lobe: ${m.yarnLobe.fabric || 'fabric not named'}, ${m.yarnLobe.threads
        ? `${m.yarnLobe.model}, ${m.yarnLobe.threads.map((t) => t.offsets.length).join(' + ')} tangents`
        : `${m.yarnLobe.groups.length} yarn groups x ${m.yarnLobe.nodes} nodes`}, IBL table ${m.yarnLobe.ibl.n_theta} x ${m.yarnLobe.ibl.n_phi}\n` : '') +
      (p.skippedTextures && !notes.length ? `textures not loaded: ${p.skippedTextures.join(', ')} (drawn without them; the console says why)\n` : '') +
      notes.map((n) => `${n}\n`).join('') +
      `tone mapping ${sc.card.tone_mapping ?? 'ACESFilmic'}, exposure ${sc.exposure}, three.js r${THREE.REVISION}`;
    showShadowBudget();
  };
  // session 23: the shadow maps kept within this GPU's texture units (web/clothfit.js
  // fitShadowBudget, run by setMaterial and setEnvironment): say which lights lost theirs.
  const infoBase = document.createElement('span'), shadowLine = document.createElement('span');
  info.replaceChildren(infoBase, shadowLine);
  const showShadowBudget = () => {
    const b = sc.shadowBudget;
    shadowLine.textContent = b?.dropped.length ? `\nshadows: no shadow from ${b.dropped.join(', ')} (this GPU: ${b.maxSamplers} texture units; docs/web.md "Real GPUs")` : '';
  };
  // renderer: the weave maps' texture.anisotropy (the preset's weave_maps.anisotropy) is clamped
  // to renderer.capabilities.getMaxAnisotropy(), with a console.info when it is.
  console.info(`viewer: max texture anisotropy ${renderer.capabilities.getMaxAnisotropy()}`);
  setPreset(await fetchClothfitPreset(presetUrl, { renderer }));
  // The sun mode: ?sun, else the preset's fit.env_sun when it names a mode (as `clothfit
  // evaluate` draws a preset: "auto", "off" or "panels"; "card" or absent: the card's), else the
  // card's environment.sun, else auto (docs/sun.md "Where the option lives").
  const fitSun = material?.userData?.clothfit?.fit?.env_sun;
  const cardSun = sc.card.environment?.sun ?? 'auto';
  if (fitSun !== undefined && !['auto', 'off', 'panels', 'card'].includes(fitSun))
    console.warn(`viewer: ${presetUrl}: fit.env_sun ${JSON.stringify(fitSun)} is not "auto", "off", "panels" or "card"; using the card's`);
  let sun = q.get('sun') ?? (['auto', 'off', 'panels'].includes(fitSun) ? fitSun : cardSun);
  let envChoice = q.get('env') ?? 'card';
  const sunSelect = document.getElementById('sun');
  sunSelect.value = sun;
  const setEnv = async (v) => {
    envChoice = v;
    if (v === 'card') { const e = sc.card.environment; await sc.setEnvironment(e?.path ?? null, { intensity: e?.intensity ?? 1, rotationYDegrees: e?.rotation_y_degrees ?? 0, sun }); }
    else if (v === 'none') await sc.setEnvironment(null);
    else await sc.setEnvironment(v, { intensity: sc.card.environment?.intensity ?? 1, sun });
    if (sc.sun) console.info(`viewer: environment ${sc.sun.summary}`);
    sc.panels.forEach((p, k) => console.info(`viewer: environment panel ${k + 1}: ${p.summary}`));
    showShadowBudget();
  };
  if ((q.get('env') ?? 'card') !== 'card' || sun !== cardSun) await setEnv(q.get('env') ?? 'card');

  // The menus and the file picker: a failure shows in the error panel (the page goes on).
  const guarded = (what, fn) => async (e) => {
    try {
      await fn(e);
      clearError(errorPanel);
    } catch (err) {
      showError(errorPanel, err, what(e));
    }
  };
  document.getElementById('card').onchange = (e) => { q.set('card', e.target.value); location.search = q.toString(); };
  document.getElementById('preset').onchange = guarded((e) => `preset ${e.target.value}`, async (e) => setPreset(await fetchClothfitPreset(e.target.value, { renderer })));
  document.getElementById('env').onchange = guarded((e) => `environment ${e.target.value}`, (e) => setEnv(e.target.value));
  sunSelect.onchange = guarded((e) => `sun ${e.target.value}`, (e) => { sun = e.target.value; return setEnv(envChoice); });
  // A local file: read and checked here, its errors shown naming it. It cannot fetch the weave
  // maps or textures it names (files next to it): drawn without them, and the info panel says so
  // and how to see them (serve the folder, ?preset=URL).
  document.getElementById('file').onchange = guarded(() => 'preset file', async (e) => {
    if (!e.target.files[0]) return;
    const { material: m, notes } = await readLocalPreset(e.target.files[0], loadClothfitPreset);
    notes.forEach((n) => console.warn(`viewer: ${n}`));
    setPreset(m, notes);
  });

  let shot = q.has('shot');
  renderer.setAnimationLoop(() => {
    controls.update();
    renderer.render(sc.scene, sc.camera);
    if (shot) {
      shot = false;
      canvas.toBlob((b) => fetch('/shot', { method: 'POST', body: b }), 'image/png');
    }
  });
}
main().catch((e) => {
  showError(errorPanel, e);  // the message in the page, the stack on the console
  fetch('/log', { method: 'POST', body: String(e?.stack ?? e) }).catch(() => {});
});
