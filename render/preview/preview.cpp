// Fit speed: the dual-number (ceres::Jet) arithmetic of the Jacobian kernels is Eigen
// fixed-size vector code marked EIGEN_STRONG_INLINE, which GCC treats as a plain `inline` hint
// and, in kernels this large, leaves out of line (a third of a fit's time was calls to
// 8-/10-element vector additions). Forcing it inline in this translation unit only; the
// arithmetic and its order are unchanged.
#if defined(__GNUC__) && !defined(EIGEN_STRONG_INLINE)
#define EIGEN_STRONG_INLINE inline __attribute__((always_inline))
#endif
#include "render/preview/preview.h"

#include "render/scene/sampler.h"  // RadicalInverse2

#include <ceres/jet.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <mutex>
#include <stdexcept>
#include <cmath>

#include "brdf/cloth.h"
#include "brdf/gltf_sheen.h"
#include "brdf/lut.h"
#include "brdf/physical_aniso.h"
#include "brdf/physical_sheen.h"
#include "brdf/standard.h"
#include "brdf/woven.h"
#include "render/scene/embree_scene.h"
#include "render/scene/lights.h"
#include "render/scene/sun.h"
#include "render/preview/prefilter.h"
#include "render/preview/sh.h"
#include "render/preview/sheen_tilt.h"
#include "render/preview/threejs_ibl.h"

namespace clothfit::render {
namespace {

// Sheen nap prototype (sheen_tilt.h): on for a non-zero tilt (Build rejects other models).
bool SheenTiltOn(const PreviewOptions& o) { return o.sheen_tilt_degrees != 0.0; }

using Vec3d = Vec3<double>;
Vec3d V(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

// Direction of the prefiltered lookup for roughness r, per engine.
Vec3d DominantDirection(ModelKind m, const Vec3d& n, const Vec3d& R, double r) {
  if (m == ModelKind::kGltfSheen) return R;  // sample viewer: plain reflection
  // Filament getSpecularDominantDirection: mix(R, n, alpha^2), alpha = r^2; the same mix is
  // used for the three.js models (documented approximation).
  const double t = cloth::DominantDirectionMix(r);
  return Normalize(R * (1.0 - t) + n * t);
}

double LodFor(ModelKind m, const PrefilteredEnvironment& pre, double r, int levels) {
  if (m == ModelKind::kGltfSheen) return r * double(levels - 1);  // sample viewer
  return pre.LodForRoughness(r);
}

// Prefiltered chains are the expensive part of a cache build and depend only on the
// environment (file, intensity, rotation) and the chain settings: build each once per process.
std::shared_ptr<const PrefilteredEnvironment> SharedPrefilter(const Environment& env,
                                                              PrefilteredEnvironment::Kernel k,
                                                              const PreviewOptions& o) {
  static std::mutex mutex;
  static std::map<std::string, std::shared_ptr<const PrefilteredEnvironment>> cache;
  // Only named sources are shareable (procedural and constant maps are cheap to rebuild and
  // may differ in content under the same name).
  const bool shareable = !env.source().empty() && env.source().find('/') != std::string::npos;
  const std::string key = env.source() + "|" + std::to_string(env.intensity()) + "|" +
                          std::to_string(env.rotation_y()) + "|" + std::to_string(int(k)) + "|" +
                          std::to_string(o.prefilter_levels) + "|" +
                          std::to_string(o.prefilter_base_width) + "|" +
                          std::to_string(o.prefilter_samples);
  if (shareable) {
    std::lock_guard<std::mutex> lock(mutex);
    auto it = cache.find(key);
    if (it != cache.end()) return it->second;
  }
  auto built = std::make_shared<const PrefilteredEnvironment>(PrefilteredEnvironment::Build(
      env, k, o.prefilter_levels, o.prefilter_base_width, o.prefilter_samples, {}));
  if (shareable) {
    std::lock_guard<std::mutex> lock(mutex);
    cache.emplace(key, built);
  }
  return built;
}

// What the environment contributes to a cache: SH irradiance and the prefiltered chains
// (Charlie for gltf-sheen only). Empty without an environment.
struct EnvironmentData {
  Sh9 sh{};
  std::shared_ptr<const PrefilteredEnvironment> ggx, charlie;
  std::shared_ptr<const ThreejsPmrem> pmrem;  // three.js r187's PMREM (UsesThreejsIbl)
};

EnvironmentData PrepareEnvironment(const Environment* env, const PreviewOptions& opt,
                                   const std::function<void(const std::string&)>& log) {
  EnvironmentData e;
  if (env) {
    if (log) log("preview: projecting the environment on SH and prefiltering");
    e.sh = ProjectEnvironment(*env);
    if (UsesThreejsIbl(opt)) e.pmrem = SharedThreejsPmrem(*env);
    else e.ggx = SharedPrefilter(*env, PrefilteredEnvironment::Kernel::kGgx, opt);
    if (opt.model == ModelKind::kGltfSheen)
      e.charlie = SharedPrefilter(*env, PrefilteredEnvironment::Kernel::kCharlie, opt);
  }
  return e;
}

// One fabric pixel's cache entries, gathered per row and then appended in pixel order.
struct PixelData {
  int index;
  float nov;
  float gr = 0.f;  // three.js geometryRoughness (standard / physical-sheen on three.js IBL)
  std::vector<PreviewLightSample> lights;
  std::array<float, 3> irr{};
  std::vector<float> rad, srad;
  std::vector<float> trad;    // sheen tilt: the K-node table about the tilted sheen normal
  std::vector<float> yrad;    // woven FIS: the yarn lobes' K-node table
  std::array<float, 2> tv{};  // woven: t.v, b.v
  std::vector<float> lt;      // woven: t.l, b.l, t.h, b.h per light sample
  std::array<float, WeaveMaps::kChannels> weave{};  // woven with maps: the sampled maps
  std::array<float, 6> yibl{};  // PreviewOptions::yarn_ibl: A_w L_w, A_f L_f
  std::array<float, 3> irr_unit{};  // VisibilityTerms::fabric_unit (light map, one bounce)
  std::array<float, 3> lm{};        // woven: the light map's E_ind / pi (PreviewCache::light_map)
  std::array<float, 2> yalb{};      // woven far-field: A_w, A_f (PreviewCache::yarn_albedo)
};

// Session 22: woven's yarn lobes reflect the light map's bounce light too (PreviewCache::
// light_map), with a split-sum environment (the far-field lobes' reads, yarn_ibl or the
// measurement's yarn_ibl_taps, carry their albedos in yarn_albedo).
bool WovenYarnReflectsLightMap(const PreviewCache& c) {
  return c.options.model == ModelKind::kWoven && c.options.visibility.indirect && c.features.ibl;
}

// What the per-pixel work of a cache build reads.
struct PixelContext {
  const Scene& scene;
  const Environment* env;  // the IBL's map (sun-free when the sun is split, render/scene/sun.h)
  const PreviewOptions& opt;
  const EmbreeScene& bvh;
  const EnvironmentData& e;
  double eps;
  bool wrap_past_terminator;
  const FisPattern* fis_yarn = nullptr;     // woven FIS (UsesWovenFis), else null
  const FisPattern* fis_diffuse = nullptr;  // woven FIS with fis_diffuse_taps > 0, else null
  const std::vector<Light>* lights = nullptr;     // scene.lights (+ the environment's sun)
  const Environment* background_env = nullptr;    // what escaping rays see: the full map
  // VisibilityOptions::uv_size > 0: the baked maps, indexed by mesh (size 0 = none), else null.
  const std::vector<UvVisibilityMap>* uv_vis = nullptr;
};

// A visible surface point: position (offset off the surface), shading normal on the viewer's
// side, view direction, and its mesh.
struct PrimaryHit {
  Vec3d p, n, v;
  Vec3d t, b;  // the reference renderer's tangent frame (path_tracer.cpp): t = mesh tangent
               // Gram-Schmidt'd against n, b = tangent_sign n x t
  double NoV;
  const Mesh* mesh;
};

// The punctual lights reaching a point (with the terminator wrap of Filament's subsurface
// cloth on the fabric), each with its cosines and irradiance.
// `light_tangent` (woven only, else null) receives t.l, b.l, t.h, b.h per kept light.
// `horizon_fade` (woven's fabric pixels): a light split off the environment
// (Light::sin_angular_radius > 0) is clipped at the horizon as a disc (ClipDiscAtHorizon): its
// irradiance times the visible fraction, its cosines and its shadow ray those of the visible
// part's centroid.
std::vector<PreviewLightSample> GatherLights(const PixelContext& x, const PreviewCache& c,
                                             const PrimaryHit& hit,
                                             std::vector<float>* light_tangent = nullptr,
                                             bool horizon_fade = false) {
  const Vec3d& p = hit.p;
  const Vec3d& n = hit.n;
  const Vec3d& v = hit.v;
  std::vector<PreviewLightSample> ls;
  for (const Light& light : *x.lights) {
    const LightSample s = EvaluateLight(light, p);
    if (s.scale <= 0.0) continue;
    const double NoL = Dot(n, s.wi);
    const bool fade = horizon_fade && light.sin_angular_radius > 0.0;
    if (NoL <= (fade ? -light.sin_angular_radius : 0.0) &&
        !(x.wrap_past_terminator && hit.mesh->is_fabric && NoL > -0.5))
      continue;
    Vec3d wi = s.wi;
    double scale = s.scale, cos_l = NoL;
    if (fade) {
      const HorizonClip clip = ClipDiscAtHorizon(NoL, light.sin_angular_radius);
      if (!(clip.visible > 0.0)) continue;
      if (clip.visible < 1.0) {
        wi = TiltToCosine(s.wi, n, clip.NoL);
        cos_l = Dot(n, wi);
        scale *= clip.visible;
      }
    }
    // A clipped disc is tested towards its visible part's centroid (above the horizon): the
    // disc's centre may be below it, where the surface itself would shadow it (review s22).
    if (c.features.shadows &&
        x.bvh.Occluded({p.x, p.y, p.z}, {wi.x, wi.y, wi.z}, 0.0,
                       std::isinf(s.distance) ? s.distance : s.distance * (1 - 1e-6)))
      continue;
    const Vec3d hv = Normalize(v + wi);
    PreviewLightSample q;
    q.NoL = float(cos_l);
    q.NoH = float(Dot(n, hv));
    q.LoH = float(Dot(wi, hv));
    for (int k = 0; k < 3; ++k) q.irradiance[k] = float(scale * light.color[size_t(k)]);
    ls.push_back(q);
    if (light_tangent)
      light_tangent->insert(light_tangent->end(),
                            {float(Dot(hit.t, wi)), float(Dot(hit.b, wi)),
                             float(Dot(hit.t, hv)), float(Dot(hit.b, hv))});
  }
  return ls;
}

// Exact IBL (PreviewOptions::exact_ibl_samples): the environment as a fixed set of directional
// "lights" per fabric pixel, see preview.h. Sampling components (counts N_k, fractions of N):
// environment luminance 1/2, cosine hemisphere 1/4, uniform hemisphere the rest (the uniform
// component bounds the weight of every direction by 2 pi / N_uni: grazing lobes such as the
// phase Fresnel's forward peak and a sharp Charlie sheen stay finite).
uint64_t SplitMix64(uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
double ToUnit(uint64_t z) { return double(z >> 11) * (1.0 / 9007199254740992.0); }

void AppendEnvironmentSamples(const PixelContext& x, const PrimaryHit& hit, size_t pix,
                              std::vector<PreviewLightSample>* ls,
                              std::vector<float>* light_tangent, int N) {
  const int n_env = N / 2, n_cos = N / 4, n_uni = N - n_env - n_cos;
  const Vec3d& n = hit.n;
  // Orthonormal basis around n (Frisvad-style, any completion works: the integral does not
  // depend on it).
  const Vec3d a = std::abs(n.x) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0);
  const Vec3d e1 = Normalize(Cross(a, n)), e2 = Cross(n, e1);
  uint64_t h = SplitMix64((uint64_t(x.opt.exact_ibl_seed) << 32) ^ uint64_t(pix));
  double shift[6];
  for (double& sft : shift) {
    h = SplitMix64(h);
    sft = ToUnit(h);
  }
  auto frac = [](double u) { return u - std::floor(u); };
  auto add = [&](const Vec3d& l) {
    const double NoL = Dot(n, l);
    if (!(NoL > 0.0)) return;
    const double p_env = n_env > 0 ? x.env->Pdf(l) : 0.0;
    const double pdf = double(n_env) * p_env + double(n_cos) * NoL * kInvPi +
                       double(n_uni) * (0.5 * kInvPi);
    if (!(pdf > 0.0)) return;
    const Rgb<double> L = x.env->Eval(l);
    const Vec3d hv = Normalize(hit.v + l);
    PreviewLightSample q;
    q.NoL = float(NoL);
    q.NoH = float(Dot(n, hv));
    q.LoH = float(Dot(l, hv));
    for (int k = 0; k < 3; ++k) q.irradiance[k] = float(L[k] / pdf);
    ls->push_back(q);
    if (light_tangent)
      light_tangent->insert(light_tangent->end(),
                            {float(Dot(hit.t, l)), float(Dot(hit.b, l)), float(Dot(hit.t, hv)),
                             float(Dot(hit.b, hv))});
  };
  for (int j = 0; j < n_env; ++j) {
    double pdf;
    Rgb<double> L;
    const Vec3d l = x.env->Sample(frac((j + 0.5) / n_env + shift[0]),
                                  frac(RadicalInverse2(uint32_t(j)) + shift[1]), &pdf, &L);
    if (pdf > 0.0) add(l);
  }
  for (int j = 0; j < n_cos; ++j) {  // cosine-weighted: r = sqrt(u1), phi = 2 pi u2
    const double u1 = frac((j + 0.5) / n_cos + shift[2]);
    const double u2 = frac(RadicalInverse2(uint32_t(j)) + shift[3]);
    const double r = std::sqrt(u1), phi = 2.0 * kPi * u2;
    const double z = std::sqrt(std::max(0.0, 1.0 - u1));
    add(Normalize(e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi)) + n * z));
  }
  for (int j = 0; j < n_uni; ++j) {  // uniform hemisphere: z = u1
    const double z = frac((j + 0.5) / n_uni + shift[4]);
    const double phi = 2.0 * kPi * frac(RadicalInverse2(uint32_t(j)) + shift[5]);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    add(Normalize(e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi)) + n * z));
  }
}

