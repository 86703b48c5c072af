// Renders the cases of a plan (?plan=<url>) and POSTs each frame to the test server:
//   POST /result?name=<case>  body: W*H*4 RGBA bytes (top row first, 8-bit sRGB, tone-mapped)
//                             then W*H mask bytes (255 where the fabric is drawn)
//   POST /log   text;   POST /done   when finished (or after an error).
// Paths in the plan and the cards are file-system paths, served by the test server under /fs.
import * as THREE from 'three';
import { loadSceneCard, fetchClothfitPreset, fetchLightMap, applyLightMap } from '../clothfit.js';
import { varyings } from '../tools/gpu-limits/glsl-count.js';

const post = (path, body) => fetch(path, { method: 'POST', body });
const log = (msg) => post('/log', String(msg));
const fsUrl = (p) => (p.startsWith('/') ? `/fs${p}` : p);

// run.mjs --lightmap-mutation M (a check that the light-map cases can fail; never the default):
// 'no-uv-box' drops the offset / repeat, 'flip' reverses the texture's rows (as flipY would).
function mutateLightMap(t, m) {
  if (m === 'no-uv-box') {
    t.offset.set(0, 0); t.repeat.set(1, 1);
  } else if (m === 'flip') {
    const { data, width: w, height: h } = t.image, row = w * 4, tmp = data.slice();
    for (let j = 0; j < h; ++j) data.set(tmp.subarray((h - 1 - j) * row, (h - j) * row), j * row);
    t.needsUpdate = true;
  } else throw new Error(`unknown light-map mutation ${m}`);
}

