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
import { parseExr } from './exr.js';
import { detectSun, MAX_PANEL_LIGHTS, parseSunMode, splitEnvironment } from './sun.js';

export { detectSun, parseSunMode, splitEnvironment };

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

// The tables (web/lut/*.f32) sit next to this module. A browser fetches them by URL; node's
// fetch does not read file: URLs ("fetch failed ... not implemented"), so in node a file: URL is
// read from disk (session 27: a MeshClothMaterial made in node crashed the process with that
// unhandled rejection). Errors name the table, the URL and what to serve.
async function loadTableBytes(url, what) {
  if (url.protocol === 'file:' && globalThis.process?.versions?.node) {
    const fsModule = 'node:fs/promises';  // a variable: browser bundlers leave the import alone
    const { readFile } = await import(/* @vite-ignore */ fsModule);
    let buf;
    try {
      buf = await readFile(url);
    } catch (e) {
      throw new Error(`${what}: cannot read ${decodeURIComponent(url.pathname)}: ${e.code ?? e.message} (web/lut/ must stay next to clothfit.js)`);
    }
    return buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength);
  }
  let r;
  try {
    r = await fetch(url);
  } catch (e) {
    throw new Error(`${what}: cannot fetch ${url.href}: ${e.message}${e.cause?.message ? ` (${e.cause.message})` : ''}`);
  }
  if (!r.ok) throw new Error(`${what}: ${url.href}: HTTP ${r.status} (serve web/lut/ next to clothfit.js; docs/web.md "Use it in your own page")`);
  return r.arrayBuffer();
}

// A material's constructor starts the table load without awaiting it: a failure is reported
// once per table on the console (not an unhandled rejection); awaiting clothDGTable() /
// wovenPhaseTable() (loadSceneCard does) still throws it.
const reportedTableErrors = new WeakSet();
function reportTableError(promise) {
  promise.catch((e) => {
    if (reportedTableErrors.has(promise)) return;
    reportedTableErrors.add(promise);
    console.error(`clothfit: ${e.message}; materials that need it do not draw correctly`);
  });
}

