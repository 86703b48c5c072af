// clothfit's three.js side (three.js r187, plain ES module, no bundler).
//
//   MeshClothMaterial       the real-time cloth model (brdf/cloth.h): Charlie sheen + Neubelt
//                           visibility + Lambert diffuse, optional wrapped subsurface; variants
//                           'filament' and 'seed-threejs' (the seed thesis, chapter 5).
//   loadClothfitPreset(j)   a clothfit.preset (docs/preset-format.md) -> a three.js material.
//   loadSceneCard(url)      a scene card (docs/scene-card.md) -> {scene, camera, renderer setup}.
//
// Conventions (the toolkit's, docs/preset-format.md and docs/scene-card.md):
//   - preset colours are LINEAR sRGB; they are written into THREE.Color components as they
//     are (THREE.Color stores linear values with ColorManagement on, the r152+ default), never
//     through Color.setHex/setStyle (which would decode sRGB).
//   - roughness is perceptual r; the models square it inside.
//   - environment orientation: three.js equirect (equirectUv), rotation_y_degrees maps to
//     scene.environmentRotation.y (and backgroundRotation.y).
//   - two-sidedness: the fabric material keeps the side that GLTFLoader derived from the glTF
//     material's doubleSided (DoubleSide when true, FrontSide = back faces culled otherwise);
//     a preset's own "side" (written by `clothfit convert --to threejs`) is used when the
//     material is made outside a scene.
//
// The cloth shading is injected into three.js's own MeshStandardMaterial program through
// onBeforeCompile: only the RE_Direct / RE_IndirectDiffuse / RE_IndirectSpecular hooks and the
// roughness set-up are replaced, so lights, shadows, fog, tone mapping, output colour space and
// the PMREM environment lookups (getIBLRadiance / getIBLIrradiance) are three.js's.

import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';
import { HDRLoader } from 'three/addons/loaders/HDRLoader.js';

const HERE = new URL('.', import.meta.url);

// ---------------------------------------------------------------------------------------------
// The cloth DG table: int D_Charlie(alpha = r^2) V_Neubelt cos dl over the hemisphere, the B
// channel of clothfit's DFG LUT (brdf/lut.h), 128 x 128, u = NoV (columns), v = perceptual r
// (rows), texel centres at (i + 0.5)/128. Stored as little-endian float32, row-major (row = r).
// Regenerate with `node web/tools/export-cloth-dg.mjs` (reads clothfit's own table cache).
// Sampled with the same clamp-to-edge bilinear rule as render::Table2D::Sample, in the shader
// with texelFetch (so no float-linear-filtering extension is needed and nothing is rounded to
// fp16).

let clothDGPromise = null;
let clothDGTexture = null;

export function clothDGTable() {
  if (!clothDGPromise) {
    clothDGPromise = fetch(new URL('lut/cloth_dg_128.f32', HERE))
      .then((r) => {
        if (!r.ok) throw new Error(`cloth DG table: HTTP ${r.status}`);
        return r.arrayBuffer();
      })
      .then((buf) => {
        const data = new Float32Array(buf);
        const n = Math.round(Math.sqrt(data.length));
        if (n * n !== data.length) throw new Error('cloth DG table: not square');
        const t = new THREE.DataTexture(data, n, n, THREE.RedFormat, THREE.FloatType);
        t.minFilter = THREE.NearestFilter;
        t.magFilter = THREE.NearestFilter;
        t.generateMipmaps = false;
        t.colorSpace = THREE.NoColorSpace;
        t.needsUpdate = true;
        clothDGTexture = t;
        return t;
      });
  }
  return clothDGPromise;
}

// ---------------------------------------------------------------------------------------------
// GLSL, written from brdf/cloth.h and brdf/terms.h (Estevez & Kulla 2017 Charlie; Neubelt &
// Pettineo 2013 visibility; Filament "Physically Based Rendering", section 4.12.2; the seed
// thesis chapter 5 for the seed variant).

