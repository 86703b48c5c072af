// render/preview/preview.h: what the real-time engine draws for a scene, computed on the CPU, pixel
// aligned with the reference renderer and differentiable in the material parameters.
//
// Pipeline (per scene, once): primary visibility at pixel centres through the same camera
// (Scene::CameraRay(x + 0.5, y + 0.5), the reference renderer's pixel convention) -> a
// G-buffer of the fabric pixels -> a cache of everything that does not depend on material
// parameters: per light the shading cosines, the light's irradiance colour and (optionally)
// its ray-traced visibility; the SH irradiance E_d(n); and the prefiltered environment
// radiance each pixel needs, tabulated over roughness (K nodes, dominant direction and LOD
// recomputed per node as the engine does) so that evaluating a frame for new parameters
// interpolates that table (Catmull-Rom cubic in r: C1, differentiable in roughness) instead of touching the
// environment. Non-fabric meshes are shaded once (MeshStandardMaterial, their glTF base
// colour, roughness 1) into a constant layer.
//
// Per frame: for each cached fabric pixel, sum over lights model.EvalDirect x irradiance,
// plus the IBL weights x (tabulated radiance, E_d, Charlie radiance). The kernel is a
// template specialised on (model, direct?, IBL?, subsurface?) chosen once per scene: no
// environment -> no IBL code path; no lights -> no direct path; no subsurface -> no wrap.
//
// IBL engines (PreviewOptions::ibl_engine): three.js r187 (render/preview/threejs_ibl.h: PMREM
// cube, irradiance from its top level, 16 x 16 DFG, per-quad geometryRoughness) or Filament
// (SH9 irradiance, GGX prefilter chain with lod = (levels - 1) r (2 - r)).
// Faces: drawn as the glTF material's doubleSided says (back faces culled when false, the ray
// continues behind them); on three.js IBL a double-sided face's normal is flipped by the
// triangle's winding (gl_FrontFacing), on Filament IBL by the shading normal (as the reference
// renderer). Approximations that remain, each measured in docs/preview.md against three.js in
// Chromium: radiance tabulated at K = 33 roughness nodes (Catmull-Rom; K = 257 changed the
// drape/studio metal frame's pixels off by > 2 levels from 983 to 955 only);
// on three.js IBL the G-buffer (normal, view direction, geometryRoughness from coarse per-quad
// derivatives) is interpolated at the rasteriser's barycentrics, vertices snapped to
// SwiftShader's 1/16 pixel (PreviewOptions::raster_subpixel_bits), but visibility (which
// triangle covers a pixel) is the exact ray's and the arithmetic is double where the GPU's is
// fp32: on drape/studio metal 104 of the 18 339 compared pixels (0.6 %) still have a
// geometryRoughness differing from the GPU's by > 0.01 (206 before the snapping);
// the seed variant's accumulation of `directDiffuse *= saturate(subsurface + NoL)` across
// lights is evaluated per light.
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "brdf/math.h"
#include "brdf/table.h"
#include "brdf/woven.h"
#include "brdf/yarn_table.h"
#include "render/preview/visibility.h"
#include "render/preview/weave_maps.h"
#include "render/scene/environment.h"
#include "render/scene/material.h"
#include "render/scene/scene.h"