export function clothDGTable() {
  if (!clothDGPromise) {
    clothDGPromise = loadTableBytes(new URL('lut/cloth_dg_128.f32', HERE), 'cloth DG table')
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
	#ifdef USE_LIGHTMAP
		// The card's light map (applyLightMap): E_ind joins E_d under the IBL diffuse weight.
		reflectedLight.indirectDiffuse += diffuse * clothfitLightMapIrradiance * RECIPROCAL_PI;
	#endif
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

// Shared by MeshClothMaterial and MeshWovenMaterial: `prefix` (#defines, uniforms) before
// three.js r187's fragment shader, `pars` after its lights_physical_pars_fragment chunk (the
// material's functions and RE_* hooks), `setup` after lights_physical_fragment (after three.js's
// roughness set-up). Throws, naming the material, if those chunks are missing.
function injectPhysicalChunks(shader, who, prefix, pars, setup) {
  const fs = shader.fragmentShader;
  const parsChunk = '#include <lights_physical_pars_fragment>';
  const setupChunk = '#include <lights_physical_fragment>';
  if (!fs.includes(parsChunk) || !fs.includes(setupChunk)) throw new Error(`${who}: unexpected three.js fragment shader (needs r187 chunks)`);
  shader.fragmentShader = prefix +
    fs.replace(parsChunk, parsChunk + '\n' + pars).replace(setupChunk, setupChunk + '\n' + setup);
}

// The light map (material.lightMap, applyLightMap) in MeshClothMaterial and MeshWovenMaterial.
// three.js r187 adds the texel to `irradiance` (lights_fragment_maps), which reaches only
// RE_IndirectDiffuse; these materials' RE_IndirectDiffuse is a plain Lambert for ambient lights,
// while their IBL diffuse (in RE_IndirectSpecular) has the model's own weight (cloth: c (1 - E)
// [wrap]; woven: c kd s y). The C++ preview adds E_ind / pi to E_d under that weight, so here the
// texel goes to the global clothfitLightMapIrradiance instead, which RE_IndirectSpecular_Cloth /
// _Woven add to their E_d. Everything is inside #ifdef USE_LIGHTMAP: without a light map the
// program is the one compiled before. Call after injectPhysicalChunks.
function routeLightMapToIblDiffuse(shader, who) {
  const fs = shader.fragmentShader;
  const parsChunk = '#include <lights_physical_pars_fragment>', mapsChunk = '#include <lights_fragment_maps>';
  const add = 'irradiance += lightMapIrradiance;';
  const maps = THREE.ShaderChunk.lights_fragment_maps;
  if (!fs.includes(parsChunk) || !fs.includes(mapsChunk) || maps.split(add).length !== 2) throw new Error(`${who}: unexpected three.js lights_fragment_maps (the light-map routing needs r187's)`);
  shader.fragmentShader = fs
    .replace(parsChunk, '#ifdef USE_LIGHTMAP\nvec3 clothfitLightMapIrradiance = vec3( 0.0 );\n#endif\n' + parsChunk)
    .replace(mapsChunk, maps.replace(add, 'clothfitLightMapIrradiance += lightMapIrradiance;'));
}

// The horizon fade (MeshWovenMaterial) applies to directional lights only: three.js r187's
// lights_fragment_begin is inlined with wovenDirectional = true around the RE_Direct call of its
// directional-light loop (the flag is declared in WOVEN_PARS), so RE_Direct_Woven can tell a
// directional light from a point or spot light that happens to lie in the same direction.
function markDirectionalLights(shader, who) {
  const fs = shader.fragmentShader, chunkInclude = '#include <lights_fragment_begin>';
  const chunk = THREE.ShaderChunk.lights_fragment_begin;
  const loop = /(getDirectionalLightInfo\( directionalLight, directLight \);)([\s\S]*?)(RE_Direct\( directLight,[^;]*;)/;
  if (!fs.includes(chunkInclude) || chunk.split('getDirectionalLightInfo( directionalLight, directLight );').length !== 2 || !loop.test(chunk)) throw new Error(`${who}: unexpected three.js lights_fragment_begin (the horizon fade needs r187's)`);
  shader.fragmentShader = fs.replace(chunkInclude, () => chunk.replace(loop, '$1\n\t\twovenDirectional = true;$2$3\n\t\twovenDirectional = false;'));
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
    if (!clothDGTexture) {
      clothDGTable().then((t) => { this._clothUniforms.clothDG.value = t; this.needsUpdate = true; }, () => {});
      reportTableError(clothDGPromise);
    }
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
    injectPhysicalChunks(shader, 'MeshClothMaterial', defs.join('\n') + '\n', CLOTH_PARS, CLOTH_ROUGHNESS);
    routeLightMapToIblDiffuse(shader, 'MeshClothMaterial');
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
// MeshWovenMaterial: clothfit's real-time woven-cloth model (brdf/woven.h), uniform or with the
// preset's weave maps (setWeaveMaps; read per fragment into wovenWeaveSample(), see below).
// Written from brdf/woven.h and brdf/terms.h; every clamp and constant is the C++ one:
//   frame: t = the mesh tangent (TANGENT attribute, +u = WARP) Gram-Schmidt'd against the shading
//     normal (after three.js's DoubleSide flip), b = tangent.w (n x t) (+v = WEFT);
//   lobes: warp axes a_w = cos(twist) t + sin(twist) b, c_w = -sin(twist) t + cos(twist) b;
//     weft a_f = c_w, c_f = -a_w; alpha_a = r^2, alpha_c = r^2 + (1 - r^2) s^2;
//     D_GGX_Anisotropic(alpha_c along c, alpha_a along a) x V_SmithGGXCorrelated_Anisotropic;
//   phase Fresnel Fp = f0 + (1 - f0) exp(-2 beta LoH^2); sheen Charlie + Neubelt (no clamp);
//     diffuse base kd / pi x On (Fujii's improved Oren-Nayar, On = A (1 + sigma s / t), sigma =
//     diffuse_roughness; Lambert, On = 1 and the old program, at sigma 0: WOVEN_ROUGH_DIFFUSE);
//     sheen layered by albedo scaling S(mu) = sat(1 - max3(sheen) Es(mu)),
//     Es = the cloth DG table (channel 2 of clothfit's DFG LUT) at (mu, r_s);
//   IBL (split sum): yarn = S ks glint [f0 PT_0 + (1 - f0) PT_beta](NoV, r_e) x radiance at r_e,
//     r_e = (alpha_a alpha_c)^(1/4); sheen = sheen Es(NoV) x radiance at r_s; diffuse =
//     S Y base Eo(NoV) x E_d (E_d = three.js's iblIrradiance / pi; Eo = A (1 + sigma G(NoV)), the
//     directional albedo of On, 1 at sigma 0). PT = web/lut/woven_phase_32.f32, the
//     same table as the C++ lut::DefaultWovenPhase() (web/tools/export-woven-phase.mjs), beta
//     linear between the nodes kWovenPhaseBetas (the node and weight are computed here on the CPU,
//     as woven::PhaseAlbedo does).
//   IBL with the preset's "woven": {"ibl": "fis"}: the yarn lobes' radiance and (fis_diffuse_taps
//     > 0) E_d by filtered importance sampling of the PMREM (wovenFisRadiance /
//     wovenFisIrradianceOverPi below; docs/web.md "Filtered importance sampling").
// No geometryRoughness (as the C++ preview for this model). A mesh without a TANGENT attribute
// gets BufferGeometry.computeTangents() after its first frame (three.js's own, not clothfit's
// generator: a stated difference for such meshes; the canonical glTFs carry TANGENT; see
// onBeforeRender).

export const WOVEN_PHASE_BETAS = Object.freeze([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0]);
const WOVEN_MIN_ROUGHNESS = 0.045, WOVEN_MAX_BETA = 8.0;

let wovenPhasePromise = null;
let wovenPhaseTexture = null;
export function wovenPhaseTable() {
  if (!wovenPhasePromise) {
    wovenPhasePromise = loadTableBytes(new URL('lut/woven_phase_32.f32', HERE), 'woven phase table')
      .then((buf) => {
        const data = new Float32Array(buf);
        const n = 32, ch = WOVEN_PHASE_BETAS.length;
        if (data.length !== n * n * ch) throw new Error(`woven phase table: ${data.length} floats, expected ${n * n * ch}`);
        const t = new THREE.DataTexture(data, n * ch, n, THREE.RedFormat, THREE.FloatType);
        t.minFilter = THREE.NearestFilter;
        t.magFilter = THREE.NearestFilter;
        t.generateMipmaps = false;
        t.colorSpace = THREE.NoColorSpace;
        t.needsUpdate = true;
        wovenPhaseTexture = t;
        return t;
      });
  }
  return wovenPhasePromise;
}

const clamp01 = (x) => Math.min(Math.max(x, 0), 1);

// diffuse_roughness checked as the C++ preset reader checks a parameter (render/scene/material.cpp
// ParseParameter: a finite number in the table's range [0, 1]); `fail(msg)` throws.
export function checkWovenDiffuseRoughness(v, fail) {
  if (typeof v !== 'number') fail(`expected a number, got ${v === null ? 'null' : Array.isArray(v) ? 'array' : typeof v}`);
  if (!Number.isFinite(v)) fail('not finite');
  if (v < 0 || v > 1) fail(`value ${v} outside [0, 1]`);
}

// The rough diffuse's A and A sigma (woven::PrepareOn; sigma = saturate(diffuse_roughness), a
// missing one is 0): On = onA + onB s/t, Eo = onA + onB G. rough: sigma > 0, i.e. not Lambert
// (woven::FrameTerms::lambert; the program then has WOVEN_ROUGH_DIFFUSE).
const WOVEN_ON_ALBEDO_SLOPE = 0.5 - 2 / (3 * Math.PI);  // brdf/woven.h kOnAlbedoSlope
export function wovenOnTerms(diffuseRoughness) {
  const sg = clamp01(diffuseRoughness ?? 0);
  const a = 1 / (1 + WOVEN_ON_ALBEDO_SLOPE * sg);
  return { rough: sg > 0, onA: a, onB: a * sg };
}

// woven::PrepareLobes + the phase node of woven::PhaseAlbedo, on the CPU (per material).
export function wovenLobes(p) {
  const r = Math.min(Math.max(p.roughness, WOVEN_MIN_ROUGHNESS), 1);
  const s = clamp01(p.anisotropy);
  const alphaA = r * r;
  const alphaC = alphaA + (1 - alphaA) * s * s;
  const rho = p.twist * Math.PI / 180;
  const beta = Math.min(Math.max(p.forward_scattering, 0), WOVEN_MAX_BETA);
  const b = WOVEN_PHASE_BETAS;
  let k = 0;
  while (k + 2 < b.length && !(beta < b[k + 1])) ++k;
  const t = clamp01((beta - b[k]) / (b[k + 1] - b[k]));
  return {
    alphaA, alphaC, rE: Math.sqrt(Math.sqrt(alphaA * alphaC)),
    rS: Math.min(Math.max(p.sheen_roughness, WOVEN_MIN_ROUGHNESS), 1),
    cr: Math.cos(rho), sr: Math.sin(rho), f0: clamp01(p.specular_f0), beta, m: clamp01(p.warp_share), s,
    phaseK: k, phaseT: t, ...wovenOnTerms(p.diffuse_roughness),
  };
}

// ---------------------------------------------------------------------------------------------
// The far-field yarn lobe (session 12; a woven preset's "woven": {"yarn_lobe": {...}}, written by
// `clothfit fit --model woven --fabric <irawan fabric>` (--yarn-lobe auto / preset); docs/web.md "The far-field yarn lobe"). The fabric's
// Irawan-Marschner yarn specular averaged over the weave tile by quadrature, per group of
// identical yarns (fit/yarn_farfield.cpp YarnFarField::EvalQuadrature, render/reference/irawan.cpp
// IrawanBsdf::Specular with a band extent, SpineRadius / FilamentRadius), replaces woven's GGX
// yarn lobes: per light ks (tint_w 2 m_w T_w + tint_f 2 m_f T_f) glint s_l, and for the
// environment one PMREM read per lobe at the lobe's tabulated IBL summary (brdf/yarn_table.h
// Table::Ibl). Local frame: x = t (+u, warp), y = b (+v, weft), z = n.
// yarnLobeOptions checks the block (errors name the field), yarnLobeEval is a double-precision
// port of the lobe for node-side tests, yarnLobePack makes the shader's source (yarnLobeGlsl) and
// the IBL texture. Session 19 adds a second model, "sadeghi-microcylinder" (below: the
// microcylinder lobe), in the same two slots, with the same IBL summary and texture.

export const YARN_LOBE_MAX_GROUPS = 16, YARN_LOBE_MAX_NODES = 64;
const YL_DEG = Math.PI / 180;

// Modified Bessel I0 (render/reference/irawan.cpp BesselI0): sum (x^2/4)^k / (k!)^2.
export function besselI0(x) {
  const q = 0.25 * x * x;
  let term = 1, sum = 1;
  for (let k = 1; k < 500; ++k) {
    term *= q / (k * k);
    sum += term;
    if (term < 1e-17 * sum) break;
  }
  return sum;
}

// The yarn spine's radius of curvature at slope |u| (render/reference/irawan.cpp SpineRadius):
// a conic arc chosen by rhat = 1 + kappa (1 + 1/tan umax): circle, ellipse, parabola, hyperbola.
export function yarnSpineRadius(uAbs, umax, kappa, width, length) {
  const a = 0.5 * width;
  const hx = 0.5 * length - a * Math.sin(umax);
  const rhat = kappa === 0 ? 1 : 1 + kappa * (1 + 1 / Math.tan(umax));
  const u = Math.min(uAbs, umax);
  if (Math.abs(rhat - 1) < 1e-12) return hx / Math.sin(umax);
  if (rhat > 1e-9) {
    const tmax = Math.atan(rhat * Math.tan(umax));
    const b = hx / Math.sin(tmax), c = b / rhat;
    const t = Math.atan(rhat * Math.tan(u));
    const ct = Math.cos(t), st = Math.sin(t);
    return Math.pow(b * b * ct * ct + c * c * st * st, 1.5) / (b * c);
  }
  if (rhat > -1e-9) {
    const tu = Math.tan(u);
    return hx / Math.tan(umax) * Math.pow(1 + tu * tu, 1.5);
  }
  const rho = -rhat;
  const smax = Math.atanh(Math.min(rho * Math.tan(umax), 1 - 1e-9));
  const b = hx / Math.sinh(smax), c = b / rho;
  const s = Math.atanh(Math.min(rho * Math.tan(u), 1 - 1e-9));
  const ch = Math.cosh(s), sh = Math.sinh(s);
  return Math.pow(b * b * ch * ch + c * c * sh * sh, 1.5) / (b * c);
}

export function yarnFilamentRadius(uhAbs, umax, ss, kappa, width, length) {
  if (ss <= 0) return yarnSpineRadius(uhAbs, umax, kappa, width, length);
  const umaxS = (1 - ss) * umax;
  return yarnSpineRadius(Math.min(uhAbs, umaxS), umaxS, kappa, width, length);
}

const YARN_LOBE_KEYS = ['model', 'fabric', 'nodes', 'alpha', 'beta', 'h_width', 'ss', 'scale', 'groups', 'ibl'];
const YARN_GROUP_KEYS = ['type', 'share', 'psi', 'umax', 'kappa', 'width', 'length', 'across', 'along', 'area_factor'];

/**
 * A preset's "woven": {"yarn_lobe": {...}} checked; throws naming the field
 * (`woven.yarn_lobe.groups[1].umax: ...`). Returns {model, fabric, nodes, alpha, beta, h_width,
 * ss, scale, groups: [{type, share, psi, umax, kappa, width, length, across, along,
 * area_factor}], ibl: {n_theta, n_phi, summary: Float32Array}} (angles still in degrees); for
 * "model": "sadeghi-microcylinder" (session 19) {model, fabric, threads: [{eta, kd, gamma_s,
 * gamma_v, a, volume_scale, offsets}] x 2, ibl} (microcylinderThreads; the C++ messages).
 */
export function yarnLobeOptions(v, f = 'woven.yarn_lobe') {
  const fail = (field, msg) => { throw new Error(`loadClothfitPreset: ${field}: ${msg}`); };
  const obj = (x, field, keys) => {
    if (x === null || typeof x !== 'object' || Array.isArray(x)) fail(field, 'expected an object');
    for (const k of Object.keys(x)) if (!keys.includes(k)) fail(`${field}.${ylKeyShown(k)}`, `unknown key (valid: ${keys.join(', ')})`);
    for (const k of keys) if (x[k] === undefined && k !== 'fabric') fail(`${field}.${k}`, 'missing');
  };
  const num = (x, field, ok = () => true, range = '') => {
    if (typeof x !== 'number') fail(field, 'expected a number');
    if (!Number.isFinite(x)) fail(field, 'not finite');
    if (!ok(x)) fail(field, `must be ${range}`);
    return x;
  };
  const int = (x, field, lo, hi) => {
    if (typeof x !== 'number' || !Number.isInteger(x)) fail(field, 'expected an integer');
    if (x < lo || x > hi) fail(field, `must be in [${lo}, ${hi}]`);
    return x;
  };
  // the model first (it decides the keys), as the C++ reader
  if (v === null || typeof v !== 'object' || Array.isArray(v)) fail(f, 'expected an object');
  if (v.model === undefined) fail(`${f}.model`, 'missing');
  if (v.model !== 'irawan-far-field' && v.model !== MICROCYLINDER_MODEL) fail(`${f}.model`, `expected "irawan-far-field" or "${MICROCYLINDER_MODEL}"`);
  if (v.model === MICROCYLINDER_MODEL) {
    obj(v, f, MICROCYLINDER_KEYS);
    if (v.fabric !== undefined && typeof v.fabric !== 'string') fail(`${f}.fabric`, 'expected a string');
    return { model: v.model, fabric: v.fabric ?? '', threads: microcylinderThreads(v.threads, `${f}.threads`, fail, obj), ibl: yarnLobeIblOptions(v.ibl, `${f}.ibl`, fail, obj, int) };
  }
  obj(v, f, YARN_LOBE_KEYS);
  if (v.fabric !== undefined && typeof v.fabric !== 'string') fail(`${f}.fabric`, 'expected a string');
  const out = {
    model: v.model, fabric: v.fabric ?? '',
    nodes: int(v.nodes, `${f}.nodes`, 1, YARN_LOBE_MAX_NODES),
    alpha: num(v.alpha, `${f}.alpha`, (x) => x >= 0, '>= 0'),
    beta: num(v.beta, `${f}.beta`, (x) => x >= 0, '>= 0'),
    h_width: num(v.h_width, `${f}.h_width`, (x) => x > 0 && x <= 1, 'in (0, 1]'),
    ss: num(v.ss, `${f}.ss`, (x) => x >= 0 && x < 1, 'in [0, 1)'),
    scale: num(v.scale, `${f}.scale`, (x) => x >= 0, '>= 0'),
  };
  if (!Array.isArray(v.groups)) fail(`${f}.groups`, 'expected an array');
  if (v.groups.length < 1 || v.groups.length > YARN_LOBE_MAX_GROUPS) fail(`${f}.groups`, `${v.groups.length} groups, expected 1 to ${YARN_LOBE_MAX_GROUPS}`);
  out.groups = v.groups.map((g, i) => {
    const gf = `${f}.groups[${i}]`;
    obj(g, gf, YARN_GROUP_KEYS);
    if (g.type !== 'warp' && g.type !== 'weft') fail(`${gf}.type`, 'expected "warp" or "weft"');
    const pos = (k) => num(g[k], `${gf}.${k}`, (x) => x > 0 && x <= 1e6, 'in (0, 1e6]');
    const q = {
      type: g.type,
      share: num(g.share, `${gf}.share`, (x) => x > 0 && x <= 1, 'in (0, 1]'),
      psi: num(g.psi, `${gf}.psi`, (x) => Math.abs(x) < 90, 'in (-90, 90) degrees'),
      umax: num(g.umax, `${gf}.umax`, (x) => x > 0 && x < 90, 'in (0, 90) degrees'),
      kappa: num(g.kappa, `${gf}.kappa`, (x) => x >= -1 && x <= 1e6, 'in [-1, 1e6]'),
      width: pos('width'), length: pos('length'), across: pos('across'), along: pos('along'),
      area_factor: num(g.area_factor, `${gf}.area_factor`, (x) => x >= 1 && x <= 1e6, 'in [1, 1e6]'),
    };
    if (!(q.width * Math.sin(q.umax * YL_DEG) < q.length)) fail(`${gf}.umax`, 'width sin(umax) must be < length');
    return q;
  });
  out.ibl = yarnLobeIblOptions(v.ibl, `${f}.ibl`, fail, obj, int);
  return out;
}

// The lobe's "ibl" block (both models; brdf/yarn_table.h Table): n_theta in [2, 64], n_phi in
// [3, 128], 2 x n_theta x n_phi x 5 finite summary numbers (|x| <= 1e30), as a Float32Array.
function yarnLobeIblOptions(ibl, f, fail, obj, int) {
  obj(ibl, f, ['n_theta', 'n_phi', 'summary']);
  const nt = int(ibl.n_theta, `${f}.n_theta`, 2, 64), np = int(ibl.n_phi, `${f}.n_phi`, 3, 128);
  const want = 2 * nt * np * 5;
  if (!Array.isArray(ibl.summary) && !(ibl.summary instanceof Float32Array)) fail(`${f}.summary`, 'expected an array');
  if (ibl.summary.length !== want) fail(`${f}.summary`, `${ibl.summary.length} numbers, expected 2 x n_theta x n_phi x 5 = ${want}`);
  const summary = new Float32Array(want);
  ibl.summary.forEach((x, i) => {
    if (typeof x !== 'number') fail(`${f}.summary[${i}]`, 'expected a number');
    if (!Number.isFinite(x)) fail(`${f}.summary[${i}]`, 'not finite');
    if (Math.abs(x) > 1e30) fail(`${f}.summary[${i}]`, 'out of float range');
    summary[i] = x;
  });
  return { n_theta: nt, n_phi: np, summary };
}

// A key of the preset shown in an error: as it is when it is a plain identifier, else
// JSON-quoted and cut to 40 characters (no control character, quote or markup reaches the
// message unescaped).
function ylKeyShown(k) {
  if (/^[A-Za-z0-9_]{1,40}$/.test(k)) return k;
  // markup, DEL and the C1 controls, the line / paragraph separators and the bidirectional
  // overrides as \u escapes (JSON.stringify escapes only the C0 controls and quotes)
  const q = JSON.stringify(k.slice(0, 40)).replace(/[<>&\u007f-\u009f\u2028\u2029\u202a-\u202e\u2066-\u2069]/g, (c) => `\\u${c.charCodeAt(0).toString(16).padStart(4, '0')}`);
  return k.length > 40 ? `${q}...` : q;
}

const ylSmoothStep01 = (x) => { const c = clamp01(x); return c * c * (3 - 2 * c); };
const ylSeeliger = (cos1, cos2) => {
  const c1 = Math.max(0, cos1), c2 = Math.max(0, cos2);
  if (c1 <= 0 || c2 <= 0) return 0;
  return (1 / (4 * Math.PI)) * c1 * c2 / (c1 + c2);
};
const ylBandMean = (c, delta, e) => Math.max(Math.min(c + 0.5 * delta, e) - Math.max(c - 0.5 * delta, -e), 0) / (2 * e);
const ylToYarn = (d, weft) => (weft ? [-d[0], -d[1], d[2]] : [-d[1], d[0], d[2]]);

/**
 * The far-field lobe [T_warp, T_weft] at local unit directions wo, wi ([x, y, z] in the frame
 * t, b, n), in double precision: yarnLobeOptions' result `lobe`. Zero unless wo.z, wi.z > 0.
 * The shader evaluates the same (wovenYarnLobe), in float.
 */
export function yarnLobeEval(lobe, wo, wi) {
  if (lobe.model === MICROCYLINDER_MODEL) return microcylinderEvalSplit(lobe, wo, wi);
  const T = [0, 0];
  if (!(wo[2] > 0) || !(wi[2] > 0)) return T;
  const N = lobe.nodes, vmNorm = 1 / (2 * Math.PI * besselI0(Math.abs(lobe.beta)));
  for (const g of lobe.groups) {
    const weft = g.type === 'weft';
    const o = ylToYarn(wo, weft), i = ylToYarn(wi, weft);
    const sum = [i[0] + o[0], i[1] + o[1], i[2] + o[2]];
    const len = Math.hypot(sum[0], sum[1], sum[2]);
    if (!(len > 1e-12)) continue;
    const h = sum.map((x) => x / len);
    const umax = g.umax * YL_DEG, w = g.width, l = g.length, a = 0.5 * w;
    const fc = lobe.alpha + Math.exp(lobe.beta * -(i[0] * o[0] + i[1] * o[1] + i[2] * o[2])) * vmNorm;
    let s = 0;
    for (let j = 0; j < N; ++j) {
      const sj = -1 + (2 * j + 1) / N;
      if (g.psi === 0) {
        const q = h[1] / h[2], uh = Math.atan(q);
        if (!(Math.abs(uh) < umax)) break;
        const delta = l * lobe.h_width;
        const yh = Math.min(Math.max(uh / umax * 0.5 * l, -0.5 * (l - delta)), 0.5 * (l - delta));
        const cuh = 1 / Math.sqrt(1 + q * q), suh = q * cuh;
        const v = Math.min(Math.max(sj * g.across * Math.PI / w, -0.5 * Math.PI), 0.5 * Math.PI);
        const sv = Math.sin(v), cv = Math.cos(v);
        const n = [sv, suh * cv, cuh * cv];
        const R = yarnFilamentRadius(Math.abs(uh), umax, lobe.ss, g.kappa, w, l);
        const txh = cuh * h[2] + suh * h[1];
        const G = a * (R + a * cv) / (len * Math.abs(txh));
        let A = ylSeeliger(n[0] * i[0] + n[1] * i[1] + n[2] * i[2], n[0] * o[0] + n[1] * o[1] + n[2] * o[2]);
        if (lobe.ss > 0) A *= 1 - ylSmoothStep01((Math.abs(uh) - (1 - lobe.ss) * umax) / (lobe.ss * umax));
        s += G * fc * A * Math.PI * l / delta * ylBandMean(yh, delta, g.along);
      } else {
        const psi = g.psi * YL_DEG;
        const u = Math.min(Math.max(sj * g.along / (0.5 * l) * umax, -umax), umax);
        const su = Math.sin(u), cu = Math.cos(u);
        const R = yarnSpineRadius(Math.abs(u), umax, g.kappa, w, l);
        const bterm = h[1] * su + h[2] * cu;
        const r = Math.sqrt(h[0] * h[0] + bterm * bterm);
        const D = (h[1] * cu - h[2] * su) / (r * Math.tan(psi));
        if (!(Math.abs(D) < 1)) continue;
        const ca = h[0] / r, sa = -bterm / r, sb = Math.sqrt(1 - D * D);
        const cvh = ca * D - sa * sb, svh = sa * D + ca * sb;
        const vh = Math.atan2(svh, cvh);
        if (!(Math.abs(vh) < 0.5 * Math.PI)) continue;
        const delta = w * lobe.h_width;
        const xh = Math.min(Math.max(vh * w / Math.PI, -0.5 * (w - delta)), 0.5 * (w - delta));
        const n = [svh, su * cvh, cu * cvh];
        const NoH = n[0] * h[0] + n[1] * h[1] + n[2] * h[2];
        if (!(NoH > 0)) continue;
        const G = a * (R + a * cvh) / (len * NoH * Math.abs(Math.sin(psi)));
        const A = ylSeeliger(n[0] * i[0] + n[1] * i[1] + n[2] * i[2], n[0] * o[0] + n[1] * o[1] + n[2] * o[2]);
        s += G * fc * A * 2 * w * umax / delta * ylBandMean(xh, delta, g.across);
      }
    }
    T[weft ? 1 : 0] += g.share * g.area_factor * lobe.scale * s / N;
  }
  return T;
}

/**
 * The lobes' IBL summary at wo (brdf/yarn_table.h Table::Ibl): [{albedo, dir: [x, y, z],
 * roughness}] for warp and weft, bilinear in (theta, phi) of wo, phi periodic.
 */
export function yarnLobeIbl(lobe, woIn) {
  const { n_theta: nt, n_phi: np, summary } = lobe.ibl;
  const wo = [woIn[0], woIn[1], Math.max(woIn[2], 1e-4)];
  const th = Math.acos(Math.min(Math.max(wo[2], -1), 1));
  let ph = Math.atan2(wo[1], wo[0]);
  if (ph < 0) ph += 2 * Math.PI;
  const u = Math.min(Math.max(th / (0.5 * Math.PI) * nt - 0.5, 0), nt - 1);
  const t0 = Math.min(Math.trunc(u), nt - 2), ft = u - t0;
  let v = ph / (2 * Math.PI) * np - 0.5;
  if (v < 0) v += np;
  const p0 = Math.min(Math.trunc(v), np - 1), fp = v - p0, p1 = (p0 + 1) % np;
  return [0, 1].map((k) => {
    const e = [0, 0, 0, 0, 0];
    for (const [t, wt] of [[t0, 1 - ft], [t0 + 1, ft]]) {
      for (const [p, wp] of [[p0, 1 - fp], [p1, fp]]) {
        for (let c = 0; c < 5; ++c) e[c] += wt * wp * summary[((k * nt + t) * np + p) * 5 + c];
      }
    }
    const d = Math.hypot(e[1], e[2], e[3]);
    return { albedo: Math.max(e[0], 0), dir: d > 1e-12 ? [e[1] / d, e[2] / d, e[3] / d] : [0, 0, 1], roughness: clamp01(e[4]) };
  });
}

// A float constant for generated GLSL: the double rounded to float once (Math.fround), printed
// as the shortest decimal that reads back as that float (so the shader's constant is exactly
// the float a Float32Array would have held), with a '.0' when it would read as an int.
const ylFloat = (x) => { const s = String(Math.fround(x)); return /[.e]/.test(s) ? s : `${s}.0`; };

// A 64-bit FNV-1a-style digest of a string (two 32-bit lanes, hex): the program key of a
// generated lobe, so a preset with other constants compiles its own program.
function ylDigest(s) {
  let a = 0x811c9dc5, b = 0x9e3779b9;
  for (let k = 0; k < s.length; ++k) {
    const c = s.charCodeAt(k);
    a = Math.imul(a ^ c, 0x01000193);
    b = Math.imul(b ^ c, 0x5bd1e995);
    b ^= b >>> 13;
  }
  return (a >>> 0).toString(16).padStart(8, '0') + (b >>> 0).toString(16).padStart(8, '0');
}

// wovenYarnLobe(wo, wi) of one lobe as GLSL, every per-lobe number a compile-time constant
// (session 16: the per-light quadrature was 7-10x cloth's frame cost in SwiftShader). The same
// value as yarnLobeEval (the terms of fit/yarn_farfield.cpp EvalQuadrature) in float, with the
// algebra rearranged where it is the same in exact arithmetic:
//   - per yarn type (all warp groups share the yarn frame) H = wi_s + wo_s, NOT normalised:
//     every staple term is homogeneous in H (with h = H / |H|, |H| = len): bt = |H| (h.y su +
//     h.z cu), r2 = |H|^2 r^2, p = |H| r D, q = sqrt(r2 - p^2) = |H| r sqrt(1 - D^2) = len NoH
//     (NoH = n . h = r sqrt(1 - D^2) identically), cos v_h = (H.x p + bt q) / r2, sin v_h =
//     (H.x q - bt p) / r2; so G = a (R + a cos v_h) / (q |sin psi|), no atan, one sqrt;
//   - |v_h| < pi / 2 is cos v_h > 0, |D| < 1 and NoH > 0 are r2 - p^2 > 0 (and r > 0);
//   - the band mean: |x_h| <= (w - delta) / 2, so when the extent e >= w / 2 the band
//     [x_h - delta/2, x_h + delta/2] lies inside [-e, e] and its mean is delta / (2 e) for every
//     x_h: a constant, and v_h (its atan) is not needed (every fitted canvas / twill group:
//     across = w / 2); otherwise v_h = atan(sin, cos) and the band as before;
//   - the node-independent factors (the weight, a / |sin psi|, 1 / 4pi, the phase fc, a
//     constant band; the filament's 1 / (len |t . h|), smoothing and band) multiply the sum of
//     the nodes once per group; each node is a helper call with its sin, cos and SpineRadius
//     as literals (inlined and folded by the compiler: no texture, no loop).
// Conditions select (no early continue), so the quad's lanes stay converged.
export function yarnLobeGlsl(lobe) {
  const F = ylFloat, N = lobe.nodes, inv4pi = 1 / (4 * Math.PI);
  const vmNorm = 1 / (2 * Math.PI * besselI0(Math.abs(lobe.beta)));
  const L = [
    `// generated by yarnLobeGlsl: ${lobe.groups.length} groups x ${N} nodes`,
    'vec2 wovenYarnLobe( const in vec3 wo, const in vec3 wi ) {',
    '\tvec2 T = vec2( 0.0 );',
    '\tif ( !( wo.z > 0.0 ) || !( wi.z > 0.0 ) ) return T;',
    `\tfloat fc = ${F(lobe.alpha)} + exp( ${F(lobe.beta)} * -dot( wi, wo ) ) * ${F(vmNorm)};`,
  ];
  for (const weft of [false, true]) {
    const groups = lobe.groups.map((g, k) => ({ g, k })).filter(({ g }) => (g.type === 'weft') === weft);
    if (!groups.length) continue;
    L.push(`\t{  // ${weft ? 'weft' : 'warp'}: the yarn frame ${weft ? '(-x, -y, z)' : '(-y, x, z)'}`,
      weft ? '\t\tvec3 o = vec3( -wo.x, -wo.y, wo.z ), i = vec3( -wi.x, -wi.y, wi.z );'
        : '\t\tvec3 o = vec3( -wo.y, wo.x, wo.z ), i = vec3( -wi.y, wi.x, wi.z );',
      '\t\tvec3 H = i + o;  // |H| h',
      '\t\tfloat t = 0.0;',
      '\t\tif ( dot( H, H ) > 1e-24 ) {');
    for (const { g, k } of groups) {
      const staple = g.psi !== 0, umax = g.umax * YL_DEG, w = g.width, l = g.length, a = 0.5 * w;
      const delta = (staple ? w : l) * lobe.h_width, e = staple ? g.across : g.along;
      const gain = staple ? 2 * w * umax / delta : Math.PI * l / delta;
      const weight = g.share * g.area_factor * lobe.scale / N * gain * inv4pi * a;  // x the sum
      const xmax = 0.5 * ((staple ? w : l) - delta);
      const band = (c) => `wovenYlBand( ${c}, ${F(delta)}, ${F(e)} )`;
      L.push(`\t\t\t{  // group ${k}: ${staple ? 'staple' : 'filament'}, psi ${g.psi}, umax ${g.umax}, w ${w}, l ${l}`);
      if (staple) {
        const psi = g.psi * YL_DEG, constBand = 0.5 * w <= e;
        const args = (j) => {
          const u = Math.min(Math.max((-1 + (2 * j + 1) / N) * g.along / (0.5 * l) * umax, -umax), umax);
          const R = yarnSpineRadius(Math.abs(u), umax, g.kappa, w, l);
          return `H, i, o, ${F(Math.sin(u))}, ${F(Math.cos(u))}, ${F(R)}, ${F(a)}, ${F(1 / Math.tan(psi))}`
            + (constBand ? '' : `, ${F(w / Math.PI)}, ${F(xmax)}, ${F(delta)}, ${F(e)}`);
        };
        L.push('\t\t\t\tfloat s = 0.0;');
        for (let j = 0; j < N; ++j) L.push(`\t\t\t\ts += ${constBand ? 'wovenYlStaple' : 'wovenYlStapleBand'}( ${args(j)} );`);
        const K = weight / Math.abs(Math.sin(psi)) * (constBand ? delta / (2 * e) : 1);
        L.push(`\t\t\t\tt += ${F(K)} * s;`);
      } else {
        const umaxS = lobe.ss > 0 ? (1 - lobe.ss) * umax : umax;
        const pk = yarnLobeRadiusConic(g.kappa, umaxS, w, l);
        L.push('\t\t\t\tfloat qy = H.y / H.z, uh = atan( qy );',
          `\t\t\t\tif ( abs( uh ) < ${F(umax)} ) {`,
          '\t\t\t\t\tfloat cuh = inversesqrt( 1.0 + qy * qy ), suh = qy * cuh;',
          `\t\t\t\t\tfloat R = wovenYlRadius( vec4( ${pk.map(F).join(', ')} ), ${F(umaxS)}, abs( uh ) );`,
          '\t\t\t\t\tfloat bi = suh * i.y + cuh * i.z, bo = suh * o.y + cuh * o.z, s = 0.0;');
        for (let j = 0; j < N; ++j) {
          const v = Math.min(Math.max((-1 + (2 * j + 1) / N) * g.across * Math.PI / w, -0.5 * Math.PI), 0.5 * Math.PI);
          L.push(`\t\t\t\t\ts += wovenYlFilament( i.x, bi, o.x, bo, ${F(Math.sin(v))}, ${F(Math.cos(v))}, R, ${F(a)} );`);
        }
        const smooth = lobe.ss > 0
          ? ` * ( 1.0 - smoothstep( 0.0, 1.0, ( abs( uh ) - ${F((1 - lobe.ss) * umax)} ) * ${F(1 / (lobe.ss * umax))} ) )` : '';
        // len |t . h| = |cuh H.z + suh H.y|
        L.push(`\t\t\t\t\tt += ${F(weight)} * s${smooth} * ${band(`clamp( uh * ${F(0.5 * l / umax)}, ${F(-xmax)}, ${F(xmax)} )`)} / abs( cuh * H.z + suh * H.y );`,
          '\t\t\t\t}');
      }
      L.push('\t\t\t}');
    }
    L.push('\t\t}', `\t\tT.${weft ? 'y' : 'x'} = fc * t;`, '\t}');
  }
  L.push('\treturn T;', '}', '');
  return L.join('\n');
}

// The filament's SpineRadius(., umax_s, kappa, w, l) as (branch, p0, p1, rhat) for
// wovenYlRadius (yarnSpineRadius, same guards): 0 circle R = p0; 1 ellipse (b, c); 2 parabola
// p0 = hx / tan umax_s; 3 hyperbola (b, c).
function yarnLobeRadiusConic(kappa, umaxS, w, l) {
  const hx = 0.5 * l - 0.5 * w * Math.sin(umaxS);
  const rhat = kappa === 0 ? 1 : 1 + kappa * (1 + 1 / Math.tan(umaxS));
  if (Math.abs(rhat - 1) < 1e-12) return [0, hx / Math.sin(umaxS), 0, rhat];
  if (rhat > 1e-9) {
    const b = hx / Math.sin(Math.atan(rhat * Math.tan(umaxS)));
    return [1, b, b / rhat, rhat];
  }
  if (rhat > -1e-9) return [2, hx / Math.tan(umaxS), 0, rhat];
  const b = hx / Math.sinh(Math.atanh(Math.min(-rhat * Math.tan(umaxS), 1 - 1e-9)));
  return [3, b, b / -rhat, rhat];
}

// The shader side of a lobe: wovenYarnLobe's source (yarnLobeGlsl, or microcylinderGlsl) and
// its digest for the program key, and the IBL summary as an RGBA32F texture, 2 n_phi x 2 n_theta: texel (2 p,
// k n_theta + t) = entries 0..3 of (lobe k, theta bin t, phi bin p), texel (2 p + 1, ...) =
// (entry 4, 0, 0, 0), read with texelFetch (no filtering, no float-linear extension).
export function yarnLobePack(lobe) {
  const micro = lobe.model === MICROCYLINDER_MODEL;
  const glsl = micro ? microcylinderGlsl(lobe) : yarnLobeGlsl(lobe);
  const { n_theta: nt, n_phi: np, summary } = lobe.ibl;
  const ibl = new Float32Array(2 * np * 2 * nt * 4);
  for (let k = 0; k < 2; ++k) {
    for (let t = 0; t < nt; ++t) {
      for (let p = 0; p < np; ++p) {
        const e = ((k * nt + t) * np + p) * 5, row = k * nt + t, o = (row * 2 * np + 2 * p) * 4;
        for (let c = 0; c < 4; ++c) ibl[o + c] = summary[e + c];
        ibl[o + 4] = summary[e + 4];
      }
    }
  }
  const t = new THREE.DataTexture(ibl, 2 * np, 2 * nt, THREE.RGBAFormat, THREE.FloatType);
  t.minFilter = THREE.NearestFilter; t.magFilter = THREE.NearestFilter;
  t.generateMipmaps = false; t.flipY = false; t.colorSpace = THREE.NoColorSpace;
  t.needsUpdate = true;
  // the program key's lobe part: groups x nodes (Irawan), -mc and the tangent calls (microcylinder)
  const shape = micro ? `-mc${(glsl.match(/^\twovenMcTangent\( /gm) ?? []).length}` : `${lobe.groups.length}x${lobe.nodes}`;
  return {
    model: lobe.model, shape, nTheta: nt, nPhi: np,
    ...(micro ? {} : { groups: lobe.groups.length, nodes: lobe.nodes }),
    glsl, digest: ylDigest(glsl),
    iblTexture: t,
    dispose() { this.iblTexture.dispose(); },
  };
}

// ---------------------------------------------------------------------------------------------
// The microcylinder lobe (session 19; "yarn_lobe": {"model": "sadeghi-microcylinder"}, written by
// `clothfit fit --model woven --fabric <sadeghi fabric> --yarn-lobe preset`; docs/web.md "The
// microcylinder lobe"). A Sadeghi fabric (Sadeghi, Bisker, De Deken, Jensen 2013, "A Practical
// Microcylinder Appearance Model for Cloth Rendering", ACM TOG 32(2)) does not vary over the
// cloth, so its far field is its BSDF, in closed form (brdf/microcylinder.h EvalSplit):
// [the fibres' surface (Fresnel) reflection, white; their volume scattering per unit albedo,
// each thread's times its volume_scale], no cosine. The two values take the Irawan lobe's slots
// [T_warp, T_weft]: woven draws ks (tint_warp 2 m_w out[0] + tint_weft 2 m_f out[1]), and the
// fit starts at tint_warp 1, tint_weft = the threads' albedo, ks 1, m 0.5 (the reference BSDF).
// Local frame x = +u (thread 0, the warp), y = +v (thread 1, the weft), z = n; angles in degrees.
// Per tangent k (thread j, offset o): t = cos(o) d_j + sin(o) n, n_k = -sin(o) d_j + cos(o) n,
// b_k = t x n_k, weight a_j / N_j. The environment uses the same "ibl" summary as the Irawan lobe.

export const MICROCYLINDER_MODEL = 'sadeghi-microcylinder';
export const MICROCYLINDER_MAX_OFFSETS = 64;
const MICROCYLINDER_KEYS = ['model', 'fabric', 'threads', 'ibl'];
const MICROCYLINDER_THREAD_KEYS = ['eta', 'kd', 'gamma_s', 'gamma_v', 'a', 'volume_scale', 'offsets'];
const MC_MASKING_SIGMA = 20 * YL_DEG;  // Sadeghi et al. eq. 10's sigma (microcylinder::kMaskingSigmaDeg)

const ylTypeName = (x) => (x === null ? 'null' : Array.isArray(x) ? 'array' : typeof x);

// The "threads" of a microcylinder lobe, checked as render/scene/material.cpp ParseYarnLobe and
// brdf/yarn_lobe.cpp Validate check them (the same messages): exactly 2 objects of exactly the 7
// keys; eta in (1, 3), kd in [0, 1], gamma_s, gamma_v degrees in (0, 90], a in [0, 1],
// volume_scale in [0, 1], 1 to 64 offsets each degrees in [-90, 90]; a_1 + a_2 <= 1 (+1e-9).
function microcylinderThreads(v, f, fail, obj) {
  if (!Array.isArray(v) || v.length !== 2) fail(f, 'expected an array of 2 threads');
  const num = (x, field, ok, what) => {
    if (typeof x !== 'number') fail(field, `expected a number, got ${ylTypeName(x)}`);
    if (!Number.isFinite(x)) fail(field, 'not finite');
    if (!ok(x)) fail(field, what);
    return x;
  };
  const unit = (x) => x >= 0 && x <= 1, deg = (x) => x > 0 && x <= 90;
  const threads = v.map((t, j) => {
    const tf = `${f}[${j}]`;
    obj(t, tf, MICROCYLINDER_THREAD_KEYS);
    const th = {
      eta: num(t.eta, `${tf}.eta`, (x) => x > 1 && x < 3, 'expected a number in (1, 3)'),
      kd: num(t.kd, `${tf}.kd`, unit, 'expected a number in [0, 1]'),
      gamma_s: num(t.gamma_s, `${tf}.gamma_s`, deg, 'expected degrees in (0, 90]'),
      gamma_v: num(t.gamma_v, `${tf}.gamma_v`, deg, 'expected degrees in (0, 90]'),
      a: num(t.a, `${tf}.a`, unit, 'expected a number in [0, 1]'),
      volume_scale: num(t.volume_scale, `${tf}.volume_scale`, unit, 'expected a number in [0, 1] (this thread\'s albedo over the lobe\'s)'),
    };
    const o = t.offsets;
    if (!Array.isArray(o) || o.length < 1 || o.length > MICROCYLINDER_MAX_OFFSETS) {
      fail(`${tf}.offsets`, `expected an array of 1 to ${MICROCYLINDER_MAX_OFFSETS} numbers (degrees)${Array.isArray(o) ? `, got ${o.length}` : ''}`);
    }
    th.offsets = o.map((x, k) => num(x, `${tf}.offsets[${k}]`, (y) => y >= -90 && y <= 90, 'expected degrees in [-90, 90]'));
    return th;
  });
  if (!(threads[0].a + threads[1].a <= 1 + 1e-9)) fail(f, 'a_1 + a_2 must be <= 1');
  return threads;
}

const mcDot = (p, q) => p[0] * q[0] + p[1] * q[1] + p[2] * q[2];

/**
 * brdf/microcylinder.h MakeTangents in double: [{t, n, b, thread, weight}], thread 0's first,
 * offsets in order (duplicates kept).
 */
export function microcylinderTangents(lobe) {
  const out = [];
  lobe.threads.forEach((th, j) => {
    for (const off of th.offsets) out.push(mcTangent(j, off, th.a / th.offsets.length));
  });
  return out;
}
// microcylinder::MakeTangent: thread j (0: along x, 1: along y), offset in degrees.
function mcTangent(j, offsetDeg, weight) {
  const o = offsetDeg * YL_DEG, c = Math.cos(o), s = Math.sin(o);
  const t = j === 0 ? [c, 0, s] : [0, c, s], n = j === 0 ? [-s, 0, c] : [0, -s, c];
  const b = [t[1] * n[2] - t[2] * n[1], t[2] * n[0] - t[0] * n[2], t[0] * n[1] - t[1] * n[0]];
  return { t, n, b, thread: j, weight };
}

const mcFresnel = (cosI, eta) => {
  const ci = Math.min(Math.max(cosI, 0), 1);
  const st2 = (1 - ci * ci) / (eta * eta);
  if (st2 >= 1) return 1;
  const ct = Math.sqrt(1 - st2);
  const rs = (ci - eta * ct) / (ci + eta * ct), rp = (eta * ci - ct) / (eta * ci + ct);
  return 0.5 * (rs * rs + rp * rp);
};
const mcGaussian = (sigma, x) => Math.exp(-x * x / (2 * sigma * sigma)) / (sigma * Math.sqrt(2 * Math.PI));
const mcWrap = (a) => { while (a > Math.PI) a -= 2 * Math.PI; while (a < -Math.PI) a += 2 * Math.PI; return a; };

/**
 * brdf/microcylinder.h EvalSplit, operation for operation in double (asin, atan2, the wrap, the
 * identities for cos(theta_d) and cos(phi_d / 2), the 1e-4 guards): [surface, volume] at local
 * unit directions wo (to the viewer), wi (to the light) for yarnLobeOptions' result `lobe`
 * (model sadeghi-microcylinder). 0 unless wo.z, wi.z > 0. No cosine. The shader evaluates the
 * same in float (microcylinderGlsl).
 */
export function microcylinderEvalSplit(lobe, wo, wi, tangents = microcylinderTangents(lobe)) {
  const out = [0, 0];
  if (!(wo[2] > 0) || !(wi[2] > 0)) return out;
  const threads = lobe.threads;
  let q = (1 - threads[0].a - threads[1].a) * wo[2], sSum = 0, vSum = 0;
  for (const tg of tangents) {
    const proj = Math.max(0, mcDot(wo, tg.n));  // OutgoingAngles
    q += tg.weight * proj;
    if (proj <= 0) continue;
    const th = threads[tg.thread];
    const sinO = Math.min(Math.max(mcDot(wo, tg.t), -1), 1), thetaO = Math.asin(sinO);
    const cosO = Math.sqrt(Math.max(0, 1 - sinO * sinO));
    const xo = mcDot(wo, tg.n), yo = mcDot(wo, tg.b), phiO = Math.atan2(yo, xo), ro = Math.sqrt(xo * xo + yo * yo);
    const cosPhiO = ro > 0 ? xo / ro : 1, sinPhiO = ro > 0 ? yo / ro : 0;
    const x = mcDot(wi, tg.n), y = mcDot(wi, tg.b), r = Math.sqrt(x * x + y * y);  // Scatter
    const cosPhiI = r > 0 ? x / r : 1;
    const mi = Math.max(0, cosPhiI), mo = Math.max(0, cosPhiO);
    if (mi <= 0 || mo <= 0) continue;
    const phiD = mcWrap(Math.atan2(y, x) - phiO);
    const uu = Math.exp(-phiD * phiD / (2 * MC_MASKING_SIGMA * MC_MASKING_SIGMA));
    const mask = (1 - uu) * mi * mo + uu * Math.min(mi, mo);
    if (mask <= 0) continue;
    const sinI = Math.min(Math.max(mcDot(wi, tg.t), -1), 1), thetaI = Math.asin(sinI);
    const cosI = Math.sqrt(Math.max(0, 1 - sinI * sinI));
    const thetaH = 0.5 * (thetaI + thetaO);
    const cosDiff = cosI * cosO + sinI * sinO;
    const cosD = Math.sqrt(Math.min(Math.max(0.5 * (1 + cosDiff), 0), 1));
    const sinPhiI = r > 0 ? y / r : 0;
    const cosPhiDiff = cosPhiI * cosPhiO + sinPhiI * sinPhiO;
    const cosHalfPhi = Math.sqrt(Math.min(Math.max(0.5 * (1 + cosPhiDiff), 0), 1));
    const fr = mcFresnel(cosD * cosHalfPhi, th.eta), ft = 1 - fr;
    const fSurface = fr * cosHalfPhi * mcGaussian(th.gamma_s * YL_DEG, thetaH);
    const vol = ft * ft * ((1 - th.kd) * mcGaussian(th.gamma_v * YL_DEG, thetaH) + th.kd) / Math.max(cosI + cosO, 1e-4);
    const wt = tg.weight * proj * mask * cosI * (1 / Math.max(cosD * cosD, 1e-4));
    sSum += wt * fSurface;
    vSum += wt * vol * th.volume_scale;
  }
  if (!(q > 0)) return out;
  const k = 1 / (q * wi[2]);
  out[0] = sSum * k;
  out[1] = vSum * k;
  return out;
}

// wovenYarnLobe(wo, wi) of a microcylinder lobe as GLSL: (surface, volume) = EvalSplit in float,
// every per-lobe number a compile-time constant (rounded once from double, as yarnLobeGlsl),
// one call of wovenMcTangent per distinct tangent with its frame, weight and thread constants as
// literals (no loop, no texture). Rearranged where equal in exact arithmetic:
//   - a thread's identical offsets are one tangent of weight count x a_j / N_j (satin's
//     -32, -32, 0, 0, 32, 32) and a thread with a_j = 0 has no tangent (its terms are 0 x finite);
//   - phi_d = phi_i - phi_o is one atan(r_i r_o sin phi_d, r_i r_o cos phi_d) =
//     atan(y_i x_o - x_i y_o, x_i x_o + y_i y_o) instead of two atan2 and the wrap: a term needs
//     cos phi_i > 0 and cos phi_o > 0, so |phi_i|, |phi_o| < pi/2 and |phi_d| < pi (the wrap does
//     nothing); its arguments are never both 0 (x_o > 0), so GLSL's atan(0, 0) never occurs; r_i = 0
//     (wi along the fibre) is atan2(0, 0) = 0 in C++: (x_i, y_i) taken as (1, 0);
//   - cos^2(theta_d) is the clamped (1 + cos(theta_i - theta_o)) / 2 itself (its sqrt only for
//     the Fresnel cosine); volume_scale is folded into the volume Gaussian's and kd's constants;
//   - conditions select (no early return), so the quad's lanes stay converged.
export function microcylinderGlsl(lobe) {
  const F = ylFloat, threads = lobe.threads;
  const tangents = [];
  threads.forEach((th, j) => {
    if (!(th.a > 0)) return;
    const count = new Map();
    for (const off of th.offsets) count.set(off, (count.get(off) ?? 0) + 1);
    for (const [off, c] of count) tangents.push({ ...mcTangent(j, off, c * th.a / th.offsets.length), off, count: c });
  });
  const v3 = (p) => `vec3( ${p.map(F).join(', ')} )`;
  const gs = threads.map((th) => { const s = th.gamma_s * YL_DEG; return [1 / (2 * s * s), 1 / (s * Math.sqrt(2 * Math.PI))]; });
  const gv = threads.map((th) => { const s = th.gamma_v * YL_DEG; return [1 / (2 * s * s), (1 - th.kd) * th.volume_scale / (s * Math.sqrt(2 * Math.PI))]; });
  const L = [
    `// generated by microcylinderGlsl: ${tangents.length} tangents (thread offsets ${threads.map((th) => `[${th.offsets.join(', ')}]`).join(' / ')})`,
    '// Unpolarised Fresnel reflectance of a dielectric of index eta > 1 (microcylinder::FresnelDielectric).',
    'float wovenMcFresnel( const in float cosI, const in float eta ) {',
    '\tfloat ci = clamp( cosI, 0.0, 1.0 );',
    '\tfloat st2 = ( 1.0 - ci * ci ) / ( eta * eta );',
    '\tfloat ct = sqrt( max( 1.0 - st2, 0.0 ) );',
    '\tfloat rs = ( ci - eta * ct ) / ( ci + eta * ct ), rp = ( eta * ci - ct ) / ( eta * ci + ct );',
    '\treturn st2 >= 1.0 ? 1.0 : 0.5 * ( rs * rs + rp * rp );',
    '}',
    '// One tangent (t, n_k, b_k; weight w) of microcylinder::EvalSplit\'s sum: acc.x (Q(wo)) += w P(wo),',
    '// acc.yz += w P(wo) mask cos_i / max(cos^2 theta_d, 1e-4) x (f_r,s, f_r,v volume_scale) (Scatter;',
    '// 0 unless x_o = wo.n_k > 0, cos phi_i > 0, mask > 0). g = (1 / (2 gamma_s^2), 1 / (gamma_s',
    '// sqrt(2 pi)), 1 / (2 gamma_v^2), (1 - kd) volume_scale / (gamma_v sqrt(2 pi))) in radians,',
    '// kv = kd volume_scale.',
    'void wovenMcTangent( const in vec3 wo, const in vec3 wi, const in vec3 t, const in vec3 nk, const in vec3 bk, const in float w,',
    '\t\tconst in float eta, const in vec4 g, const in float kv, inout vec3 acc ) {',
    '\tfloat xo = dot( wo, nk ), yo = dot( wo, bk );',
    '\tacc.x += w * max( xo, 0.0 );',
    '\tfloat xi = dot( wi, nk ), yi = dot( wi, bk );',
    '\tbool alongFibre = !( xi * xi + yi * yi > 0.0 );  // r_i = 0: phi_i = atan2(0, 0) = 0',
    '\txi = alongFibre ? 1.0 : xi;',
    '\tyi = alongFibre ? 0.0 : yi;',
    '\tfloat ri = sqrt( xi * xi + yi * yi ), ro = sqrt( xo * xo + yo * yo );',
    '\tfloat mi = xi / ri, mo = xo / ro;  // cos phi_i, cos phi_o',
    '\tfloat cpd = xi * xo + yi * yo;     // r_i r_o cos(phi_d)',
    '\tfloat pd = atan( yi * xo - xi * yo, cpd );  // phi_d in (-pi, pi) when mi, mo > 0',
    `\tfloat uu = exp( -pd * pd * ${F(1 / (2 * MC_MASKING_SIGMA * MC_MASKING_SIGMA))} );`,
    '\tfloat mask = ( 1.0 - uu ) * mi * mo + uu * min( mi, mo );  // Sadeghi et al. eq. 10',
    '\tfloat so = clamp( dot( wo, t ), -1.0, 1.0 ), si = clamp( dot( wi, t ), -1.0, 1.0 );',
    '\tfloat co = sqrt( max( 1.0 - so * so, 0.0 ) ), ci = sqrt( max( 1.0 - si * si, 0.0 ) );',
    '\tfloat th = 0.5 * ( asin( si ) + asin( so ) );  // theta_h',
    '\tfloat cd2 = clamp( 0.5 * ( 1.0 + ci * co + si * so ), 0.0, 1.0 );  // cos^2 theta_d',
    '\tfloat chp = sqrt( clamp( 0.5 * ( 1.0 + cpd / ( ri * ro ) ), 0.0, 1.0 ) );  // cos(phi_d / 2)',
    '\tfloat fr = wovenMcFresnel( sqrt( cd2 ) * chp, eta ), ft = 1.0 - fr;',
    '\tfloat th2 = th * th;',
    '\tfloat fs = fr * chp * g.y * exp( -th2 * g.x );                             // eq. 4',
    '\tfloat fv = ft * ft * ( g.w * exp( -th2 * g.z ) + kv ) / max( ci + co, 1e-4 );  // eq. 5; guard 1e-4',
    '\tfloat wt = w * xo * mask * ci / max( cd2, 1e-4 );  // guard: cos^2 theta_d >= 1e-4',
    '\tbool lit = xo > 0.0 && mi > 0.0 && mask > 0.0;',
    '\tacc.y += lit ? wt * fs : 0.0;',
    '\tacc.z += lit ? wt * fv : 0.0;',
    '}',
    'vec2 wovenYarnLobe( const in vec3 wo, const in vec3 wi ) {',
    '\tif ( !( wo.z > 0.0 ) || !( wi.z > 0.0 ) ) return vec2( 0.0 );',
    '\t// (Q(wo), surface sum, volume sum); Q starts with the gaps between the threads',
    `\tvec3 acc = vec3( ${F(1 - threads[0].a - threads[1].a)} * wo.z, 0.0, 0.0 );`,
  ];
  for (const tg of tangents) {
    const j = tg.thread;
    L.push(`\t// thread ${j}, offset ${tg.off}${tg.count > 1 ? ` (x ${tg.count})` : ''}`,
      `\twovenMcTangent( wo, wi, ${v3(tg.t)}, ${v3(tg.n)}, ${v3(tg.b)}, ${F(tg.weight)}, ${F(threads[j].eta)}, `
      + `vec4( ${[...gs[j], ...gv[j]].map(F).join(', ')} ), ${F(threads[j].kd * threads[j].volume_scale)}, acc );`);
  }
  L.push('\tfloat k = 1.0 / ( acc.x * wi.z );', '\treturn acc.x > 0.0 ? vec2( acc.y * k, acc.z * k ) : vec2( 0.0 );', '}', '');
  return L.join('\n');
}

const WOVEN_VERTEX_PARS = /* glsl */ `
#ifndef USE_TANGENT
attribute vec4 tangent;
#endif
varying vec3 vWovenTangent;
varying float vWovenTangentSign;
#if defined( WOVEN_WEAVE_MAPS )
uniform mat3 wovenWeaveTransform;
varying vec2 vWovenWeaveUv;
#endif
`;
const WOVEN_VERTEX = /* glsl */ `
vWovenTangent = ( modelViewMatrix * vec4( tangent.xyz, 0.0 ) ).xyz;
vWovenTangentSign = tangent.w < 0.0 ? -1.0 : 1.0;
#if defined( WOVEN_WEAVE_MAPS )
vWovenWeaveUv = ( wovenWeaveTransform * vec3( uv, 1.0 ) ).xy;
#endif
`;

const wovenTangentsPending = new WeakSet();  // geometries whose tangents are computed after this frame

// The horizon fade's light slots: the environment's sun and its panels (web/sun.js).
const WOVEN_AREA_LIGHTS = 1 + MAX_PANEL_LIGHTS;
const _areaDir = new THREE.Vector3(), _areaTarget = new THREE.Vector3();

const WOVEN_PARS = /* glsl */ `
// The environment's sun and panels (loadSceneCard's setEnvironment: scene.userData.clothfitAreaLights),
// filled per frame by MeshWovenMaterial.onBeforeRender: xyz = the light's view-space direction
// as three.js computes directionalLights[ i ].direction, w = sin of its angular radius (0: unused).
uniform vec4 wovenAreaLights[ ${WOVEN_AREA_LIGHTS} ];
bool wovenDirectional = false;
// render/scene/lights.h ClipDiscAtHorizon: a disc light of angular radius asin( sinR ) whose
// centre is at n.l = NoL, clipped at the horizon; returns ( visible fraction, n.l' of the
// visible part's centroid ).
vec2 wovenClipDiscAtHorizon( const in float NoL, const in float sinR ) {
	if ( sinR <= 0.0 || NoL >= sinR ) return vec2( 1.0, NoL );
	if ( NoL <= -sinR ) return vec2( 0.0, NoL );
	float a = -NoL / sinR;
	float q = sqrt( max( 1.0 - a * a, 0.0 ) );
	float A = acos( a ) - a * q;
	float yc = A > 0.0 ? 2.0 * q * q * q / ( 3.0 * A ) : 1.0;
	return vec2( A * RECIPROCAL_PI, max( NoL + sinR * yc, 0.0 ) );
}
uniform vec3 wovenSpecularColor;
uniform vec3 wovenSheenColor;
uniform vec3 wovenTintWarp;
uniform vec3 wovenTintWeft;
uniform float wovenAlphaA;
uniform float wovenAlphaC;
uniform float wovenRS;
uniform float wovenCr;
uniform float wovenSr;
uniform float wovenF0;
uniform float wovenBeta;
uniform float wovenM;
uniform float wovenAniso;
uniform int wovenPhaseK;
uniform float wovenPhaseT;
uniform sampler2D wovenPhase;
uniform sampler2D clothDG;
varying vec3 vWovenTangent;
varying float vWovenTangentSign;

// Per-pixel weave sample (woven::WeaveSample): lobe weight ratios, diffuse ratio, glint.
// With weave maps (WOVEN_WEAVE_MAPS, a preset's "weave_maps"): the two textures are read ONCE
// per fragment in main (WOVEN_ROUGHNESS below, in uniform control flow, so the GPU's implicit
// LOD from the quad's uv derivatives applies: trilinear, REPEAT, as render/preview/weave_maps.h
// emulates) into wovenWS. Another source may define WOVEN_WEAVE_SAMPLE and its own
// wovenWeaveSample() before this chunk; the uniform material is all ones.
struct WovenWeave { float warp; float weft; vec3 kd; float glint; };
#if defined( WOVEN_WEAVE_MAPS )
uniform sampler2D wovenWeaveWeights;
uniform sampler2D wovenWeaveKd;
varying vec2 vWovenWeaveUv;
WovenWeave wovenWS;
WovenWeave wovenWeaveSample() { return wovenWS; }
#elif !defined( WOVEN_WEAVE_SAMPLE )
WovenWeave wovenWeaveSample() { return WovenWeave( 1.0, 1.0, vec3( 1.0 ), 1.0 ); }
#endif

// Table2D::Sample: bilinear, texel centres (i + 0.5)/n, clamped to edge; texelFetch (no fp16).
float wovenTable( const in sampler2D tex, const in int n, const in int channel, const in float u, const in float v ) {
	vec2 x = clamp( vec2( u, v ) * float( n ) - 0.5, vec2( 0.0 ), vec2( float( n - 1 ) ) );
	ivec2 i0 = ivec2( floor( x ) );
	ivec2 i1 = min( i0 + 1, ivec2( n - 1 ) );
	vec2 f = x - vec2( i0 );
	int o = channel * n;
	float a = texelFetch( tex, ivec2( o + i0.x, i0.y ), 0 ).r;
	float b = texelFetch( tex, ivec2( o + i1.x, i0.y ), 0 ).r;
	float c = texelFetch( tex, ivec2( o + i0.x, i1.y ), 0 ).r;
	float d = texelFetch( tex, ivec2( o + i1.x, i1.y ), 0 ).r;
	return ( a * ( 1.0 - f.x ) + b * f.x ) * ( 1.0 - f.y ) + ( c * ( 1.0 - f.x ) + d * f.x ) * f.y;
}

float wovenMax3( const in vec3 c ) { return max( c.r, max( c.g, c.b ) ); }

// f0 PT_0 + (1 - f0) PT_beta at (NoV, r_e) (woven::YarnAlbedo).
float wovenYarnAlbedo( const in float NoV, const in float rE ) {
	float p0 = wovenTable( wovenPhase, 32, wovenPhaseK, NoV, rE );
	float p1 = wovenTable( wovenPhase, 32, wovenPhaseK + 1, NoV, rE );
	return wovenF0 * wovenTable( wovenPhase, 32, 0, NoV, rE ) + ( 1.0 - wovenF0 ) * ( p0 + ( p1 - p0 ) * wovenPhaseT );
}

float wovenSheenScaling( const in float mu ) {
	return saturate( 1.0 - wovenMax3( saturate( wovenSheenColor ) ) * wovenTable( clothDG, 128, 0, mu, wovenRS ) );
}

float wovenYarnScaling( const in float mu, const in float rE ) {
	#if defined( WOVEN_ALBEDO_SCALED )
		return saturate( 1.0 - wovenMax3( wovenSpecularColor ) * wovenYarnAlbedo( mu, rE ) );
	#else
		return 1.0;
	#endif
}

float wovenDGgxAniso( float at, float ab, const in float NoH, const in float ToH, const in float BoH ) {
	at = max( at, 1e-8 );
	ab = max( ab, 1e-8 );
	float a2 = at * ab;
	float q2 = max( pow2( ab * ToH ) + pow2( at * BoH ) + pow2( a2 * NoH ), 1e-12 );
	return RECIPROCAL_PI * a2 * pow2( a2 / q2 );
}

float wovenVSmithAniso( const in float at, const in float ab, const in float NoV, const in float NoL, const in float ToV, const in float BoV, const in float ToL, const in float BoL ) {
	float lv = sqrt( pow2( at * ToV ) + pow2( ab * BoV ) + pow2( NoV ) + 1e-20 );
	float ll = sqrt( pow2( at * ToL ) + pow2( ab * BoL ) + pow2( NoL ) + 1e-20 );
	return 0.5 / max( NoL * lv + NoV * ll, 1e-6 );
}

float wovenLobeDV( const in float NoV, const in float NoL, const in float NoH, const in float AoV, const in float CoV, const in float AoL, const in float CoL, const in float AoH, const in float CoH ) {
	return wovenDGgxAniso( wovenAlphaC, wovenAlphaA, NoH, CoH, AoH ) *
		wovenVSmithAniso( wovenAlphaC, wovenAlphaA, NoV, NoL, CoV, AoV, CoL, AoL );
}

void wovenFrame( const in vec3 n, out vec3 t, out vec3 b ) {
	vec3 t0 = vWovenTangent;
	t = normalize( t0 - n * dot( t0, n ) );
	b = vWovenTangentSign * cross( n, t );
}

float wovenCharlie( const in float alpha, const in float NoH ) {
	float a = max( alpha, 1e-8 );
	float invAlpha = 1.0 / a;
	float sin2h = max( 1.0 - NoH * NoH, 0.0078125 );
	return ( 2.0 + invAlpha ) * pow( sin2h, invAlpha * 0.5 ) * ( 0.5 * RECIPROCAL_PI );
}

// The rough diffuse (WOVEN_ROUGH_DIFFUSE: diffuse_roughness sigma > 0; without it the diffuse
// is Lambert and none of this is compiled): Fujii's improved Oren-Nayar (brdf/woven.h On,
// OnSOverT, OnAlbedoG, PrepareOn). On = A + A sigma s / t multiplies the lights' diffuse,
// Eo(NoV) = A + A sigma G(NoV) (On's directional albedo) every irradiance under the diffuse
// weight; wovenOnA = A = 1 / (1 + (1/2 - 2/(3 pi)) sigma), wovenOnB = A sigma (wovenOnTerms).
#if defined( WOVEN_ROUGH_DIFFUSE )
uniform float wovenOnA;
uniform float wovenOnB;
// s / t: s = l.v - NoL NoV (l.v = 2 LoH^2 - 1) floored at -1, t = max(NoL, NoV, 1e-6) if s > 0
float wovenOnSOverT( const in float NoV, const in float NoL, const in float LoH ) {
	float s = max( ( 2.0 * LoH * LoH - 1.0 ) - NoL * NoV, - 1.0 );
	if ( ! ( s > 0.0 ) ) return s;
	return s / max( max( NoL, NoV ), 1e-6 );
}
// G(mu) = [sin th (th - sin th cos th) + (2/3) sin th cos th (1 + sin th + sin^2 th) /
// (1 + sin th) - (2/3) sin th] / pi, th = acos(mu)
float wovenOnAlbedoG( const in float mu ) {
	float c = clamp( mu, 0.0, 1.0 );
	float th = acos( c );
	float sn = sqrt( max( 0.0, 1.0 - c * c ) );
	return ( sn * ( th - sn * c ) + ( 2.0 / 3.0 ) * sn * c * ( 1.0 + sn + sn * sn ) / ( 1.0 + sn ) - ( 2.0 / 3.0 ) * sn ) * RECIPROCAL_PI;
}
#endif

// The far-field yarn lobe (WOVEN_YARN_LOBE, a preset's "woven": {"yarn_lobe": {...}}; the CPU
// side: yarnLobePack). wovenYarnLobe(wo, wi) = (T_warp, T_weft) at local unit directions (x = t,
// y = b, z = n), fit/yarn_farfield.cpp EvalQuadrature's terms in float, is generated per lobe
// (yarnLobeGlsl: its constants as literals, one helper call per node) and replaces the marker
// line below; wovenYarnLobeIbl reads the lobes' IBL summary (brdf/yarn_table.h Table::Ibl) and
// the PMREM once per lobe.
#if defined( WOVEN_YARN_LOBE )
uniform sampler2D wovenYlIbl;

// The highlight band's mean over its coordinate uniform in [-e, e].
float wovenYlBand( const in float c, const in float delta, const in float e ) {
	return max( min( c + 0.5 * delta, e ) - max( c - 0.5 * delta, -e ), 0.0 ) / ( 2.0 * e );
}
// FilamentRadius(|u|): SpineRadius at umax_s by branch k.x with tau = rhat tan u
// (ellipse: cos^2 t = 1 / (1 + tau^2); hyperbola: cosh^2 s = 1 / (1 - tau^2), tau <= 1 - 1e-9 as
// the C++ clamp, its 1 - tau^2 floored at 2e-9 since float rounds 1 - 1e-9 to 1).
float wovenYlRadius( const in vec4 k, const in float umaxS, const in float uAbs ) {
	if ( k.x < 0.5 ) return k.y;
	float tu = tan( min( uAbs, umaxS ) );
	float q;
	if ( k.x < 1.5 ) {
		float tau = k.w * tu;
		q = ( k.y * k.y + k.z * k.z * tau * tau ) / ( 1.0 + tau * tau );
	} else if ( k.x < 2.5 ) {
		q = 1.0 + tu * tu;
		return k.y * q * sqrt( q );
	} else {
		float tau = min( -k.w * tu, 1.0 - 1e-9 );
		q = ( k.y * k.y + k.z * k.z * tau * tau ) / max( 1.0 - tau * tau, 2e-9 );
	}
	return q * sqrt( q ) / ( k.y * k.z );
}
// One staple node u_j (su = sin u_j, cu = cos u_j, R = SpineRadius(|u_j|), a = w / 2, it =
// 1 / tan psi) at H = |H| h in the yarn frame: (R + a cos v_h) Seeliger'(n . wi, n . wo) /
// (|H| NoH), Seeliger' = c1 c2 / (c1 + c2) (the 1 / 4pi, a, 1 / |sin psi| and the weight are
// the caller's); 0 unless |D| < 1, |v_h| < pi / 2, c1, c2 > 0 (yarnLobeGlsl has the algebra).
float wovenYlStaple( const in vec3 H, const in vec3 i, const in vec3 o, const in float su, const in float cu, const in float R, const in float a, const in float it ) {
	float bt = H.y * su + H.z * cu;
	float r2 = H.x * H.x + bt * bt;            // |H|^2 r^2
	float p = ( H.y * cu - H.z * su ) * it;    // |H| r D
	float q2 = r2 - p * p;                     // |H|^2 r^2 (1 - D^2): > 0 iff |D| < 1 and r > 0
	float q = sqrt( max( q2, 0.0 ) );          // |H| NoH
	float ir2 = 1.0 / r2;
	float cv = ( H.x * p + bt * q ) * ir2, sv = ( H.x * q - bt * p ) * ir2;  // cos v_h, sin v_h
	float c1 = sv * i.x + cv * ( su * i.y + cu * i.z ), c2 = sv * o.x + cv * ( su * o.y + cu * o.z );
	float t = ( R + a * cv ) * c1 * c2 / ( q * ( c1 + c2 ) );
	return ( q2 > 0.0 && cv > 0.0 && c1 > 0.0 && c2 > 0.0 ) ? t : 0.0;
}
// The same with the band mean across at x_h = clamp(v_h w / pi, -xmax, xmax) (wpi = w / pi),
// for a group whose extent e < w / 2.
float wovenYlStapleBand( const in vec3 H, const in vec3 i, const in vec3 o, const in float su, const in float cu, const in float R, const in float a, const in float it,
		const in float wpi, const in float xmax, const in float delta, const in float e ) {
	float bt = H.y * su + H.z * cu;
	float r2 = H.x * H.x + bt * bt;
	float p = ( H.y * cu - H.z * su ) * it;
	float q2 = r2 - p * p;
	float q = sqrt( max( q2, 0.0 ) );
	float ir2 = 1.0 / r2;
	float cv = ( H.x * p + bt * q ) * ir2, sv = ( H.x * q - bt * p ) * ir2;
	float c1 = sv * i.x + cv * ( su * i.y + cu * i.z ), c2 = sv * o.x + cv * ( su * o.y + cu * o.z );
	float t = ( R + a * cv ) * c1 * c2 / ( q * ( c1 + c2 ) ) * wovenYlBand( clamp( atan( sv, cv ) * wpi, -xmax, xmax ), delta, e );
	return ( q2 > 0.0 && cv > 0.0 && c1 > 0.0 && c2 > 0.0 ) ? t : 0.0;
}
// One filament node v_j (sv, cv = sin v_j, cos v_j) with n = (sv, suh cv, cuh cv): ix, bi = i's
// x and (suh i.y + cuh i.z), the same for o: (R + a cos v_j) Seeliger'(n . wi, n . wo).
float wovenYlFilament( const in float ix, const in float bi, const in float ox, const in float bo, const in float sv, const in float cv, const in float R, const in float a ) {
	float c1 = sv * ix + cv * bi, c2 = sv * ox + cv * bo;
	float t = ( R + a * cv ) * c1 * c2 / ( c1 + c2 );
	return ( c1 > 0.0 && c2 > 0.0 ) ? t : 0.0;
}
// @wovenYarnLobe (yarnLobeGlsl's source replaces this line)
// Table::Ibl's entry of lobe k at wo: (A, dir) and r (bilinear in theta, phi; phi periodic).
vec4 wovenYlIblEntry( const in int k, const in vec3 woIn, out float r ) {
	const int NT = WOVEN_YL_N_THETA, NP = WOVEN_YL_N_PHI;
	float th = acos( clamp( max( woIn.z, 1e-4 ), -1.0, 1.0 ) );
	float ph = ( woIn.x == 0.0 && woIn.y == 0.0 ) ? 0.0 : atan( woIn.y, woIn.x );
	if ( ph < 0.0 ) ph += 2.0 * PI;
	float u = clamp( th / ( 0.5 * PI ) * float( NT ) - 0.5, 0.0, float( NT - 1 ) );
	int t0 = min( int( u ), NT - 2 );
	float ft = u - float( t0 );
	float v = ph / ( 2.0 * PI ) * float( NP ) - 0.5;
	if ( v < 0.0 ) v += float( NP );
	int p0 = min( int( v ), NP - 1 );
	float fp = v - float( p0 );
	int p1 = ( p0 + 1 ) % NP;
	int r0 = k * NT + t0, r1 = r0 + 1;
	vec4 e = ( 1.0 - ft ) * ( ( 1.0 - fp ) * texelFetch( wovenYlIbl, ivec2( 2 * p0, r0 ), 0 ) + fp * texelFetch( wovenYlIbl, ivec2( 2 * p1, r0 ), 0 ) ) +
		ft * ( ( 1.0 - fp ) * texelFetch( wovenYlIbl, ivec2( 2 * p0, r1 ), 0 ) + fp * texelFetch( wovenYlIbl, ivec2( 2 * p1, r1 ), 0 ) );
	float e4 = ( 1.0 - ft ) * ( ( 1.0 - fp ) * texelFetch( wovenYlIbl, ivec2( 2 * p0 + 1, r0 ), 0 ).x + fp * texelFetch( wovenYlIbl, ivec2( 2 * p1 + 1, r0 ), 0 ).x ) +
		ft * ( ( 1.0 - fp ) * texelFetch( wovenYlIbl, ivec2( 2 * p0 + 1, r1 ), 0 ).x + fp * texelFetch( wovenYlIbl, ivec2( 2 * p1 + 1, r1 ), 0 ).x );
	r = clamp( e4, 0.0, 1.0 );
	float dl = length( e.yzw );
	return vec4( max( e.x, 0.0 ), dl > 1e-12 ? e.yzw / dl : vec3( 0.0, 0.0, 1.0 ) );
}
#if defined( USE_ENVMAP ) && defined( ENVMAP_TYPE_PMREM )
// A_k L_pref(dir_k, r_k) for both lobes (rgb each): the PMREM read as getIBLRadiance reads it
// (world direction, envMapRotation, roughnessToMip, envMapIntensity), t, b, n in view space.
void wovenYarnLobeIbl( const in vec3 wo, const in vec3 t, const in vec3 b, const in vec3 n, out vec3 yw, out vec3 yf ) {
	for ( int k = 0; k < 2; ++k ) {
		float r;
		vec4 e = wovenYlIblEntry( k, wo, r );
		vec3 d = transformDirectionByInverseViewMatrix( normalize( t * e.y + b * e.z + n * e.w ), viewMatrix );
		vec3 L = textureLod( envMap, envMapRotation * d, roughnessToMip( r ) ).rgb * envMapIntensity;
		#ifdef USE_LIGHTMAP
			// the light map's E_ind / pi as uniform radiance, under the lobe's albedo e.x (session 22;
			// render/preview PreviewCache::light_map)
			L += clothfitLightMapIrradiance * RECIPROCAL_PI;
		#endif
		if ( k == 0 ) yw = e.x * L;
		else yf = e.x * L;
	}
}
#endif
#endif

void RE_Direct_Woven( const in IncidentLight directLight, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	vec3 n = geometryNormal, v = geometryViewDir, l = directLight.direction;
	vec3 lightColor = directLight.color;
	// The horizon fade of a light split off the environment (render/preview GatherLights): the
	// disc's visible fraction, drawn from its visible part's centroid.
	// Only three.js's directional lights (wovenDirectional: set around RE_Direct in their loop,
	// MeshWovenMaterial.onBeforeCompile); a point or spot light is always a delta.
	float sinR = 0.0;
	if ( wovenDirectional ) {
		for ( int k = 0; k < ${WOVEN_AREA_LIGHTS}; ++k ) {
			if ( wovenAreaLights[ k ].w > 0.0 && dot( l, wovenAreaLights[ k ].xyz ) > 0.99999 ) sinR = wovenAreaLights[ k ].w;
		}
	}
	if ( sinR > 0.0 ) {
		float NoL0 = dot( n, l );
		vec2 clip = wovenClipDiscAtHorizon( NoL0, sinR );
		if ( clip.x <= 0.0 ) return;
		if ( clip.x < 1.0 ) {
			vec3 u = l - n * NoL0;
			float len = length( u );
			if ( len > 1e-12 ) l = n * clip.y + u * ( sqrt( max( 1.0 - clip.y * clip.y, 0.0 ) ) / len );
			lightColor *= clip.x;
		}
	}
	vec3 h = normalize( l + v );
	vec3 t, b;
	wovenFrame( n, t, b );
	float NoV = clamp( dot( n, v ), 1e-4, 1.0 );
	float NoL = saturate( dot( n, l ) );
	float NoH = saturate( dot( n, h ) );
	float LoH = saturate( dot( l, h ) );
	float ToV = dot( t, v ), BoV = dot( b, v ), ToL = dot( t, l ), BoL = dot( b, l ), ToH = dot( t, h ), BoH = dot( b, h );
	float cr = wovenCr, sr = wovenSr;
	float AoV = cr * ToV + sr * BoV, CoV = cr * BoV - sr * ToV;
	float AoL = cr * ToL + sr * BoL, CoL = cr * BoL - sr * ToL;
	float AoH = cr * ToH + sr * BoH, CoH = cr * BoH - sr * ToH;
	WovenWeave ws = wovenWeaveSample();
	#if defined( WOVEN_YARN_LOBE )
		// the far-field lobe in place of woven's GGX yarn lobes: ks (tint_w 2 m_w T_w + tint_f
		// 2 m_f T_f) glint (preview.cpp WovenKernel far_field), raw cosines (the lobe gates on them)
		vec2 Ty = wovenYarnLobe( vec3( ToV, BoV, dot( n, v ) ), vec3( ToL, BoL, dot( n, l ) ) );
		vec3 yarn = wovenSpecularColor * ( wovenTintWarp * ( 2.0 * wovenM * ws.warp * Ty.x ) + wovenTintWeft * ( 2.0 * ( 1.0 - wovenM ) * ws.weft * Ty.y ) ) * ws.glint;
	#else
		float Lw = wovenLobeDV( NoV, NoL, NoH, AoV, CoV, AoL, CoL, AoH, CoH );
		float Lf = wovenLobeDV( NoV, NoL, NoH, CoV, AoV, CoL, AoL, CoH, AoH );
		vec3 lobes = wovenTintWarp * ( wovenM * ws.warp * Lw ) + wovenTintWeft * ( ( 1.0 - wovenM ) * ws.weft * Lf );
		float Fp = wovenF0 + ( 1.0 - wovenF0 ) * exp( -2.0 * wovenBeta * LoH * LoH );
		vec3 yarn = wovenSpecularColor * lobes * ( Fp * ws.glint );
	#endif
	vec3 diffuse = material.diffuseColor * ws.kd * RECIPROCAL_PI;
	#if defined( WOVEN_ROUGH_DIFFUSE )
		diffuse *= wovenOnA + wovenOnB * wovenOnSOverT( NoV, NoL, LoH );
	#endif
	float rE = material.roughness;
	float y = min( wovenYarnScaling( NoV, rE ), wovenYarnScaling( NoL, rE ) );
	float s = min( wovenSheenScaling( NoV ), wovenSheenScaling( NoL ) );
	float dv = wovenCharlie( wovenRS * wovenRS, NoH ) / max( 4.0 * ( NoL + NoV - NoL * NoV ), 1e-12 );
	reflectedLight.directSpecular += lightColor * NoL * ( wovenSheenColor * dv + yarn * s );
	reflectedLight.directDiffuse += lightColor * NoL * ( diffuse * ( y * s ) );
}

void RE_IndirectDiffuse_Woven( const in vec3 irradiance, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	reflectedLight.indirectDiffuse += irradiance * material.diffuseColor * RECIPROCAL_PI;
}

// Filtered importance sampling of the environment (Colbert & Krivanek 2007, "GPU-Based
// Importance Sampling", GPU Gems 3 ch. 20), the session-8 spec shared with the C++ preview
// (render/preview, ThreejsPmrem): WOVEN_FIS_TAPS taps of the yarn lobe's isotropic GGX
// (alpha = max(r_e^2, 1e-3)) replace the single split-sum read the yarn lobes multiply;
// WOVEN_FIS_DIFFUSE_TAPS > 0 cosine taps replace three.js's irradiance (the top PMREM level).
// Each tap is read from three.js's PMREM cube with textureLod at the mip whose roughness lobe
// covers the tap's solid angle. Conventions: WORLD space (n, v taken out of view space with
// transformDirectionByInverseViewMatrix, as getIBLRadiance does), the frame built from the
// world-space n (Duff et al. 2017), then envMapRotation and envMapIntensity at the lookup.
#if defined( WOVEN_FIS ) && defined( USE_ENVMAP ) && defined( ENVMAP_TYPE_PMREM )
// Van der Corput radical inverse base 2 of i (bit-reversed 32-bit i times 2^-32).
float wovenRadicalInverse( const in int i ) {
	uint b = uint( i );
	b = ( b << 16u ) | ( b >> 16u );
	b = ( ( b & 0x55555555u ) << 1u ) | ( ( b & 0xAAAAAAAAu ) >> 1u );
	b = ( ( b & 0x33333333u ) << 2u ) | ( ( b & 0xCCCCCCCCu ) >> 2u );
	b = ( ( b & 0x0F0F0F0Fu ) << 4u ) | ( ( b & 0xF0F0F0F0u ) >> 4u );
	b = ( ( b & 0x00FF00FFu ) << 8u ) | ( ( b & 0xFF00FF00u ) >> 8u );
	return float( b ) * 2.3283064365386963e-10;
}
// Orthonormal basis (t1, t2, n) from a unit n (Duff et al. 2017, JCGT 6(1)).
void wovenFisBasis( const in vec3 n, out vec3 t1, out vec3 t2 ) {
	float s = n.z >= 0.0 ? 1.0 : -1.0;
	float a = -1.0 / ( s + n.z );
	float b = n.x * n.y * a;
	t1 = vec3( 1.0 + s * n.x * n.x * a, s * b, -s * n.x );
	t2 = vec3( b, s + n.y * n.y * a, -n.y );
}
// The PMREM read of one tap of the given pdf (per solid angle) out of count taps, at the
// roughness whose lobe covers Omega_s = 4 / (count pdf): the factor 4 is Colbert & Krivanek's
// +1 LOD bias, a measured deviation of the C++ reference from the session-8 spec's 1 / (N pdf),
// which under-filters (render/preview/threejs_ibl.cpp kFisSolidAngleBias).
vec3 wovenFisTap( const in vec3 l, const in float pdf, const in float count ) {
	float omegaS = 4.0 / ( count * pdf );
	float rT = min( sqrt( sqrt( omegaS / ( 4.0 * PI ) ) ), 1.0 );
	return textureLod( envMap, envMapRotation * l, roughnessToMip( rT ) ).rgb * envMapIntensity;
}
// L_fis(n, v, r): the NoL-weighted mean of the GGX taps; fallback (the split-sum read at r)
// when no tap is above the horizon. nView, vView: view space (unit).
vec3 wovenFisRadiance( const in vec3 nView, const in vec3 vView, const in float r, const in vec3 fallback ) {
	vec3 n = transformDirectionByInverseViewMatrix( nView, viewMatrix );
	vec3 v = transformDirectionByInverseViewMatrix( vView, viewMatrix );
	vec3 t1, t2;
	wovenFisBasis( n, t1, t2 );
	float alpha = max( r * r, 1e-3 ), a2 = alpha * alpha;
	vec3 sum = vec3( 0.0 );
	float wsum = 0.0;
	for ( int i = 0; i < WOVEN_FIS_TAPS; ++i ) {
		float u1 = ( float( i ) + 0.5 ) / float( WOVEN_FIS_TAPS );
		float phi = 2.0 * PI * wovenRadicalInverse( i );
		float cosH = sqrt( ( 1.0 - u1 ) / ( 1.0 + ( a2 - 1.0 ) * u1 ) );
		float sinH = sqrt( max( 1.0 - cosH * cosH, 0.0 ) );
		vec3 h = t1 * ( sinH * cos( phi ) ) + t2 * ( sinH * sin( phi ) ) + n * cosH;
		float VoH = dot( v, h );
		vec3 l = 2.0 * VoH * h - v;
		float NoL = dot( n, l );
		if ( NoL <= 0.0 || VoH <= 0.0 ) continue;
		float d = ( a2 - 1.0 ) * cosH * cosH + 1.0;
		float D = a2 / ( PI * d * d );
		float pdf = D * cosH / ( 4.0 * VoH );
		sum += NoL * wovenFisTap( l, pdf, float( WOVEN_FIS_TAPS ) );
		wsum += NoL;
	}
	return wsum > 0.0 ? sum / wsum : fallback;
}
#if WOVEN_FIS_DIFFUSE_TAPS > 0
// (WOVEN_FIS_DIFFUSE: so no #if elsewhere names WOVEN_FIS_DIFFUSE_TAPS when it is undefined.)
#define WOVEN_FIS_DIFFUSE
// E_fis(n) / pi: the mean of cosine-distributed taps (pdf cos / pi). nView: view space (unit).
vec3 wovenFisIrradianceOverPi( const in vec3 nView ) {
	vec3 n = transformDirectionByInverseViewMatrix( nView, viewMatrix );
	vec3 t1, t2;
	wovenFisBasis( n, t1, t2 );
	vec3 sum = vec3( 0.0 );
	for ( int i = 0; i < WOVEN_FIS_DIFFUSE_TAPS; ++i ) {
		float u1 = ( float( i ) + 0.5 ) / float( WOVEN_FIS_DIFFUSE_TAPS );
		float phi = 2.0 * PI * wovenRadicalInverse( i );
		float cosT = sqrt( 1.0 - u1 ), sinT = sqrt( u1 );
		vec3 l = t1 * ( sinT * cos( phi ) ) + t2 * ( sinT * sin( phi ) ) + n * cosT;
		sum += wovenFisTap( l, cosT * RECIPROCAL_PI, float( WOVEN_FIS_DIFFUSE_TAPS ) );
	}
	return sum / float( WOVEN_FIS_DIFFUSE_TAPS );
}
#endif
#endif

// three.js getIBLAnisotropyRadiance's bent normal about bitangent B (physical_aniso::BentNormal):
// w >= 1 is n itself.
vec3 wovenBentNormal( const in vec3 n, const in vec3 v, const in vec3 B, const in float w ) {
	if ( w >= 1.0 ) return n;
	vec3 bn = normalize( cross( cross( B, v ), B ) );
	return normalize( mix( bn, n, w ) );
}

// radiance: three.js's getIBLRadiance at material.roughness = r_e; the sheen lobe's at r_s.
// With WOVEN_FIS (preset "woven": {"ibl": "fis"}) the yarn lobes multiply wovenFisRadiance
// instead, and with WOVEN_FIS_DIFFUSE_TAPS > 0 the diffuse E_d = wovenFisIrradianceOverPi.
void RE_IndirectSpecular_Woven( const in vec3 radiance, const in vec3 iblIrradiance, const in vec3 clearcoatRadiance, const in vec3 geometryPosition, const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal, const in PhysicalMaterial material, inout ReflectedLight reflectedLight ) {
	float NoV = clamp( dot( geometryNormal, geometryViewDir ), 1e-4, 1.0 );
	float rE = material.roughness;
	WovenWeave ws = wovenWeaveSample();
	float s = wovenSheenScaling( NoV );
	vec3 yarn = wovenSpecularColor * ( s * ws.glint * wovenYarnAlbedo( NoV, rE ) );
	vec3 lobes = yarn * ( wovenTintWarp * ( wovenM * ws.warp ) + wovenTintWeft * ( ( 1.0 - wovenM ) * ws.weft ) );
	// The yarn lobes reflect the card's light map too, as uniform radiance E_ind / pi (session 22;
	// the far-field lobes add it inside wovenYarnLobeIbl). The sheen lobe does not, as three.js's.
	#if defined( USE_LIGHTMAP ) && defined( USE_ENVMAP )
		// (with an environment only, as the C++ preview, whose yarn IBL path needs one)
		vec3 wovenLm = clothfitLightMapIrradiance * RECIPROCAL_PI;
	#else
		vec3 wovenLm = vec3( 0.0 );
	#endif
	#if defined( WOVEN_YARN_LOBE )
		// far-field lobe: ks (tint_w 2 m_w A_w L_w + tint_f 2 m_f A_f L_f) s_v glint
		#if defined( USE_ENVMAP ) && defined( ENVMAP_TYPE_PMREM )
			vec3 ylT, ylB, ylW, ylF;
			wovenFrame( geometryNormal, ylT, ylB );
			wovenYarnLobeIbl( vec3( dot( ylT, geometryViewDir ), dot( ylB, geometryViewDir ), dot( geometryNormal, geometryViewDir ) ), ylT, ylB, geometryNormal, ylW, ylF );
			reflectedLight.indirectSpecular += wovenSpecularColor * ( wovenTintWarp * ( 2.0 * wovenM * ws.warp ) * ylW + wovenTintWeft * ( 2.0 * ( 1.0 - wovenM ) * ws.weft ) * ylF ) * ( s * ws.glint );
		#endif
	#elif defined( WOVEN_FIS ) && defined( USE_ENVMAP ) && defined( ENVMAP_TYPE_PMREM )
		reflectedLight.indirectSpecular += lobes * ( wovenFisRadiance( geometryNormal, geometryViewDir, rE, radiance ) + wovenLm );
	#elif defined( WOVEN_BENT ) && defined( USE_ENVMAP ) && defined( STANDARD )
		// brdf/woven.h IblMode::kBent: each lobe's radiance about its bent normal, the fibre axis
		// as three.js's anisotropy bitangent, w = (1 - s (1 - r_e))^4, read at r_e.
		vec3 bt, bb;
		wovenFrame( geometryNormal, bt, bb );
		vec3 aW = wovenCr * bt + wovenSr * bb, aF = wovenCr * bb - wovenSr * bt;
		float wB = pow2( pow2( 1.0 - wovenAniso * ( 1.0 - rE ) ) );
		vec3 radW = getIBLRadiance( geometryViewDir, wovenBentNormal( geometryNormal, geometryViewDir, aW, wB ), rE );
		vec3 radF = getIBLRadiance( geometryViewDir, wovenBentNormal( geometryNormal, geometryViewDir, aF, wB ), rE );
		reflectedLight.indirectSpecular += yarn * ( wovenTintWarp * ( wovenM * ws.warp ) * ( radW + wovenLm ) + wovenTintWeft * ( ( 1.0 - wovenM ) * ws.weft ) * ( radF + wovenLm ) );
	#else
		reflectedLight.indirectSpecular += lobes * ( radiance + wovenLm );
	#endif
	#if defined( USE_ENVMAP ) && defined( STANDARD )
		vec3 sheenRadiance = getIBLRadiance( geometryViewDir, geometryNormal, wovenRS );
		reflectedLight.indirectSpecular += wovenSheenColor * wovenTable( clothDG, 128, 0, NoV, wovenRS ) * sheenRadiance;
	#endif
	#if defined( WOVEN_FIS_DIFFUSE )
		vec3 wovenEd = wovenFisIrradianceOverPi( geometryNormal );
	#else
		vec3 wovenEd = iblIrradiance * RECIPROCAL_PI;
	#endif
	#ifdef USE_LIGHTMAP
		// The card's light map (applyLightMap): E_d + E_ind / pi under the IBL diffuse weight.
		wovenEd += clothfitLightMapIrradiance * RECIPROCAL_PI;
	#endif
	#if defined( WOVEN_ROUGH_DIFFUSE )
		// every irradiance under the diffuse weight (IBL, FIS taps, light map) x Eo(NoV)
		wovenEd *= wovenOnA + wovenOnB * wovenOnAlbedoG( NoV );
	#endif
	reflectedLight.indirectDiffuse += material.diffuseColor * ws.kd * ( s * wovenYarnScaling( NoV, rE ) ) * wovenEd;
}

#undef RE_Direct
#undef RE_Direct_RectArea
#undef RE_IndirectDiffuse
#undef RE_IndirectSpecular
#define RE_Direct           RE_Direct_Woven
#define RE_IndirectDiffuse  RE_IndirectDiffuse_Woven
#define RE_IndirectSpecular RE_IndirectSpecular_Woven
`;

// View bands (session 14; injected only with them, after WOVEN_PARS' "varying vec2 vWovenWeaveUv;",
// so a program without bands is the old source text): WOVEN_VIEW_BANDS bands packed in
// WOVEN_VIEW_TEXTURES RGBA textures (weaveMapViewBands), blended by NoV in main.
const WOVEN_VIEW_PARS = /* glsl */ `
uniform sampler2D wovenViewMaps[ WOVEN_VIEW_TEXTURES ];
uniform float wovenViewCosines[ WOVEN_VIEW_BANDS ];  // strictly decreasing, as in the preset
// weaveMapViewWeights / WeaveMaps::ViewWeights: linear in nov between the nodes, clamped to the
// end bands (band 0 the most frontal).
void wovenViewWeights( const in float nov, out float w[ WOVEN_VIEW_BANDS ] ) {
	for ( int k = 0; k < WOVEN_VIEW_BANDS; ++ k ) w[ k ] = 0.0;
	if ( nov >= wovenViewCosines[ 0 ] ) { w[ 0 ] = 1.0; return; }
	if ( nov <= wovenViewCosines[ WOVEN_VIEW_BANDS - 1 ] ) { w[ WOVEN_VIEW_BANDS - 1 ] = 1.0; return; }
	for ( int k = 0; k < WOVEN_VIEW_BANDS - 1; ++ k ) {
		if ( nov <= wovenViewCosines[ k ] && nov >= wovenViewCosines[ k + 1 ] ) {
			float t = ( wovenViewCosines[ k ] - nov ) / ( wovenViewCosines[ k ] - wovenViewCosines[ k + 1 ] );
			w[ k ] = 1.0 - t;
			w[ k + 1 ] = t;
			return;
		}
	}
}
`;

// After three.js's roughness set-up: the IBL radiance three.js fetches is at r_e.
const WOVEN_ROUGHNESS = /* glsl */ `
material.roughness = wovenRE;
#if defined( WOVEN_WEAVE_MAPS )
{
	vec2 wovenW = texture2D( wovenWeaveWeights, vWovenWeaveUv ).rg;
	wovenWS = WovenWeave( wovenW.x, wovenW.y, texture2D( wovenWeaveKd, vWovenWeaveUv ).rgb, 1.0 );
}
#endif
`;

// The view bands' blend in main (uniform control flow: every texture is read, so the implicit LOD
// and the anisotropic footprint are the main maps'): NoV = clamp(dot(N, V), 0, 1) with N the
// interpolated normal of normal_fragment_begin (faceDirection applied; nonPerturbedNormal, i.e.
// before any normal map) and V three.js's geometryViewDir (render/preview/preview.cpp hit.NoV
// before the relief normal); band k's channel c is component (5 k + c) & 3 of texture
// (5 k + c) >> 2. Generated per K (the program key names K).
function wovenViewBlendGlsl(K) {
  const nc = WEAVE_MAP_CHANNELS.length, T = Math.ceil((K * nc) / 4), comp = 'xyzw';
  const lines = ['{',
    '\tfloat wovenNoVView = clamp( dot( nonPerturbedNormal, ( isOrthographic ) ? vec3( 0.0, 0.0, 1.0 ) : normalize( vViewPosition ) ), 0.0, 1.0 );',
    '\tfloat wovenVW[ WOVEN_VIEW_BANDS ];',
    '\twovenViewWeights( wovenNoVView, wovenVW );'];
  for (let j = 0; j < T; ++j) lines.push(`\tvec4 wovenVT${j} = texture2D( wovenViewMaps[ ${j} ], vWovenWeaveUv );`);
  const ch = (c) => Array.from({ length: K }, (_, k) => { const g = nc * k + c; return `wovenVW[ ${k} ] * wovenVT${g >> 2}.${comp[g & 3]}`; }).join(' + ');
  lines.push(`\twovenWS = WovenWeave( ${ch(0)}, ${ch(1)},`, `\t\tvec3( ${ch(2)},`, `\t\t\t${ch(3)},`, `\t\t\t${ch(4)} ), 1.0 );`, '}');
  return lines.join('\n');
}

/**
 * MeshWovenMaterial: brdf/woven.h on three.js's MeshStandardMaterial program. Parameters are the
 * preset's (snake_case, linear colours): base_color, specular_color, roughness, anisotropy,
 * twist (degrees), warp_share, specular_f0, forward_scattering, sheen_color, sheen_roughness,
 * diffuse_roughness (sigma of the rough diffuse On, [0, 1], default 0 = Lambert; > 0 compiles
 * WOVEN_ROUGH_DIFFUSE, and crossing 0 recompiles);
 * options: yarnLayer 'additive' (default) | 'albedo-scaled', tintWarp / tintWeft (THREE.Color);
 * ibl 'split' (default: the split sum, one PMREM read at r_e) | 'fis' (filtered importance
 * sampling of the yarn lobe, fisTaps taps, 1..64, default 16; fisDiffuseTaps 0..64 cosine taps
 * for the diffuse irradiance, default 0 = three.js's getIBLIrradiance) | 'bent' (the split sum
 * about each yarn lobe's bent normal, three.js getIBLAnisotropyRadiance style: brdf/woven.h
 * IblMode::kBent). Changing them recompiles.
 */
export class MeshWovenMaterial extends THREE.MeshStandardMaterial {
  constructor(parameters = {}, {
    yarnLayer = 'additive', tintWarp = null, tintWeft = null,
    ibl = 'split', fisTaps = WOVEN_OPTION_DEFAULTS.fis_taps, fisDiffuseTaps = WOVEN_OPTION_DEFAULTS.fis_diffuse_taps,
    yarnLobe = null, ...standard
  } = {}) {
    const p = { ...WOVEN_DEFAULTS, ...parameters };
    checkWovenDiffuseRoughness(p.diffuse_roughness, (msg) => { throw new Error(`MeshWovenMaterial: diffuse_roughness: ${msg}`); });
    super({ metalness: 0, roughness: 1, color: linear(p.base_color), ...standard });
    this.isMeshWovenMaterial = true;
    this.woven = p;
    this.yarnLayer = yarnLayer;
    if (yarnLayer !== 'additive' && yarnLayer !== 'albedo-scaled') throw new Error(`MeshWovenMaterial: yarnLayer '${yarnLayer}' (valid: additive, albedo-scaled)`);
    if (ibl !== 'split' && ibl !== 'fis' && ibl !== 'bent') throw new Error(`MeshWovenMaterial: ibl '${ibl}' (valid: split, fis, bent)`);
    if (!Number.isInteger(fisTaps) || fisTaps < 1 || fisTaps > WOVEN_FIS_MAX_TAPS) throw new Error(`MeshWovenMaterial: fisTaps ${fisTaps} (an integer in [1, ${WOVEN_FIS_MAX_TAPS}])`);
    if (!Number.isInteger(fisDiffuseTaps) || fisDiffuseTaps < 0 || fisDiffuseTaps > WOVEN_FIS_MAX_TAPS) throw new Error(`MeshWovenMaterial: fisDiffuseTaps ${fisDiffuseTaps} (an integer in [0, ${WOVEN_FIS_MAX_TAPS}])`);
    if (yarnLobe && (yarnLayer !== 'additive' || ibl !== 'split')) throw new Error(`MeshWovenMaterial: a yarnLobe needs yarnLayer 'additive' and ibl 'split' (got '${yarnLayer}', '${ibl}')`);
    this.ibl = ibl;
    this.fisTaps = fisTaps;
    this.fisDiffuseTaps = fisDiffuseTaps;
    this.tintWarp = tintWarp ? new THREE.Color().copy(tintWarp) : new THREE.Color(1, 1, 1);
    this.tintWeft = tintWeft ? new THREE.Color().copy(tintWeft) : new THREE.Color(1, 1, 1);
    this._wovenUniforms = {
      wovenSpecularColor: { value: new THREE.Color() }, wovenSheenColor: { value: new THREE.Color() },
      wovenTintWarp: { value: new THREE.Color() }, wovenTintWeft: { value: new THREE.Color() },
      wovenAlphaA: { value: 0 }, wovenAlphaC: { value: 0 }, wovenRE: { value: 0 }, wovenRS: { value: 0 },
      wovenCr: { value: 1 }, wovenSr: { value: 0 }, wovenF0: { value: 0 }, wovenBeta: { value: 0 },
      wovenM: { value: 0 }, wovenAniso: { value: 0 }, wovenPhaseK: { value: 0 }, wovenPhaseT: { value: 0 },
      wovenOnA: { value: 1 }, wovenOnB: { value: 0 },
      wovenPhase: { value: wovenPhaseTexture }, clothDG: { value: clothDGTexture },
      wovenWeaveWeights: { value: null }, wovenWeaveKd: { value: null },
      wovenWeaveTransform: { value: new THREE.Matrix3() },
      wovenViewMaps: { value: [] }, wovenViewCosines: { value: [] },
      wovenAreaLights: { value: Array.from({ length: WOVEN_AREA_LIGHTS }, () => new THREE.Vector4()) },
    };
    this.weaveMaps = null;  // a WeaveMaps (weaveMapsFromExr) or null: the uniform material
    this._setYarnLobe(yarnLobe);
    this._updateWovenUniforms();
    if (!wovenPhaseTexture) {
      wovenPhaseTable().then(() => { this.needsUpdate = true; }, () => {});
      reportTableError(wovenPhasePromise);
    }
    if (!clothDGTexture) {
      clothDGTable().then(() => { this.needsUpdate = true; }, () => {});
      reportTableError(clothDGPromise);
    }
  }

  _updateWovenUniforms() {
    const u = this._wovenUniforms, p = this.woven, lb = wovenLobes(p);
    u.wovenSpecularColor.value.copy(linear(p.specular_color));
    u.wovenSheenColor.value.copy(linear(p.sheen_color));
    u.wovenTintWarp.value.copy(this.tintWarp);
    u.wovenTintWeft.value.copy(this.tintWeft);
    u.wovenAlphaA.value = lb.alphaA; u.wovenAlphaC.value = lb.alphaC;
    u.wovenRE.value = lb.rE; u.wovenRS.value = lb.rS;
    u.wovenCr.value = lb.cr; u.wovenSr.value = lb.sr;
    u.wovenF0.value = lb.f0; u.wovenBeta.value = lb.beta; u.wovenM.value = lb.m; u.wovenAniso.value = lb.s;
    u.wovenPhaseK.value = lb.phaseK; u.wovenPhaseT.value = lb.phaseT;
    u.wovenOnA.value = lb.onA; u.wovenOnB.value = lb.onB;
    // sigma crossing 0 switches WOVEN_ROUGH_DIFFUSE (the program key names it): recompile
    if (this._roughDiffuse !== undefined && this._roughDiffuse !== lb.rough) this.needsUpdate = true;
    this._roughDiffuse = lb.rough;
    u.wovenPhase.value = wovenPhaseTexture; u.clothDG.value = clothDGTexture;
    const wm = this.weaveMaps;
    u.wovenWeaveWeights.value = wm ? wm.weightsTexture : null;
    u.wovenWeaveKd.value = wm ? wm.kdTexture : null;
    if (wm) u.wovenWeaveTransform.value.copy(wm.uvTransform);
    u.wovenViewMaps.value = wm?.viewTextures ? wm.viewTextures.slice() : [];
    u.wovenViewCosines.value = wm?.viewCosines ? wm.viewCosines.slice() : [];
  }

  /** Whether the diffuse is the rough On (diffuse_roughness > 0; false: Lambert). */
  get roughDiffuse() { return wovenOnTerms(this.woven.diffuse_roughness).rough; }

  /** The number of view bands the program blends (0: the main maps alone). */
  get viewBands() { return this.weaveMaps?.viewCosines?.length ?? 0; }

  // The far-field yarn lobe (yarnLobeOptions' result or a preset's raw "yarn_lobe" block, checked
  // here) or null; its uniforms and textures (yarnLobePack) join the material's uniforms.
  _setYarnLobe(block) {
    this._yarnLobePack?.dispose();
    this.yarnLobe = block ? yarnLobeOptions(block) : null;
    this._yarnLobePack = this.yarnLobe ? yarnLobePack(this.yarnLobe) : null;
    // The lobe's constants are in the program's source (yarnLobeGlsl; the key names their
    // digest). The IBL texture's uniform object is created once and only its value changes: a
    // compiled program whose key is unchanged is reused by three.js without onBeforeCompile, and
    // keeps reading the object it was given then.
    const u = this._wovenUniforms;
    const pk = this._yarnLobePack;
    if (u.wovenYlIbl) u.wovenYlIbl.value = pk ? pk.iblTexture : null;
    else u.wovenYlIbl = { value: pk ? pk.iblTexture : null };
  }

  /** Sets (a "yarn_lobe" block) or removes (null) the far-field yarn lobe; recompiles the program. */
  setYarnLobe(block) {
    if (block && (this.yarnLayer !== 'additive' || this.ibl !== 'split')) throw new Error('MeshWovenMaterial: a yarnLobe needs yarnLayer \'additive\' and ibl \'split\'');
    this._setYarnLobe(block);
    this.needsUpdate = true;
    return this;
  }

  dispose() {
    this._yarnLobePack?.dispose();
    super.dispose();
  }

  /** Attaches weave maps (weaveMapsFromExr) or removes them (null); recompiles the program. */
  setWeaveMaps(maps) {
    this.weaveMaps = maps ?? null;
    this._updateWovenUniforms();
    this.needsUpdate = true;
    return this;
  }

  onBeforeRender(renderer, scene, camera, geometry) {
    // A mesh without TANGENT: three.js's computeTangents, added AFTER this frame (session 27).
    // three.js r187 uploads a geometry's attributes before onBeforeRender and caches the vertex
    // bindings at the draw, so an attribute added here was never bound: the tangent read as
    // (0, 0, 0) and the lit fabric drew black on such a mesh (web/test/own-page.test.mjs). Added
    // between frames, the next frame uploads and binds it; this first frame has no tangent.
    if (!geometry.attributes.tangent && geometry.attributes.uv && geometry.index && !wovenTangentsPending.has(geometry)) {
      wovenTangentsPending.add(geometry);
      queueMicrotask(() => {
        wovenTangentsPending.delete(geometry);
        if (!geometry.attributes.tangent) geometry.computeTangents();
      });
    }
    this._updateWovenUniforms();
    // The horizon fade's lights (scene.userData.clothfitAreaLights, set by setEnvironment: the
    // environment's sun and panels, each with userData.sinAngularRadius), in view space as
    // three.js's WebGLLights computes a directional light's direction.
    const area = scene?.userData?.clothfitAreaLights ?? [];
    const slots = this._wovenUniforms.wovenAreaLights.value;
    for (let k = 0; k < slots.length; ++k) {
      const light = area[k];
      const sinR = light?.userData?.sinAngularRadius ?? 0;
      if (!light || !(sinR > 0)) { slots[k].set(0, 0, 0, 0); continue; }
      _areaDir.setFromMatrixPosition(light.matrixWorld);
      _areaTarget.setFromMatrixPosition(light.target.matrixWorld);
      _areaDir.sub(_areaTarget).transformDirection(camera.matrixWorldInverse);
      slots[k].set(_areaDir.x, _areaDir.y, _areaDir.z, sinR);
    }
  }

  onBeforeCompile(shader) {
    Object.assign(shader.uniforms, this._wovenUniforms);
    const defs = [];
    if (this.yarnLayer === 'albedo-scaled') defs.push('#define WOVEN_ALBEDO_SCALED');
    if (this.roughDiffuse) defs.push('#define WOVEN_ROUGH_DIFFUSE');
    if (this.weaveMaps) defs.push('#define WOVEN_WEAVE_MAPS');
    const K = this.viewBands;
    if (K > 0) defs.push(`#define WOVEN_VIEW_BANDS ${K}`, `#define WOVEN_VIEW_TEXTURES ${this.weaveMaps.viewTextures.length}`);
    if (this.ibl === 'bent') defs.push('#define WOVEN_BENT');
    if (this.ibl === 'fis') {
      defs.push('#define WOVEN_FIS', `#define WOVEN_FIS_TAPS ${this.fisTaps}`, `#define WOVEN_FIS_DIFFUSE_TAPS ${this.fisDiffuseTaps}`);
    }
    const yl = this._yarnLobePack;
    if (yl) {
      defs.push('#define WOVEN_YARN_LOBE', `#define WOVEN_YL_N_THETA ${yl.nTheta}`, `#define WOVEN_YL_N_PHI ${yl.nPhi}`);
    }
    // with view bands: their pars after the weave-map varying, and their blend in place of the
    // main maps' read (the program without bands is unchanged)
    let pars = WOVEN_PARS, setup = WOVEN_ROUGHNESS;
    if (yl) {
      const anchor = '// @wovenYarnLobe (yarnLobeGlsl\'s source replaces this line)\n';
      if (pars.split(anchor).length !== 2) throw new Error('MeshWovenMaterial: yarn lobe: unexpected WOVEN_PARS');
      pars = pars.replace(anchor, () => yl.glsl);
    }
    if (K > 0) {
      const anchor = 'varying vec2 vWovenWeaveUv;\nWovenWeave wovenWS;', mainRead = /#if defined\( WOVEN_WEAVE_MAPS \)\n\{[^}]*\}\n#endif/;
      if (pars.split(anchor).length !== 2 || !mainRead.test(setup)) throw new Error('MeshWovenMaterial: view bands: unexpected WOVEN_PARS / WOVEN_ROUGHNESS');
      pars = pars.replace(anchor, 'varying vec2 vWovenWeaveUv;\n' + WOVEN_VIEW_PARS + 'WovenWeave wovenWS;');
      setup = setup.replace(mainRead, wovenViewBlendGlsl(K));
    }
    injectPhysicalChunks(shader, 'MeshWovenMaterial', defs.join('\n') + '\nuniform float wovenRE;\n', pars, setup);
    routeLightMapToIblDiffuse(shader, 'MeshWovenMaterial');
    markDirectionalLights(shader, 'MeshWovenMaterial');
    const vs = shader.vertexShader;
    if (!vs.includes('void main() {') || !vs.includes('#include <project_vertex>')) throw new Error('MeshWovenMaterial: unexpected three.js vertex shader');
    shader.vertexShader = (this.weaveMaps ? '#define WOVEN_WEAVE_MAPS\n' : '') + vs.replace('void main() {', WOVEN_VERTEX_PARS + 'void main() {')
      .replace('#include <project_vertex>', '#include <project_vertex>\n' + WOVEN_VERTEX);
  }

  customProgramCacheKey() {
    const ibl = this.ibl === 'fis' ? `fis${this.fisTaps}/${this.fisDiffuseTaps}` : this.ibl;
    const yl = this._yarnLobePack;
    const lobe = yl ? [`yarn-lobe${yl.shape}/${yl.nTheta}x${yl.nPhi}/${yl.digest}`] : [];
    const maps = this.weaveMaps ? (this.viewBands ? `maps-views${this.viewBands}` : 'maps') : 'uniform';
    const rough = this.roughDiffuse ? ['rough-diffuse'] : [];
    return ['woven', this.yarnLayer, maps, ibl, ...lobe, ...rough].join(':');
  }

  copy(source) {
    super.copy(source);
    if (source.isMeshWovenMaterial) {
      this.woven = { ...source.woven };
      this.yarnLayer = source.yarnLayer;
      this.ibl = source.ibl;
      this.fisTaps = source.fisTaps;
      this.fisDiffuseTaps = source.fisDiffuseTaps;
      this.tintWarp = source.tintWarp.clone();
      this.tintWeft = source.tintWeft.clone();
      this.weaveMaps = source.weaveMaps;
      this._wovenUniforms = THREE.UniformsUtils.clone(source._wovenUniforms);
      this._yarnLobePack = null;
      this._setYarnLobe(source.yarnLobe);
      this._updateWovenUniforms();
    }
    return this;
  }
}

// brdf/woven.h kParameterTable defaults.
const WOVEN_DEFAULTS = Object.freeze({
  base_color: [0.5, 0.5, 0.5], specular_color: [0.5, 0.5, 0.5], roughness: 0.6, anisotropy: 0.7,
  twist: 0, warp_share: 0.5, specular_f0: 0.05, forward_scattering: 2, sheen_color: [0, 0, 0],
  sheen_roughness: 0.6, diffuse_roughness: 0,
});

// ---------------------------------------------------------------------------------------------
// Weave maps (issue 12; the C++ side: render/preview/weave_maps.h, docs/fitting.md "Weave maps").
// A woven or physical-aniso preset may name, in its top-level "weave_maps", a float EXR of one
// weave period: channels warp, weft, kd.R, kd.G, kd.B, all LINEAR ratios to the tile mean.
// Convention (the C++ one): texel (i, j), i = column from the left, j = row from the TOP of the
// image, covers TEXCOORD_0 [i, i+1) / (size R) x [j, j+1) / (size R), R = uv_repeats (the
// preset's value wins over the file's clothfit:uv_repeats), texel centres at +0.5, REPEAT.
// In three.js: a DataTexture whose data row 0 is the image's top row with flipY = false puts
// that row at t = 0, i.e. at TEXCOORD_0 v = 0 (glTF's v runs down from the top, GLTFLoader does
// not flip), and the uv transform scales by R (texture.repeat = (R, R), offset 0, the same
// matrix three.js builds for a map's uvTransform). Filtering is the GPU's own: RepeatWrapping,
// LinearFilter / LinearMipmapLinearFilter, implicit LOD from the quad's uv derivatives, and
// texture.anisotropy = the preset's weave_maps.anisotropy (an integer in [1, 16], missing = 1:
// isotropic, GL's default), clamped to the renderer's getMaxAnisotropy() when options.renderer
// (or options.maxAnisotropy) is given, with a console.info naming both values; three.js clamps
// to the same limit itself (WebGLTextures). The C++ preview filters as
// EXT_texture_filter_anisotropic specifies (render/preview/weave_maps.h; docs/web.md). The mip chain is NOT generated by the GPU (gl.generateMipmap's filter
// is implementation-defined): it is built here, 2 x 2 box averages down to 1 x 1, in double and
// rounded to float32 exactly as WeaveMaps::FromLevel0 / BuildBoxMips do, and uploaded level by
// level; level 0 is renormalised to a tile mean of 1 per channel as the C++ reader does. The
// textures are 32-bit float (RG32F weights, RGBA32F kd with alpha 1), filtered with
// OES_texture_float_linear (SwiftShader and desktop GPUs expose it). Without that extension (iOS
// Safari, many Android GPUs) a 32-bit float texture is not filterable, WebGL treats it as
// incomplete and the fabric draws nearly black (measured, session 23), so the textures are then
// uploaded as HALF floats, which WebGL2 always filters (rounding each texel to 11 significant bits,
// about 5e-4 relative): floatTexturesFilterable() decides, `halfFloat` forces either way.
// Not drawn by web/ (refused with a clear error): a relief normal map (channels N.X/N.Y/N.Z,
// `--weave-maps relief`) and a glint map ("glint_file", `--weave-maps glint`).

export const WEAVE_MAP_CHANNELS = Object.freeze(['warp', 'weft', 'kd.R', 'kd.G', 'kd.B']);

// Does this WebGL context filter 32-bit float textures (OES_texture_float_linear)? With a
// renderer: its own context (three.js enables the extension when it exists). Without one: a
// throw-away WebGL2 context, probed once per page; outside a browser (node): true, i.e. 32-bit
// floats as before. A probe that cannot create a context answers false (half floats: filterable
// everywhere, so the safe side).
let floatLinearProbe;
export function floatTexturesFilterable(renderer) {
  if (renderer?.extensions?.has) return renderer.extensions.has('OES_texture_float_linear');
  if (floatLinearProbe === undefined) {
    floatLinearProbe = true;
    if (typeof document !== 'undefined' && document.createElement) {
      try {
        const gl = document.createElement('canvas').getContext('webgl2');
        floatLinearProbe = Boolean(gl?.getExtension('OES_texture_float_linear'));
        gl?.getExtension('WEBGL_lose_context')?.loseContext();
      } catch {
        floatLinearProbe = false;
      }
    }
  }
  return floatLinearProbe;
}

// The float textures' upload type: `halfFloat` when the caller says (true / false), else half
// floats exactly when the context cannot filter 32-bit ones (logged once).
let halfFloatNoted = false;
function useHalfFloat(halfFloat, renderer) {
  if (halfFloat !== undefined && halfFloat !== null) return Boolean(halfFloat);
  const half = !floatTexturesFilterable(renderer);
  if (half && !halfFloatNoted) {
    halfFloatNoted = true;
    console.info(`clothfit: ${renderer ? "the renderer's WebGL context has" : 'a probed WebGL2 context has (or no context could be made, so'} no OES_texture_float_linear${renderer ? '' : ')'}: weave maps and light maps are uploaded as half floats (filterable; about 5e-4 relative rounding)`);
  }
  return half;
}

function boxMip(src, s, nc) {  // s = the source side; returns side s/2
  const h = s >> 1, out = new Float32Array(h * h * nc);
  for (let j = 0; j < h; ++j) {
    for (let i = 0; i < h; ++i) {
      for (let c = 0; c < nc; ++c) {
        const at = (ii, jj) => src[(jj * s + ii) * nc + c];
        out[(j * h + i) * nc + c] = 0.25 * (at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) + at(2 * i + 1, 2 * j + 1));
      }
    }
  }
  return out;
}

function weaveTexture(levels, size, nc, format, type, anisotropy = 1) {
  const mipmaps = [];
  for (let l = 0, s = size; l < levels.length; ++l, s >>= 1) mipmaps.push({ data: levels[l], width: s, height: s });
  const t = new THREE.DataTexture(levels[0], size, size, format, type);
  t.mipmaps = mipmaps;
  t.generateMipmaps = false;
  t.wrapS = THREE.RepeatWrapping;
  t.wrapT = THREE.RepeatWrapping;
  t.magFilter = THREE.LinearFilter;
  t.minFilter = THREE.LinearMipmapLinearFilter;
  t.anisotropy = anisotropy;
  t.flipY = false;
  t.colorSpace = THREE.NoColorSpace;
  t.needsUpdate = true;
  return t;
}

// Level 0 of a ratio map: the named channels of an EXR image, each divided by its mean over the
// n texels (interleaved, channel k at t * names.length + k). Calls fail(message) on a negative
// or non-finite texel or a zero mean. Float32Array rounds as float(double / double), as the
// C++ reader (render/preview/weave_maps.cpp FromLevel0).
function ratioLevel0(img, names, n, fail) {
  const nc = names.length;
  const l0 = new Float32Array(n * nc);
  names.forEach((c, k) => {
    const src = img.channels[c];
    let mean = 0;
    for (let t = 0; t < n; ++t) {
      const x = src[t];
      if (!Number.isFinite(x) || x < 0) fail(`channel ${c} has a negative or non-finite texel`);
      mean += x;
    }
    mean /= n;
    if (!(mean > 0)) fail(`channel ${c} has a zero mean`);
    for (let t = 0; t < n; ++t) l0[t * nc + k] = src[t] / mean;
  });
  return l0;
}

/**
 * Weave maps from an EXR (ArrayBuffer) as clothfit writes them. `field` is the preset's
 * "weave_maps" object (its uv_repeats wins), `name` names the file in errors. Returns
 * {size, uvRepeats, levels: [Float32Array size_l^2 x 5 (warp, weft, kd.R, kd.G, kd.B)],
 * weightsTexture (RG: warp, weft), kdTexture (RGBA: kd, 1), uvTransform (THREE.Matrix3),
 * anisotropyTexture(), dispose()}.
 */
export function weaveMapsFromExr(buffer, { field = {}, name = 'weave maps', halfFloat, renderer, maxAnisotropy = Infinity } = {}) {
  const fail = (msg) => { throw new Error(`${name}: weave maps: ${msg}`); };
  halfFloat = useHalfFloat(halfFloat, renderer);
  const requested = weaveMapAnisotropy(field);
  const anisotropy = Math.max(1, Math.min(requested, Math.floor(maxAnisotropy)));
  if (anisotropy !== requested) console.info(`clothfit: weave_maps.anisotropy ${requested} clamped to the renderer's max anisotropy ${anisotropy} (renderer.capabilities.getMaxAnisotropy())`);
  const img = parseExr(buffer, name);
  if (img.width !== img.height) fail('not square');
  const size = img.width;
  if (size < 1 || size > 4096 || (size & (size - 1))) fail(`size ${size} is not a power of two in [1, 4096]`);
  for (const c of WEAVE_MAP_CHANNELS) if (!img.channels[c]) fail(`no channel ${c}`);
  if (img.channels['N.X'] || img.channels['N.Y'] || img.channels['N.Z']) fail('relief normal channels N.X/N.Y/N.Z are not drawn by web/ (fit with --weave-maps auto or indicator)');
  let uvRepeats = Number(img.attributes['clothfit:uv_repeats']);
  if (field.uv_repeats !== undefined) {
    if (typeof field.uv_repeats !== 'number' || !(field.uv_repeats > 0) || !Number.isFinite(field.uv_repeats)) fail('weave_maps.uv_repeats: expected a positive number');
    uvRepeats = field.uv_repeats;
  }
  if (!(uvRepeats > 0) || !Number.isFinite(uvRepeats)) fail('no clothfit:uv_repeats metadata (and none in the preset)');
  const n = size * size, nc = WEAVE_MAP_CHANNELS.length;
  const l0 = ratioLevel0(img, WEAVE_MAP_CHANNELS, n, fail);
  const levels = [l0];
  for (let s = size; s > 1; s >>= 1) levels.push(boxMip(levels[levels.length - 1], s, nc));
  const type = halfFloat ? THREE.HalfFloatType : THREE.FloatType;
  const pack = (f) => levels.map((lv) => {
    const m = lv.length / nc, out = f(m);
    return out;
  });
  const weights = pack((m) => new Float32Array(m * 2)), kd = pack((m) => new Float32Array(m * 4));
  levels.forEach((lv, l) => {
    for (let t = 0; t < lv.length / nc; ++t) {
      weights[l][t * 2] = lv[t * nc]; weights[l][t * 2 + 1] = lv[t * nc + 1];
      for (let c = 0; c < 3; ++c) kd[l][t * 4 + c] = lv[t * nc + 2 + c];
      kd[l][t * 4 + 3] = 1;
    }
  });
  const toHalf = (arrs) => (halfFloat ? arrs.map((a) => Uint16Array.from(a, (x) => THREE.DataUtils.toHalfFloat(x))) : arrs);
  const views = weaveMapViewBands(img, field, name, size, type, anisotropy, toHalf);
  const maps = {
    size, uvRepeats, levels, field,
    // View bands (session 14; weaveMapViewBands): null unless the preset names view_cosines.
    viewCosines: views?.cosines ?? null, viewLevels: views?.levels ?? null, viewTextures: views?.textures ?? null,
    anisotropy, requestedAnisotropy: requested,
    weightsTexture: weaveTexture(toHalf(weights), size, 2, THREE.RGFormat, type, anisotropy),
    kdTexture: weaveTexture(toHalf(kd), size, 4, THREE.RGBAFormat, type, anisotropy),
    // TEXCOORD_0 -> weave-texture coordinates: scale by R (Texture.setUvTransform(0, 0, R, R, 0, 0, 0)).
    uvTransform: new THREE.Matrix3().setUvTransform(0, 0, uvRepeats, uvRepeats, 0, 0, 0),
    _aniso: null,
    // three.js anisotropyMap for physical-aniso (see anisotropyFromWeave): made on first use.
    anisotropyTexture() {
      if (!this._aniso) {
        const a = [anisotropyFromWeave(l0, size)];
        for (let s = size; s > 1; s >>= 1) a.push(boxMip(a[a.length - 1], s, 4));
        this._aniso = weaveTexture(toHalf(a), size, 4, THREE.RGBAFormat, type, anisotropy);
      }
      return this._aniso;
    },
    dispose() { this.weightsTexture.dispose(); this.kdTexture.dispose(); this._aniso?.dispose(); this.viewTextures?.forEach((t) => t.dispose()); },
  };
  maps.kdTexture.repeat.set(uvRepeats, uvRepeats);
  return maps;
}

// ---- view-dependent weave maps (session 14; docs/web.md "View-dependent weave maps") ----------
// The EXR keeps its 5 all-views channels and may carry K view bands, channels view{k}.warp,
// view{k}.weft, view{k}.kd.R, view{k}.kd.G, view{k}.kd.B, baked from the pairs of one view cosine
// each (metadata clothfit:view_cosines "c0 c1 ...", strictly decreasing in (0, 1]). They are
// drawn only when the preset's weave_maps names the same cosines ("view_cosines": [...], 2 to 8
// numbers): render/preview/weave_maps.cpp LoadPresetWeaveMaps, which requires the file's list to
// agree within 1e-9. Extra view channels without the preset's view_cosines are ignored (the
// preset draws exactly as before). MeshWovenMaterial blends the bands per pixel by NoV
// (weaveMapViewWeights); physical-aniso draws the 5 main channels only.
export const WEAVE_MAP_MAX_VIEW_BANDS = 8;

/** The preset's weave_maps.view_cosines checked (2..8 numbers, strictly decreasing, in (0, 1]), or null. */
export function weaveMapViewCosines(field) {
  if (field === null || typeof field !== 'object' || field.view_cosines === undefined) return null;
  const v = field.view_cosines;
  const fail = (why) => { throw new Error(`loadClothfitPreset: weave_maps.view_cosines: ${why}`); };
  if (!Array.isArray(v)) fail(`expected an array of 2 to ${WEAVE_MAP_MAX_VIEW_BANDS} numbers, got ${v === null ? 'null' : typeof v}`);
  if (v.length < 2 || v.length > WEAVE_MAP_MAX_VIEW_BANDS) fail(`${v.length} numbers, expected 2 to ${WEAVE_MAP_MAX_VIEW_BANDS}`);
  v.forEach((c, k) => {
    if (typeof c !== 'number' || !Number.isFinite(c)) fail(`[${k}]: expected a finite number, got ${typeof c === 'number' ? String(c) : c === null ? 'null' : typeof c}`);
    if (!(c > 0) || c > 1) fail(`[${k}]: ${c} is not in (0, 1]`);
    if (k > 0 && !(c < v[k - 1])) fail(`[${k}]: ${c} is not below [${k - 1}] ${v[k - 1]} (expected strictly decreasing)`);
  });
  return v.slice();
}

/**
 * The blend weights of the view bands at view cosine nov (render/preview/weave_maps.cpp
 * WeaveMaps::ViewWeights): cosines strictly decreasing (band 0 the most frontal); piecewise
 * linear interpolation in nov between the nodes (the hat functions over the ascending cosines),
 * clamped to the end bands outside [min, max]. Sum 1; exactly one 1 at a node.
 */
export function weaveMapViewWeights(cosines, nov) {
  const K = cosines.length, w = new Array(K).fill(0);
  const x = Number.isFinite(nov) ? nov : 0;
  if (x >= cosines[0]) { w[0] = 1; return w; }
  if (x <= cosines[K - 1]) { w[K - 1] = 1; return w; }
  for (let k = 0; k + 1 < K; ++k) {
    if (x <= cosines[k] && x >= cosines[k + 1]) {
      const t = (cosines[k] - x) / (cosines[k] - cosines[k + 1]);
      w[k] = 1 - t; w[k + 1] = t;
      break;
    }
  }
  return w;
}

// Reads the bands the preset names (null without view_cosines): each band renormalised to a tile
// mean of 1 and box-mipped exactly as the main maps (WeaveMaps::SetViews -> FromLevel0). Upload:
// the K x 5 band channels packed in order (channel g = 5 k + c, c = warp, weft, kd.R, kd.G, kd.B)
// into ceil(5 K / 4) RGBA textures (texture g >> 2, component g & 3; unused components 1), with the
// main maps' settings (float, REPEAT, trilinear, anisotropy, own box mips): 4 samplers for the
// bake's 3 bands, 10 for 8, instead of 2 per band. Filtering is per component, so the packing
// changes no value.
function weaveMapViewBands(img, field, name, size, type, anisotropy, toHalf) {
  const cosines = weaveMapViewCosines(field);
  if (!cosines) return null;
  const K = cosines.length, nc = WEAVE_MAP_CHANNELS.length, n = size * size;
  const fail = (msg) => { throw new Error(`${name}: weave maps: ${msg}`); };
  const attr = img.attributes['clothfit:view_cosines'];
  if (attr === undefined) fail(`no clothfit:view_cosines metadata (the preset's weave_maps.view_cosines names ${K} view bands)`);
  const fileCos = String(attr).trim().split(/\s+/).map(Number);
  if (fileCos.length !== K) fail(`clothfit:view_cosines names ${fileCos.length} view bands, the preset's weave_maps.view_cosines ${K}`);
  fileCos.forEach((c, k) => { if (!(Math.abs(c - cosines[k]) <= 1e-9)) fail(`clothfit:view_cosines differs from the preset's weave_maps.view_cosines at [${k}]`); });
  const bands = [];
  for (let k = 0; k < K; ++k) {
    const names = WEAVE_MAP_CHANNELS.map((c) => `view${k}.${c}`);
    for (const ch of names)
      if (!img.channels[ch]) fail(`no channel ${ch} (weave_maps.view_cosines names ${K} view bands: view0..view${K - 1}.{${WEAVE_MAP_CHANNELS.join(',')}})`);
    const l0 = ratioLevel0(img, names, n, fail);
    const lv = [l0];
    for (let s = size; s > 1; s >>= 1) lv.push(boxMip(lv[lv.length - 1], s, nc));
    bands.push(lv);
  }
  const T = Math.ceil((K * nc) / 4), textures = [];
  for (let j = 0; j < T; ++j) {
    const lvls = bands[0].map((_, l) => {
      const m = bands[0][l].length / nc, out = new Float32Array(m * 4).fill(1);
      for (let q = 0; q < 4; ++q) {
        const g = 4 * j + q;
        if (g >= K * nc) break;
        const src = bands[Math.floor(g / nc)][l], c = g % nc;
        for (let t = 0; t < m; ++t) out[t * 4 + q] = src[t * nc + c];
      }
      return out;
    });
    textures.push(weaveTexture(toHalf(lvls), size, 4, THREE.RGBAFormat, type, anisotropy));
  }
  return { cosines, levels: bands, textures };
}

// The preset's weave_maps.anisotropy (texture.anisotropy of every map; render/preview/weave_maps.h
// PresetMapAnisotropy): missing -> 1; else an integer in [1, 16], as the C++ reader requires
// (a literal 16.0 is refused by presetIntegerLiterals on the preset's text, as C++ refuses it).
export function weaveMapAnisotropy(field) {
  if (field === null || typeof field !== 'object' || field.anisotropy === undefined) return 1;
  const a = field.anisotropy;
  if (typeof a !== 'number' || !Number.isInteger(a) || a < 1 || a > 16) throw new Error(`weave_maps.anisotropy: expected an integer in [1, 16] (texture.anisotropy), got ${typeof a === 'number' ? String(a).slice(0, 40) : typeof a}`);
  return a;
}

// The preset's integer fields written with a fraction or an exponent in the JSON text ("fis_taps":
// 16.0), which JSON.parse turns into the integer 16 and the C++ reader (nlohmann is_number_integer)
// refuses: woven.fis_taps, woven.fis_diffuse_taps, weave_maps.anisotropy, at exactly those paths
// (a float "anisotropy" or "fis_taps" elsewhere in the preset is not checked, as in C++). The text
// is walked with a stack of the keys of the open objects (strings with escapes and braces inside
// them are skipped as strings); call it on text JSON.parse accepted. Throws naming the field, in
// the message shape of the other checks; the literal echoed is digits only, at most 40 characters.
const PRESET_INTEGER_FIELDS = new Map([
  ['woven.fis_taps', 'loadClothfitPreset: woven.fis_taps: expected an integer (JSON integer literal)'],
  ['woven.fis_diffuse_taps', 'loadClothfitPreset: woven.fis_diffuse_taps: expected an integer (JSON integer literal)'],
  ['weave_maps.anisotropy', 'weave_maps.anisotropy: expected an integer in [1, 16] (JSON integer literal)'],
  ['woven.yarn_lobe.nodes', 'loadClothfitPreset: woven.yarn_lobe.nodes: expected an integer (JSON integer literal)'],
  ['woven.yarn_lobe.ibl.n_theta', 'loadClothfitPreset: woven.yarn_lobe.ibl.n_theta: expected an integer (JSON integer literal)'],
  ['woven.yarn_lobe.ibl.n_phi', 'loadClothfitPreset: woven.yarn_lobe.ibl.n_phi: expected an integer (JSON integer literal)'],
]);
export function presetIntegerLiterals(text) {
  const keys = [];  // per open container: the current key (object) or '#' (array)
  let expectKey = false;
  for (let i = 0; i < text.length;) {
    const c = text[i];
    if (c === '{') { keys.push(null); expectKey = true; ++i; continue; }
    if (c === '[') { keys.push('#'); expectKey = false; ++i; continue; }
    if (c === '}' || c === ']') { keys.pop(); expectKey = false; ++i; continue; }
    if (c === ',') { expectKey = keys.length > 0 && keys[keys.length - 1] !== '#'; ++i; continue; }
    if (c === '"') {
      let j = i + 1;
      while (j < text.length && text[j] !== '"') j += text[j] === '\\' ? 2 : 1;
      if (expectKey) { keys[keys.length - 1] = JSON.parse(text.slice(i, j + 1)); expectKey = false; }
      i = j + 1;
      continue;
    }
    if (c === '-' || (c >= '0' && c <= '9')) {
      let j = i;
      while (j < text.length && /[-+0-9.eE]/.test(text[j])) ++j;
      const lit = text.slice(i, j), msg = PRESET_INTEGER_FIELDS.get(keys.join('.'));
      if (msg !== undefined && /[.eE]/.test(lit)) throw new Error(`${msg}, got ${lit.slice(0, 40)}`);
      i = j;
      continue;
    }
    ++i;  // ':', whitespace, the letters of true / false / null
  }
}

// The anisotropyMap texel a weave-map texel stands for (render/preview/preview.cpp
// AnisoFromWeave, the issue's along-the-yarn mapping): direction t (+u, warp) where the warp
// weight dominates (warp >= weft), b (+v, weft) otherwise; strength |warp - weft| / (warp + weft).
// three.js encoding (KHR_materials_anisotropy): RG = direction * 0.5 + 0.5, B = strength; A = 1.
export function anisotropyFromWeave(level0, size) {
  const nc = WEAVE_MAP_CHANNELS.length, n = size * size, out = new Float32Array(n * 4);
  for (let t = 0; t < n; ++t) {
    const wa = level0[t * nc], wb = level0[t * nc + 1];
    const warp = wa >= wb;
    out[t * 4] = warp ? 1 : 0.5;
    out[t * 4 + 1] = warp ? 0.5 : 1;
    out[t * 4 + 2] = wa + wb > 0 ? Math.abs(wa - wb) / (wa + wb) : 0;
    out[t * 4 + 3] = 1;
  }
  return out;
}

// Where a preset's weave-map file is fetched from (docs/preset-format.md "Weave maps: `uri` and
// `file`"). "uri" is read first: a path relative to the preset's URL, generic "/" separators; an
// absolute path, a scheme ("http:", "data:", ...), a backslash, a control character or ".."
// that leaves the preset's directory is refused (the same rules as the C++ readers,
// render::ResolvePresetWeaveMapPaths). Only without a "uri" is "file" used: absolute (the fit
// writes the absolute path) or relative; a relative one resolves against the preset's URL, an
// absolute one becomes its base name next to the preset (the fit writes <stem>.weave.exr next to
// <stem>.json). options.resolveWeaveMapPath(file, presetUrl) overrides the "file" rule (e.g. a
// server that maps file paths); it is not asked for a "uri".
export function weaveMapUriUrl(uri, presetUrl, fieldName = 'weave_maps.uri') {
  const shown = JSON.stringify(uri);
  const bad = (why) => new Error(`${fieldName}: ${shown} ${why}`);
  if (typeof uri !== 'string' || uri.length === 0) throw bad('must be a non-empty string');
  if (/[\u0000-\u001f\u007f\\%]/.test(uri)) throw bad('has a control character, a backslash or a "%" (a percent-escape could hide "..")');
  if (uri.startsWith('/') || /^[A-Za-z][A-Za-z0-9+.-]*:/.test(uri)) throw bad('must be relative to the preset (no scheme, no leading "/")');
  let depth = 0;
  for (const part of uri.split('/')) {
    if (part === '..') { if (--depth < 0) throw bad('escapes the preset\'s directory ("..")'); }
    else if (part !== '' && part !== '.') ++depth;
  }
  const base = new URL(presetUrl, globalThis.location?.href ?? 'file:///');
  const href = new URL(uri, base).href;
  if (!href.startsWith(new URL('./', base).href)) throw bad('escapes the preset\'s directory');
  return href;
}

export function weaveMapUrl(file, presetUrl, options = {}) {
  if (options.resolveWeaveMapPath) return options.resolveWeaveMapPath(file, presetUrl);
  const base = new URL(presetUrl, globalThis.location?.href ?? 'file:///');
  if (file.startsWith('/') || /^[A-Za-z]:[\\/]/.test(file)) return new URL(file.split(/[\\/]/).pop(), base).href;
  return new URL(file, base).href;
}

// Bounded downloads (session 23): the byte limits of the C++ readers (render/scene/input_limits.h:
// kMaxJsonFileBytes 16 MiB for cards and presets, kMaxImageFileBytes 512 MiB for images). A
// response whose Content-Length says more is refused before its body is read; otherwise the body
// is read in chunks and the download stops as soon as it passes the limit, so a hostile or
// mistaken URL cannot make the page buffer gigabytes before a parser sees them.
export const FETCH_LIMITS = Object.freeze({ json: 16 * 1024 * 1024, image: 512 * 1024 * 1024 });
export async function fetchBounded(url, maxBytes, what = 'file') {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  const declared = Number(r.headers?.get?.('content-length') ?? NaN);
  if (Number.isFinite(declared) && declared > maxBytes) {
    r.body?.cancel?.();
    throw new Error(`${url}: ${what} of ${declared} bytes, over the limit of ${maxBytes}`);
  }
  if (!r.body?.getReader) {
    const b = new Uint8Array(await r.arrayBuffer());
    if (b.byteLength > maxBytes) throw new Error(`${url}: ${what} over the limit of ${maxBytes} bytes`);
    return b;
  }
  const reader = r.body.getReader(), chunks = [];
  let total = 0;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    total += value.byteLength;
    if (total > maxBytes) {
      reader.cancel();
      throw new Error(`${url}: ${what} over the limit of ${maxBytes} bytes (stopped reading at ${total})`);
    }
    chunks.push(value);
  }
  const out = new Uint8Array(total);
  let o = 0;
  for (const c of chunks) { out.set(c, o); o += c.byteLength; }
  return out;
}

/** Fetches and parses the weave maps a preset's "weave_maps" field names (or null if none). */
export async function fetchWeaveMaps(preset, presetUrl, options = {}) {
  const field = preset?.weave_maps;
  if (field === undefined || field === null) return null;
  const hasUri = field !== null && typeof field === 'object' && field.uri !== undefined;
  if (typeof field !== 'object' || (!hasUri && typeof field.file !== 'string')) throw new Error('weave_maps: expected an object with a string "uri" or "file"');
  if (field.glint_file !== undefined || field.glint_uri !== undefined) throw new Error('weave_maps.glint_file: glint maps are not drawn by web/ (fit with --weave-maps auto or indicator)');
  const url = hasUri ? weaveMapUriUrl(field.uri, presetUrl) : weaveMapUrl(field.file, presetUrl, options);
  let bytes;
  try {
    bytes = await fetchBounded(url, FETCH_LIMITS.image, 'weave maps');
  } catch (e) {
    throw new Error(`weave_maps.${hasUri ? 'uri' : 'file'}: ${e.message}`);
  }
  const maxAnisotropy = options.maxAnisotropy ?? options.renderer?.capabilities?.getMaxAnisotropy?.() ?? Infinity;
  return weaveMapsFromExr(bytes, { field, name: hasUri ? field.uri : field.file, halfFloat: options.halfFloat, renderer: options.renderer, maxAnisotropy });
}

// ---------------------------------------------------------------------------------------------
// The scene card's light map (session 13; docs/web.md "The light map"). A card with
// "visibility": {"light_map": ...} makes `clothfit render-preview --light-map-out F.exr` bake the
// fabric mesh's one-bounce indirect irradiance over its TEXCOORD_0 (render/preview/visibility.h):
// RGB = irradiance E (linear Rec.709, the lights' units; three.js lightMapIntensity 1), size x
// size texels, metadata clothfit:uv_box "u0 v0 u1 v1": texel (i, j) sits at uv = uv0 +
// (i + 0.5, j + 0.5) / size x (uv1 - uv0), row j = 0 is the FIRST row of the file and is v = v0.
// Drawn here as three.js draws material.lightMap: a float RGBA DataTexture (flipY false, so data
// row 0 is texture t = 0 = glTF v0, as GLTFLoader does not flip uv), LinearFilter, no mipmaps,
// ClampToEdge, NoColorSpace (linear), uv channel 0 with offset = -uv0 / (uv1 - uv0) and repeat =
// 1 / (uv1 - uv0). Fabric material only: the preview gives non-fabric meshes no light map.

/** The clothfit:uv_box of a light-map EXR ("u0 v0 u1 v1", or 4 numbers): [u0, v0, u1, v1]. */
export function lightMapUvBox(box, name = 'light map') {
  const v = typeof box === 'string' ? box.trim().split(/\s+/).map(Number) : Array.isArray(box) ? box.map(Number) : [];
  if (v.length !== 4 || !v.every(Number.isFinite) || !(v[2] > v[0]) || !(v[3] > v[1])) {
    throw new Error(`${name}: clothfit:uv_box: expected "u0 v0 u1 v1" with u1 > u0 and v1 > v0, got ${JSON.stringify(box)?.slice(0, 80)}`);
  }
  return v;
}

/**
 * A light-map texture from a parsed EXR (web/exr.js parseExr) or its bytes (ArrayBuffer / typed
 * array). meta: {name (in errors), uvBox (overrides the file's clothfit:uv_box), halfFloat (true /
 * false; default: half floats exactly when floatTexturesFilterable(meta.renderer) is false)}.
 * Returns a THREE.DataTexture (RGBA, A = 1) with the conventions above; texture.userData.clothfit
 * = {uvBox, size}.
 */
const HALF_MAX = 65504;
export function lightMapTextureFromExr(exr, meta = {}) {
  const name = meta.name ?? 'light map';
  const img = exr && exr.channels ? exr : parseExr(exr, name);
  const { width: w, height: h } = img;
  for (const c of ['R', 'G', 'B']) if (!img.channels[c]) throw new Error(`${name}: light map: no channel ${c}`);
  const uvBox = lightMapUvBox(meta.uvBox ?? img.attributes?.['clothfit:uv_box'], name);
  const data = new Float32Array(w * h * 4);
  for (let t = 0; t < w * h; ++t) {
    for (let k = 0; k < 3; ++k) {
      const x = img.channels['RGB'[k]][t];
      if (!Number.isFinite(x) || x < 0) throw new Error(`${name}: light map: texel ${t} channel ${'RGB'[k]} is negative or not finite (${x})`);
      data[t * 4 + k] = x;
    }
    data[t * 4 + 3] = 1;
  }
  const half = useHalfFloat(meta.halfFloat, meta.renderer);
  if (half) {  // irradiance above the half range (65504): clamped here, with one warning (three.js's toHalfFloat would warn per value)
    let over = 0;
    for (let i = 0; i < data.length; ++i) if (data[i] > HALF_MAX) { data[i] = HALF_MAX; ++over; }
    if (over) console.warn(`clothfit: ${name}: ${over} light-map values above ${HALF_MAX} clamped to it (half-float upload)`);
  }
  const type = half ? THREE.HalfFloatType : THREE.FloatType;
  const t = new THREE.DataTexture(half ? Uint16Array.from(data, (x) => THREE.DataUtils.toHalfFloat(x)) : data, w, h, THREE.RGBAFormat, type);
  t.flipY = false;                 // data row 0 (the file's first row) = t 0 = glTF v0
  t.magFilter = THREE.LinearFilter;
  t.minFilter = THREE.LinearFilter;
  t.generateMipmaps = false;
  t.wrapS = THREE.ClampToEdgeWrapping;
  t.wrapT = THREE.ClampToEdgeWrapping;
  t.colorSpace = THREE.NoColorSpace;  // linear irradiance
  t.channel = 0;                   // TEXCOORD_0
  const [u0, v0, u1, v1] = uvBox;
  t.offset.set(-u0 / (u1 - u0), -v0 / (v1 - v0));
  t.repeat.set(1 / (u1 - u0), 1 / (v1 - v0));
  t.name = name;
  t.userData.clothfit = { uvBox, width: w, height: h };
  t.needsUpdate = true;
  return t;
}

/**
 * Sets the card's baked light map on a fabric material (any of loadClothfitPreset's: standard,
 * physical-sheen / gltf-sheen / physical-aniso (three.js's own light-map path), MeshClothMaterial,
 * MeshWovenMaterial (the light map joins their IBL diffuse, routeLightMapToIblDiffuse)).
 * exrData: a parsed EXR, its bytes, a texture from lightMapTextureFromExr, or null (removes it).
 * meta: as lightMapTextureFromExr, plus intensity (lightMapIntensity, default 1). Returns the
 * texture (or null); the caller disposes it.
 */
export function applyLightMap(material, exrData, meta = {}) {
  if (!material?.isMeshStandardMaterial) throw new Error('applyLightMap: expected a MeshStandardMaterial-based fabric material');
  const texture = exrData == null ? null : exrData.isTexture ? exrData : lightMapTextureFromExr(exrData, meta);
  if (Boolean(material.lightMap) !== Boolean(texture)) material.needsUpdate = true;  // USE_LIGHTMAP changes
  material.lightMap = texture;
  material.lightMapIntensity = meta.intensity ?? 1;
  return texture;
}

/** Fetches a light-map EXR (url) and returns its texture (lightMapTextureFromExr). */
export async function fetchLightMap(url, meta = {}) {
  return lightMapTextureFromExr(await fetchBounded(url, FETCH_LIMITS.image, 'light map'), { name: String(url), ...meta });
}

// ---------------------------------------------------------------------------------------------
// Presets (docs/preset-format.md). One factory per model name; parameters not in the preset take
// the model's table default (the kParameterTable of brdf/<model>.h). A model added later (e.g.
// 'woven') registers itself with registerClothfitModel(name, {defaults, make}).

const linear = (rgb) => new THREE.Color(rgb[0], rgb[1], rgb[2]);
const SIDES = { front: THREE.FrontSide, back: THREE.BackSide, double: THREE.DoubleSide };

const MODELS = new Map();

// Each model's `ranges`: the values a preset may give per parameter, inclusive, as the C++ reader
// checks them (render/scene/material.cpp PresetRange: the table's range, except that roughness
// may be given below the engine clamp, down to 0; `clothfit models --json` "preset_range", which
// tests/browser/unit.mjs compares with these). A parameter's size is its default's (number or
// [r, g, b]).
const UNIT = Object.freeze([0, 1]);

export function registerClothfitModel(name, model) {
  MODELS.set(name, model);
}

export function clothfitModels() { return [...MODELS.keys()]; }

/**
 * A registered model's parameter table: [{name, size, default, preset_range: [lo, hi]}] in the
 * preset's order of defaults, the values loadClothfitPreset accepts (compare `clothfit models
 * --json`). null for an unknown model.
 */
export function clothfitModelParameters(name) {
  const m = MODELS.get(name);
  if (!m) return null;
  return Object.entries(m.defaults).map(([k, d]) => ({
    name: k, size: Array.isArray(d) ? d.length : 1, default: Array.isArray(d) ? [...d] : d,
    preset_range: [...(m.ranges?.[k] ?? [-Infinity, Infinity])],
  }));
}

registerClothfitModel('standard', {
  engine: 'three.js r187 MeshStandardMaterial',
  defaults: { base_color: [1, 1, 1], roughness: 1, metalness: 0 },
  ranges: { base_color: UNIT, roughness: UNIT, metalness: UNIT },
  make: (p) => new THREE.MeshStandardMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metalness }),
});