const CLOTH_PARS = /* glsl */ `
uniform vec3 clothSheenColor;
uniform vec3 clothSubsurfaceColor;
uniform float clothSubsurfaceIntensity;
uniform sampler2D clothDG;

float clothDGSample( const in float u, const in float v ) {
	ivec2 n = textureSize( clothDG, 0 );
	vec2 x = clamp( vec2( u, v ) * vec2( n ) - 0.5, vec2( 0.0 ), vec2( n - 1 ) );
	ivec2 i0 = ivec2( floor( x ) );
	ivec2 i1 = min( i0 + 1, n - 1 );
	vec2 f = x - vec2( i0 );
	float a = texelFetch( clothDG, ivec2( i0.x, i0.y ), 0 ).r;
	float b = texelFetch( clothDG, ivec2( i1.x, i0.y ), 0 ).r;
	float c = texelFetch( clothDG, ivec2( i0.x, i1.y ), 0 ).r;
	float d = texelFetch( clothDG, ivec2( i1.x, i1.y ), 0 ).r;
	return mix( mix( a, b, f.x ), mix( c, d, f.x ), f.y );
}

// D(h) = (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi), sin^2 floored at 2^-7 as the engines do.
float clothDCharlie( const in float alpha, const in float NoH ) {
	float invAlpha = 1.0 / alpha;
	float sin2h = max( 1.0 - NoH * NoH, 0.0078125 );
	return ( 2.0 + invAlpha ) * pow( sin2h, invAlpha * 0.5 ) / ( 2.0 * PI );
}

// V = 1 / (4 (NoL + NoV - NoL NoV)); seed (three.js): saturated; Filament mobile: <= 65504.
float clothVNeubelt( const in float NoV, const in float NoL ) {
	float v = 1.0 / max( 4.0 * ( NoL + NoV - NoL * NoV ), 1e-12 );
	#if defined( CLOTH_SEED )
		return min( v, 1.0 );
	#elif defined( CLOTH_MOBILE )
		return min( v, 65504.0 );
	#else
		return v;
	#endif
}

// Energy-conserving wrap without 1/pi: saturate((x + w) / (1 + w)^2).
float clothWrap( const in float x, const in float w ) {
	return saturate( ( x + w ) / ( ( 1.0 + w ) * ( 1.0 + w ) ) );
}

float clothShadingNoV( const in vec3 n, const in vec3 v ) {
	#if defined( CLOTH_SEED )
		return saturate( dot( n, v ) );
	#else
		return clamp( dot( n, v ), 1e-4, 1.0 );
	#endif
}

void RE_Direct_Cloth( const in IncidentLight directLight, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	vec3 l = directLight.direction;
	float nl = dot( geometryNormal, l );
	float NoL = saturate( nl );
	float NoV = clothShadingNoV( geometryNormal, geometryViewDir );
	vec3 h = normalize( l + geometryViewDir );
	float NoH = saturate( dot( geometryNormal, h ) );
	float alpha = material.roughness * material.roughness;
	vec3 Fr = clothSheenColor * ( clothDCharlie( alpha, NoH ) * clothVNeubelt( NoV, NoL ) );
	vec3 E = directLight.color;
	#if defined( CLOTH_SUBSURFACE )
		vec3 sss = saturate( clothSubsurfaceColor + vec3( NoL ) );
		vec3 Fd = material.diffuseColor * RECIPROCAL_PI * clothWrap( nl, 0.5 );
		#if defined( CLOTH_SEED )
			// The seed (thesis listing 5.4): diffuse and sheen are multiplied by three.js's
			// irradiance = saturate(n.l) E; then the accumulated directDiffuse (including the
			// earlier lights') is scaled by saturate(subsurface + n.l).
			reflectedLight.directDiffuse += E * NoL * Fd;
			reflectedLight.directDiffuse *= sss;
			reflectedLight.directSpecular += E * NoL * Fr;
		#else
			// Filament: the wrap carries light past the terminator (n.l < 0).
			reflectedLight.directDiffuse += E * Fd * sss;
			reflectedLight.directSpecular += E * NoL * Fr;
		#endif
	#else
		reflectedLight.directDiffuse += E * NoL * material.diffuseColor * RECIPROCAL_PI;
		reflectedLight.directSpecular += E * NoL * Fr;
	#endif
}

// Ambient / hemisphere / probe lights: Lambert (the cloth's diffuse lobe).
void RE_IndirectDiffuse_Cloth( const in vec3 irradiance, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	reflectedLight.indirectDiffuse += irradiance * material.diffuseColor * RECIPROCAL_PI;
}

// Split sum: E = sheen DG(NoV, r) (seed: DG(NoV, r^2)); specular E x prefiltered radiance
// (three.js's getIBLRadiance at the material roughness: dominant direction mix(R, n, r^4),
// mip = maxLod r (2 - r)); diffuse c (1 - E) [wrap(NoV) saturate(subsurface + NoV)] x E_d where
// E_d = iblIrradiance / pi (three.js r187: the top PMREM level).
void RE_IndirectSpecular_Cloth( const in vec3 radiance, const in vec3 iblIrradiance, const in vec3 clearcoatRadiance, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	float NoV = clothShadingNoV( geometryNormal, geometryViewDir );
	#if defined( CLOTH_SEED )
		float dg = clothDGSample( NoV, material.roughness * material.roughness );
	#else
		float dg = clothDGSample( NoV, material.roughness );
	#endif
	vec3 E = clothSheenColor * dg;
	reflectedLight.indirectSpecular += E * radiance;
	vec3 diffuse = material.diffuseColor * ( vec3( 1.0 ) - E );
	#if defined( CLOTH_SUBSURFACE )
		diffuse *= clothWrap( NoV, clothSubsurfaceIntensity ) * saturate( clothSubsurfaceColor + vec3( NoV ) );
	#endif
	reflectedLight.indirectDiffuse += diffuse * iblIrradiance * RECIPROCAL_PI;
}

#undef RE_Direct
#undef RE_Direct_RectArea
#undef RE_IndirectDiffuse
#undef RE_IndirectSpecular
#define RE_Direct           RE_Direct_Cloth
#define RE_IndirectDiffuse  RE_IndirectDiffuse_Cloth
#define RE_IndirectSpecular RE_IndirectSpecular_Cloth
`;