namespace clothfit::render {

class PrefilteredEnvironment;

// Whose image-based lighting the preview reproduces: Filament's (SH9 irradiance, its GGX
// prefilter chain and LOD mapping, the 128 x 128 DFG LUT) or three.js r187's
// (render/preview/threejs_ibl.h: PMREM cube, irradiance from its top level, 16 x 16 DFG).
// kAuto: three.js for what web/ draws with three.js's PMREM (standard, physical-sheen,
// physical-aniso, woven and the seed cloth variant), Filament for the Filament cloth variant
// and gltf-sheen (the Khronos sample viewer's chain).
enum class IblEngine { kAuto, kFilament, kThreejs };

struct PreviewOptions {
  ModelKind model = ModelKind::kCloth;
  IblEngine ibl_engine = IblEngine::kFilament;  // default: unchanged fits and previews
  cloth::Options cloth;      // model == kCloth
  ::clothfit::woven::Options woven;  // model == kWoven (qualified: render::woven is the reference sampler);
                                     // its ibl / fis_taps / fis_diffuse_taps apply on three.js IBL
                                     // only (UsesWovenFis); on Filament IBL the split sum is kept
  // Woven only: the weave maps (render/preview/weave_maps.h), sampled per fabric pixel at cache
  // build with the GPU's LOD times weave_footprint_scale (the image fit keeps one pixel per
  // stride x stride cell and passes the stride, so a kept pixel carries its cell's average).
  // Null: the uniform model (bit-identical to a preview without maps).
  std::shared_ptr<const WeaveMaps> weave_maps;
  double weave_footprint_scale = 1.0;
  // Woven only, for tests: evaluate frames through the generic per-light kernel
  // (woven::EvalDirect / EvalIbl at every light and pixel), the definition the fast woven kernel
  // (brdf/woven.h's split evaluation) is checked against. false: the fast kernel.
  bool woven_reference_kernel = false;
  bool shadows = false;      // ray-traced light visibility (a perfect shadow map)
  // Woven's fabric pixels: a light split off the environment (the sun, the panels; non-zero
  // Light::sin_angular_radius) fades across the surface's horizon as a disc of its size
  // (render/scene/lights.h ClipDiscAtHorizon; web/clothfit.js draws the same). false (a
  // measurement): every light a delta, as before session 22. Card lights are always deltas.
  bool horizon_fade = true;
  // Visibility prototype (render/preview/visibility.h, docs/visibility.md; measurement, default
  // off = bit-identical): a ray-traced AO map and one-bounce light map applied as three.js r187
  // applies aoMap / lightMap, to the split-sum IBL (not with exact_ibl_samples). With a
  // sample_mask (the fit), only fabric pixels get the terms (non-fabric pixels never enter a
  // block).
  VisibilityOptions visibility;
  // Exact image-based light (a measurement tool, not an engine; docs/fitting.md "The sphere's
  // error decomposed"): when > 0 and the scene has an environment, the split sum is replaced by
  // a Monte Carlo integral of the environment against the model's own direct BRDF, with this
  // many directions per fabric pixel, cached as extra "lights" (PreviewLightSample) so that a
  // frame (and its Jacobian) is the exact integral of a fixed sample set:
  //   L_o = sum_j f(v, l_j) (n.l_j) L_env(l_j) / (sum_k N_k p_k(l_j))
  // (multi-sample MIS, balance heuristic; components k: the environment's luminance sampling
  // (Environment::Sample), cosine-weighted and uniform hemisphere around the shading normal;
  // N_k fixed counts, stratified Hammersley points under a per-pixel Cranley-Patterson shift
  // seeded by (exact_ibl_seed, pixel index): deterministic, the same directions for a pixel in
  // a fit's sampled cache and in a full frame). Diffuse, specular and sheen lobes all go through
  // it: no SH irradiance, no prefiltered radiance, no DFG/phase albedo table for the fabric.
  // Visibility is not traced (exact only on convex fabric such as the sphere). Non-fabric
  // meshes keep the split sum.
  int exact_ibl_samples = 0;
  unsigned exact_ibl_seed = 1;
  // Split sum with an exact diffuse term (measurement): when > 0 (and exact_ibl_samples == 0),
  // the fabric's Lambert irradiance E_d(n) is the Monte Carlo integral of the environment over
  // the hemisphere (the same sampler and seed, this many directions) instead of SH9 / the
  // PMREM; the specular and sheen lobes keep the split sum. Separates the diffuse part of the
  // IBL approximation from the lobes' part.
  int exact_irradiance_samples = 0;
  // physical-aniso only: the anisotropy_rotation (radians) the bent-normal IBL radiance cache is
  // built for (three.js bends the normal toward B = b cos(rot) - t sin(rot)); the direct light
  // uses the evaluated parameter. render-preview sets it from the preset; 0: rotation 0.
  double anisotropy_rotation = 0.0;
  // three.js IBL engine only: the sub-pixel precision of the rasteriser whose G-buffer the
  // preview reproduces (render/preview/threejs_ibl.h RasterBarycentrics): normals, view
  // directions and geometryRoughness are interpolated at the barycentrics of the triangle with
  // its vertices snapped to 1 / 2^bits pixel. 4: SwiftShader (GL_SUBPIXEL_BITS of Chromium's
  // WebGL2 on SwiftShader); -1: exact (the camera ray's hit).
  int raster_subpixel_bits = 4;
  // Sheen nap prototype (render/preview/sheen_tilt.h, docs/velvet.md; measurement, opt-in):
  // cloth and woven only: the sheen lobe (direct and IBL) shaded with its own normal
  // n_s = cos(theta) n + sin(theta) t, theta = this many degrees towards +t (the mesh tangent,
  // +u). 0 (default): the untouched paths, bit-identical. Not with cloth subsurface.
  double sheen_tilt_degrees = 0.0;
  // The environment's sun as a directional light (render/scene/sun.h, docs/sun.md): kAuto
  // detects a compact sun and, when found, the IBL (SH, prefilter / PMREM, exact IBL) is built
  // from the sun-free map and the sun is one more directional light (the background keeps the
  // full map). env_sun set: that mode for every scene (a CLI flag, a preset's fit.env_sun);
  // unset: the card's "environment": {"sun"}, else env_sun_default. The library default is off
  // (bit-identical to no split); the clothfit commands default to auto (docs/sun.md).
  std::optional<SunMode> env_sun;
  SunMode env_sun_default = SunMode::kOff;
  // Far-field yarn lobe (measurement, docs/fitting.md "The far-field yarn lobe (session 11)";
  // woven only, additive yarn layer, every light through the light samples: exact_ibl_samples
  // > 0 when the scene has an environment): when set, the woven yarn lobes (anisotropic GGX x
  // phase Fresnel) are replaced by this function's values, computed once per light sample at
  // cache build: out[0], out[1] = the warp and the weft yarn specular BRDF (no cosine, no ks)
  // for the local directions wo (to the viewer) and wi (to the light), x = t (+u, warp),
  // y = b (+v, weft), z = n (fit/yarn_farfield.h: the period-averaged Irawan specular). The
  // frame is then ks (x) glint [2 m tint_w out[0] + 2 (1 - m) tint_f out[1]] + the diffuse
  // and sheen terms as usual (m = warp_share; m = 0.5 reproduces the function's lobe).
  // roughness, anisotropy, twist, specular_f0 and forward_scattering have no effect.
  // Must be thread-safe. Empty (default): the model's own lobes.
  std::function<void(const Vec3<double>& wo, const Vec3<double>& wi, double out[2])> yarn_lobe;
  // With yarn_lobe, the split-sum IBL of those lobes (session 11; woven, the environment's
  // split sum): per fabric pixel the function gives, for wo (local frame as above), each lobe's
  // albedo A_k, mean direction (local) and equivalent roughness (brdf/yarn_table.h IblLobe);
  // the cache reads the prefiltered environment (the IBL engine's: three.js PMREM or
  // Filament's chain) at that direction and roughness: yarn IBL = ks (x) glint S(NoV)
  // [2 m tint_w A_w L_w + 2 (1 - m) tint_f A_f L_f]. Empty: yarn_lobe needs exact_ibl_samples.
  // Must be thread-safe (called from the parallel cache build); needs yarn_lobe.
  std::function<void(const Vec3<double>& wo, yarn_table::IblLobe out[2])> yarn_ibl;
  // Or (takes precedence) the yarn lobes' environment as a list of reads (measurement; brdf/
  // yarn_table.h IblTap): A_k L_k = sum_taps weight_k L_pref(dir, roughness). Thread-safe;
  // needs yarn_lobe.
  std::function<void(const Vec3<double>& wo, std::vector<yarn_table::IblTap>* taps)> yarn_ibl_taps;
  // Whether the scene card's "visibility" block applies (session 13, WithCardVisibility):
  // its shadows, and its light map (baked over the fabric's uv with visibility.fabric_albedo,
  // which the caller sets from the material: render::DiffuseAlbedo) unless `visibility` already
  // has terms or exact_ibl_samples > 0. false: the card's block is ignored (measurement).
  bool card_visibility = true;
  int roughness_nodes = 33;  // K: radiance table nodes over r in [0, 1]
  int prefilter_levels = 6;  // mip levels of the prefiltered environment
  int prefilter_base_width = 256;
  int prefilter_samples = 128;
  // Fit speed (fit/image_fit.cpp): when non-empty (one entry per image pixel), only the fabric
  // pixels with a non-zero entry get cache entries (lights, irradiance, radiance tables); the
  // other fabric pixels are still marked in fabric_mask but not shaded. Empty: every pixel.
  std::vector<unsigned char> sample_mask;
};

// A preset's far-field yarn lobe ("woven": {"yarn_lobe"}; MaterialPreset::yarn_lobe): sets
// o->yarn_lobe to its quadrature (brdf/yarn_lobe.h Lobe::Eval) and o->yarn_ibl to its table's
// split sum (yarn_table::Table::Ibl), as web/clothfit.js MeshWovenMaterial draws it. A preset
// without one leaves o unchanged. Every place that previews a preset calls it (render-preview,
// evaluate, fits: fit/image_fit.cpp PreviewOptionsFor).
void ApplyPresetYarnLobe(const MaterialPreset& p, PreviewOptions* o);

// A preset's linear diffuse albedo: base_color x (1 - metalness) where the model has a
// metalness, clamped to [0, 1]; {-1, -1, -1} (the glTF's colour) without a base_color. The
// fabric's albedo for the light map's bounce (VisibilityOptions::fabric_albedo).
std::array<double, 3> DiffuseAlbedo(const MaterialPreset& p);

// The options with the scene card's "visibility" block applied (see card_visibility).
PreviewOptions WithCardVisibility(const PreviewOptions& o, const SceneCard& card);

// Whether the preview uses three.js r187's IBL for these options (see IblEngine).
bool UsesThreejsIbl(const PreviewOptions& o);
// Whether the woven yarn lobes use filtered importance sampling (woven, ibl == kFis, three.js
// IBL engine, no exact IBL).
bool UsesWovenFis(const PreviewOptions& o);
// Whether the woven yarn lobes use the bent-normal tables (woven, ibl == kBent, an environment's
// split sum, no exact IBL; both engines). CheckWovenBentFrame: a frame's anisotropy and twist
// must be the cache's options.woven.bent_anisotropy / bent_twist (throws std::invalid_argument).
bool UsesWovenBent(const PreviewOptions& o);
void CheckWovenBentFrame(const PreviewOptions& o, double anisotropy, double twist);
// Whether three.js's geometryRoughness and 16 x 16 DFG table apply (MeshStandardMaterial and
// MeshPhysicalMaterial on three.js IBL; the cloth keeps clothfit's 128 x 128 table, as
// web/clothfit.js does).
bool ThreejsGeometryRoughnessApplies(const PreviewOptions& o);

// Which code paths a scene needs (decided once when the cache is built).
struct PreviewFeatures {
  bool direct = false;      // the scene has punctual lights
  bool ibl = false;         // the scene has an environment
  bool subsurface = false;  // cloth with subsurface colour
  bool shadows = false;
};

struct PreviewLightSample {
  float NoL, NoH, LoH;  // raw cosines for this light at this pixel
  float irradiance[3];  // light colour x intensity x attenuation x visibility
};

class PreviewCache {
 public:
  // `environment` may be null. `progress` may be empty. Throws on bad input.
  static std::unique_ptr<PreviewCache> Build(
      const Scene& scene, const Environment* environment, const PreviewOptions& options,
      const std::function<void(const std::string&)>& log = {});
  ~PreviewCache();