registerClothfitModel('physical-sheen', {
  engine: 'three.js r187 MeshPhysicalMaterial (sheen)',
  defaults: { base_color: [1, 1, 1], roughness: 1, metalness: 0, sheen_color: [0, 0, 0], sheen_roughness: 1 },
  ranges: { base_color: UNIT, roughness: UNIT, metalness: UNIT, sheen_color: UNIT, sheen_roughness: UNIT },
  // sheen_color is three.js sheenColor x sheen: sheen = 1 keeps USE_SHEEN on.
  make: (p) => new THREE.MeshPhysicalMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metalness,
    sheen: 1, sheenColor: linear(p.sheen_color), sheenRoughness: p.sheen_roughness }),
});

// ---- physical-aniso (brdf/physical_aniso.h; issue 12's honest baseline) ----------------------
// MeshPhysicalMaterial with sheen + anisotropy + specular, every parameter the C++ one
// (specular_color is three.js specularColor, linear, may exceed 1; anisotropy_rotation radians).
// With weave maps (the preset's top-level "weave_maps", the same EXR as a woven preset's; the
// C++ preview's reading, render/preview/preview.cpp): the kd ratio is three.js's own `map`
// (diffuseColor *= texel, linear, no colour-space decode) and the warp/weft weights give an
// `anisotropyMap` (anisotropyFromWeave: direction along the dominant yarn, strength
// |warp - weft| / (warp + weft)), both with the weave uv transform (repeat R) and the GPU's
// trilinear filtering. Without maps: no colour map, anisotropy along the mesh tangent.
registerClothfitModel('physical-aniso', {
  engine: 'three.js r187 MeshPhysicalMaterial (sheen + anisotropy + specular)',
  defaults: {
    base_color: [1, 1, 1], roughness: 1, metalness: 0, sheen_color: [0, 0, 0], sheen_roughness: 1,
    anisotropy_strength: 0, anisotropy_rotation: 0, specular_intensity: 1, specular_color: [1, 1, 1],
  },
  ranges: {
    base_color: UNIT, roughness: UNIT, metalness: UNIT, sheen_color: UNIT, sheen_roughness: UNIT,
    anisotropy_strength: UNIT, anisotropy_rotation: [-Math.PI, Math.PI], specular_intensity: UNIT,
    specular_color: [0, 25],
  },
  make: (p) => new THREE.MeshPhysicalMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metalness,
    sheen: 1, sheenColor: linear(p.sheen_color), sheenRoughness: p.sheen_roughness,
    anisotropy: p.anisotropy_strength, anisotropyRotation: p.anisotropy_rotation,
    specularIntensity: p.specular_intensity, specularColor: linear(p.specular_color) }),
  weaveMaps: (m, maps) => {
    m.map = maps.kdTexture;
    m.anisotropyMap = maps.anisotropyTexture();
    for (const t of [m.map, m.anisotropyMap]) { t.repeat.set(maps.uvRepeats, maps.uvRepeats); t.offset.set(0, 0); }
    m.needsUpdate = true;
  },
});
// ---- end physical-aniso ---------------------------------------------------------------------