// After three.js's roughness set-up (which adds geometryRoughness): the cloth clamps the
// perceptual roughness to its engine minimum and, by default, adds no geometry roughness
// (Filament's cloth has no specular anti-aliasing unless enabled; the C++ preview matches).
const CLOTH_ROUGHNESS = /* glsl */ `
#if defined( CLOTH_GEOMETRY_ROUGHNESS )
	material.roughness = min( max( roughnessFactor, CLOTH_MIN_ROUGHNESS ) + geometryRoughness, 1.0 );
#else
	material.roughness = clamp( roughnessFactor, CLOTH_MIN_ROUGHNESS, 1.0 );
#endif
`;

export const ClothVariant = Object.freeze({ FILAMENT: 'filament', SEED: 'seed-threejs' });
export const SheenDefault = Object.freeze({ EXPLICIT: 'explicit', SQRT_BASE_COLOR: 'sqrt-base-color', WHITE: 'white' });

// Engine minimum perceptual roughness (brdf/cloth.h MinRoughness).
export function clothMinRoughness(variant, platform) {
  if (variant === ClothVariant.SEED) return 0.0525;
  return platform === 'mobile' ? 0.089 : 0.045;
}

/**
 * MeshClothMaterial: clothfit's cloth model on three.js's MeshStandardMaterial program.
 *
 * Parameters (besides MeshStandardMaterial's: map, normalMap, side, fog, ...):
 *   color              base colour (linear)
 *   roughness          perceptual r
 *   sheenColor         THREE.Color (linear); used when sheenDefault is 'explicit'
 *   sheenDefault       'explicit' | 'sqrt-base-color' | 'white'
 *   subsurface         boolean; subsurfaceColor THREE.Color (linear)
 *   subsurfaceIntensity  the seed's IBL wrap w (default 0.5; Filament's is fixed at 0.5)
 *   variant            'filament' | 'seed-threejs'
 *   platform           'desktop' | 'mobile' (Filament clamps)
 *   geometryRoughness  add three.js's normal-derivative roughness (default false)
 */