  int width = 0, height = 0;
  PreviewOptions options;
  PreviewFeatures features;
  std::vector<int> pixels;       // image index (y * W + x) of each fabric pixel
  std::vector<float> NoV;        // per fabric pixel
  std::vector<int> light_begin;  // CSR: samples of pixel i in [begin[i], begin[i+1])
  std::vector<PreviewLightSample> light_samples;
  std::vector<float> geometry_roughness;  // three.js geometryRoughness per fabric pixel (empty: 0)
  std::vector<float> irradiance;          // E_d(n), 3 per fabric pixel
  std::vector<float> radiance;            // K x 3 per fabric pixel: GGX-prefiltered, node k
  std::vector<float> sheen_radiance;      // K x 3 per fabric pixel: Charlie (gltf-sheen only)
  // options.sheen_tilt_degrees != 0 with a split-sum environment (else empty): K x 3 per fabric
  // pixel, the radiance table looked up about the tilted sheen normal (sheen_tilt.h).
  std::vector<float> sheen_tilt_radiance;
  // Woven with options.woven.ibl == kFis on the three.js IBL engine (else empty): K x 3 per
  // fabric pixel, the yarn lobes' radiance at node k's r by filtered importance sampling
  // (FisGgxRadiance, options.woven.fis_taps taps; the split-sum read where no tap survives).
  // The yarn lobes interpolate this table (Catmull-Rom in r_e, as `radiance`); the sheen lobe
  // keeps `radiance`. With fis_diffuse_taps > 0, `irradiance` is FisIrradianceOverPi.
  std::vector<float> yarn_radiance;
  std::vector<float> background;          // linear RGB of every pixel without fabric
  std::vector<float> fabric_mask;         // 1 where a fabric pixel is shaded
  // Woven and physical-aniso, and cloth with a sheen tilt (else empty): raw cosines against the reference renderer's
  // tangent frame (t = mesh tangent Gram-Schmidt'd against the viewer-side n, +u = warp;
  // b = tangent_sign n x t, +v = weft): t.v, b.v per fabric pixel; t.l, b.l, t.h, b.h per
  // light sample (parallel to light_samples).
  std::vector<float> tangent_v;
  std::vector<float> light_tangent;
  // Woven with weave maps only (else empty): WeaveMaps::kChannels per fabric pixel (warp,
  // weft, kd.R, kd.G, kd.B ratios), the maps sampled at the pixel's uv and footprint.
  std::vector<float> weave;
  // PreviewOptions::yarn_lobe set (else empty): its two values per light sample (parallel to
  // light_samples).
  std::vector<float> yarn_lobe;
  // PreviewOptions::yarn_ibl set with a split-sum environment (else empty): 6 per fabric pixel,
  // A_w L_w (RGB) then A_f L_f (RGB).
  std::vector<float> yarn_ibl;
  // VisibilityOptions::uv_size > 0: the baked AO / light map of each mesh (indexed by mesh; a
  // map of size 0 where none was baked), else empty. What an engine would load as aoMap /
  // lightMap (clothfit evaluate --light-map-out writes them).
  std::vector<UvVisibilityMap> uv_visibility;
  // A light map with one bounce (visibility.indirect, bounces 1), else empty: 3 per fabric
  // pixel, the part of `irradiance` that bounced off the fabric per unit fabric albedo
  // (VisibilityTerms::fabric_unit), so irradiance + (kd' - kd) x irradiance_unit is the cache
  // baked with albedo kd' instead of options.visibility.fabric_albedo's kd (fit: second pass).
  std::vector<float> irradiance_unit;
  // Woven with a light map (visibility.indirect) and a split-sum environment (session 22), else
  // empty: 3 per fabric pixel, the light map's E_ind / pi alone (the part of `irradiance` it
  // adds). The yarn lobes reflect it as uniform radiance E_ind / pi: each lobe's weight times
  // its directional albedo (the far-field lobes: yarn_albedo; the GGX lobes: their IBL
  // weights), as the diffuse reflects `irradiance`. web/clothfit.js does the same with
  // three.js's lightMap; the baselines keep three.js's (the light map in the diffuse only).
  // The fit's albedo pass re-weights it with irradiance_unit as it does `irradiance`.
  std::vector<float> light_map;
  // With light_map and far-field lobes (yarn_ibl, or the measurement's yarn_ibl_taps): 2 per
  // fabric pixel, the lobes' directional albedos A_w, A_f (the weights their reads carry).
  std::vector<float> yarn_albedo;
  const Table2D* woven_phase = nullptr;   // lut::DefaultWovenPhase() (woven only)
  const Table2D* dfg = nullptr;           // DFG LUT (brdf/lut.h default)
  const Table2D* sheen_albedo = nullptr;  // glTF sheen albedo table
  double build_seconds = 0.0;
  bool sun_split = false;   // lights were split off the environment (its sun, or with
                            // SunMode::kPanels also panels; PreviewOptions::env_sun)
  std::string sun_summary;  // what the sun detection found (empty without an environment)
};

// Linear radiance of every fabric pixel (3 per pixel, cache order) for flat parameters `x`
// in the model's parameter-table order. T = double, float or ceres::Jet.
template <typename T>
void EvaluatePreview(const PreviewCache& cache, const T* x, std::vector<Rgb<T>>& out);

// The full linear frame (fabric pixels + constant background), 3 floats per pixel.
std::vector<float> ComposeFrame(const PreviewCache& cache, const std::vector<Rgb<double>>& fabric);

}  // namespace clothfit::render