// glTF 2.0 + KHR_materials_sheen: three.js draws it the way GLTFLoader maps the extension, as a
// MeshPhysicalMaterial with sheen (so in three.js it is the physical-sheen model).
registerClothfitModel('gltf-sheen', {
  engine: 'glTF 2.0 + KHR_materials_sheen (drawn by three.js r187 as MeshPhysicalMaterial)',
  defaults: { base_color: [1, 1, 1], roughness: 1, metallic: 0, sheen_color: [0, 0, 0], sheen_roughness: 0 },
  ranges: { base_color: UNIT, roughness: UNIT, metallic: UNIT, sheen_color: UNIT, sheen_roughness: UNIT },
  make: (p) => new THREE.MeshPhysicalMaterial({
    color: linear(p.base_color), roughness: p.roughness, metalness: p.metallic,
    sheen: 1, sheenColor: linear(p.sheen_color), sheenRoughness: p.sheen_roughness }),
});

registerClothfitModel('cloth', {
  engine: 'clothfit MeshClothMaterial (Filament cloth / seed)',
  defaults: { base_color: [1, 1, 1], sheen_color: [1, 1, 1], roughness: 1, subsurface_color: [0, 0, 0] },
  ranges: { base_color: UNIT, sheen_color: UNIT, roughness: UNIT, subsurface_color: UNIT },
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

registerClothfitModel('woven', {
  engine: 'clothfit MeshWovenMaterial (brdf/woven.h; weave maps as GPU textures)',
  defaults: WOVEN_DEFAULTS,
  ranges: {
    base_color: UNIT, specular_color: UNIT, roughness: UNIT, anisotropy: UNIT, twist: [-90, 90],
    warp_share: UNIT, specular_f0: UNIT, forward_scattering: [0, 8], sheen_color: UNIT,
    sheen_roughness: UNIT, diffuse_roughness: UNIT,
  },
  // the preset's own parameters, before any default (loadClothfitPreset)
  checkParameters: (given) => {
    if ('diffuse_roughness' in given) {
      checkWovenDiffuseRoughness(given.diffuse_roughness, (msg) => { throw new Error(`loadClothfitPreset: parameters.diffuse_roughness: ${msg}`); });
    }
  },
  make: (p, preset) => {
    const w = wovenOptions(preset.woven);
    return new MeshWovenMaterial(p, {
      yarnLayer: w.yarn_layer,
      tintWarp: linear(w.tint_warp),
      tintWeft: linear(w.tint_weft),
      ibl: w.ibl,
      fisTaps: w.fis_taps,
      fisDiffuseTaps: w.fis_diffuse_taps,
      yarnLobe: w.yarn_lobe,
    });
  },
  weaveMaps: (m, maps) => m.setWeaveMaps(maps),
});

// A woven preset's "woven" object, checked as the C++ reader checks it (render/scene/material.cpp
// ParseWovenOptions; brdf/woven.h woven::Options): yarn_layer 'additive' (default) |
// 'albedo-scaled'; tint_warp / tint_weft linear RGB, each >= 0, default [1, 1, 1]; ibl 'split'
// (default: old presets keep their meaning) | 'fis' | 'bent'; fis_taps an integer in [1, 64] (default 16),
// fis_diffuse_taps an integer in [0, 64] (default 0 = three.js's irradiance), both only
// allowed with "ibl": "fis" (brdf/woven.h kDefaultFisTaps / kDefaultFisDiffuseTaps, as the C++
// reader). Unknown keys and values throw, naming the field.
const WOVEN_FIS_MAX_TAPS = 64;
export const WOVEN_OPTION_DEFAULTS = Object.freeze({
  yarn_layer: 'additive', tint_warp: [1, 1, 1], tint_weft: [1, 1, 1], ibl: 'split', fis_taps: 16, fis_diffuse_taps: 0,
  yarn_lobe: null,
});
export function wovenOptions(w) {
  if (w === undefined) return { ...WOVEN_OPTION_DEFAULTS };
  const fail = (f, msg) => { throw new Error(`loadClothfitPreset: ${f}: ${msg}`); };
  if (w === null || typeof w !== 'object' || Array.isArray(w)) fail('woven', 'expected an object');
  const out = { ...WOVEN_OPTION_DEFAULTS };
  for (const [k, v] of Object.entries(w)) {
    const f = `woven.${k}`;
    if (k === 'yarn_layer') {
      if (v !== 'additive' && v !== 'albedo-scaled') fail(f, 'expected "additive" or "albedo-scaled"');
      out.yarn_layer = v;
    } else if (k === 'tint_warp' || k === 'tint_weft') {
      if (!Array.isArray(v) || v.length !== 3) fail(f, 'expected an array of 3 numbers');
      v.forEach((x, c) => {
        if (typeof x !== 'number') fail(`${f}[${c}]`, 'expected a number');
        if (!Number.isFinite(x)) fail(`${f}[${c}]`, 'not finite');
        if (x < 0) fail(`${f}[${c}]`, 'must be >= 0');
      });
      out[k] = [...v];
    } else if (k === 'ibl') {
      if (v !== 'split' && v !== 'fis' && v !== 'bent') fail(f, 'expected "split", "fis" or "bent"');
      out.ibl = v;
    } else if (k === 'fis_taps' || k === 'fis_diffuse_taps') {
      const lo = k === 'fis_taps' ? 1 : 0;
      if (typeof v !== 'number' || !Number.isInteger(v)) fail(f, 'expected an integer');
      if (v < lo || v > WOVEN_FIS_MAX_TAPS) fail(f, `must be in [${lo}, ${WOVEN_FIS_MAX_TAPS}]`);
      out[k] = v;
    } else if (k === 'yarn_lobe') {
      out.yarn_lobe = yarnLobeOptions(v, f);
    } else {
      fail(f, 'unknown key (valid: yarn_layer, tint_warp, tint_weft, ibl, fis_taps, fis_diffuse_taps, yarn_lobe)');
    }
  }
  if (out.yarn_lobe && out.yarn_layer !== 'additive') fail('woven.yarn_layer', 'must be "additive" with a yarn_lobe');
  if (out.yarn_lobe && out.ibl !== 'split') fail('woven.ibl', 'must be "split" with a yarn_lobe');
  if (out.ibl !== 'fis') {
    for (const k of ['fis_taps', 'fis_diffuse_taps']) if (k in w) fail(`woven.${k}`, 'only allowed with "ibl": "fis"');
  }
  return out;
}

/**
 * A clothfit preset (object or JSON text) -> a three.js material. Throws on an unknown model or
 * parameter name (as the C++ reader does). The material's userData.clothfit keeps the preset.
 * `side` ('front' | 'back' | 'double' or three.js's 0/1/2) is honoured when present.
 * A preset naming "weave_maps" (woven, physical-aniso) needs options.weaveMaps: the parsed maps
 * (fetchWeaveMaps / weaveMapsFromExr), or null to draw the uniform material on purpose;
 * fetchClothfitPreset(url) fetches them next to the preset.
 * three.js JSON (`clothfit convert --to threejs`) naming textures takes options.textures
 * (uuid -> THREE.Texture: fetchThreejsTextures); without them it is drawn without its textures,
 * with a console warning and userData.clothfit.skippedTextures listing the slots.
 */
export function loadClothfitPreset(json, options = {}) {
  if (typeof json === 'string') presetIntegerLiterals(json);  // "fis_taps": 16.0 etc. (C++ refuses them)
  const preset = typeof json === 'string' ? JSON.parse(json) : json;
  if (preset?.metadata?.type === 'Material') return fromThreejsJson(preset, options);
  if (preset?.schema !== 'clothfit.preset') throw new Error('loadClothfitPreset: schema is not "clothfit.preset"');
  if (preset.version !== 1) throw new Error(`loadClothfitPreset: version ${preset.version} not supported (1)`);
  const model = MODELS.get(preset.model);
  if (!model) throw new Error(`loadClothfitPreset: model: unknown ${typeof preset.model === 'string' ? ylKeyShown(preset.model) : typeof preset.model} (known: ${clothfitModels().join(', ')})`);
  checkPresetTopLevelKeys(preset);
  const given = preset.parameters;  // required, as the C++ reader has it
  if (given === null || typeof given !== 'object' || Array.isArray(given)) throw new Error('loadClothfitPreset: parameters: missing or not an object');
  for (const k of Object.keys(given)) {
    if (!Object.hasOwn(model.defaults, k)) throw new Error(`loadClothfitPreset: parameters.${ylKeyShown(k)}: unknown for model '${preset.model}' (valid: ${Object.keys(model.defaults).join(', ')})`);
  }
  if (preset.woven !== undefined && preset.model !== 'woven') throw new Error('loadClothfitPreset: woven: only allowed with model "woven"');
  checkPresetParameters(model, given);
  model.checkParameters?.(given);
  const p = { ...model.defaults, ...given };
  if (preset.weave_maps !== undefined && preset.weave_maps !== null) {
    if (!model.weaveMaps) throw new Error(`loadClothfitPreset: weave_maps: not used by model '${preset.model}' (woven, physical-aniso)`);
    if (options.weaveMaps === undefined) throw new Error(`loadClothfitPreset: weave_maps: the preset names weave maps (${preset.weave_maps?.file}); load it with fetchClothfitPreset(url), or pass {weaveMaps} (fetchWeaveMaps / weaveMapsFromExr; null = the uniform material)`);
    // view bands (session 14): drawn only when the preset names them, and the maps given must
    // carry the same ones (weaveMapsFromExr reads them when its field is the preset's weave_maps)
    const vc = weaveMapViewCosines(preset.weave_maps), mc = options.weaveMaps?.viewCosines ?? null;
    if (options.weaveMaps && JSON.stringify(vc) !== JSON.stringify(mc)) {
      throw new Error(`loadClothfitPreset: weave_maps.view_cosines: the preset names ${vc ? vc.length : 'no'} view bands, the weave maps given carry ${mc ? mc.length : 'none'} (build them with weaveMapsFromExr(buffer, {field: preset.weave_maps}))`);
    }
  }
  const m = model.make(p, preset);
  if (options.weaveMaps && model.weaveMaps) model.weaveMaps(m, options.weaveMaps);
  if (preset.side !== undefined) m.side = typeof preset.side === 'number' ? preset.side : SIDES[preset.side];
  m.name = preset.name ?? preset.provenance?.fabric ?? preset.model;
  m.userData.clothfit = preset;
  return m;
}

// Top-level keys (session 27, as render/scene/material.cpp ParsePreset): an ASCII key that is a
// case variant of a known one, one edit from it for names of 6 or 7 letters, two for 8 or more, is a typo
// ("weave_map", "Woven") and refused: kept, it would draw the material without what it meant.
// Any other unknown key is left alone (a newer writer's field).
const PRESET_TOP_LEVEL_KEYS = ['schema', 'version', 'model', 'engine', 'cloth', 'woven', 'conventions',
  'parameters', 'fit', 'provenance', 'weave_maps', 'convert', 'maps', 'side', 'name'];
function presetKeyDistance(a, b) {
  // optimal string alignment, case-folded (render/scene/input_limits.cpp NameDistance)
  if (a.length > 64 || b.length > 64) return 1000;
  a = a.toLowerCase(); b = b.toLowerCase();
  const d = Array.from({ length: a.length + 1 }, (_, i) => Array.from({ length: b.length + 1 }, (_, j) => (i === 0 ? j : j === 0 ? i : 0)));
  for (let i = 1; i <= a.length; ++i) {
    for (let j = 1; j <= b.length; ++j) {
      d[i][j] = Math.min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] === b[j - 1] ? 0 : 1));
      if (i > 1 && j > 1 && a[i - 1] === b[j - 2] && a[i - 2] === b[j - 1]) d[i][j] = Math.min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.length][b.length];
}
function checkPresetTopLevelKeys(preset) {
  for (const k of Object.keys(preset)) {
    if (PRESET_TOP_LEVEL_KEYS.includes(k) || !/^[\x00-\x7f]*$/.test(k)) continue;  // ASCII keys only
    for (const known of PRESET_TOP_LEVEL_KEYS) {
      const limit = known.length >= 8 ? 2 : known.length >= 6 ? 1 : 0;
      if (presetKeyDistance(k, known) <= limit) {
        throw new Error(`loadClothfitPreset: ${ylKeyShown(k)}: unknown field; did you mean '${known}'? (a misspelt field would be ignored and the material drawn without it)`);
      }
    }
  }
}