async function run() {
  const planUrl = new URLSearchParams(location.search).get('plan');
  const plan = await (await fetch(planUrl)).json();
  // The main renderer, and (s23, cases with c.noFloatLinear) a second one on its own canvas
  // whose context hides OES_texture_float_linear, as a GPU without it (iOS Safari, many Android
  // GPUs): 32-bit float textures are then not filterable, and web/clothfit.js must upload its
  // weave maps and light maps as half floats (floatTexturesFilterable). SwiftShader has the
  // extension, so hiding it from getExtension is the only way to see that path here: three.js
  // never enables it, and WebGL then treats linear-filtered float textures as incomplete.
  const makeRenderer = (canvas, hideFloatLinear) => {
    if (hideFloatLinear) {
      const getContext = canvas.getContext.bind(canvas);
      canvas.getContext = (type, attrs) => {
        const ctx = getContext(type, attrs);
        if (ctx && !ctx.clothfitHidden) {
          const ge = ctx.getExtension.bind(ctx), gs = ctx.getSupportedExtensions.bind(ctx);
          ctx.getExtension = (n) => (n === 'OES_texture_float_linear' ? null : ge(n));
          ctx.getSupportedExtensions = () => gs().filter((n) => n !== 'OES_texture_float_linear');
          ctx.clothfitHidden = true;
        }
        return ctx;
      };
    }
    const r = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true, powerPreference: 'high-performance' });
    const g = r.getContext();
    // s23: a GPU with `linkLimit` texture units (cases with c.samplerLimit): as ANGLE does at
    // its MAX_TEXTURE_IMAGE_UNITS, a program with more active samplers fails to link
    // (LINK_STATUS false), so web/clothfit.js's shadow budget meets the failure a real 16-unit
    // GPU gives, not a linked program it can count. SwiftShader itself allows 32.
    const linkStatus = g.getProgramParameter.bind(g);
    const samplerTypes = new Set(['SAMPLER_2D', 'SAMPLER_3D', 'SAMPLER_CUBE', 'SAMPLER_2D_SHADOW', 'SAMPLER_2D_ARRAY', 'SAMPLER_2D_ARRAY_SHADOW',
      'SAMPLER_CUBE_SHADOW', 'INT_SAMPLER_2D', 'INT_SAMPLER_3D', 'INT_SAMPLER_CUBE', 'INT_SAMPLER_2D_ARRAY', 'UNSIGNED_INT_SAMPLER_2D',
      'UNSIGNED_INT_SAMPLER_3D', 'UNSIGNED_INT_SAMPLER_CUBE', 'UNSIGNED_INT_SAMPLER_2D_ARRAY'].map((k) => g[k]));
    // s24: a GPU with `varyingLimit` varying vectors (cases with c.varyingLimit; WebGL2 guarantees
    // 15, SwiftShader allows 31): a program whose fragment shader reads more, packed by the rule
    // of GLSL ES 1.00 Appendix A.7 (web/tools/gpu-limits/glsl-count.js, session 23's audit),
    // fails to link. WebGL has no query for a program's varyings, so web/clothfit.js's budget
    // only sees the failed link.
    const fragmentSource = (prog) => {
      for (const sh of g.getAttachedShaders(prog) ?? []) if (g.getShaderParameter(sh, g.SHADER_TYPE) === g.FRAGMENT_SHADER) return g.getShaderSource(sh);
      return null;
    };
    g.getProgramParameter = (prog, pname) => {
      const v = linkStatus(prog, pname);
      if (pname !== g.LINK_STATUS || !v || (emulated.linkLimit === null && emulated.varyingLimit === null)) return v;
      if (emulated.linkLimit !== null) {
        let n = 0;
        for (let i = 0, k = linkStatus(prog, g.ACTIVE_UNIFORMS); i < k; ++i) {
          const u = g.getActiveUniform(prog, i);
          if (u && samplerTypes.has(u.type)) n += u.size;
        }
        if (n > emulated.linkLimit) { emulated.failures++; return false; }
      }
      if (emulated.varyingLimit !== null) {
        const src = fragmentSource(prog);
        const n = src === null ? 0 : varyings(src).packedVectors;
        emulated.maxVaryings = Math.max(emulated.maxVaryings, n);
        if (n > emulated.varyingLimit) { emulated.failures++; return false; }
      }
      return v;
    };
    // A shader that does not compile is reported through /log (three.js would only console.error).
    r.debug.onShaderError = (gg, program, vs, fs) => {
      log(`shader error: ${gg.getProgramInfoLog(program)}\n${gg.getShaderInfoLog(fs)}\n${gg.getShaderInfoLog(vs)}`.slice(0, 4000));
    };
    log(`WebGL${hideFloatLinear ? ' (OES_texture_float_linear hidden)' : ''}: ${g.getParameter(g.VERSION)} / ${g.getParameter(g.getExtension('WEBGL_debug_renderer_info')?.UNMASKED_RENDERER_WEBGL ?? g.RENDERER)}; OES_texture_float_linear: ${r.extensions.has('OES_texture_float_linear')}; max anisotropy: ${r.capabilities.getMaxAnisotropy()}`);
    return { renderer: r, gl: g };
  };
  const emulated = { linkLimit: null, varyingLimit: null, failures: 0, maxVaryings: 0 };  // see makeRenderer
  const main = makeRenderer(document.getElementById('c'), false);
  let noFloatLinear = null, restoring = null;
  const resolvePath = (p, base) => (p.startsWith('/') ? fsUrl(p) : new URL(p, base).href);
  const cards = new Map();
  let previous = null;  // the last case's material and light map, disposed after the next case
  for (const c of plan.cases) {
    const t0 = performance.now();
    if (c.noFloatLinear && !noFloatLinear) {
      const cv = document.createElement('canvas');
      document.body.appendChild(cv);
      noFloatLinear = makeRenderer(cv, true);
    }
    if (c.contextRestore && !restoring) {  // s23: its own renderer, so the other cases never see a restored context
      const cv = document.createElement('canvas');
      document.body.appendChild(cv);
      restoring = makeRenderer(cv, false);
    }
    const { renderer, gl } = c.noFloatLinear ? noFloatLinear : c.contextRestore ? restoring : main;
    const cardKey = `${c.noFloatLinear ? 'nfl:' : c.contextRestore ? 'ctx:' : ''}${c.card}`;
    let sc = cards.get(cardKey);
    if (!sc) {
      sc = await loadSceneCard(fsUrl(c.card), { renderer, resolvePath: (p, base) => {
        if (!p.includes('/') && !/\.[A-Za-z0-9]+$/.test(p) && base && p !== c.card) return fsUrl(`${plan.hdri_dir}/${p}.exr`);
        return resolvePath(p, base);
      } });
      cards.set(cardKey, sc);
    }
    // fetchClothfitPreset: also fetches a preset's weave maps; their "file" is an absolute
    // file-system path here, served under /fs.
    // renderer: texture.anisotropy of the maps clamped to getMaxAnisotropy() (logged when it is).
    const material = await fetchClothfitPreset(fsUrl(c.preset), { renderer, resolveWeaveMapPath: (file) => fsUrl(file) });
    const wmap = material.userData.clothfit?.weave_maps;
    if (wmap) log(`${c.name}: weave maps ${wmap.file}${wmap.anisotropy ? `, anisotropy ${wmap.anisotropy} (max ${renderer.capabilities.getMaxAnisotropy()})` : ''}${material.viewBands ? `, ${material.viewBands} view bands (${material.weaveMaps.viewCosines.join(' ')}; max texture units ${renderer.capabilities.maxTextures})` : ''}${material.weaveMaps?.weightsTexture ? `, ${material.weaveMaps.weightsTexture.type === THREE.HalfFloatType ? 'half' : '32-bit'} float` : ''}`);
    // s13-lm: the card's light map, baked by the case's own `clothfit render-preview
    // --light-map-out` (c.lightMap, an EXR: irradiance E over the fabric's uv box), on the fabric
    // material only (applyLightMap; the non-fabric meshes get none, as in the preview).
    let lightMap = null;
    if (c.lightMap) {
      lightMap = applyLightMap(material, await fetchLightMap(fsUrl(c.lightMap), { renderer }));
      if (c.lightMapMutation) mutateLightMap(lightMap, c.lightMapMutation);
      const { uvBox, width } = lightMap.userData.clothfit;
      log(`${c.name}: light map ${width}x${width}, uv box ${uvBox.join(' ')}, ${lightMap.type === THREE.HalfFloatType ? 'half' : '32-bit'} float${c.lightMapMutation ? `, MUTATED: ${c.lightMapMutation}` : ''}`);
    }
    sc.samplerLimit = c.samplerLimit ?? null;  // before setMaterial, whose budget check uses it
    emulated.linkLimit = c.samplerLimit ?? null;
    emulated.varyingLimit = c.varyingLimit ?? null;
    emulated.failures = 0;
    emulated.maxVaryings = 0;
    sc.setMaterial(material);
    // Shadow cases (run.mjs SHADOW_CASES, session 13): three.js shadow maps with the case's
    // settings; a case without them leaves the scene as loaded (no shadows).
    if (c.shadows || sc.shadows) sc.setShadows(c.shadows ?? null);
    // s23: a case with c.samplerLimit checks the card's shadow budget at that many texture units
    // (WebGL2's minimum is 16; SwiftShader has 32): web/clothfit.js fitShadowBudget.
    sc.apply(renderer);
    const budget = sc.shadowBudget;
    if (c.varyingLimit) log(`${c.name}: shadow budget ${budget ? `${budget.samplers} of ${budget.maxSamplers} samplers, linked ${budget.linked}, no shadow from: ${budget.dropped.join(', ') || 'none'}` : 'none (no shadows)'}; emulated link failures (programs over ${c.varyingLimit} varying vectors) while fitting: ${emulated.failures}, most varyings seen ${emulated.maxVaryings}`);
    if (c.samplerLimit) log(`${c.name}: shadow budget ${budget ? `${budget.samplers} of ${budget.maxSamplers} samplers, linked ${budget.linked}, no shadow from: ${budget.dropped.join(', ') || 'none'}` : 'none (no shadows)'}; emulated link failures (programs over ${c.samplerLimit} samplers) while fitting: ${emulated.failures}`);
    renderer.setSize(sc.width, sc.height, false);
    if (c.contextRestore) {
      // s23: a WebGL context loss and restore (WEBGL_lose_context; what a mobile browser does to a
      // page in the background) after a first frame; the frame compared is drawn after the
      // restore. three.js re-uploads its own textures but not render targets' contents: before
      // session 23 the environment's PMREMs (web/clothfit.js pmremCacheOf) came back black.
      renderer.render(sc.scene, sc.camera);
      const ext = gl.getExtension('WEBGL_lose_context');
      const canvas = renderer.domElement;
      const lost = new Promise((r) => canvas.addEventListener('webglcontextlost', (e) => { e.preventDefault(); r(); }, { once: true }));
      const restored = new Promise((r) => canvas.addEventListener('webglcontextrestored', () => r(), { once: true }));
      ext.loseContext();
      await lost;
      await new Promise((r) => setTimeout(r, 0));  // Chromium reads defaultPrevented after the event: restore one task later
      ext.restoreContext();
      await restored;
      log(`${c.name}: context lost and restored (isContextLost ${gl.isContextLost()})`);
    }
    renderer.render(sc.scene, sc.camera);
    const W = sc.width, H = sc.height;
    const px = new Uint8Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, px);
    // plan.frames > 0 (run.mjs --frames N): the mean wall time of N more frames of the compiled
    // program, each finished by a 1-pixel readPixels (a GPU sync); a cost figure, not a check.
    let msFrame = '';
    if (plan.frames > 0) {
      const one = new Uint8Array(4);
      const f0 = performance.now();
      for (let f = 0; f < plan.frames; ++f) {
        renderer.render(sc.scene, sc.camera);
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
      }
      msFrame = ((performance.now() - f0) / plan.frames).toFixed(1);
      // s13-lm: a light-map case also times the same material without its light map (compiled
      // first), then with it again, under the same load: "with (without)", with = the mean of
      // the two runs with it.
      if (lightMap) {
        const time = () => {
          renderer.render(sc.scene, sc.camera);
          gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
          const t1 = performance.now();
          for (let f = 0; f < plan.frames; ++f) {
            renderer.render(sc.scene, sc.camera);
            gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, one);
          }
          return (performance.now() - t1) / plan.frames;
        };
        for (const mesh of sc.fabricMeshes) applyLightMap(mesh.material, null);
        const without = time();
        for (const mesh of sc.fabricMeshes) applyLightMap(mesh.material, lightMap);
        const again = time();
        msFrame = `${((Number(msFrame) + again) / 2).toFixed(1)} (${without.toFixed(1)})`;
      }
    }
    // Mask pass: fabric white, everything else black, no tone mapping, same culling.
    const saved = [];
    const white = new THREE.MeshBasicMaterial({ color: 0xffffff });
    const black = new THREE.MeshBasicMaterial({ color: 0x000000 });
    sc.scene.traverse((o) => { if (o.isMesh) { saved.push([o, o.material]); const m = (sc.fabricMeshes.includes(o) ? white : black).clone(); m.side = o.material.side; o.material = m; } });
    const bg = sc.scene.background; sc.scene.background = new THREE.Color(0, 0, 0);
    const tm = renderer.toneMapping; renderer.toneMapping = THREE.NoToneMapping;
    renderer.render(sc.scene, sc.camera);
    const mk = new Uint8Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, mk);
    renderer.toneMapping = tm; sc.scene.background = bg;
    for (const [o, m] of saved) o.material = m;
    // Disposed one case later (s23): a material's program stays in three.js's cache only while a
    // material uses it, so the next case's material (run.mjs orders the plan by preset) reuses it
    // instead of compiling it again. Only the compile time changes: same programs, same frames.
    previous?.material.dispose();
    previous?.lightMap?.dispose();
    previous = { material, lightMap };
    const out = new Uint8Array(W * H * 5);
    for (let y = 0; y < H; ++y) {
      const src = (H - 1 - y) * W;  // readPixels rows are bottom-up
      for (let x = 0; x < W; ++x) {
        for (let k = 0; k < 4; ++k) out[(y * W + x) * 4 + k] = px[(src + x) * 4 + k];
        out[W * H * 4 + y * W + x] = mk[(src + x) * 4] > 127 ? 255 : 0;
      }
    }
    await post(`/result?name=${encodeURIComponent(c.name)}&w=${W}&h=${H}&ms=${(performance.now() - t0).toFixed(0)}&msFrame=${encodeURIComponent(msFrame)}${budget ? `&samplers=${budget.samplers}&maxSamplers=${budget.maxSamplers}&linked=${budget.linked}&dropped=${encodeURIComponent(budget.dropped.join(','))}&why=${encodeURIComponent(budget.why ?? '')}` : ''}`, out);
  }
  await post('/done', 'ok');
}

run().catch(async (e) => { await log(`error: ${e?.stack ?? e}`); await post('/done', 'error'); });