// Constant layer: MeshStandardMaterial, glTF base colour, roughness 1.
Rgb<double> ShadeNonFabric(const PixelContext& x, const PreviewCache& c, const PrimaryHit& hit,
                           const std::vector<PreviewLightSample>& ls, const Vec3d& R,
                           const Rgb<double>& Ed, double spec_occlusion = 1.0) {
  const double NoV = hit.NoV;
  standard::Params<double> sp;
  sp.base_color = {double(hit.mesh->base_color[0]), double(hit.mesh->base_color[1]),
                     double(hit.mesh->base_color[2])};
  Rgb<double> out(0, 0, 0);
  for (const PreviewLightSample& q : ls) {
    if (q.NoL <= 0.f) continue;
    const Cosines<double> cs{NoV, double(q.NoL), double(q.NoH), double(q.LoH)};
    const Rgb<double> f = standard::EvalDirect(sp, {}, cs, *c.dfg);
    out += f * Rgb<double>(double(q.irradiance[0]), double(q.irradiance[1]),
                             double(q.irradiance[2]));
  }
  if (x.env) {
    const IblWeights<double> w = standard::EvalIbl(sp, {}, NoV, *c.dfg);
    const Vec3d dd = DominantDirection(ModelKind::kStandard, hit.n, R, 1.0);
    const Rgb<double> Lr = x.e.pmrem ? x.e.pmrem->Sample(dd, x.e.pmrem->MipForRoughness(1.0))
                                     : x.e.ggx->Sample(dd, x.e.ggx->LodForRoughness(1.0));
    out += w.specular * Lr * spec_occlusion + w.diffuse * Ed;
  }
  return out;
}

// Visibility prototype (PreviewOptions::visibility): the AO and light-map terms of a shaded
// point, with the engine's own unoccluded irradiance for the bounce hit points. Applied as
// three.js r187 applies aoMap and lightMap (docs/visibility.md): E_d -> ao E_d + E_ind / pi,
// specular radiance x computeSpecularOcclusion(n.v, ao, r). Off: ao 1, no bounce.
IrradianceOverPiFn EnvIrradianceFn(const PixelContext& x) {
  IrradianceOverPiFn env;
  if (x.env)
    env = [&x](const Vec3d& n) {
      return x.e.pmrem ? x.e.pmrem->IrradianceOverPi(n) : IrradianceOverPi(x.e.sh, n);
    };
  return env;
}

// The environment's radiance in a direction (the AO map's environment weighting); empty without
// an environment.
RadianceFn EnvRadianceFn(const PixelContext& x) {
  RadianceFn radiance;
  if (x.env) radiance = [&x](const Vec3d& l) { return x.env->Eval(l); };
  return radiance;
}

// VisibilityOptions::uv_size > 0: each fabric mesh's terms baked over its uv (visibility.h).
std::vector<UvVisibilityMap> BakeFabricUvVisibility(const PixelContext& x) {
  std::vector<UvVisibilityMap> maps(x.scene.meshes.size());
  for (size_t i = 0; i < x.scene.meshes.size(); ++i)
    if (x.scene.meshes[i].is_fabric)
      maps[i] = BakeUvVisibility(x.scene, x.bvh, x.opt.visibility, EnvIrradianceFn(x), int(i),
                                 x.eps, EnvRadianceFn(x), x.lights);
  return maps;
}

VisibilityTerms PointVisibility(const PixelContext& x, const PrimaryHit& hit, const Hit& h,
                                size_t pix) {
  Vec3d ng = V(h.ng);  // the geometric normal on the shading normal's side
  if (Dot(ng, hit.n) < 0.0) ng = ng * -1.0;
  VisibilityTerms t = ComputeVisibility(x.scene, x.bvh, x.opt.visibility, EnvIrradianceFn(x),
                                        hit.p, hit.n, ng, pix, x.eps, EnvRadianceFn(x), x.lights);
  if (!x.opt.visibility.ao) t.ao = 1.0;
  return t;
}

// The prefiltered GGX radiance along dd at perceptual roughness r: three.js's PMREM at its mip
// for r, else the Filament-style chain at LodFor (every radiance table below reads through it).
Rgb<double> PrefilteredRead(const PixelContext& x, const Vec3d& dd, double r) {
  return x.e.pmrem ? x.e.pmrem->Sample(dd, x.e.pmrem->MipForRoughness(r))
                   : x.e.ggx->Sample(dd, LodFor(x.opt.model, *x.e.ggx, r, x.opt.prefilter_levels));
}

// The K-node radiance tables of a fabric pixel (GGX; Charlie for gltf-sheen).
void FillRadianceTables(const PixelContext& x, const Vec3d& n, const Vec3d& R, PixelData* pd) {
  const int K = x.opt.roughness_nodes;
  pd->rad.resize(size_t(K) * 3);
  for (int k = 0; k < K; ++k) {
    const double r = double(k) / double(K - 1);
    const Vec3d dd = DominantDirection(x.opt.model, n, R, r);
    const Rgb<double> L = PrefilteredRead(x, dd, r);
    for (int ch = 0; ch < 3; ++ch) pd->rad[size_t(k) * 3 + size_t(ch)] = float(L[ch]);
  }
  if (x.e.charlie) {
    pd->srad.resize(size_t(K) * 3);
    for (int k = 0; k < K; ++k) {
      const double r = double(k) / double(K - 1);
      const Rgb<double> L = x.e.charlie->Sample(R, r * double(x.opt.prefilter_levels - 1));
      for (int ch = 0; ch < 3; ++ch) pd->srad[size_t(k) * 3 + size_t(ch)] = float(L[ch]);
    }
  }
}

// Woven FIS (UsesWovenFis): the yarn lobes' K-node table by filtered importance sampling of
// the PMREM at each node's r (FisGgxRadiance, world space, n and v of the G-buffer); where no
// tap survives (grazing), the node keeps the split-sum read of `pd->rad` (getIBLRadiance), so a
// pixel is never black. Needs pd->rad filled first.
void FillFisYarnTable(const PixelContext& x, const PrimaryHit& hit, PixelData* pd) {
  const int K = x.opt.roughness_nodes;
  pd->yrad.resize(size_t(K) * 3);
  for (int k = 0; k < K; ++k) {
    const double r = double(k) / double(K - 1);
    int used = 0;
    const Rgb<double> L = FisGgxRadiance(*x.e.pmrem, *x.fis_yarn, hit.n, hit.v, r, &used);
    for (int ch = 0; ch < 3; ++ch)
      pd->yrad[size_t(k) * 3 + size_t(ch)] =
          used > 0 ? float(L[ch]) : pd->rad[size_t(k) * 3 + size_t(ch)];
  }
}

// Woven "ibl": "bent" (UsesWovenBent; brdf/woven.h IblMode::kBent): two K-node tables, the warp
// lobe's then the weft lobe's, each node k read about the lobe's bent normal at r_e = k / (K - 1)
// (three.js getIBLRadiance about the bent normal: direction mix(reflect(-v, bn), bn, r_e^4), mip
// of r_e), w = woven::BentNormalWeight(bent_anisotropy, r_e), fibre axes from bent_twist.
void FillBentYarnTables(const PixelContext& x, const PrimaryHit& hit, PixelData* pd) {
  const int K = x.opt.roughness_nodes;
  pd->yrad.resize(size_t(K) * 3 * 2);
  const double rho = x.opt.woven.bent_twist * kPi / 180.0;
  const double cr = std::cos(rho), sr = std::sin(rho);
  const Vec3d axes[2] = {hit.t * cr + hit.b * sr,    // warp fibre axis a_w
                         hit.b * cr - hit.t * sr};   // weft fibre axis a_f = c_w
  for (int j = 0; j < 2; ++j) {
    for (int k = 0; k < K; ++k) {
      const double r = double(k) / double(K - 1);
      const double w = woven::BentNormalWeight(x.opt.woven.bent_anisotropy, r);
      const Vec3d bent = physical_aniso::BentNormal(hit.n, hit.v, axes[j], w);
      const Vec3d dd = physical_aniso::IblDirection(bent, hit.v, r);
      const Rgb<double> L = PrefilteredRead(x, dd, r);
      for (int ch = 0; ch < 3; ++ch)
        pd->yrad[(size_t(j) * size_t(K) + size_t(k)) * 3 + size_t(ch)] = float(L[ch]);
    }
  }
}