// Every given parameter: a finite number, or an array of 3 for a colour, each within the model's
// `ranges` (messages as the C++ reader's: `parameters.roughness: value 7 outside [0, 1]`).
function checkPresetParameters(model, given) {
  const fail = (f, msg) => { throw new Error(`loadClothfitPreset: ${f}: ${msg}`); };
  const number = (x, f) => {
    if (typeof x !== 'number') fail(f, `expected a number, got ${x === null ? 'null' : Array.isArray(x) ? 'array' : typeof x}`);
    if (!Number.isFinite(x)) fail(f, 'not finite');
    return x;
  };
  for (const [k, v] of Object.entries(given)) {
    const f = `parameters.${k}`;
    const size = Array.isArray(model.defaults[k]) ? model.defaults[k].length : 1;
    const [lo, hi] = model.ranges?.[k] ?? [-Infinity, Infinity];
    const inRange = (x, fc) => { if (x < lo || x > hi) fail(fc, `value ${x} outside [${lo}, ${hi}]`); };
    if (size === 1) {
      inRange(number(v, f), f);
    } else {
      if (!Array.isArray(v) || v.length !== size) fail(f, `expected an array of ${size} numbers`);
      for (let c = 0; c < size; ++c) inRange(number(v[c], `${f}[${c}]`), `${f}[${c}]`);  // holes too
    }
  }
}