export class MeshClothMaterial extends THREE.MeshStandardMaterial {
  constructor(parameters = {}) {
    const {
      sheenColor, sheenDefault, subsurface, subsurfaceColor, subsurfaceIntensity,
      variant, platform, geometryRoughness, ...standard
    } = parameters;
    super({ metalness: 0, ...standard });
    this.isMeshClothMaterial = true;
    // `type` stays 'MeshStandardMaterial': three.js picks the shader program by type.
    this.sheenColor = sheenColor ? new THREE.Color().copy(sheenColor) : new THREE.Color(1, 1, 1);
    this.sheenDefault = sheenDefault ?? SheenDefault.EXPLICIT;
    this.subsurface = subsurface ?? false;
    this.subsurfaceColor = subsurfaceColor ? new THREE.Color().copy(subsurfaceColor) : new THREE.Color(0, 0, 0);
    this.subsurfaceIntensity = subsurfaceIntensity ?? 0.5;
    this.variant = variant ?? ClothVariant.FILAMENT;
    this.platform = platform ?? 'desktop';
    this.geometryRoughness = geometryRoughness ?? false;
    this._clothUniforms = {
      clothSheenColor: { value: new THREE.Color() },
      clothSubsurfaceColor: { value: new THREE.Color() },
      clothSubsurfaceIntensity: { value: 0.5 },
      clothDG: { value: clothDGTexture },
    };
    if (!clothDGTexture) clothDGTable().then((t) => { this._clothUniforms.clothDG.value = t; this.needsUpdate = true; });
  }

  // The sheen colour the engine uses (brdf/cloth.h EffectiveSheen).
  effectiveSheenColor(target = new THREE.Color()) {
    switch (this.sheenDefault) {
      case SheenDefault.SQRT_BASE_COLOR:
        return target.setRGB(Math.sqrt(this.color.r), Math.sqrt(this.color.g), Math.sqrt(this.color.b));
      case SheenDefault.WHITE: return target.setRGB(1, 1, 1);
      default: return target.copy(this.sheenColor);
    }
  }

  onBeforeRender() {
    const u = this._clothUniforms;
    this.effectiveSheenColor(u.clothSheenColor.value);
    u.clothSubsurfaceColor.value.copy(this.subsurfaceColor);
    u.clothSubsurfaceIntensity.value = this.subsurfaceIntensity;
    u.clothDG.value = clothDGTexture;
  }

  onBeforeCompile(shader) {
    Object.assign(shader.uniforms, this._clothUniforms);
    const defs = [];
    if (this.variant === ClothVariant.SEED) defs.push('#define CLOTH_SEED');
    if (this.platform === 'mobile') defs.push('#define CLOTH_MOBILE');
    if (this.subsurface) defs.push('#define CLOTH_SUBSURFACE');
    if (this.geometryRoughness) defs.push('#define CLOTH_GEOMETRY_ROUGHNESS');
    defs.push(`#define CLOTH_MIN_ROUGHNESS ${clothMinRoughness(this.variant, this.platform).toFixed(6)}`);
    const fs = shader.fragmentShader;
    const pars = '#include <lights_physical_pars_fragment>';
    const setup = '#include <lights_physical_fragment>';
    if (!fs.includes(pars) || !fs.includes(setup)) throw new Error('MeshClothMaterial: unexpected three.js fragment shader (needs r187 chunks)');
    shader.fragmentShader = defs.join('\n') + '\n' +
      fs.replace(pars, pars + '\n' + CLOTH_PARS).replace(setup, setup + '\n' + CLOTH_ROUGHNESS);
  }

  customProgramCacheKey() {
    return ['cloth', this.variant, this.platform, this.subsurface, this.geometryRoughness].join(':');
  }

  copy(source) {
    super.copy(source);
    if (source.isMeshClothMaterial) {
      this.sheenColor.copy(source.sheenColor);
      this.sheenDefault = source.sheenDefault;
      this.subsurface = source.subsurface;
      this.subsurfaceColor.copy(source.subsurfaceColor);
      this.subsurfaceIntensity = source.subsurfaceIntensity;
      this.variant = source.variant;
      this.platform = source.platform;
      this.geometryRoughness = source.geometryRoughness;
    }
    return this;
  }
}