// physical-aniso (three.js getIBLAnisotropyRadiance): the bent normal depends on the fitted
// anisotropy and roughness through one weight w = (1 - a (1 - r))^4, so the cache holds the
// K-node roughness table at kAnisoBentNodes values of w in [0, 1] (node w = 1 is the
// isotropic table: bent = n exactly); the kernel interpolates linearly in w. The bitangent
// B of the anisotropy frame comes from the weave-map direction rotated by
// PreviewOptions::anisotropy_rotation (render-preview: the preset's; the fit locks the rotation
// and leaves it at 0).
constexpr int kAnisoBentNodes = 17;
// Which way the anisotropy direction (where three.js raises the roughness to alpha_t) points
// relative to the dominant yarn: false = along it (warp -> t, weft -> b, the mapping),
// true = across it (warp -> b, weft -> t: a cylinder's normals spread across its axis).
// Both measured in docs/fitting.md, "The honest baseline".
constexpr bool kAnisoAcrossYarn = false;

// physical-aniso with weave maps: the cache's weave[0..1] hold the three.js anisotropyMap
// sample (WeaveMaps::SampleAnisotropy: the map of direction t where the warp weight dominates,
// b where the weft does, strength |warp - weft| / (warp + weft), filtered as the GPU filters that
// texture, decoded (vx, vy) = normalize(2 rg - 1) b), swapped to (vy, vx) when kAnisoAcrossYarn.
template <typename T>
physical_aniso::AnisoSample<T> AnisoFromWeave(const float* wv) {
  physical_aniso::AnisoSample<T> s;
  const double vx = double(wv[0]), vy = double(wv[1]);
  s.dx = Const<T>(vx);
  s.dy = Const<T>(vy);
  s.b = Const<T>(std::hypot(vx, vy));  // MakeFrame: direction (vx, vy) / |v|, strength x |v|
  return s;
}

void FillAnisoRadianceTables(const PixelContext& x, const PrimaryHit& hit, const float* weave,
                             PixelData* pd) {
  const int K = x.opt.roughness_nodes;
  pd->rad.resize(size_t(K) * kAnisoBentNodes * 3);
  // The map direction (AnisoFromWeave; (1, 0) without maps or where the sample is 0, as three.js
  // takes it), rotated by the preset's rotation as physical_aniso::MakeFrame does:
  // (ux, uy) = R(rot) (dx, dy); B = b ux - t uy.
  const double vl = weave ? std::hypot(double(weave[0]), double(weave[1])) : 0.0;
  const double dx = vl > 0.0 ? double(weave[0]) / vl : 1.0, dy = vl > 0.0 ? double(weave[1]) / vl : 0.0;
  const double cr = std::cos(x.opt.anisotropy_rotation), sr = std::sin(x.opt.anisotropy_rotation);
  const double ux = cr * dx - sr * dy, uy = sr * dx + cr * dy;
  const Vec3d B = hit.b * ux - hit.t * uy;
  for (int j = 0; j < kAnisoBentNodes; ++j) {
    const double w = double(j) / double(kAnisoBentNodes - 1);
    const Vec3d bent = physical_aniso::BentNormal(hit.n, hit.v, B, w);
    for (int k = 0; k < K; ++k) {
      const double r = double(k) / double(K - 1);
      const Vec3d dd = physical_aniso::IblDirection(bent, hit.v, r);
      const Rgb<double> L = PrefilteredRead(x, dd, r);
      for (int ch = 0; ch < 3; ++ch)
        pd->rad[(size_t(j) * size_t(K) + size_t(k)) * 3 + size_t(ch)] = float(L[ch]);
    }
  }
}

// Whether the camera ray `d` sees triangle `tri` of `m` from its back: glTF front faces are
// counter-clockwise (the scene loader fixes the winding of mirroring transforms), so the face is
// a back face when (P1 - P0) x (P2 - P0) points away from the viewer (gl_FrontFacing false).
bool BackFacing(const Mesh& m, int tri, const Vec3d& d) {
  const uint32_t* idx = &m.indices[size_t(tri) * 3];
  auto p = [&](int k) {
    const auto& q = m.positions[idx[k]];
    return Vec3d(double(q[0]), double(q[1]), double(q[2]));
  };
  const Vec3d p0 = p(0);
  return Dot(Cross(p(1) - p0, p(2) - p0), d) > 0.0;
}

// Primary visibility with back-face culling as the glTF material says (doubleSided false: back
// faces are not drawn, as three.js's FrontSide and Filament's culling do): a culled hit is
// skipped and the ray continues past it. *back_face: whether the kept hit is a back face (of a
// double-sided material).
Hit IntersectCulled(const PixelContext& x, const std::array<double, 3>& org,
                    const std::array<double, 3>& dir, bool* back_face) {
  const Vec3d d = V(dir);
  double tnear = 0.0;
  for (int guard = 0; guard < 64; ++guard) {
    const Hit h = x.bvh.Intersect(org, dir, tnear);
    if (!h.valid) return h;
    const Mesh& m = x.scene.meshes[size_t(h.mesh)];
    *back_face = BackFacing(m, h.triangle, d);
    if (!*back_face || m.double_sided) return h;
    tnear = h.t * (1.0 + 1e-6) + 1e-7 * x.bvh.scale();
  }
  return Hit{};
}