// `clothfit convert --to threejs` output: three.js MaterialLoader JSON (MeshPhysicalMaterial, read
// by three.js's own MaterialLoader) or the seed's MeshClothMaterial layout (type
// "MeshClothMaterial"; color / sheen / subsurfaceColor are sRGB hex, decoded to linear by
// THREE.Color.setHex as MaterialLoader does; roughness perceptual; the seed variant).
//
// Textures (session 27; before, they were dropped without a word): such a JSON may name textures
// by uuid (convert's weave textures: `map` and `anisotropyMap`; any MaterialLoader slot:
// normalMap, roughnessMap, sheenColorMap, ...) and carry ObjectLoader-format `textures` and
// `images` arrays. options.textures (uuid -> THREE.Texture, as fetchThreejsTextures or
// ObjectLoader.parseTextures make them) attaches them; a slot whose texture is not given is left
// empty, listed in userData.clothfit.skippedTextures and warned about on the console (not when
// options.textures is null: the material without its textures on purpose).
export function threejsTextureSlots(j) {
  const uuids = new Set(Array.isArray(j?.textures) ? j.textures.map((t) => t?.uuid).filter((u) => typeof u === 'string') : []);
  const slots = [];
  for (const [k, v] of Object.entries(j ?? {})) {
    if (k === 'uuid' || k === 'name' || k === 'type' || typeof v !== 'string') continue;
    if (uuids.has(v) || k === 'map' || /Map$/.test(k)) slots.push([k, v]);
  }
  return slots;
}