// ---------------------------------------------------------------------------------------------
// Presets (docs/preset-format.md). One factory per model name; parameters not in the preset take
// the model's table default (the kParameterTable of brdf/<model>.h). A model added later (e.g.
// 'woven') registers itself with registerClothfitModel(name, {defaults, make}).

const linear = (rgb) => new THREE.Color(rgb[0], rgb[1], rgb[2]);
const SIDES = { front: THREE.FrontSide, back: THREE.BackSide, double: THREE.DoubleSide };

const MODELS = new Map();

export function registerClothfitModel(name, model) {
  MODELS.set(name, model);
}

export function clothfitModels() { return [...MODELS.keys()]; }

registerClothfitModel('standard', {
  engine: 'three.js r187 MeshStandardMaterial',
  defaults: { base_color: [1, 1, 1], roughness: 1, metalness: 0 },
  make: (p) => new THREE.MeshStandardMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metalness }),
});

registerClothfitModel('physical-sheen', {
  engine: 'three.js r187 MeshPhysicalMaterial (sheen)',
  defaults: { base_color: [1, 1, 1], roughness: 1, metalness: 0, sheen_color: [0, 0, 0], sheen_roughness: 1 },
  // sheen_color is three.js sheenColor x sheen: sheen = 1 keeps USE_SHEEN on.
  make: (p) => new THREE.MeshPhysicalMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metalness,
    sheen: 1, sheenColor: linear(p.sheen_color), sheenRoughness: p.sheen_roughness }),
});

// glTF 2.0 + KHR_materials_sheen: three.js draws it the way GLTFLoader maps the extension, as a
// MeshPhysicalMaterial with sheen (so in three.js it is the physical-sheen model).
registerClothfitModel('gltf-sheen', {
  engine: 'glTF 2.0 + KHR_materials_sheen (drawn by three.js r187 as MeshPhysicalMaterial)',
  defaults: { base_color: [1, 1, 1], roughness: 1, metallic: 0, sheen_color: [0, 0, 0], sheen_roughness: 0 },
  make: (p) => new THREE.MeshPhysicalMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metallic,
    sheen: 1, sheenColor: linear(p.sheen_color), sheenRoughness: p.sheen_roughness }),
});

registerClothfitModel('cloth', {
  engine: 'clothfit MeshClothMaterial (Filament cloth / seed)',
  defaults: { base_color: [1, 1, 1], sheen_color: [1, 1, 1], roughness: 1, subsurface_color: [0, 0, 0] },
  make: (p, preset) => {
    const c = preset.cloth ?? {};
    return new MeshClothMaterial({
      color: linear(p.base_color), roughness: p.roughness, sheenColor: linear(p.sheen_color),
      subsurfaceColor: linear(p.subsurface_color),
      variant: c.variant ?? ClothVariant.FILAMENT,
      sheenDefault: c.sheen_default ?? SheenDefault.EXPLICIT,
      subsurface: c.subsurface ?? false,
      platform: c.platform ?? 'desktop',
    });
  },
});

/**
 * A clothfit preset (object or JSON text) -> a three.js material. Throws on an unknown model or
 * parameter name (as the C++ reader does). The material's userData.clothfit keeps the preset.
 * `side` ('front' | 'back' | 'double' or three.js's 0/1/2) is honoured when present.
 */
export function loadClothfitPreset(json) {
  const preset = typeof json === 'string' ? JSON.parse(json) : json;
  if (preset?.metadata?.type === 'Material') return fromThreejsJson(preset);
  if (preset?.schema !== 'clothfit.preset') throw new Error('loadClothfitPreset: schema is not "clothfit.preset"');
  if (preset.version !== 1) throw new Error(`loadClothfitPreset: version ${preset.version} not supported (1)`);
  const model = MODELS.get(preset.model);
  if (!model) throw new Error(`loadClothfitPreset: unknown model '${preset.model}' (known: ${clothfitModels().join(', ')})`);
  const given = preset.parameters ?? {};
  for (const k of Object.keys(given)) {
    if (!(k in model.defaults)) throw new Error(`loadClothfitPreset: parameters.${k}: unknown for model '${preset.model}' (valid: ${Object.keys(model.defaults).join(', ')})`);
  }
  const p = { ...model.defaults, ...given };
  const m = model.make(p, preset);
  if (preset.side !== undefined) m.side = typeof preset.side === 'number' ? preset.side : SIDES[preset.side];
  m.name = preset.name ?? preset.provenance?.fabric ?? preset.model;
  m.userData.clothfit = preset;
  return m;
}