// Primary visibility at the centres of row y: background and non-fabric pixels go straight
// into c->background, fabric pixels into *row.
void BuildRow(const PixelContext& x, int y, PreviewCache* c, std::vector<PixelData>* row) {
  const int W = c->width;
  for (int px = 0; px < W; ++px) {
    const size_t pix = size_t(y) * size_t(W) + size_t(px);
    std::array<double, 3> org, dir;
    x.scene.CameraRay(px + 0.5, y + 0.5, org, dir);
    bool back_face = false;
    const Hit h = IntersectCulled(x, org, dir, &back_face);
    const Vec3d d = V(dir);
    if (!h.valid) {
      const Rgb<double> bg =
          x.background_env ? x.background_env->Eval(d)
                : Rgb<double>(x.scene.card.background[0], x.scene.card.background[1],
                              x.scene.card.background[2]);
      for (int k = 0; k < 3; ++k) c->background[pix * 3 + size_t(k)] = float(bg[k]);
      continue;
    }
    if (!x.opt.sample_mask.empty() && x.scene.meshes[size_t(h.mesh)].is_fabric &&
        x.opt.sample_mask[pix] == 0) {
      c->fabric_mask[pix] = 1.f;  // fabric, but not sampled: no cache entries
      continue;
    }
    const SurfaceAttributes a = x.bvh.Attributes(h);
    std::array<double, 2> uv{a.uv[0], a.uv[1]};  // where the weave maps are read
    PrimaryHit hit;
    hit.v = d * -1.0;
    hit.n = V(a.normal);
    if (UsesThreejsIbl(x.opt)) {
      // The GPU's G-buffer: normal and view direction interpolated at the rasteriser's
      // perspective-correct barycentrics of the pixel centre, which SwiftShader computes from
      // the vertices snapped to its sub-pixel grid (RasterBarycentrics), not at the exact ray
      // hit. (Visibility, position for the lights and the other attributes stay exact.)
      const Mesh& m = x.scene.meshes[size_t(h.mesh)];
      const uint32_t* idx = &m.indices[size_t(h.triangle) * 3];
      auto v3 = [](const std::array<float, 3>& q) {
        return Vec3d(double(q[0]), double(q[1]), double(q[2]));
      };
      const std::array<Vec3d, 3> P{v3(m.positions[idx[0]]), v3(m.positions[idx[1]]),
                                   v3(m.positions[idx[2]])};
      double b[3];
      if (x.opt.raster_subpixel_bits >= 0 &&
          RasterBarycentrics(x.scene, P, px + 0.5, y + 0.5, x.opt.raster_subpixel_bits, b)) {
        hit.n = Normalize(v3(m.normals[idx[0]]) * b[0] + v3(m.normals[idx[1]]) * b[1] +
                          v3(m.normals[idx[2]]) * b[2]);
        hit.v = Normalize(V(x.scene.camera.position) - (P[0] * b[0] + P[1] * b[1] + P[2] * b[2]));
        if (!m.uvs.empty())  // TEXCOORD_0 as the GPU interpolates it (the weave maps' uv)
          for (int k = 0; k < 2; ++k)
            uv[size_t(k)] = double(m.uvs[idx[0]][size_t(k)]) * b[0] +
                            double(m.uvs[idx[1]][size_t(k)]) * b[1] +
                            double(m.uvs[idx[2]][size_t(k)]) * b[2];
      }
      // three.js (normal_fragment_begin, DoubleSide): normal *= faceDirection, i.e. flipped on
      // back faces by the triangle's winding (gl_FrontFacing), not by the shading normal; a
      // front face may keep n.v < 0 near silhouettes (NoV then saturates to 0).
      if (back_face) hit.n = hit.n * -1.0;
    } else if (Dot(hit.n, hit.v) < 0.0) {
      hit.n = hit.n * -1.0;  // two-sided by the shading normal, as the reference renderer
    }
    hit.p = V(a.position) + V(h.ng) * (Dot(V(h.ng), hit.v) > 0 ? x.eps : -x.eps);
    hit.NoV = Dot(hit.n, hit.v);
    hit.mesh = &x.scene.meshes[size_t(h.mesh)];
    hit.t = V(a.tangent);
    hit.t = Normalize(hit.t - hit.n * Dot(hit.t, hit.n));
    hit.b = Cross(hit.n, hit.t) * a.tangent_sign;
    const bool woven_frame = (x.opt.model == ModelKind::kWoven ||
                              x.opt.model == ModelKind::kPhysicalAniso) &&
                             hit.mesh->is_fabric;
    // Woven weave maps: sampled at the pixel's uv and GPU footprint; a relief normal map
    // (if any) replaces n by normalize(t N.x + b N.y + n N.z) and re-derives t and b from it,
    // before anything is shaded (lights, irradiance, reflection vector).
    std::array<float, WeaveMaps::kChannels> weave{};
    if (woven_frame && x.opt.weave_maps) {
      const WeaveMaps& wm = *x.opt.weave_maps;
      const std::array<double, 4> duv = UvDerivatives(x.scene, h, px + 0.5, y + 0.5);
      // GPU footprint (isotropic LOD, or anisotropic probes with wm.anisotropy > 1;
      // render/preview/weave_maps.h), the same for the weave, normal and anisotropy maps.
      const WeaveMaps::Footprint lod = wm.FootprintAt(duv, x.opt.weave_footprint_scale);
      // woven: the view bands (if the preset names them) blended by NoV before the relief
      // normal (weave_maps.h SampleView); physical-aniso draws the main maps only.
      const auto s = x.opt.model == ModelKind::kWoven
                         ? wm.SampleView(uv[0], uv[1], lod, std::clamp(hit.NoV, 0.0, 1.0))
                         : wm.Sample(uv[0], uv[1], lod);
      for (int k = 0; k < WeaveMaps::kChannels; ++k) weave[size_t(k)] = float(s[size_t(k)]);
      if (wm.has_glint()) {  // the glint multiplies both yarn lobes: fold it into their weights
        const double g = wm.SampleGlint(uv[0], uv[1], duv, x.opt.weave_footprint_scale);
        weave[0] = float(s[0] * g);
        weave[1] = float(s[1] * g);
      }
      if (x.opt.model == ModelKind::kPhysicalAniso) {  // the anisotropyMap sample (AnisoFromWeave)
        const auto av = wm.SampleAnisotropy(uv[0], uv[1], lod);
        weave[0] = float(kAnisoAcrossYarn ? av[1] : av[0]);
        weave[1] = float(kAnisoAcrossYarn ? av[0] : av[1]);
      }
      if (wm.has_normals()) {
        const auto nm = wm.SampleNormal(uv[0], uv[1], lod);
        const Vec3d np = Normalize(hit.t * nm[0] + hit.b * nm[1] + hit.n * nm[2]);
        hit.n = np;
        hit.NoV = Dot(hit.n, hit.v);
        hit.t = Normalize(hit.t - hit.n * Dot(hit.t, hit.n));
        hit.b = Cross(hit.n, hit.t) * a.tangent_sign;
      }
    }
    // physical-aniso is three.js's own MeshPhysicalMaterial, whose anisotropy frame on a back face
    // of a DoubleSide mesh is tbn[0] *= faceDirection, tbn[1] *= faceDirection
    // (normal_fragment_begin). Here n is already flipped and b = (-n) x t = -b as three.js's,
    // but t is not: flip it too, or a rotated anisotropy direction (b cos - t sin) is mirrored on
    // back faces. woven keeps its own frame (web/clothfit.js vWovenTangent: t is not flipped).
    if (UsesThreejsIbl(x.opt) && back_face && x.opt.model == ModelKind::kPhysicalAniso &&
        hit.mesh->is_fabric)
      hit.t = hit.t * -1.0;
    std::vector<float> lt;
    // Sheen tilt (sheen_tilt.h): the tilted cosines come from the tangent cosines, so a cloth
    // fabric pixel gathers them too.
    const bool tangent_cosines = woven_frame || (SheenTiltOn(x.opt) && hit.mesh->is_fabric);
    std::vector<PreviewLightSample> ls =
        GatherLights(x, *c, hit, tangent_cosines ? &lt : nullptr,
                     x.opt.horizon_fade && x.opt.model == ModelKind::kWoven &&
                         hit.mesh->is_fabric);
    if (x.env && x.opt.exact_ibl_samples > 0 && hit.mesh->is_fabric)
      AppendEnvironmentSamples(x, hit, pix, &ls, tangent_cosines ? &lt : nullptr,
                               x.opt.exact_ibl_samples);
    Rgb<double> Ed(0, 0, 0);
    if (x.env) Ed = x.e.pmrem ? x.e.pmrem->IrradianceOverPi(hit.n) : IrradianceOverPi(x.e.sh, hit.n);
    if (x.fis_diffuse && hit.mesh->is_fabric)  // woven FIS: E_fis / pi replaces the top level
      Ed = FisIrradianceOverPi(*x.e.pmrem, *x.fis_diffuse, hit.n);
    if (x.env && x.opt.exact_ibl_samples <= 0 && x.opt.exact_irradiance_samples > 0 &&
        hit.mesh->is_fabric) {  // E_d / pi = sum_j (n.l_j) L(l_j) / (pi pdf_j)
      std::vector<PreviewLightSample> es;
      AppendEnvironmentSamples(x, hit, pix, &es, nullptr, x.opt.exact_irradiance_samples);
      Ed = Rgb<double>(0, 0, 0);
      for (const PreviewLightSample& q : es)
        for (int k = 0; k < 3; ++k) Ed[k] += double(q.NoL) * double(q.irradiance[k]) * kInvPi;
    }
    VisibilityTerms vis;  // visibility prototype (off: ao 1, no bounce)
    // Per pixel: fabric pixels (and, in full frames, every shaded pixel); baked over uv
    // (uv_size > 0): the fabric only, the meshes that have the texture, as an engine draws it.
    const bool vis_on = x.opt.visibility.enabled() &&
                        (x.opt.visibility.uv_size > 0
                             ? hit.mesh->is_fabric
                             : (hit.mesh->is_fabric || x.opt.sample_mask.empty()));
    if (vis_on) {
      const UvVisibilityMap* um =  // the texture's terms at the pixel's uv (uv_size > 0)
          x.uv_vis && size_t(h.mesh) < x.uv_vis->size() && (*x.uv_vis)[size_t(h.mesh)].size > 0
              ? &(*x.uv_vis)[size_t(h.mesh)]
              : nullptr;
      if (um) {
        vis = um->Sample(uv[0], uv[1]);
        if (!x.opt.visibility.ao) vis.ao = 1.0;
      } else {
        vis = PointVisibility(x, hit, h, pix);
      }
      Ed = Ed * vis.ao + vis.indirect_over_pi;
    }
    const Vec3d R = hit.n * (2.0 * hit.NoV) - hit.v;
    if (!hit.mesh->is_fabric) {
      const double so =  // three.js's specular occlusion at the layer's roughness 1
          vis_on ? SpecularOcclusion(std::clamp(hit.NoV, 0.0, 1.0), vis.ao, 1.0) : 1.0;
      const Rgb<double> out = ShadeNonFabric(x, *c, hit, ls, R, Ed, so);
      for (int k = 0; k < 3; ++k) c->background[pix * 3 + size_t(k)] = float(out[k]);
      continue;
    }
    PixelData pd;
    pd.index = int(pix);
    pd.nov = float(hit.NoV);
    if (ThreejsGeometryRoughnessApplies(x.opt))
      pd.gr = float(ThreejsGeometryRoughness(x.scene, h.mesh, h.triangle, px, y,
                                                x.opt.raster_subpixel_bits));
    pd.lights = std::move(ls);
    pd.tv = {float(Dot(hit.t, hit.v)), float(Dot(hit.b, hit.v))};
    pd.lt = std::move(lt);
    pd.weave = weave;
    for (int k = 0; k < 3; ++k) pd.irr[size_t(k)] = float(Ed[k]);
    for (int k = 0; k < 3; ++k) pd.irr_unit[size_t(k)] = float(vis.fabric_unit[k]);
    for (int k = 0; k < 3; ++k) pd.lm[size_t(k)] = vis_on ? float(vis.indirect_over_pi[k]) : 0.f;
    const bool split_sum = x.env && x.opt.exact_ibl_samples <= 0;
    if (split_sum && x.opt.model == ModelKind::kPhysicalAniso)
      FillAnisoRadianceTables(x, hit, x.opt.weave_maps ? weave.data() : nullptr, &pd);
    else if (split_sum)
      FillRadianceTables(x, hit.n, R, &pd);
    if (split_sum && x.fis_yarn) FillFisYarnTable(x, hit, &pd);
    if (split_sum && UsesWovenBent(x.opt)) FillBentYarnTables(x, hit, &pd);
    if (split_sum && x.opt.yarn_ibl_taps) {  // the yarn lobes' environment as reads
      std::vector<yarn_table::IblTap> taps;
      x.opt.yarn_ibl_taps(Vec3d(Dot(hit.t, hit.v), Dot(hit.b, hit.v), hit.NoV), &taps);
      for (const yarn_table::IblTap& tp : taps) {
        const Vec3d dd = Normalize(hit.t * tp.dir.x + hit.b * tp.dir.y + hit.n * tp.dir.z);
        const double so =  // the AO map's specular occlusion at the read's roughness
            vis_on ? SpecularOcclusion(std::clamp(hit.NoV, 0.0, 1.0), vis.ao, tp.roughness) : 1.0;
        const Rgb<double> L = PrefilteredRead(x, dd, tp.roughness) * so;
        for (int k = 0; k < 2; ++k) {
          for (int ch = 0; ch < 3; ++ch) pd.yibl[size_t(k * 3 + ch)] += float(tp.weight[k] * L[ch]);
          pd.yalb[size_t(k)] += float(tp.weight[k]);  // the reads' weights sum to the albedo
        }
      }
    } else if (split_sum && x.opt.yarn_ibl) {  // the tabulated lobes' split sum (PreviewOptions::yarn_ibl)
      yarn_table::IblLobe lobes[2];
      x.opt.yarn_ibl(Vec3d(Dot(hit.t, hit.v), Dot(hit.b, hit.v), hit.NoV), lobes);
      for (int k = 0; k < 2; ++k) {
        const Vec3d& ld = lobes[k].dir;
        const Vec3d dd = Normalize(hit.t * ld.x + hit.b * ld.y + hit.n * ld.z);
        const double so =  // the AO map's specular occlusion at the lobe's roughness
            vis_on ? SpecularOcclusion(std::clamp(hit.NoV, 0.0, 1.0), vis.ao, lobes[k].roughness)
                   : 1.0;
        const Rgb<double> L = PrefilteredRead(x, dd, lobes[k].roughness);
        for (int ch = 0; ch < 3; ++ch)
          pd.yibl[size_t(k * 3 + ch)] = float(lobes[k].albedo * so * L[ch]);
        pd.yalb[size_t(k)] = float(lobes[k].albedo);
      }
    }
    if (split_sum && SheenTiltOn(x.opt)) {  // the sheen lobe's table about n_s (sheen_tilt.h)
      const double th = x.opt.sheen_tilt_degrees * kPi / 180.0;
      const Vec3d ns = hit.n * std::cos(th) + hit.t * std::sin(th);
      PixelData tmp;
      FillRadianceTables(x, ns, ns * (2.0 * Dot(ns, hit.v)) - hit.v, &tmp);
      pd.trad = std::move(tmp.rad);
    }
    if (vis_on && vis.ao != 1.0) {  // three.js aomap_fragment: indirectSpecular x SO, sheen x ao
      const int K = x.opt.roughness_nodes;
      ApplySpecularOcclusion(pd.rad.data(), pd.rad.size() / (size_t(K) * 3), K, hit.NoV, vis.ao);
      ApplySpecularOcclusion(pd.yrad.data(), pd.yrad.size() / (size_t(K) * 3), K, hit.NoV, vis.ao);
      for (float& v : pd.srad) v = float(double(v) * vis.ao);
      ApplySpecularOcclusion(pd.trad.data(), pd.trad.size() / (size_t(K) * 3), K, hit.NoV, vis.ao);
    }
    row->push_back(std::move(pd));
  }
}