function fromThreejsJson(j, options = {}) {
  const given = options.textures ?? {};
  const slots = threejsTextureSlots(j);
  let m;
  const isSlot = (mat, k) => k in mat && (mat[k] === null || mat[k]?.isTexture);
  const skipped = [];
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
    for (const [k, uuid] of slots) {
      if (given[uuid]?.isTexture && isSlot(m, k)) m[k] = given[uuid];
      else skipped.push(k);
    }
  } else {
    // Slots whose texture is not given are taken out before MaterialLoader sees them (it would
    // set them to undefined with a bare "Undefined texture" warning).
    const missing = new Set(slots.filter(([, uuid]) => !given[uuid]?.isTexture).map(([k]) => k));
    const src = missing.size ? Object.fromEntries(Object.entries(j).filter(([k]) => !missing.has(k))) : j;
    m = new THREE.MaterialLoader().setTextures(given).parse(src);
    for (const [k] of slots) if (missing.has(k) || !isSlot(m, k)) skipped.push(k);
  }
  if (j.side !== undefined) m.side = j.side;
  m.userData.clothfit = { schema: 'three.js', model: j.type, parameters: {}, source: j };
  if (skipped.length) {
    m.userData.clothfit.skippedTextures = skipped;
    if (options.textures !== null) {
      const why = options.texturesNote ?? 'the JSON names them by uuid; its "images" and "textures" must be loaded';
      console.warn(`loadClothfitPreset: ${JSON.stringify(j.name ?? j.type ?? '')}: textures not loaded (${skipped.join(', ')}): ${why}; drawn without them. Load the file with fetchClothfitPreset(url), which loads the images next to it, or pass {textures} (uuid -> THREE.Texture, fetchThreejsTextures)`);
    }
  }
  return m;
}

/**
 * The textures of a three.js MaterialLoader JSON (ObjectLoader-format "images" and "textures",
 * as `clothfit convert --to threejs` writes them): uuid -> THREE.Texture, for
 * loadClothfitPreset(json, {textures}). An image `url` is relative to jsonUrl and is refused if it
 * is absolute, has a scheme or leaves the JSON's directory (the rule of weave_maps.uri), except
 * "data:image/..." URLs; embedded image data ({data, width, height, type}, three.js's
 * DataTexture form) is taken as it is. Each texture's `anisotropy` is clamped to the renderer's
 * max (options.renderer). Decoding a PNG or JPEG needs a DOM (an HTMLImageElement): where there is
 * none (node) such images are skipped and listed in `skipped` with the reason.
 * Returns {textures, skipped: [{field, why}]}; a malformed entry or an image that fails to load
 * throws, naming the field and the URL.
 */
export async function fetchThreejsTextures(json, jsonUrl, options = {}) {
  const images = json?.images ?? [], textures = json?.textures ?? [];
  if (!Array.isArray(images)) throw new Error('images: expected an array');
  if (!Array.isArray(textures)) throw new Error('textures: expected an array');
  const hasDom = typeof document !== 'undefined' && typeof document.createElementNS === 'function';
  const loader = new THREE.ObjectLoader().setResourcePath('');
  const loaded = {}, skipped = [];
  for (let i = 0; i < images.length; ++i) {
    const im = images[i], f = `images[${i}]`;
    if (im === null || typeof im !== 'object' || Array.isArray(im)) throw new Error(`${f}: expected an object {uuid, url}`);
    if (typeof im.uuid !== 'string') throw new Error(`${f}.uuid: expected a string`);
    const one = (u, fu) => {
      if (typeof u === 'string') return /^data:image\/[a-z0-9.+-]+[;,]/i.test(u) ? u : weaveMapUriUrl(u, jsonUrl, `${fu}`);
      if (u !== null && typeof u === 'object' && !Array.isArray(u) && u.data !== undefined) return u;
      throw new Error(`${fu}: expected a URL relative to the JSON or embedded image data {data, width, height, type}`);
    };
    const url = Array.isArray(im.url) ? im.url.map((u, k) => one(u, `${f}.url[${k}]`)) : one(im.url, `${f}.url`);
    if (!hasDom && [url].flat().some((u) => typeof u === 'string')) {
      skipped.push({ field: `${f}.url`, why: 'no DOM to decode PNG / JPEG images in (node)' });
      continue;
    }
    try {
      Object.assign(loaded, await loader.parseImagesAsync([{ uuid: im.uuid, url }]));
    } catch (e) {
      throw new Error(`${f}.url: cannot load ${[url].flat().map((u) => (typeof u === 'string' ? u.slice(0, 200) : 'embedded data')).join(', ')}${e instanceof Error ? `: ${e.message}` : ' (not found or not an image)'}`);
    }
  }
  const maxAnisotropy = options.maxAnisotropy ?? options.renderer?.capabilities?.getMaxAnisotropy?.() ?? Infinity;
  const out = {};
  for (let i = 0; i < textures.length; ++i) {
    const t = textures[i], f = `textures[${i}]`;
    if (t === null || typeof t !== 'object' || Array.isArray(t)) throw new Error(`${f}: expected an object {uuid, image, ...}`);
    if (typeof t.uuid !== 'string') throw new Error(`${f}.uuid: expected a string`);
    if (!images.some((im) => im?.uuid === t.image)) throw new Error(`${f}.image: ${ylKeyShown(String(t.image))} is not the uuid of an entry of "images"`);
    if (!loaded[t.image]) continue;  // its image is in `skipped`
    const [tex] = Object.values(loader.parseTextures([t], loaded));
    if (tex.anisotropy > maxAnisotropy) {
      console.info(`clothfit: ${f} (${ylKeyShown(t.name ?? t.uuid)}): anisotropy ${tex.anisotropy} clamped to the renderer's max anisotropy ${maxAnisotropy}`);
      tex.anisotropy = maxAnisotropy;
    }
    out[t.uuid] = tex;
  }
  return { textures: out, skipped };
}