// `clothfit convert --to threejs` output: three.js MaterialLoader JSON (MeshPhysicalMaterial, read
// by three.js's own MaterialLoader) or the seed's MeshClothMaterial layout (type
// "MeshClothMaterial"; color / sheen / subsurfaceColor are sRGB hex, decoded to linear by
// THREE.Color.setHex as MaterialLoader does; roughness perceptual; the seed variant).
function fromThreejsJson(j) {
  let m;
  if (j.type === 'MeshClothMaterial') {
    m = new MeshClothMaterial({
      color: new THREE.Color().setHex(j.color ?? 0xffffff),
      roughness: j.roughness ?? 1,
      sheenColor: new THREE.Color().setHex(j.sheen ?? 0xffffff),
      sheenDefault: SheenDefault.EXPLICIT,
      subsurface: j.subsurface ?? false,
      subsurfaceColor: new THREE.Color().setHex(j.subsurfaceColor ?? 0x000000),
      variant: ClothVariant.SEED,
    });
    m.name = j.name ?? '';
  } else {
    m = new THREE.MaterialLoader().parse(j);
  }
  if (j.side !== undefined) m.side = j.side;
  m.userData.clothfit = { schema: 'three.js', model: j.type, parameters: {}, source: j };
  return m;
}

export async function fetchClothfitPreset(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return loadClothfitPreset(await r.json());
}

// ---------------------------------------------------------------------------------------------
// Scene cards (docs/scene-card.md, schema version 1).

const TONE_MAPPINGS = {
  Linear: THREE.LinearToneMapping, Reinhard: THREE.ReinhardToneMapping, Cineon: THREE.CineonToneMapping,
  ACESFilmic: THREE.ACESFilmicToneMapping, AgX: THREE.AgXToneMapping, Neutral: THREE.NeutralToneMapping,
};

function resolveRelative(path, base) {
  return new URL(path, base).href;
}

/**
 * Where an environment name or path points: a name ('studio') is looked up under options.hdriBase
 * (default: the viewer server's /hdri/, which serves the data cache) as <name>.exr; a value with
 * '/' or an extension is relative to the card. options.resolvePath(path, cardUrl) overrides both.
 */
export function environmentUrl(path, cardUrl, options = {}) {
  if (options.resolvePath) return options.resolvePath(path, cardUrl);
  if (path.includes('/') || /\.[A-Za-z0-9]+$/.test(path)) return resolveRelative(path, cardUrl);
  return resolveRelative(`${path}.exr`, options.hdriBase ?? new URL('/hdri/', cardUrl).href);
}

const envCache = new Map();
const pmremCache = new WeakMap();  // renderer -> Map(url -> PMREM render target)

// One PMREM per renderer and map (PMREMGenerator.fromEquirectangular), shared by every card.
async function pmremFor(renderer, url) {
  if (!pmremCache.has(renderer)) pmremCache.set(renderer, new Map());
  const m = pmremCache.get(renderer);
  if (!m.has(url)) {
    m.set(url, loadEquirect(url).then((eq) => {
      const gen = new THREE.PMREMGenerator(renderer);
      const target = gen.fromEquirectangular(eq);
      gen.dispose();
      return target;
    }));
  }
  return m.get(url);
}

async function loadEquirect(url) {
  if (!envCache.has(url)) {
    const loader = /\.hdr$/i.test(url) ? new HDRLoader() : new EXRLoader();
    envCache.set(url, loader.loadAsync(url).then((t) => { t.mapping = THREE.EquirectangularReflectionMapping; return t; }));
  }
  return envCache.get(url);
}

/**
 * Load a scene card: returns {card, gltf, scene, camera, fabricMeshes, setMaterial(m),
 * setEnvironment(pathOrNull, {intensity, rotationYDegrees}), apply(renderer), width, height}.
 * Non-fabric meshes are drawn as MeshStandardMaterial with the glTF base colour and roughness 1
 * (metalness 0), which is what the card semantics read; options.keepGltfMaterials keeps them.
 * Needs a renderer for the PMREM: options.renderer.
 */