// Appends the fabric pixels in image order (rows were built in parallel).
void AssembleFabricPixels(std::vector<std::vector<PixelData>>& rows, PreviewCache* c) {
  // Reserve every array once (physical-aniso's 17 bent-normal tables make radiance the largest:
  // growing it by doubling copied and page-faulted it several times over).
  size_t n = 0, nl = 0, nirr = 0, nrad = 0, nsrad = 0, nyrad = 0, ntrad = 0;
  for (const auto& row : rows) {
    n += row.size();
    for (const PixelData& pd : row) {
      nl += pd.lights.size();
      nirr += pd.irr.size();
      nrad += pd.rad.size();
      nsrad += pd.srad.size();
      nyrad += pd.yrad.size();
      ntrad += pd.trad.size();
    }
  }
  c->pixels.reserve(c->pixels.size() + n);
  c->NoV.reserve(c->NoV.size() + n);
  c->light_begin.reserve(c->light_begin.size() + n + 1);
  c->light_samples.reserve(c->light_samples.size() + nl);
  c->irradiance.reserve(c->irradiance.size() + nirr);
  c->radiance.reserve(c->radiance.size() + nrad);
  c->sheen_radiance.reserve(c->sheen_radiance.size() + nsrad);
  c->yarn_radiance.reserve(c->yarn_radiance.size() + nyrad);
  c->sheen_tilt_radiance.reserve(c->sheen_tilt_radiance.size() + ntrad);
  c->light_begin.push_back(0);
  for (auto& row : rows) {
    for (PixelData& pd : row) {
      c->pixels.push_back(pd.index);
      c->fabric_mask[size_t(pd.index)] = 1.f;
      c->NoV.push_back(pd.nov);
      if (ThreejsGeometryRoughnessApplies(c->options)) c->geometry_roughness.push_back(pd.gr);
      c->light_samples.insert(c->light_samples.end(), pd.lights.begin(), pd.lights.end());
      // < 2^28 by the budget check in Build, so an int holds it.
      c->light_begin.push_back(int(c->light_samples.size()));
      c->irradiance.insert(c->irradiance.end(), pd.irr.begin(), pd.irr.end());
      if (c->options.visibility.indirect && c->options.visibility.bounces == 1)
        c->irradiance_unit.insert(c->irradiance_unit.end(), pd.irr_unit.begin(), pd.irr_unit.end());
      c->radiance.insert(c->radiance.end(), pd.rad.begin(), pd.rad.end());
      c->sheen_radiance.insert(c->sheen_radiance.end(), pd.srad.begin(), pd.srad.end());
      c->yarn_radiance.insert(c->yarn_radiance.end(), pd.yrad.begin(), pd.yrad.end());
      c->sheen_tilt_radiance.insert(c->sheen_tilt_radiance.end(), pd.trad.begin(), pd.trad.end());
      if ((c->options.yarn_ibl || c->options.yarn_ibl_taps) && c->features.ibl)
        c->yarn_ibl.insert(c->yarn_ibl.end(), pd.yibl.begin(), pd.yibl.end());
      if (WovenYarnReflectsLightMap(*c)) {  // session 22: the yarn lobes reflect the light map
        c->light_map.insert(c->light_map.end(), pd.lm.begin(), pd.lm.end());
        if (c->options.yarn_ibl || c->options.yarn_ibl_taps)
          c->yarn_albedo.insert(c->yarn_albedo.end(), pd.yalb.begin(), pd.yalb.end());
      }
      if (c->options.model == ModelKind::kWoven ||
          c->options.model == ModelKind::kPhysicalAniso || SheenTiltOn(c->options)) {
        c->tangent_v.insert(c->tangent_v.end(), pd.tv.begin(), pd.tv.end());
        c->light_tangent.insert(c->light_tangent.end(), pd.lt.begin(), pd.lt.end());
        if (c->options.weave_maps) c->weave.insert(c->weave.end(), pd.weave.begin(), pd.weave.end());
      }
    }
    std::vector<PixelData>().swap(row);  // release the row's copy as soon as it is in the cache
  }
}

}  // namespace

PreviewCache::~PreviewCache() = default;

std::array<double, 3> DiffuseAlbedo(const MaterialPreset& p) {
  std::array<double, 3> a{-1.0, -1.0, -1.0};
  int base = -1;
  try {
    base = p.Offset("base_color");
  } catch (const std::invalid_argument&) {
    return a;  // no base colour: the glTF's
  }
  double metal = 0.0;
  try {
    metal = std::clamp(p.values.at(size_t(p.Offset("metalness"))), 0.0, 1.0);
  } catch (const std::invalid_argument&) {
  }
  for (int c = 0; c < 3; ++c)
    a[size_t(c)] = std::clamp(p.values.at(size_t(base + c)) * (1.0 - metal), 0.0, 1.0);
  return a;
}

PreviewOptions WithCardVisibility(const PreviewOptions& in, const SceneCard& card) {
  if (!in.card_visibility || !card.visibility) return in;
  PreviewOptions o = in;
  const CardVisibility& v = *card.visibility;
  if (v.shadows) o.shadows = true;
  // The card's light map, unless the caller asked for its own terms or integrates the
  // environment exactly (a measurement without visibility).
  if (v.light_map && !o.visibility.enabled() && o.exact_ibl_samples <= 0) {
    o.visibility.indirect = true;
    o.visibility.uv_size = v.size;
    o.visibility.samples = v.samples;
    o.visibility.hit_samples = v.hit_samples;
    o.visibility.bounces = v.bounces;
  }
  return o;
}

std::unique_ptr<PreviewCache> PreviewCache::Build(
    const Scene& scene, const Environment* env, const PreviewOptions& opt_in,
    const std::function<void(const std::string&)>& log) {
  const auto t0 = std::chrono::steady_clock::now();
  const PreviewOptions opt = WithCardVisibility(opt_in, scene.card);  // the card's "visibility"
  auto c = std::make_unique<PreviewCache>();
  c->width = scene.card.width;
  c->height = scene.card.height;
  c->options = opt;
  if (opt.exact_irradiance_samples < 0 || opt.exact_irradiance_samples > 1 << 16)
    throw std::invalid_argument("preview: exact_irradiance_samples " +
                                std::to_string(opt.exact_irradiance_samples) +
                                " not in [0, 65536]");
  ValidateVisibilityOptions(opt.visibility);
  if (opt.visibility.enabled() && opt.exact_ibl_samples > 0)
    throw std::invalid_argument("preview: visibility (AO / light map) applies to the split-sum "
                                "IBL; not with exact_ibl_samples");
  if (opt.exact_ibl_samples < 0 || opt.exact_ibl_samples > 1 << 16)
    throw std::invalid_argument("preview: exact_ibl_samples " +
                                std::to_string(opt.exact_ibl_samples) + " not in [0, 65536]");
  if (SheenTiltOn(opt)) {
    if (!std::isfinite(opt.sheen_tilt_degrees) || std::abs(opt.sheen_tilt_degrees) > 90.0)
      throw std::invalid_argument("preview: sheen tilt " + std::to_string(opt.sheen_tilt_degrees) +
                                  " degrees not in [-90, 90]");
    if (opt.model != ModelKind::kCloth && opt.model != ModelKind::kWoven)
      throw std::invalid_argument("preview: a sheen tilt applies to the cloth and woven models only, not " +
                                  ToString(opt.model));
    if (opt.model == ModelKind::kCloth && opt.cloth.subsurface)
      throw std::invalid_argument("preview: a sheen tilt is not implemented for cloth with subsurface");
  }
  // The environment's sun as a directional light (render/scene/sun.h, docs/sun.md): the IBL
  // gets the sun-free map, the sun joins the scene's lights; the background keeps the full map.
  const Environment* background_env = env;
  std::shared_ptr<const SunSplitEnvironment> sun;
  std::vector<Light> lights = scene.lights;
  if (env) {
    sun = SplitEnvironmentSun(*env, EffectiveSunMode(scene, opt.env_sun, opt.env_sun_default));
    env = sun->environment.get();
    lights.insert(lights.end(), sun->lights.begin(), sun->lights.end());
    c->sun_summary = sun->summary;
    c->sun_split = sun->found();
  }
  const bool exact_ibl = env != nullptr && opt.exact_ibl_samples > 0;
  if (opt.yarn_lobe) {  // far-field yarn lobe (measurement): every light a light sample
    if (opt.model != ModelKind::kWoven)
      throw std::invalid_argument("preview: a yarn_lobe applies to the woven model only, not " +
                                  ToString(opt.model));
    if (env && !exact_ibl && !opt.yarn_ibl && !opt.yarn_ibl_taps)
      throw std::invalid_argument("preview: a yarn_lobe needs exact_ibl_samples > 0 or a "
                                  "yarn_ibl with an environment");
    if (opt.woven.yarn_layer != woven::YarnLayer::kAdditive || SheenTiltOn(opt) ||
        opt.woven_reference_kernel)
      throw std::invalid_argument("preview: a yarn_lobe needs the additive yarn layer, no sheen "
                                  "tilt and the fast woven kernel");
    // The AO map's specular occlusion applies to the yarn_ibl reads at each read's roughness
    // (session 13), as three.js's computeSpecularOcclusion at the lobe's roughness. (Weave maps
    // are allowed: their warp / weft / kd channels are ratios to the tile mean, so they give the
    // tile-averaged lobe a per-texel pattern without changing its tile mean.)
  } else if (opt.yarn_ibl || opt.yarn_ibl_taps) {
    throw std::invalid_argument("preview: a yarn_ibl needs a yarn_lobe");
  }
  c->features.direct = !lights.empty() || exact_ibl;
  c->features.ibl = env != nullptr && !exact_ibl;  // exact: the environment is in the lights
  c->features.subsurface = opt.model == ModelKind::kCloth && opt.cloth.subsurface;
  c->features.shadows = opt.shadows && c->features.direct;
  c->dfg = &lut::DefaultDfg();
  if (ThreejsGeometryRoughnessApplies(opt)) c->dfg = &ThreejsDfgTable();  // three.js's 16 x 16
  c->sheen_albedo = &lut::DefaultSheenAlbedo();
  if (opt.model == ModelKind::kWoven) c->woven_phase = &lut::DefaultWovenPhase();
  const int W = c->width, H = c->height;
  const size_t np = size_t(W) * size_t(H);
  c->background.assign(np * 3, 0.f);
  c->fabric_mask.assign(np, 0.f);
  if (!opt.sample_mask.empty() && opt.sample_mask.size() != np)
    throw std::invalid_argument("preview: sample_mask has " + std::to_string(opt.sample_mask.size()) +
                                " entries for " + std::to_string(np) + " pixels");

  // Validate before allocating: the exact IBL keeps N samples per covered pixel (24 B each, 40 B
  // with a tangent, 48 B with a yarn_lobe), and light_begin indexes them with an int. Refuse
  // more than 2^28 samples (about 6-13 GB) rather than exhaust memory or wrap the offsets;
  // --stride or fewer samples (or render-preview's row chunks) bring a frame under the budget.
  if (exact_ibl) {
    size_t candidates = np;
    if (!opt.sample_mask.empty())
      candidates = size_t(std::count_if(opt.sample_mask.begin(), opt.sample_mask.end(),
                                        [](auto m) { return m != 0; }));
    const size_t per_pixel = size_t(opt.exact_ibl_samples) + lights.size();
    constexpr size_t kMaxLightSamples = size_t(1) << 28;
    if (per_pixel > 0 && candidates > kMaxLightSamples / per_pixel)
      throw std::invalid_argument(
          "preview: exact_ibl_samples " + std::to_string(opt.exact_ibl_samples) + " x " +
          std::to_string(candidates) + " sampled pixels exceeds the budget of 2^28 samples; use a "
          "larger --stride or fewer samples");
  }

  EmbreeScene bvh(scene);
  const double eps = 1e-5 * bvh.scale();
  // Environment-derived data (only when the scene has an environment).
  const EnvironmentData e = PrepareEnvironment(env, opt, log);

  // Primary visibility at pixel centres. Per-pixel work is independent; gather per row.
  std::vector<std::vector<PixelData>> rows(static_cast<size_t>(H));
  const bool wrap_past_terminator = c->features.subsurface &&
                                    opt.cloth.variant == cloth::Variant::kFilament;
  // Woven FIS (UsesWovenFis; only with an environment): the tap patterns, shared by every pixel.
  std::unique_ptr<FisPattern> fis_yarn, fis_diffuse;
  if (env && UsesWovenFis(opt)) {
    if (opt.woven.fis_taps < 1 || opt.woven.fis_taps > woven::kMaxFisTaps)
      throw std::invalid_argument("preview: woven.fis_taps " + std::to_string(opt.woven.fis_taps) +
                                  " not in [1, " + std::to_string(woven::kMaxFisTaps) + "]");
    if (opt.woven.fis_diffuse_taps < 0 || opt.woven.fis_diffuse_taps > woven::kMaxFisTaps)
      throw std::invalid_argument("preview: woven.fis_diffuse_taps " +
                                  std::to_string(opt.woven.fis_diffuse_taps) + " not in [0, " +
                                  std::to_string(woven::kMaxFisTaps) + "]");
    fis_yarn = std::make_unique<FisPattern>(opt.woven.fis_taps);
    if (opt.woven.fis_diffuse_taps > 0)
      fis_diffuse = std::make_unique<FisPattern>(opt.woven.fis_diffuse_taps);
  }
  std::vector<UvVisibilityMap> uv_vis;  // VisibilityOptions::uv_size > 0 (filled below)
  const bool uv_bake = opt.visibility.enabled() && opt.visibility.uv_size > 0;
  const PixelContext x{scene,          env,      opt,           bvh, e, eps, wrap_past_terminator,
                       fis_yarn.get(), fis_diffuse.get(), &lights, background_env,
                       uv_bake ? &uv_vis : nullptr};
  if (uv_bake) uv_vis = BakeFabricUvVisibility(x);
  tbb::parallel_for(0, H, [&](int y) { BuildRow(x, y, c.get(), &rows[size_t(y)]); });

  AssembleFabricPixels(rows, c.get());
  c->uv_visibility = std::move(uv_vis);
  if (opt.yarn_lobe) {  // the far-field lobe per light sample, local frame (t, b, n)
    c->yarn_lobe.assign(c->light_samples.size() * 2, 0.f);
    tbb::parallel_for(size_t(0), c->pixels.size(), [&](size_t i) {
      const Vec3d wo{double(c->tangent_v[i * 2]), double(c->tangent_v[i * 2 + 1]),
                     double(c->NoV[i])};
      for (int s = c->light_begin[i]; s < c->light_begin[i + 1]; ++s) {
        const float* lt = &c->light_tangent[size_t(s) * 4];
        const Vec3d wi{double(lt[0]), double(lt[1]), double(c->light_samples[size_t(s)].NoL)};
        double v[2] = {0.0, 0.0};
        if (wo.z > 0.0 && wi.z > 0.0) opt.yarn_lobe(Normalize(wo), Normalize(wi), v);
        c->yarn_lobe[size_t(s) * 2] = float(v[0]);
        c->yarn_lobe[size_t(s) * 2 + 1] = float(v[1]);
      }
    });
  }
  c->build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return c;
}