// options.resolveWeaveMapPath(file, presetUrl): where the preset's weave-map file is fetched
// from (default weaveMapUrl: relative to the preset, an absolute path by its base name).
export async function fetchClothfitPreset(url, options = {}) {
  const text = new TextDecoder().decode(await fetchBounded(url, FETCH_LIMITS.json, 'preset'));
  let j;
  try {
    j = JSON.parse(text);
    presetIntegerLiterals(text);
    if (j?.metadata?.type === 'Material') {
      // three.js JSON from `clothfit convert --to threejs`: its textures, loaded next to it
      const { textures, skipped } = await fetchThreejsTextures(j, url, options);
      const texturesNote = skipped.length ? `${skipped.map((x) => x.field).join(', ')} skipped: ${[...new Set(skipped.map((x) => x.why))].join('; ')}` : undefined;
      return loadClothfitPreset(j, { textures, texturesNote });
    }
    const weaveMaps = j?.schema === 'clothfit.preset' ? await fetchWeaveMaps(j, url, options) : null;
    return loadClothfitPreset(j, { weaveMaps });
  } catch (e) {
    throw new Error(`${url}: ${e.message}`);  // name the file, as the C++ reader does
  }
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

/**
 * The message for an environment map that did not load (session 27): a name ('studio') that is
 * not found (HTTP 404) is an HDRI missing from the data cache, with the command that fetches it;
 * any other failure names the environment and the URL.
 */
export function environmentLoadError(path, url, e) {
  const status = e?.response?.status;
  const shown = JSON.stringify(String(path));
  const isName = typeof path === 'string' && !path.includes('/') && !/\.[A-Za-z0-9]+$/.test(path);
  if (status === 404 && isName) {
    return `environment ${shown}: ${url} not found (HTTP 404): the HDRI is not in the data cache. Run scripts/fetch-data (or make data) to fetch the HDRIs into $CLOTHFIT_DATA/hdri (default ~/.cache/clothfit/hdri), which web/serve.mjs serves at /hdri/, then reload`;
  }
  if (status === 404) return `environment ${shown}: ${url} not found (HTTP 404; a path is relative to the scene card)`;
  return `environment ${shown}: ${url}: ${e instanceof Error ? e.message : String(e?.type ?? e)}`;
}

const envCache = new Map();
const pmremCache = new WeakMap();  // renderer -> Map(key -> Promise<{target, source}>)

// The renderer's PMREM cache. A WebGL context loss (mobile browsers drop the context of a page in
// the background) loses the PMREMs' pixels: three.js restores the textures it uploaded itself,
// but not the contents of render targets, so after 'webglcontextrestored' the environment
// lighting was black (measured, session 23: the woven drape's mean 8-bit RGB 58/117/87 ->
// 25/59/40). The cache keeps each PMREM's source texture, and on restore rebuilds every PMREM
// into its own target, so scene.environment stays valid. three.js's own restore listener is
// registered in the WebGLRenderer constructor, hence runs first.
function pmremCacheOf(renderer) {
  let m = pmremCache.get(renderer);
  if (!m) {
    m = new Map();
    pmremCache.set(renderer, m);
    renderer.domElement?.addEventListener?.('webglcontextrestored', () => {
      for (const entry of m.values()) {
        entry.then(({ target, source }) => {
          const gen = new THREE.PMREMGenerator(renderer);
          gen.fromEquirectangular(source, target);
          gen.dispose();
        });
      }
    });
  }
  return m;
}

function buildPmrem(renderer, source) {
  const gen = new THREE.PMREMGenerator(renderer);
  const target = gen.fromEquirectangular(source);
  gen.dispose();
  return { target, source };
}

// One PMREM per renderer and map (PMREMGenerator.fromEquirectangular), shared by every card.
async function pmremFor(renderer, url) {
  const m = pmremCacheOf(renderer);
  if (!m.has(url)) m.set(url, loadEquirect(url).then((eq) => buildPmrem(renderer, eq)));
  return (await m.get(url)).target;
}

// The environment's sun (web/sun.js, docs/sun.md): detected once per map on the texture's own
// texels (half floats from EXRLoader, rows bottom-up), at intensity 1 and rotation 0; when found,
// a sun-free copy of the texture (the sun texels set to the fill) feeds the PMREM.
const sunCache = new Map();  // url#mode -> Promise<{split, sunFree: THREE.DataTexture | null}>
async function sunSplitFor(url, mode = 'auto') {
  const key = `${url}#${mode}`;
  if (!sunCache.has(key)) {
    sunCache.set(key, loadEquirect(url).then((eq) => {
      const { data, width, height } = eq.image;
      const channels = data.length / (width * height);
      const half = eq.type === THREE.HalfFloatType;
      const split = splitEnvironment(data, width, height, {
        mode, channels, rowsBottomUp: !eq.flipY,
        decode: half ? THREE.DataUtils.fromHalfFloat : null,
        encode: half ? THREE.DataUtils.toHalfFloat : null,
      });
      if (!split.data) return { split, sunFree: null };
      const sunFree = eq.clone();
      sunFree.source = new THREE.TextureSource({ data: split.data, width, height });  // r187 renamed Source (a deprecation warning)
      sunFree.needsUpdate = true;
      return { split, sunFree };
    }));
  }
  return sunCache.get(key);
}

async function pmremForTexture(renderer, key, texture) {
  const m = pmremCacheOf(renderer);
  if (!m.has(key)) m.set(key, Promise.resolve(buildPmrem(renderer, texture)));
  return (await m.get(key)).target;
}

async function loadEquirect(url) {
  if (!envCache.has(url)) {
    const loader = /\.hdr$/i.test(url) ? new HDRLoader() : new EXRLoader();
    const loading = loader.loadAsync(url);
    loading.catch(() => envCache.delete(url));  // not cached: a later call tries again (after scripts/fetch-data)
    envCache.set(url, loading.then((t) => {
      t.mapping = THREE.EquirectangularReflectionMapping;
      const st = clampEnvironmentTexels(t);
      if (st.negative || st.nonfinite) {
        console.warn(`clothfit: ${url}: ${t.image.width}x${t.image.height} environment map has ${st.negative} texels with negative values (most negative ${st.mostNegative}) and ${st.nonfinite} texels with NaN/Inf values; those channels were set to 0`);
      }
      return t;
    }));
  }
  return envCache.get(url);
}

/**
 * An environment map's colour channels as the C++ reader keeps them (render/scene/environment.cpp
 * Environment::FromImage): a negative or non-finite value of R, G or B is set to 0 (alpha as it
 * is), in place, on the texture's own data (THREE.FloatType: Float32Array; THREE.HalfFloatType, as
 * EXRLoader and HDRLoader give by default: Uint16Array of IEEE half floats). Some published HDRIs
 * carry negative texels (pmndrs-hall: 1909, down to -9.06); three.js would prefilter them as
 * they are, the reference renderer and the C++ preview as 0 (session 24: up to 1.4 / 255 mean on
 * the drape). Returns {negative, nonfinite, mostNegative} counts of texels, as the C++ warning.
 */
export function clampEnvironmentTexels(texture) {
  const { data, width, height } = texture.image;
  const n = width * height, ch = data.length / n;
  if (!Number.isInteger(ch) || ch < 1) throw new Error(`environment map: ${data.length} values for ${width}x${height} texels`);
  const half = data instanceof Uint16Array && texture.type === THREE.HalfFloatType;
  if (!half && !(data instanceof Float32Array)) return { negative: 0, nonfinite: 0, mostNegative: 0 };  // integer data: never negative or non-finite
  const colour = ch >= 3 ? 3 : 1;  // as the C++ reader: one or two channels, the first is grey
  let negative = 0, nonfinite = 0, mostNegative = 0;
  for (let p = 0; p < n; ++p) {
    let neg = false, bad = false;
    for (let c = 0; c < colour; ++c) {
      const i = p * ch + c, v = data[i];
      if (half) {
        if ((v & 0x7c00) === 0x7c00) { bad = true; data[i] = 0; }
        else if ((v & 0x8000) && (v & 0x7fff)) { neg = true; mostNegative = Math.min(mostNegative, THREE.DataUtils.fromHalfFloat(v)); data[i] = 0; }
      } else if (!Number.isFinite(v)) { bad = true; data[i] = 0; }
      else if (v < 0) { neg = true; mostNegative = Math.min(mostNegative, v); data[i] = 0; }
    }
    negative += neg ? 1 : 0;
    nonfinite += bad ? 1 : 0;
  }
  if (negative || nonfinite) texture.needsUpdate = true;
  return { negative, nonfinite, mostNegative };
}

// ---------------------------------------------------------------------------------------------
// Shadow maps (session 13, opt-in; docs/web.md "Shadows (session 13, measured)").
// three.js's own renderer.shadowMap for the card's punctual lights (and the environment's sun),
// every mesh casting and receiving. Off unless asked for (loadSceneCard options.shadows, the
// card's "visibility": {"shadows": true}, or sc.setShadows(spec)); off leaves the renderer, the
// lights and the meshes at three.js's defaults, so frames without shadows are unchanged.
//   spec: true (the defaults below) or an object overriding any of
//     type        'pcf' (PCFShadowMap: r187's 5 Vogel-disk taps of a hardware 2 x 2 compare,
//                 rotated per pixel by interleaved gradient noise) | 'basic' (one nearest
//                 compare, a hard edge) | 'vsm' (no point-light shadows in r187)
//                 ('pcfsoft' is refused: r187 removed PCFSoftShadowMap, it falls back to PCF)
//     mapSize     shadow map texels per side (cube face for the point light), 64..8192
//     radius      PCF disk radius in texels (three.js default 1)
//     bias        added to the normalised depth (negative: fewer self-shadowing artefacts)
//     normalBias  world metres along the vertex normal
//     texelBias   directional lights: the depth bias is at least this many shadow-map texels of
//                 world depth (default 8; 0 = the normalised bias alone, as before session 24),
//                 so on them `bias` is a floor, not the value used, unless texelBias is 0
//     fit         'fabric' (default): each shadow camera frames the fabric meshes' bounding box
//                 (as receivers) and reaches back to the scene's box towards the light (casters),
//                 which is exact for the fabric: anything that can shadow it lies in that
//                 volume; the floor outside it is unshadowed. 'scene': frames the whole scene.
export const SHADOW_DEFAULTS = Object.freeze({ type: 'basic', mapSize: 2048, radius: 1, bias: -0.001, normalBias: 0, texelBias: 8, fit: 'fabric' });
const SHADOW_TYPES = { basic: THREE.BasicShadowMap, pcf: THREE.PCFShadowMap, vsm: THREE.VSMShadowMap };

export function shadowOptions(spec, where = 'shadows') {
  if (spec === undefined || spec === null || spec === false) return null;
  if (spec === true) return { ...SHADOW_DEFAULTS };
  if (typeof spec !== 'object' || Array.isArray(spec)) throw new Error(`${where}: expected true, false or an object {${Object.keys(SHADOW_DEFAULTS).join(', ')}}`);
  const out = { ...SHADOW_DEFAULTS };
  for (const [k, v] of Object.entries(spec)) {
    if (!Object.hasOwn(SHADOW_DEFAULTS, k)) throw new Error(`${where}.${ylKeyShown(k)}: unknown field (fields: ${Object.keys(SHADOW_DEFAULTS).join(', ')})`);
    const num = (lo, hi) => {
      if (typeof v !== 'number' || !Number.isFinite(v) || v < lo || v > hi) throw new Error(`${where}.${k}: expected a number in [${lo}, ${hi}], got ${JSON.stringify(v)}`);
      return v;
    };
    if (k === 'type') {
      if (v === 'pcfsoft') throw new Error(`${where}.type: 'pcfsoft' (PCFSoftShadowMap) was removed in three.js r187; use 'pcf' with a larger radius`);
      if (!(v in SHADOW_TYPES)) throw new Error(`${where}.type: expected one of ${Object.keys(SHADOW_TYPES).join(', ')}, got ${JSON.stringify(v)}`);
      out.type = v;
    } else if (k === 'fit') {
      if (v !== 'fabric' && v !== 'scene') throw new Error(`${where}.fit: expected 'fabric' or 'scene', got ${JSON.stringify(v)}`);
      out.fit = v;
    } else if (k === 'mapSize') {
      if (!Number.isInteger(num(64, 8192))) throw new Error(`${where}.mapSize: expected an integer`);
      out.mapSize = v;
    } else if (k === 'radius') out.radius = num(0, 64);
    else if (k === 'bias') out.bias = num(-1, 1);
    else if (k === 'texelBias') out.texelBias = num(0, 64);
    else out.normalBias = num(-1, 1);
  }
  return out;
}

const boxCorners = (b) => [0, 1, 2, 3, 4, 5, 6, 7].map((i) => new THREE.Vector3(i & 1 ? b.max.x : b.min.x, i & 2 ? b.max.y : b.min.y, i & 4 ? b.max.z : b.min.z));

// Points the shadow camera of `light` at its target and fits its frustum: receivers = the box
// whose shadows are wanted, casters = the scene's box (everything that can occlude them).
export function fitShadowCamera(light, receivers, casters, mapSize, texelBias = 0) {
  const shadow = light.shadow, cam = shadow.camera;
  const margin = 1.02;
  light.updateMatrixWorld(true);
  const lightPos = new THREE.Vector3().setFromMatrixPosition(light.matrixWorld);
  if (light.isPointLight) {
    // A cube around the light: near below the nearest caster, far past the farthest receiver
    // (three.js uses light.distance instead when the light has a range).
    const dNear = casters.distanceToPoint(lightPos);
    cam.near = Math.max(1e-3, 0.5 * dNear);
    cam.far = Math.max(cam.near * 2, Math.max(...boxCorners(receivers).map((p) => p.distanceTo(lightPos))) * margin);
    cam.updateProjectionMatrix();
    return;
  }
  // The view the shadow camera will have (LightShadow.updateMatrices: at the light, looking at
  // the target).
  light.target.updateMatrixWorld(true);
  cam.position.copy(lightPos);
  cam.lookAt(new THREE.Vector3().setFromMatrixPosition(light.target.matrixWorld));
  cam.updateMatrixWorld(true);
  const view = cam.matrixWorldInverse.clone();
  const rv = boxCorners(receivers).map((p) => p.applyMatrix4(view));
  const cv = boxCorners(casters).map((p) => p.applyMatrix4(view));
  if (light.isDirectionalLight) {
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity, d0 = Infinity, d1 = -Infinity;
    for (const p of rv) { x0 = Math.min(x0, p.x); x1 = Math.max(x1, p.x); y0 = Math.min(y0, p.y); y1 = Math.max(y1, p.y); d1 = Math.max(d1, -p.z); d0 = Math.min(d0, -p.z); }
    for (const p of cv) d0 = Math.min(d0, -p.z);
    // square texels: the larger extent on both axes, centred; a margin of 2 texels
    const half = 0.5 * Math.max(x1 - x0, y1 - y0) * (1 + 4 / mapSize), cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
    cam.left = cx - half; cam.right = cx + half; cam.bottom = cy - half; cam.top = cy + half;
    const pad = 0.01 * (d1 - d0) + 1e-3;
    cam.near = d0 - pad; cam.far = d1 + pad;
    cam.updateProjectionMatrix();
    // texelBias (session 24): at least texelBias texels of world depth. The normalised bias is a
    // fraction of this camera's depth range, which varies with the light's direction across the
    // scene box (1.1 m for an overhead sun on the drape, 3.5 m for its fill light), so -0.001
    // alone left acne on the fabric under a strong high sun. A texel-scaled bias holds slopes up
    // to atan(texelBias) (83 degrees at 8) whatever the scene's size.
    if (texelBias > 0) shadow.bias = Math.min(shadow.bias, -texelBias * (2 * half / mapSize) / (cam.far - cam.near));
  } else if (light.isSpotLight) {
    // The cone, narrowed to the receivers' box when it is smaller (shadow.focus scales the cone
    // angle into the camera's fov in SpotLightShadow.updateMatrices).
    let half = 0, d1 = 0, behind = false;
    for (const p of rv) {
      if (-p.z <= 1e-6) { behind = true; continue; }
      half = Math.max(half, Math.atan2(Math.hypot(p.x, p.y), -p.z));
      d1 = Math.max(d1, p.length());
    }
    shadow.focus = behind ? 1 : Math.min(1, (half * margin) / light.angle);
    cam.near = Math.max(1e-3, 0.5 * casters.distanceToPoint(lightPos));
    cam.far = Math.max(cam.near * 2, (d1 || Math.max(...rv.map((p) => p.length()))) * margin);
    cam.updateProjectionMatrix();
  }
}

// ---------------------------------------------------------------------------------------------
// The shadow maps' texture units (session 23; docs/web.md "Real GPUs"). Each shadow-casting light
// costs every lit program one more sampler (three.js's directionalShadowMap[i] etc.), and
// WebGL2 guarantees only 16 fragment samplers (MAX_TEXTURE_IMAGE_UNITS; Apple GPUs and many
// Android ones have exactly 16). Woven with view-band maps, a light map and the studio map's
// four panels as shadowed lights needs 17; with the 8 panels of some maps, 21. A program over the
// limit fails to link and three.js draws nothing for it. So, with shadows on, the card compiles
// its programs, counts each one's samplers and checks that it linked; if any program is over the
// limit (or did not link, e.g. for too many varyings), the environment's weakest split-off lights
// stop casting shadows first (panels, then the sun, then the card's own lights), and the check
// repeats. What was dropped is logged (console.warn) and kept in sc.shadowBudget.

const SAMPLER_TYPES = new Set([0x8b5e, 0x8b60, 0x8b5f, 0x8b62, 0x8dc1, 0x8dc4, 0x8dc5, 0x8dc9, 0x8dca, 0x8dcb, 0x8dcc, 0x8dcf,
  0x8dd0, 0x8dd2, 0x8dd3, 0x8dd4, 0x8dd7]);  // SAMPLER_2D, _CUBE, _3D, _2D_SHADOW, _2D_ARRAY, _2D_ARRAY_SHADOW, _CUBE_SHADOW, INT_ and UNSIGNED_INT_ variants

/** Active sampler uniforms of a linked WebGL program (array elements counted), or null if it did not link. */
export function programSamplerCount(gl, program) {
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) return null;
  let n = 0;
  const count = gl.getProgramParameter(program, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < count; ++i) {
    const u = gl.getActiveUniform(program, i);
    if (u && SAMPLER_TYPES.has(u.type)) n += u.size;
  }
  return n;
}

// The lights' power for the drop order: intensity x the colour's luminance.
const lightPower = (l) => l.intensity * (0.2126 * l.color.r + 0.7152 * l.color.g + 0.0722 * l.color.b);

/**
 * Load a scene card: returns {card, gltf, scene, camera, fabricMeshes, setMaterial(m),
 * setEnvironment(pathOrNull, {intensity, rotationYDegrees}), apply(renderer), width, height}.
 * Non-fabric meshes are drawn as MeshStandardMaterial with the glTF base colour and roughness 1
 * (metalness 0), which is what the card semantics read; options.keepGltfMaterials keeps them.
 * Needs a renderer for the PMREM: options.renderer.
 */
export async function loadSceneCard(url, options = {}) {
  const cardUrl = new URL(url, document.baseURI).href;
  let card;
  try {
    card = JSON.parse(new TextDecoder().decode(await fetchBounded(cardUrl, FETCH_LIMITS.json, 'scene card')));
  } catch (e) {
    throw new Error(e instanceof SyntaxError ? `${cardUrl}: not JSON (${e.message.slice(0, 120)})` : e.message);
  }
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
    sun: null,        // the sun split of the environment (web/sun.js detectSun), when asked for
    sunLight: null,   // its THREE.DirectionalLight, when one was found
    panels: [],       // sun 'panels': the panels found (web/sun.js splitEnvironment)
    panelLights: [],  // their THREE.DirectionalLights
    // The fabric's material: keeps the side GLTFLoader derived from the glTF doubleSided.
    setMaterial(m) {
      for (const mesh of fabricMeshes) {
        const mm = fabricMeshes.length > 1 ? m.clone() : m;
        mm.side = mesh.userData.gltfMaterial.side;
        mesh.material = mm;
      }
      // a new program: check the shadow maps' samplers again (with the card's renderer)
      if (this.shadows && options.renderer) this.fitShadowBudget(options.renderer);
    },
    // sun: 'auto' (default, as `clothfit render-preview`) draws a compact sun of the map as a
    // THREE.DirectionalLight (this.sunLight) and builds the PMREM from the sun-free map
    // (web/sun.js, docs/sun.md); 'panels': the same, then up to 8 broad bright sources
    // (softboxes) as more DirectionalLights (this.panelLights); 'off': the map as is.
    async setEnvironment(path, { intensity = 1, rotationYDegrees = 0, sun = 'auto' } = {}) {
      // Overlapping calls: only the latest one's lights and maps are applied (review s21).
      const generation = (this.environmentGeneration = (this.environmentGeneration ?? 0) + 1);
      this.environment = null;
      this.sun = null;
      this.panels = [];
      for (const l of [this.sunLight, ...this.panelLights]) if (l) { scene.remove(l); l.dispose(); }
      this.sunLight = null;
      this.panelLights = [];
      scene.userData.clothfitAreaLights = [];
      parseSunMode(sun, 'environment.sun');
      if (!path) {
        scene.environment = null;
        scene.background = new THREE.Color(bg[0], bg[1], bg[2]);
        if (this.shadows && options.renderer) this.fitShadowBudget(options.renderer);  // lights removed
        return;
      }
      if (path === 'procedural-sky') throw new Error('procedural-sky is not available in the browser');
      const renderer = options.renderer;
      if (!renderer) throw new Error('loadSceneCard: options.renderer is needed for the environment PMREM');
      const url = environmentUrl(path, cardUrl, options);
      let eq;
      try {
        eq = await loadEquirect(url);
      } catch (e) {
        throw new Error(environmentLoadError(path, url, e));
      }
      const rot = THREE.MathUtils.degToRad(rotationYDegrees);
      let target;
      const sp = sun !== 'off' ? await sunSplitFor(url, sun) : null;
      const pm = sp?.sunFree ? await pmremForTexture(renderer, `${url}#sun-free#${sun}`, sp.sunFree) : await pmremFor(renderer, url);
      if (generation !== this.environmentGeneration) return;  // a later call took over
      // render/scene/sun.cpp: E = excess x intensity; world = R_y(rotation) map direction.
      const lightFor = (split, name) => {
        const E = split.irradiance.map((x) => x * intensity);
        const emax = Math.max(...E);
        const m = split.mapDirection, cr = Math.cos(rot), sr = Math.sin(rot);
        const w = [cr * m[0] + sr * m[2], m[1], -sr * m[0] + cr * m[2]];
        const light = new THREE.DirectionalLight(new THREE.Color(E[0] / emax, E[1] / emax, E[2] / emax), emax);
        light.name = name;
        light.position.set(w[0], w[1], w[2]);  // shines from w towards the target at the origin
        // The cap with the source's solid angle, cos r = 1 - Omega / (2 pi): MeshWovenMaterial's
        // horizon fade (render/scene/sun.cpp sets Light::sin_angular_radius the same way).
        const cosR = Math.min(Math.max(1 - split.solidAngle / (2 * Math.PI), -1), 1);
        light.userData.sinAngularRadius = Math.sqrt(Math.max(1 - cosR * cosR, 0));
        scene.add(light);
        return { light, split: { ...split, irradiance: E, worldDirection: w } };
      };
      target = pm;
      if (sp?.sunFree) {
        if (sp.split.sun.found) {
          const { light, split } = lightFor(sp.split.sun, 'environment sun');
          this.sunLight = light;
          this.sun = split;
        } else {
          this.sun = sp.split.sun;
        }
        sp.split.panels.forEach((p, k) => {
          const { light, split } = lightFor(p, `environment panel ${k + 1}`);
          this.panelLights.push(light);
          this.panels.push(split);
        });
      } else if (sp) {
        this.sun = sp.split.sun;
      }
      scene.userData.clothfitAreaLights = [this.sunLight, ...this.panelLights].filter(Boolean);
      // Shadow maps already on (setShadows / apply ran before): the new lights cast too.
      if (this.shadows && (this.sunLight || this.panelLights.length)) this.setShadows(this.shadows);
      this.environment = target;
      scene.environment = target.texture;
      scene.environmentIntensity = intensity;
      scene.environmentRotation.set(0, rot, 0);
      scene.background = eq;
      scene.backgroundIntensity = intensity;
      scene.backgroundRotation.set(0, rot, 0);
      // new lights (the sun, the panels) and a new map: the shadow maps' samplers again (s23)
      if (this.shadows) this.fitShadowBudget(renderer);
    },
    shadows: null,    // the shadow settings in force (shadowOptions), null = no shadow maps
    // Shadow maps on or off (see shadowOptions): castShadow on the punctual lights (the card's and
    // the environment's sun) with fitted shadow cameras, castShadow + receiveShadow on every mesh.
    // Takes effect on the renderer at apply(renderer). null / false: three.js's defaults.
    setShadows(spec) {
      const o = shadowOptions(spec);
      this.shadows = o;
      const receivers = new THREE.Box3(), casters = new THREE.Box3();
      if (o) {
        scene.updateMatrixWorld(true);
        for (const m of fabricMeshes) receivers.expandByObject(m);
        casters.setFromObject(gltf.scene);
        if (o.fit === 'scene') receivers.copy(casters);
      }
      scene.traverse((obj) => {
        if (obj.isMesh) { obj.castShadow = !!o; obj.receiveShadow = !!o; }
        if (!(obj.isDirectionalLight || obj.isSpotLight || obj.isPointLight)) return;
        obj.castShadow = !!o;
        if (!o) return;
        const sh = obj.shadow;
        if (sh.map && sh.mapSize.x !== o.mapSize) { sh.map.dispose(); sh.map = null; }
        sh.mapSize.set(o.mapSize, o.mapSize);
        sh.radius = o.radius;
        sh.bias = o.bias;
        sh.normalBias = o.normalBias;
        fitShadowCamera(obj, receivers, casters, o.mapSize, o.texelBias);
        sh.needsUpdate = true;
      });
      // the lights fitShadowBudget took the shadow from stay without it (checked again there)
      if (!o) this.shadowBudget = null;
      else if (this.shadowBudget) for (const l of this.shadowBudget.droppedLights) l.castShadow = false;
    },
    // Shadows over the renderer's sampler limit: see programSamplerCount above. maxSamplers:
    // this.samplerLimit ?? renderer.capabilities.maxTextures (MAX_TEXTURE_IMAGE_UNITS). Compiles
    // (renderer.compile) only when the materials, the shadow-casting lights or the limit changed.
    // Returns this.shadowBudget: {key (what was checked), maxSamplers, samplers (the most any
    // program uses), dropped (light names), droppedLights, linked, why (the warning's reason)}.
    samplerLimit: null,
    shadowBudget: null,
    fitShadowBudget(renderer) {
      if (!this.shadows) { this.shadowBudget = null; return null; }
      const maxSamplers = this.samplerLimit ?? renderer.capabilities.maxTextures;
      const prev = this.shadowBudget;
      const prevDropped = new Set(prev?.droppedLights ?? []);
      // The lights that want a shadow: casting now, or dropped by the last check (a page's own
      // castShadow = false on a light is left alone). Visible punctual lights only.
      const wanted = [], materials = new Set();
      scene.traverse((o) => {
        if ((o.isDirectionalLight || o.isSpotLight || o.isPointLight) && o.visible && (o.castShadow || prevDropped.has(o))) wanted.push(o);
        if (o.isMesh && o.visible) for (const m of Array.isArray(o.material) ? o.material : [o.material]) materials.add(m);
      });
      const key = [maxSamplers, this.shadows.type, scene.environment?.uuid ?? '-', ...wanted.map((l) => `${l.uuid}:${l.map?.uuid ?? ''}`),
        ...[...materials].map((m) => `${m.uuid}:${m.version}`)].join('|');
      if (prev && prev.key === key) {
        for (const l of wanted) l.castShadow = !prevDropped.has(l);
        return prev;
      }
      // Keep order: the card's own lights (strongest first), the environment's sun, its panels
      // (strongest first); the drop order is the reverse.
      const env = new Set([this.sunLight, ...this.panelLights].filter(Boolean));
      const byPower = (a, b) => lightPower(b) - lightPower(a);
      const keep = [...wanted.filter((l) => !env.has(l)).sort(byPower), ...(this.sunLight && wanted.includes(this.sunLight) ? [this.sunLight] : []),
        ...this.panelLights.filter((l) => wanted.includes(l)).sort(byPower)];
      const gl = renderer.getContext();
      renderer.shadowMap.enabled = true;  // as apply sets them, so the programs checked are the ones drawn
      renderer.shadowMap.type = SHADOW_TYPES[this.shadows.type];
      // Compiles with the first n of `keep` casting; returns {linked, samplers} over every program.
      const check = (n) => {
        keep.forEach((l, i) => { l.castShadow = i < n; });
        renderer.compile(scene, camera);
        let samplers = 0, linked = true;
        for (const m of materials) {
          const prog = renderer.properties.get(m).currentProgram;
          if (!prog) continue;
          const c = programSamplerCount(gl, prog.program);
          if (c === null) linked = false;
          else samplers = Math.max(samplers, c);
        }
        return { linked, samplers };
      };
      let n = keep.length, r = check(n), why = '';
      const first = r;  // keep.length lights casting: failed (or over the limit) when the branch below runs
      if (!(r.linked && r.samplers <= maxSamplers)) {
        // A real GPU over its limit fails the link (ANGLE: "sampler count exceeds
        // MAX_TEXTURE_IMAGE_UNITS"), so the failed program cannot be counted. Count the programs
        // without shadow maps instead: each casting light adds one sampler to them, so
        // maxSamplers - that count lights fit. Then verify, and drop one more per pass while a
        // program still fails (varyings: one vec4 per shadowed light, 15 guaranteed).
        const base = check(0);
        if (!base.linked) {
          n = 0; r = base;
          why = 'a program does not link even without shadow maps';
        } else {
          n = Math.max(0, Math.min(keep.length, maxSamplers - base.samplers));
          let linkFailures = 0;
          if (n > 0 && n === keep.length) { if (!first.linked) ++linkFailures; r = check(--n); }  // checked already: one fewer
          else r = n === 0 ? base : check(n);
          while (n > 0 && !(r.linked && r.samplers <= maxSamplers)) {
            if (!r.linked) ++linkFailures;
            r = check(--n);
          }
          // why the first lights dropped went: the texture units (counted), and for any more a
          // failed link whose cause WebGL does not say (varyings: one vec4 per shadowed light)
          const units = n < keep.length && keep.length > maxSamplers - base.samplers;
          why = !r.linked ? 'a program does not link'
            : [units ? `with more, a program needs more than the renderer's ${maxSamplers} texture units` : '',
              linkFailures ? `with ${linkFailures} more, a program within the texture units fails to link (varyings? one vector per shadowed light; WebGL2 guarantees 15)` : '']
              .filter(Boolean).join('; ') || `with more, a program goes over the renderer's ${maxSamplers} texture units`;
        }
      }
      const droppedLights = keep.slice(n);
      const dropped = droppedLights.map((l) => l.name || l.type);
      if (dropped.length) console.warn(`clothfit: shadow maps: ${dropped.length} of ${keep.length} lights cast no shadow (${dropped.join(', ')}): ${why} (docs/web.md "Real GPUs")`);
      this.shadowBudget = { key, maxSamplers, samplers: r.samplers, linked: r.linked, dropped, droppedLights, why };
      return this.shadowBudget;
    },
    apply(renderer) {
      renderer.toneMapping = this.toneMapping;
      renderer.toneMappingExposure = this.exposure;
      renderer.outputColorSpace = THREE.SRGBColorSpace;
      renderer.setPixelRatio(1);
      renderer.shadowMap.enabled = !!this.shadows;
      if (this.shadows) {
        renderer.shadowMap.type = SHADOW_TYPES[this.shadows.type];
        this.setShadows(this.shadows);  // a sun light added since is fitted too
        this.fitShadowBudget(renderer);  // within the renderer's texture units (session 23)
      }
    },
  };
  if (card.environment) {
    const e = card.environment;
    await out.setEnvironment(e.path, { intensity: e.intensity ?? 1, rotationYDegrees: e.rotation_y_degrees ?? 0, sun: e.sun ?? 'auto' });
  }
  // Shadows: options.shadows (true / false / an object, shadowOptions) wins over the card's
  // "visibility": {"shadows": bool} (the block of session 13's C++ preview, docs/scene-card.md);
  // the card's light map is a texture clothfit bakes (`render-preview --light-map-out`), which a
  // page draws with applyLightMap: loading the card only reports it.
  let shadowSpec = options.shadows;
  if (shadowSpec === undefined && card.visibility !== undefined) {
    const v = card.visibility;
    if (typeof v !== 'object' || v === null || Array.isArray(v)) throw new Error(`${cardUrl}: visibility: expected an object {shadows, light_map}`);
    if (v.shadows !== undefined && typeof v.shadows !== 'boolean') throw new Error(`${cardUrl}: visibility.shadows: expected true or false, got ${JSON.stringify(v.shadows)}`);
    shadowSpec = v.shadows ?? false;
    if (v.light_map) console.info(`${cardUrl}: visibility.light_map: draw the texture clothfit bakes (render-preview --light-map-out) with applyLightMap`);
  }
  if (shadowSpec) out.setShadows(shadowSpec);
  await Promise.all([clothDGTable(), wovenPhaseTable()]);
  return out;
}