export async function loadSceneCard(url, options = {}) {
  const cardUrl = new URL(url, document.baseURI).href;
  const r = await fetch(cardUrl);
  if (!r.ok) throw new Error(`${cardUrl}: HTTP ${r.status}`);
  const card = await r.json();
  if (card.version !== 1) throw new Error(`${cardUrl}: version must be 1`);
  const width = card.width ?? 256, height = card.height ?? 256;
  const gltfUrl = options.resolvePath ? options.resolvePath(card.gltf, cardUrl) : resolveRelative(card.gltf, cardUrl);
  const gltf = await new GLTFLoader().loadAsync(gltfUrl);
  const scene = new THREE.Scene();
  scene.add(gltf.scene);
  scene.updateMatrixWorld(true);

  const fabricIndex = card.fabric_material ?? 0;
  const fabricMeshes = [];
  const lightScale = card.light_scale ?? 1;
  scene.traverse((o) => {
    if (o.isLight) o.intensity *= lightScale;
    if (!o.isMesh) return;
    const assoc = gltf.parser.associations.get(o.material);
    const index = assoc?.materials;
    o.userData.gltfMaterial = o.material;
    if (index === fabricIndex) {
      fabricMeshes.push(o);
    } else if (!options.keepGltfMaterials) {
      const src = o.material;
      o.material = new THREE.MeshStandardMaterial({ color: src.color.clone(), roughness: 1, metalness: 0, side: src.side });
    }
  });
  if (fabricMeshes.length === 0) throw new Error(`${cardUrl}: no mesh uses fabric_material ${fabricIndex}`);

  const camIndex = card.camera ?? 0;
  const camera = gltf.cameras[camIndex];
  if (!camera) throw new Error(`${cardUrl}: camera ${camIndex} missing`);
  camera.aspect = width / height;
  camera.updateProjectionMatrix();

  const bg = card.background ?? [0, 0, 0];
  scene.background = new THREE.Color(bg[0], bg[1], bg[2]);

  const out = {
    card, cardUrl, gltf, scene, camera, fabricMeshes, width, height,
    toneMapping: TONE_MAPPINGS[card.tone_mapping ?? 'ACESFilmic'],
    exposure: card.exposure ?? 1,
    environment: null,
    // The fabric's material: keeps the side GLTFLoader derived from the glTF doubleSided.
    setMaterial(m) {
      for (const mesh of fabricMeshes) {
        const mm = fabricMeshes.length > 1 ? m.clone() : m;
        mm.side = mesh.userData.gltfMaterial.side;
        mesh.material = mm;
      }
    },
    async setEnvironment(path, { intensity = 1, rotationYDegrees = 0 } = {}) {
      this.environment = null;
      if (!path) {
        scene.environment = null;
        scene.background = new THREE.Color(bg[0], bg[1], bg[2]);
        return;
      }
      if (path === 'procedural-sky') throw new Error('procedural-sky is not available in the browser');
      const renderer = options.renderer;
      if (!renderer) throw new Error('loadSceneCard: options.renderer is needed for the environment PMREM');
      const url = environmentUrl(path, cardUrl, options);
      const eq = await loadEquirect(url);
      const target = await pmremFor(renderer, url);
      this.environment = target;
      const rot = THREE.MathUtils.degToRad(rotationYDegrees);
      scene.environment = target.texture;
      scene.environmentIntensity = intensity;
      scene.environmentRotation.set(0, rot, 0);
      scene.background = eq;
      scene.backgroundIntensity = intensity;
      scene.backgroundRotation.set(0, rot, 0);
    },
    apply(renderer) {
      renderer.toneMapping = this.toneMapping;
      renderer.toneMappingExposure = this.exposure;
      renderer.outputColorSpace = THREE.SRGBColorSpace;
      renderer.setPixelRatio(1);
    },
  };
  if (card.environment) {
    const e = card.environment;
    await out.setEnvironment(e.path, { intensity: e.intensity ?? 1, rotationYDegrees: e.rotation_y_degrees ?? 0 });
  }
  await clothDGTable();
  return out;
}