namespace {

// Interpolation of the K-node radiance table at roughness r: a uniform Catmull-Rom cubic
// (C1, so the solver's Jacobian has no jumps at the nodes; end segments use clamped
// neighbours). Jet-differentiable through the weights.
template <typename T>
Rgb<T> TableRadiance(const float* table, int K, const T& r) {
  const T s = Clamp(r, Const<T>(0.0), Const<T>(1.0)) * Const<T>(double(K - 1));
  int i1 = int(std::floor(ScalarPart(s)));
  i1 = std::clamp(i1, 0, K - 2);
  const int i0 = std::max(i1 - 1, 0), i2 = i1 + 1, i3 = std::min(i1 + 2, K - 1);
  const T t = s - Const<T>(double(i1));
  const T t2 = t * t, t3 = t2 * t;
  // Catmull-Rom basis (tension 0.5)
  const T w0 = Const<T>(-0.5) * t3 + t2 - Const<T>(0.5) * t;
  const T w1 = Const<T>(1.5) * t3 - Const<T>(2.5) * t2 + Const<T>(1.0);
  const T w2 = Const<T>(-1.5) * t3 + Const<T>(2.0) * t2 + Const<T>(0.5) * t;
  const T w3 = Const<T>(0.5) * t3 - Const<T>(0.5) * t2;
  Rgb<T> out;
  for (int ch = 0; ch < 3; ++ch) {
    out[ch] = Const<T>(double(table[i0 * 3 + ch])) * w0 + Const<T>(double(table[i1 * 3 + ch])) * w1 +
              Const<T>(double(table[i2 * 3 + ch])) * w2 + Const<T>(double(table[i3 * 3 + ch])) * w3;
    out[ch] = Max(out[ch], Const<T>(0.0));  // cubic overshoot must not create negative light
  }
  return out;
}

template <typename T>
Rgb<T> LoadRgb(const float* p) {
  return {Const<T>(double(p[0])), Const<T>(double(p[1])), Const<T>(double(p[2]))};
}

// The K-node table interpolation of TableRadiance split in two: the Catmull-Rom weights depend
// only on r, i.e. on the parameters (once per frame for the woven model), and the per-pixel
// part multiplies them by the table's constants. A constant times a Jet is evaluated as the
// Jet's scalar product: the value and derivative of Const(c) * w exactly (up to the sign of a
// zero derivative), at half the cost. Same arithmetic as TableRadiance otherwise.
template <typename T>
struct TableWeights {
  int i0 = 0, i1 = 0, i2 = 0, i3 = 0;
  T w0, w1, w2, w3;
};

template <typename T>
TableWeights<T> MakeTableWeights(int K, const T& r) {
  TableWeights<T> w;
  const T s = Clamp(r, Const<T>(0.0), Const<T>(1.0)) * Const<T>(double(K - 1));
  w.i1 = std::clamp(int(std::floor(ScalarPart(s))), 0, K - 2);
  w.i0 = std::max(w.i1 - 1, 0);
  w.i2 = w.i1 + 1;
  w.i3 = std::min(w.i1 + 2, K - 1);
  const T t = s - Const<T>(double(w.i1));
  const T t2 = t * t, t3 = t2 * t;
  w.w0 = Const<T>(-0.5) * t3 + t2 - Const<T>(0.5) * t;
  w.w1 = Const<T>(1.5) * t3 - Const<T>(2.5) * t2 + Const<T>(1.0);
  w.w2 = Const<T>(-1.5) * t3 + Const<T>(2.0) * t2 + Const<T>(0.5) * t;
  w.w3 = Const<T>(0.5) * t3 - Const<T>(0.5) * t2;
  return w;
}

// Const(c) * x, as the scalar product for a Jet.
template <typename T>
T TimesConst(double c, const T& x) {
  if constexpr (std::is_arithmetic_v<T>) {
    return Const<T>(c) * x;
  } else {
    return x * c;
  }
}

template <typename T>
Rgb<T> ApplyTableWeights(const float* table, const TableWeights<T>& w) {
  Rgb<T> out;
  for (int ch = 0; ch < 3; ++ch) {
    out[ch] = TimesConst(double(table[w.i0 * 3 + ch]), w.w0) +
              TimesConst(double(table[w.i1 * 3 + ch]), w.w1) +
              TimesConst(double(table[w.i2 * 3 + ch]), w.w2) +
              TimesConst(double(table[w.i3 * 3 + ch]), w.w3);
    out[ch] = Max(out[ch], Const<T>(0.0));  // cubic overshoot must not create negative light
  }
  return out;
}

// f (x) irradiance, the irradiance a constant (scalar product for a Jet).
template <typename T>
Rgb<T> TimesConstRgb(const Rgb<T>& f, const float* c) {
  return {TimesConst(double(c[0]), f.r), TimesConst(double(c[1]), f.g),
          TimesConst(double(c[2]), f.b)};
}

// The woven frame kernel (brdf/woven.h's split evaluation): per frame the lobe constants and
// the radiance-table weights at r_e and r_s, per pixel the view terms, per light the rest.
// Results equal the generic Kernel's (woven::EvalDirect / EvalIbl per light and pixel: bit
// equal in double; tests/test_woven_preview.cpp), which PreviewOptions::woven_reference_kernel
// still runs.
template <typename T, bool kDirect, bool kIbl>
void WovenKernel(const PreviewCache& c, const T* x, std::vector<Rgb<T>>& out) {
  using G = woven::GeomT<T>;
  const int K = c.options.roughness_nodes;
  const size_t n = c.pixels.size();
  out.resize(n);
  const woven::Options& wo = c.options.woven;
  const woven::Params<T> wp = woven::FromFlat(x);
  const Table2D& dfg = *c.dfg;
  const Table2D& phase = *c.woven_phase;
  const woven::FrameTerms<T> f = woven::PrepareFrame(wp, wo, dfg, phase);
  CheckWovenBentFrame(c.options, ScalarPart(wp.anisotropy), ScalarPart(wp.twist));
  const bool bent = UsesWovenBent(c.options) && !c.yarn_radiance.empty();
  // Far-field yarn lobe (PreviewOptions::yarn_lobe): EvalDirectLight with the yarn specular
  // zeroed gives the diffuse and sheen terms (additive layer: FrameTerms do not depend on
  // specular_color), the yarn term is added from the cached lobe values.
  const bool far_field = bool(c.options.yarn_lobe);
  if (far_field && kIbl && c.yarn_ibl.size() != c.pixels.size() * 6)
    throw std::invalid_argument("preview: the cache has no yarn IBL values (PreviewOptions::yarn_ibl)");
  if (!c.light_map.empty() &&
      (c.light_map.size() != c.pixels.size() * 3 ||
       (far_field && kIbl && c.yarn_albedo.size() != c.pixels.size() * 2)))
    throw std::invalid_argument("preview: the cache's light map (" +
                                std::to_string(c.light_map.size()) + " values) or yarn albedos (" +
                                std::to_string(c.yarn_albedo.size()) + ") do not match its " +
                                std::to_string(c.pixels.size()) + " pixels");
  if (far_field && c.yarn_lobe.size() != c.light_samples.size() * 2)  // e.g. a copied cache
    throw std::invalid_argument("preview: the cache has " + std::to_string(c.yarn_lobe.size()) +
                                " yarn lobe values for " + std::to_string(c.light_samples.size()) +
                                " light samples (PreviewOptions::yarn_lobe)");
  woven::Params<T> wp_no_yarn = wp;
  if (far_field) wp_no_yarn.specular_color = Rgb<T>(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
  TableWeights<T> tw_e, tw_s;
  if constexpr (kIbl) {
    tw_e = MakeTableWeights(K, f.lb.r_e);
    if (!f.sheen_off) tw_s = MakeTableWeights(K, f.lb.r_s);
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 512), [&](const tbb::blocked_range<size_t>& br) {
    for (size_t i = br.begin(); i != br.end(); ++i) {
      woven::WeaveSample<T> ws{};
      if (!c.weave.empty()) {
        const float* wv = &c.weave[i * WeaveMaps::kChannels];
        ws.warp = Const<T>(double(wv[0]));
        ws.weft = Const<T>(double(wv[1]));
        ws.kd = LoadRgb<T>(wv + 2);
      }
      const float* tv = &c.tangent_v[i * 2];
      const woven::ViewTerms<T> vt =
          woven::PrepareView(wp, f, G(double(c.NoV[i])), G(double(tv[0])), G(double(tv[1])),
                             ws, dfg, phase);
      Rgb<T> L(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
      if constexpr (kDirect) {
        for (int s = c.light_begin[i]; s < c.light_begin[i + 1]; ++s) {
          const PreviewLightSample& q = c.light_samples[size_t(s)];
          const float* lt = &c.light_tangent[size_t(s) * 4];
          if (far_field) {  // PreviewOptions::yarn_lobe: the model's terms without its yarn lobes
            const Rgb<T> rest = woven::EvalDirectLight(
                wp_no_yarn, f, vt, ws, G(double(q.NoL)), G(double(q.NoH)), G(double(q.LoH)),
                G(double(lt[0])), G(double(lt[1])), G(double(lt[2])), G(double(lt[3])), dfg,
                phase);
            const G NoL = Saturate(G(double(q.NoL)));
            const float* yl = &c.yarn_lobe[size_t(s) * 2];
            const T lobes_w = vt.mw * G(2.0 * double(yl[0]));
            const T lobes_f = vt.mf * G(2.0 * double(yl[1]));
            const T s_l = f.sheen_off ? Const<T>(1.0) : Min(vt.s_v, woven::SheenScalingAt(f, dfg, NoL));
            const Rgb<T> yarn = wp.specular_color * (f.tint_w * lobes_w + f.tint_f * lobes_f) *
                                (ws.glint * s_l);
            L += TimesConstRgb(rest + woven::ScaleRgb(yarn, NoL), q.irradiance);
            continue;
          }
          const Rgb<T> fl = woven::EvalDirectLight(
              wp, f, vt, ws, G(double(q.NoL)), G(double(q.NoH)), G(double(q.LoH)),
              G(double(lt[0])), G(double(lt[1])), G(double(lt[2])), G(double(lt[3])), dfg, phase);
          L += TimesConstRgb(fl, q.irradiance);
        }
      }
      if constexpr (kIbl) {
        const float* rad = &c.radiance[i * size_t(K) * 3];
        // yarn lobes: the FIS table when the cache has one (woven ibl "fis"), else the split sum's
        const woven::WovenIblWeights<T> w = woven::EvalIblView(wp, f, vt, ws);
        Rgb<T> ibl;
        // the light map's E_ind / pi, which the yarn lobes reflect too (PreviewCache::light_map)
        const float* lm = c.light_map.empty() ? nullptr : &c.light_map[i * 3];
        if (far_field) {  // PreviewOptions::yarn_ibl: A_k L_k per lobe, cached
          const float* y = &c.yarn_ibl[i * 6];
          const Rgb<T> yw = f.tint_w * (vt.mw * Const<T>(2.0)), yf = f.tint_f * (vt.mf * Const<T>(2.0));
          Rgb<T> lobes;
          for (int ch = 0; ch < 3; ++ch)
            lobes[ch] = yw[ch] * G(double(y[ch])) + yf[ch] * G(double(y[3 + ch]));
          if (lm) {
            const float* ya = &c.yarn_albedo[i * 2];
            for (int ch = 0; ch < 3; ++ch)
              lobes[ch] = lobes[ch] + (yw[ch] * G(double(ya[0])) + yf[ch] * G(double(ya[1]))) *
                                          G(double(lm[ch]));
          }
          ibl = wp.specular_color * lobes * (vt.s_v * ws.glint);
        } else if (bent) {  // woven "bent": the warp lobe's table, then the weft lobe's
          const float* yw = &c.yarn_radiance[i * size_t(K) * 6];
          ibl = w.warp * ApplyTableWeights(yw, tw_e) + w.weft * ApplyTableWeights(yw + K * 3, tw_e);
          if (lm) ibl = ibl + TimesConstRgb(w.warp + w.weft, lm);
        } else {
          const float* yrad = c.yarn_radiance.empty() ? rad : &c.yarn_radiance[i * size_t(K) * 3];
          ibl = (w.warp + w.weft) * ApplyTableWeights(yrad, tw_e);
          if (lm) ibl = ibl + TimesConstRgb(w.warp + w.weft, lm);
        }
        if (!f.sheen_off) ibl = ibl + w.sheen * ApplyTableWeights(rad, tw_s);
        L += ibl + TimesConstRgb(w.diffuse, &c.irradiance[i * 3]);
      }
      out[i] = L;
    }
  });
}

template <typename T, ModelKind M, bool kDirect, bool kIbl, bool kSub>
void Kernel(const PreviewCache& c, const T* x, std::vector<Rgb<T>>& out) {
  const int K = c.options.roughness_nodes;
  const size_t n = c.pixels.size();
  out.resize(n);
  cloth::Options co = c.options.cloth;
  co.subsurface = kSub;  // compile-time constant after inlining: no per-pixel wrap branch
  auto rgb = [&](int k) { return Rgb<T>(x[k], x[k + 1], x[k + 2]); };
  // Woven: parameter-only work (twist cos/sin, alphas, r_e) once per frame, not per pixel.
  woven::Params<T> wp;
  woven::Lobes<T> wl{};
  if constexpr (M == ModelKind::kWoven) {
    wp = woven::FromFlat(x);
    wl = woven::PrepareLobes(wp);
    CheckWovenBentFrame(c.options, ScalarPart(wp.anisotropy), ScalarPart(wp.twist));
  }
  physical_aniso::Params<T> ap;
  if constexpr (M == ModelKind::kPhysicalAniso) ap = physical_aniso::FromFlat(x);
  // Sheen nap prototype (sheen_tilt.h; cloth and woven): n_s.x = ct n.x + st t.x.
  const bool tilt = SheenTiltOn(c.options);
  const double tilt_rad = c.options.sheen_tilt_degrees * kPi / 180.0;
  const double ct = std::cos(tilt_rad), st = std::sin(tilt_rad);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 512), [&](const tbb::blocked_range<size_t>& br) {
    for (size_t i = br.begin(); i != br.end(); ++i) {
      // Woven: the pixel's weave-map sample; without maps the uniform defaults (all 1).
      woven::WeaveSample<T> ws{};
      if constexpr (M == ModelKind::kWoven) {
        if (!c.weave.empty()) {
          const float* wv = &c.weave[i * WeaveMaps::kChannels];
          ws.warp = Const<T>(double(wv[0]));
          ws.weft = Const<T>(double(wv[1]));
          ws.kd = LoadRgb<T>(wv + 2);
        }
      }
      const T NoV = Const<T>(double(c.NoV[i]));
      const T NoV_s = tilt ? Const<T>(ct * double(c.NoV[i]) + st * double(c.tangent_v[i * 2]))
                           : NoV;
      standard::Options so;  // three.js geometryRoughness (0 unless the cache has it)
      if (!c.geometry_roughness.empty()) so.geometry_roughness = double(c.geometry_roughness[i]);
      // physical-aniso: the kd map multiplies the base colour, the warp/weft weights give the
      // anisotropyMap texel (AnisoFromWeave); without maps, no map.
      physical_aniso::Params<T> apx = ap;
      physical_aniso::AnisoSample<T> as{};
      if constexpr (M == ModelKind::kPhysicalAniso) {
        if (!c.weave.empty()) {
          const float* wv = &c.weave[i * WeaveMaps::kChannels];
          as = AnisoFromWeave<T>(wv);
          for (int ch = 0; ch < 3; ++ch) apx.base_color[ch] = ap.base_color[ch] * Const<T>(double(wv[2 + ch]));
        }
      }
      Rgb<T> L(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
      if constexpr (kDirect) {
        for (int s = c.light_begin[i]; s < c.light_begin[i + 1]; ++s) {
          const PreviewLightSample& q = c.light_samples[size_t(s)];
          const Cosines<T> cs{NoV, Const<T>(double(q.NoL)), Const<T>(double(q.NoH)),
                              Const<T>(double(q.LoH))};
          Rgb<T> f;
          if constexpr (M == ModelKind::kWoven) {
            const float* tv = &c.tangent_v[i * 2];
            const float* lt = &c.light_tangent[size_t(s) * 4];
            const TangentCosines<T> tc{Const<T>(double(tv[0])), Const<T>(double(tv[1])),
                                       Const<T>(double(lt[0])), Const<T>(double(lt[1])),
                                       Const<T>(double(lt[2])), Const<T>(double(lt[3]))};
            if (tilt) {
              const sheen_tilt::TiltedCosines<T> tl{
                  NoV_s, Const<T>(ct * double(q.NoL) + st * double(lt[0])),
                  Const<T>(ct * double(q.NoH) + st * double(lt[2]))};
              f = sheen_tilt::WovenDirect(wp, c.options.woven, wl, cs, tl, tc, ws, *c.dfg,
                                          *c.woven_phase);
            } else {
              f = woven::EvalDirect(wp, c.options.woven, wl, cs, tc, ws, *c.dfg, *c.woven_phase);
            }
          } else if constexpr (M == ModelKind::kPhysicalAniso) {
            const float* tv = &c.tangent_v[i * 2];
            const float* lt = &c.light_tangent[size_t(s) * 4];
            const TangentCosines<T> tc{Const<T>(double(tv[0])), Const<T>(double(tv[1])),
                                       Const<T>(double(lt[0])), Const<T>(double(lt[1])),
                                       Const<T>(double(lt[2])), Const<T>(double(lt[3]))};
            f = physical_aniso::EvalDirect(apx, so, cs, tc, as, *c.dfg);
          } else if constexpr (M == ModelKind::kCloth) {
            if (tilt) {
              const float* lt = &c.light_tangent[size_t(s) * 4];
              const sheen_tilt::TiltedCosines<T> tl{
                  NoV_s, Const<T>(ct * double(q.NoL) + st * double(lt[0])),
                  Const<T>(ct * double(q.NoH) + st * double(lt[2]))};
              f = sheen_tilt::ClothDirect(cloth::Params<T>{rgb(0), rgb(3), x[6], rgb(7)}, co, cs, tl);
            } else {
              f = cloth::EvalDirect(cloth::Params<T>{rgb(0), rgb(3), x[6], rgb(7)}, co, cs);
            }
          } else if constexpr (M == ModelKind::kStandard) {
            f = standard::EvalDirect(standard::Params<T>{rgb(0), x[3], x[4]}, so, cs, *c.dfg);
          } else if constexpr (M == ModelKind::kPhysicalSheen) {
            f = physical_sheen::EvalDirect(
                physical_sheen::Params<T>{rgb(0), x[3], x[4], rgb(5), x[8]}, so, cs, *c.dfg);
          } else {
            f = gltf_sheen::EvalDirect(gltf_sheen::Params<T>{rgb(0), x[3], x[4], rgb(5), x[8]},
                                       {}, cs, *c.sheen_albedo);
          }
          L += f * LoadRgb<T>(q.irradiance);
        }
      }
      if constexpr (kIbl) {
        const Rgb<T> Ed = LoadRgb<T>(&c.irradiance[i * 3]);
        const size_t rad_stride =
            size_t(K) * 3 * size_t(M == ModelKind::kPhysicalAniso ? kAnisoBentNodes : 1);
        const float* rad = &c.radiance[i * rad_stride];
        if constexpr (M == ModelKind::kWoven) {
          const woven::WovenIblWeights<T> w =
              tilt ? sheen_tilt::WovenIbl(wp, c.options.woven, wl, NoV, NoV_s, ws, *c.dfg,
                                          *c.woven_phase)
                   : woven::EvalIbl(wp, c.options.woven, wl, NoV, ws, *c.dfg, *c.woven_phase);
          const bool bent = UsesWovenBent(c.options) && !c.yarn_radiance.empty();
          const float* yrad = c.yarn_radiance.empty()
                                  ? rad
                                  : &c.yarn_radiance[i * size_t(K) * 3 * (bent ? 2 : 1)];  // FIS / bent
          const float* srad = tilt ? &c.sheen_tilt_radiance[i * size_t(K) * 3] : rad;
          L += (bent ? w.warp * TableRadiance(yrad, K, wl.r_e) +
                           w.weft * TableRadiance(yrad + K * 3, K, wl.r_e)
                     : (w.warp + w.weft) * TableRadiance(yrad, K, wl.r_e)) +
               w.sheen * TableRadiance(srad, K, wl.r_s) + w.diffuse * Ed;
          if (!c.light_map.empty())  // the yarn lobes reflect the light map (PreviewCache::light_map)
            L += (w.warp + w.weft) * LoadRgb<T>(&c.light_map[i * 3]);
        } else if constexpr (M == ModelKind::kPhysicalAniso) {
          const IblWeights<T> w = physical_aniso::EvalIbl(apx, so, NoV, *c.dfg);
          const T r = standard::ClampedRoughness(apx.roughness, so);
          const T a = physical_aniso::MakeFrame(apx, as).anisotropy;
          const T bw = physical_aniso::BentNormalWeight(a, r) * Const<T>(kAnisoBentNodes - 1);
          const int j = std::clamp(int(std::floor(ScalarPart(bw))), 0, kAnisoBentNodes - 2);
          const T f = bw - Const<T>(double(j));
          const Rgb<T> L0 = TableRadiance(rad + size_t(j) * size_t(K) * 3, K, r);
          const Rgb<T> L1 = TableRadiance(rad + size_t(j + 1) * size_t(K) * 3, K, r);
          L += w.specular * (L0 * (Const<T>(1.0) - f) + L1 * f) + w.diffuse * Ed;
        } else if constexpr (M == ModelKind::kCloth) {
          const cloth::Params<T> p{rgb(0), rgb(3), x[6], rgb(7)};
          const IblWeights<T> w = tilt ? sheen_tilt::ClothIbl(p, co, NoV_s, *c.dfg)
                                       : cloth::EvalIbl(p, co, NoV, *c.dfg);
          const float* srad = tilt ? &c.sheen_tilt_radiance[i * size_t(K) * 3] : rad;
          L += w.specular * TableRadiance(srad, K, cloth::ClampedRoughness(p.roughness, co)) +
               w.diffuse * Ed;
        } else if constexpr (M == ModelKind::kStandard) {
          const standard::Params<T> p{rgb(0), x[3], x[4]};
          const IblWeights<T> w = standard::EvalIbl(p, so, NoV, *c.dfg);
          L += w.specular * TableRadiance(rad, K, standard::ClampedRoughness(p.roughness, so)) +
               w.diffuse * Ed;
        } else if constexpr (M == ModelKind::kPhysicalSheen) {
          const physical_sheen::Params<T> p{rgb(0), x[3], x[4], rgb(5), x[8]};
          const IblWeights<T> w = physical_sheen::EvalIbl(p, so, NoV, *c.dfg);
          L += w.specular * TableRadiance(rad, K, standard::ClampedRoughness(p.roughness, so)) +
               w.diffuse * Ed;
        } else {
          const gltf_sheen::Params<T> p{rgb(0), x[3], x[4], rgb(5), x[8]};
          const IblWeights<T> w = gltf_sheen::EvalIbl(p, {}, NoV, *c.dfg, *c.sheen_albedo);
          const float* srad = &c.sheen_radiance[i * size_t(K) * 3];
          L += w.specular * TableRadiance(rad, K, gltf_sheen::ClampedRoughness(p.roughness)) +
               w.diffuse * Ed +
               w.sheen * TableRadiance(srad, K, gltf_sheen::ClampedSheenRoughness(p.sheen_roughness));
        }
      }
      out[i] = L;
    }
  });
}

template <typename T, ModelKind M>
void DispatchFeatures(const PreviewCache& c, const T* x, std::vector<Rgb<T>>& out) {
  const PreviewFeatures& f = c.features;
  const int key = (f.direct ? 4 : 0) | (f.ibl ? 2 : 0) | (f.subsurface ? 1 : 0);
  if constexpr (M == ModelKind::kWoven) {
    if (!c.options.woven_reference_kernel && !SheenTiltOn(c.options)) {
      if (f.direct && f.ibl) return WovenKernel<T, true, true>(c, x, out);
      if (f.direct) return WovenKernel<T, true, false>(c, x, out);
      if (f.ibl) return WovenKernel<T, false, true>(c, x, out);
      return WovenKernel<T, false, false>(c, x, out);
    }
  }
  switch (key) {
    case 0: return Kernel<T, M, false, false, false>(c, x, out);
    case 1: return Kernel<T, M, false, false, true>(c, x, out);
    case 2: return Kernel<T, M, false, true, false>(c, x, out);
    case 3: return Kernel<T, M, false, true, true>(c, x, out);
    case 4: return Kernel<T, M, true, false, false>(c, x, out);
    case 5: return Kernel<T, M, true, false, true>(c, x, out);
    case 6: return Kernel<T, M, true, true, false>(c, x, out);
    default: return Kernel<T, M, true, true, true>(c, x, out);
  }
}

}  // namespace

template <typename T>
void EvaluatePreview(const PreviewCache& c, const T* x, std::vector<Rgb<T>>& out) {
  switch (c.options.model) {
    case ModelKind::kCloth: return DispatchFeatures<T, ModelKind::kCloth>(c, x, out);
    case ModelKind::kStandard: return DispatchFeatures<T, ModelKind::kStandard>(c, x, out);
    case ModelKind::kPhysicalSheen:
      return DispatchFeatures<T, ModelKind::kPhysicalSheen>(c, x, out);
    case ModelKind::kGltfSheen: return DispatchFeatures<T, ModelKind::kGltfSheen>(c, x, out);
    case ModelKind::kWoven: return DispatchFeatures<T, ModelKind::kWoven>(c, x, out);
    case ModelKind::kPhysicalAniso:
      return DispatchFeatures<T, ModelKind::kPhysicalAniso>(c, x, out);
  }
}

template void EvaluatePreview<double>(const PreviewCache&, const double*, std::vector<Rgb<double>>&);
template void EvaluatePreview<float>(const PreviewCache&, const float*, std::vector<Rgb<float>>&);
// Dual numbers for the fit's Jacobians: one width per number of free scalars the fit carries
// (fit/image_fit.cpp, kJetWidths).
template void EvaluatePreview<ceres::Jet<double, 4>>(const PreviewCache&,
                                                      const ceres::Jet<double, 4>*,
                                                      std::vector<Rgb<ceres::Jet<double, 4>>>&);
template void EvaluatePreview<ceres::Jet<double, 6>>(const PreviewCache&,
                                                      const ceres::Jet<double, 6>*,
                                                      std::vector<Rgb<ceres::Jet<double, 6>>>&);
template void EvaluatePreview<ceres::Jet<double, 8>>(const PreviewCache&,
                                                      const ceres::Jet<double, 8>*,
                                                      std::vector<Rgb<ceres::Jet<double, 8>>>&);
template void EvaluatePreview<ceres::Jet<double, 10>>(const PreviewCache&,
                                                       const ceres::Jet<double, 10>*,
                                                       std::vector<Rgb<ceres::Jet<double, 10>>>&);

std::vector<float> ComposeFrame(const PreviewCache& c, const std::vector<Rgb<double>>& fabric) {
  std::vector<float> frame = c.background;
  for (size_t i = 0; i < c.pixels.size() && i < fabric.size(); ++i)
    for (int ch = 0; ch < 3; ++ch)
      frame[size_t(c.pixels[i]) * 3 + size_t(ch)] = float(fabric[i][ch]);
  return frame;
}

void ApplyPresetYarnLobe(const MaterialPreset& p, PreviewOptions* o) {
  if (!p.yarn_lobe) return;
  auto lobe = std::make_shared<const yarn_lobe::Lobe>(*p.yarn_lobe);
  o->yarn_lobe = [lobe](const Vec3d& wo, const Vec3d& wi, double out[2]) { lobe->Eval(wo, wi, out); };
  o->yarn_ibl = [lobe](const Vec3d& wo, yarn_table::IblLobe out[2]) {
    lobe->description().ibl.Ibl(wo, out);
  };
}

}  // namespace clothfit::render
