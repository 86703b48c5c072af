// brdf/woven.h: the real-time woven-cloth material (issue 12). Yarn specular as two
// anisotropic GGX lobes aligned with the warp and weft yarns, under a "phase Fresnel" that
// carries the yarns' forward scattering; the cloth sheen lobe (Charlie + Neubelt) for fuzz;
// a rough diffuse (Fujii's improved Oren-Nayar; Lambert at diffuse_roughness 0, the default);
// sheen layered over everything by albedo scaling (KHR_materials_sheen).
// Not an exact MeshPhysicalMaterial (Fp and the second lobe): three.js draws it as a web/
// material. Design and the BRDF-space measurements: docs/fitting.md, "woven".
//
// Frame (stated; the same as the reference renderer, render/reference/path_tracer.cpp):
//   n is flipped towards the viewer (two-sided); t = the mesh tangent, Gram-Schmidt'd against
//   n (+u of TEXCOORD_0: the WARP direction); b = tangent_sign (n x t) (+v: the WEFT).
//   The model takes raw cosines (Cosines: n.v, n.l, n.h, l.h; TangentCosines: t.v, b.v, t.l,
//   b.l, t.h, b.h) and clamps them itself.
//
// Lobes (ASCII math; rho = twist in radians, cr = cos rho, sr = sin rho):
//   warp fibre axis a_w = cr t + sr b, across axis c_w = -sr t + cr b
//   weft fibre axis a_f = c_w,         across axis c_f = -a_w            (a_w turned +90 deg)
//   alpha_a = r^2                         roughness ALONG the fibre   (r = `roughness`, clamped
//                                         to [0.045, 1] as three.js/Filament desktop)
//   alpha_c = r^2 + (1 - r^2) s^2         ACROSS the fibre = KHR_materials_anisotropy
//                                         mix(r^2, 1, s^2), s = `anisotropy`
//   L_j  = D_GGX_Anisotropic(alpha_c along c_j, alpha_a along a_j) x
//          V_SmithGGXCorrelated_Anisotropic(same axes)                     (brdf/terms.h)
//   Fp   = F_Phase(f0, beta, LoH) = f0 + (1 - f0) exp(-2 beta LoH^2)       (Irawan's von Mises
//          forward-scattering phase written in the half vector: -l.v = 1 - 2 LoH^2)
//   f_y  = ks (x) Fp glint [ m tint_w L_w + (1 - m) tint_f L_f ]
//          ks = `specular_color`, m = `warp_share` x WeaveSample.warp (the weft weight is
//          (1 - warp_share) x WeaveSample.weft), tints from Options (1 = uniform)
//   f_s  = sheen (x) D_Charlie(r_s^2, NoH) V_Neubelt(NoV, NoL)             (= cloth::SheenDV)
//   f_d  = base (x) kd_ratio / pi x On(v, l)                  (Fujii 2012 "FON", session 18)
//   On   = A (1 + sigma s / t),  A = 1 / (1 + (1/2 - 2/(3 pi)) sigma),  sigma = `diffuse_roughness`
//          s = l.v - (n.l)(n.v),  t = max(n.l, n.v) if s > 0, else 1   (l.v = 2 LoH^2 - 1)
//          sigma = 0: On = 1 exactly (Lambert; every preset before session 18). s > 0 towards
//          the light (retro-reflection) brightens, s < 0 (light behind, forward) darkens: the
//          yarns' self-shadowing a flat Lambert surface lacks. The single-scattering lobe of
//          OpenPBR's EON diffuse (Portsmouth, Kutz, Hill 2025), without its multiple-
//          scattering compensation.
//   S(mu) = sat(1 - max3(sheen) Es(mu)),  Es = DFG.z(mu, r_s)              (KHR_materials_sheen
//          albedo scaling, with the albedo of our own Charlie + Neubelt lobe)
//   Y(mu) = 1 (kAdditive, default: Irawan's BSDF is ks spec + kd/pi, additive)
//         = sat(1 - Ey(mu)) (kAlbedoScaled), Ey(mu) = max3(ks) [f0 PT_0(mu, r_e) + (1 - f0) PT_beta(mu, r_e)]
//   direct (per unit light, cosine included):
//     out = NoL [ f_s + min(S(NoV), S(NoL)) (f_y + min(Y(NoV), Y(NoL)) f_d) ]
//   NoV = max(n.v, 1e-4) (Filament clampNoV), NoL, NoH, LoH saturated.
//
// Image-based light (split sum, EvalIbl -> WovenIblWeights):
//   yarn = S(NoV) ks (x) glint [f0 PT_0(NoV, r_e) + (1 - f0) PT_beta(NoV, r_e)]
//   warp = yarn m tint_w, weft = yarn (1 - m) tint_f       x GGX-prefiltered radiance at r_e
//   sheen = sheen Es(NoV)                                  x prefiltered radiance at r_s
//   diffuse = S(NoV) Y(NoV) base (x) kd_ratio Eo(NoV)      x Lambert irradiance E_d
//   Eo(mu) = A (1 + sigma G(mu)), the directional albedo of On (per unit base), G in closed
//   form (OnAlbedoG below; tests/test_woven_model.cpp integrates it numerically)
//   PT = lut::DefaultWovenPhase() (our own integrator; beta interpolated linearly between the
//   nodes lut::kWovenPhaseBetas), read at the effective isotropic roughness
//   r_e = (alpha_a alpha_c)^(1/4) (geometric-mean alpha). The renderer looks both yarn lobes up
//   at the dominant direction of r_e (ibl "split", the default), or each lobe about its own bent
//   normal (ibl "bent", IblMode::kBent below, session 10), or by filtered importance sampling
//   (ibl "fis").
//
// Parameters (kParameterTable, flat order):
//   name                size default     range        diff  convention
//   base_color          3    0.5,0.5,0.5 [0, 1]       yes   linear sRGB diffuse albedo
//   specular_color      3    0.5,0.5,0.5 [0, 1]       yes   linear sRGB yarn specular (Fp(0) = 1)
//   roughness           1    0.6         [0.045, 1]   yes   perceptual r along the fibre, alpha = r^2
//   anisotropy          1    0.7         [0, 1]       yes   KHR strength s (across: mix(r^2, 1, s^2))
//   twist               1    0           [-90, 90]    yes   degrees, fibre axes from +u towards +v
//   warp_share          1    0.5         [0, 1]       yes   share of the yarn specular on the warp lobe
//   specular_f0         1    0.05        [0, 1]       yes   Fp at LoH = 1 (fraction of specular_color)
//   forward_scattering  1    2           [0, 8]       yes   beta of Fp
//   sheen_color         3    0,0,0       [0, 1]       yes   linear sRGB Charlie sheen (0 = off)
//   sheen_roughness     1    0.6         [0.045, 1]   yes   perceptual r_s, alpha = r_s^2
//   diffuse_roughness   1    0           [0, 1]       yes   sigma of On (0 = Lambert; session 18,
//                                                           appended: older flat vectors keep
//                                                           their offsets)
//
// References: Irawan & Marschner 2012 ("Specular Reflection from Woven Cloth", ToG 31(1)); Burley
// 2012 (anisotropic GGX); Heitz 2014 (anisotropic Smith); Estevez & Kulla 2017 (Charlie);
// Neubelt & Pettineo 2013; Fujii 2012 ("A tiny improvement of Oren-Nayar reflectance model");
// Portsmouth, Kutz & Hill 2025 (EON, JCGT 14(1)); KHR_materials_anisotropy and KHR_materials_sheen (albedo scaling);
// Karis 2013 (split sum).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <string_view>
#include <type_traits>

#include "brdf/lut.h"
#include "brdf/math.h"
#include "brdf/params.h"
#include "brdf/table.h"
#include "brdf/terms.h"

namespace clothfit::woven {

inline constexpr std::string_view kEngine = "clothfit woven (web/ material)";
inline constexpr double kMinRoughness = 0.045;  // desktop clamp, as three.js r187 / Filament
inline constexpr double kMaxBeta = 8.0;         // last node of the phase table

enum class YarnLayer { kAdditive, kAlbedoScaled };
inline std::string_view ToString(YarnLayer y) {
  return y == YarnLayer::kAdditive ? "additive" : "albedo-scaled";
}

// How the renderer integrates the environment for the yarn lobes (and optionally the diffuse
// term): the split sum (one prefiltered read at the dominant direction of r_e) or filtered
// importance sampling (Colbert & Krivanek 2007, GPU Gems 3 ch. 20: fis_taps taps of the GGX
// lobe at alpha = r_e^2, each read from the prefiltered chain at the mip of its solid angle;
// render/preview/preview.cpp FisYarnRadiance, web/clothfit.js; spec: docs/fitting.md
// "Filtered importance sampling for woven's IBL (session 8)"). The BRDF itself is unchanged.
// kBent (session 10): the split sum with the engine-style anisotropic approximation the issue
// asks for, three.js getIBLAnisotropyRadiance's bent normal, one per yarn lobe: the warp lobe
// reads the prefiltered radiance about bn_w = normalize(mix(normalize((a_w x v) x a_w), n, w)),
// the weft lobe about bn_f (a_f in place of a_w), w = (1 - s (1 - r_e))^4 (three.js's weight
// with r_e for its roughness; s = `anisotropy`), each at the node's r_e as the split sum. The
// fibre axis a_j plays three.js's anisotropy bitangent: roughness is raised ACROSS the fibre.
// s = 0 (w = 1) is the split sum exactly. The tables depend on s and twist, which the woven
// fit holds (fit/woven_fit.cpp); Options::bent_anisotropy / bent_twist carry them.
enum class IblMode { kSplit, kFis, kBent };
inline std::string_view ToString(IblMode m) {
  return m == IblMode::kSplit ? "split" : m == IblMode::kFis ? "fis" : "bent";
}
inline constexpr int kMaxFisTaps = 64;
inline constexpr int kDefaultFisTaps = 16;
// 0: three.js's own top-level irradiance, measured closer to the exact irradiance than E_fis
// with 16-256 taps on the demo's studio (docs/fitting.md, session 8).
inline constexpr int kDefaultFisDiffuseTaps = 0;

struct Options {
  YarnLayer yarn_layer = YarnLayer::kAdditive;
  Rgb<double> tint_warp{1.0, 1.0, 1.0};  // per-lobe specular tints (weave bake; 1 = uniform)
  Rgb<double> tint_weft{1.0, 1.0, 1.0};
  // Renderer options (preset "woven": "ibl", "fis_taps", "fis_diffuse_taps"); the preview
  // applies them on the three.js IBL engine only.
  IblMode ibl = IblMode::kSplit;          // missing in a preset = split (old presets unchanged)
  int fis_taps = kDefaultFisTaps;         // yarn-lobe taps N, 1..64 (ibl == kFis)
  int fis_diffuse_taps = kDefaultFisDiffuseTaps;  // diffuse taps N_d, 0..64 (0: the engine's
                                                  // irradiance; ibl == kFis)
  // ibl == kBent: the lobe frame the bent-normal tables are built for, i.e. the preset's
  // `anisotropy` and `twist` (degrees): render::PreviewWovenOptions copies them from a preset's
  // values; a preview frame must evaluate the same values (checked).
  double bent_anisotropy = 0.7;
  double bent_twist = 0.0;
};

// Per-pixel weave-map sample (constant during a fit). Uniform material = the defaults.
template <typename T>
struct WeaveSample {
  T warp = Const<T>(1.0);  // warp-lobe weight ratio m(uv) / mean(m)
  T weft = Const<T>(1.0);  // weft-lobe weight ratio (1 - m(uv)) / (1 - mean(m))
  Rgb<T> kd{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};  // diffuse ratio kd(uv) / mean(kd)
  T glint = Const<T>(1.0);  // yarn-specular intensity multiplier
};

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(0.5), Const<T>(0.5), Const<T>(0.5)};
  Rgb<T> specular_color{Const<T>(0.5), Const<T>(0.5), Const<T>(0.5)};
  T roughness = Const<T>(0.6);
  T anisotropy = Const<T>(0.7);
  T twist = Const<T>(0.0);
  T warp_share = Const<T>(0.5);
  T specular_f0 = Const<T>(0.05);
  T forward_scattering = Const<T>(2.0);
  Rgb<T> sheen_color{Const<T>(0.0), Const<T>(0.0), Const<T>(0.0)};
  T sheen_roughness = Const<T>(0.6);
  T diffuse_roughness = Const<T>(0.0);
};

inline constexpr int kParameterCount = 17;

inline constexpr std::array<ParamInfo, 11> kParameterTable{{
    {"base_color", 3, {0.5, 0.5, 0.5}, 0.0, 1.0, true,
     "linear sRGB diffuse colour (Lambert albedo at diffuse_roughness 0)"},
    {"specular_color", 3, {0.5, 0.5, 0.5}, 0.0, 1.0, true,
     "linear sRGB yarn specular scale; Fp(LoH = 0) = 1 (F90-like)"},
    {"roughness", 1, {0.6, 0.0, 0.0}, kMinRoughness, 1.0, true,
     "perceptual r along the fibre, clamped to [0.045, 1]; alpha_along = r^2 (KHR roughness)"},
    {"anisotropy", 1, {0.7, 0.0, 0.0}, 0.0, 1.0, true,
     "KHR_materials_anisotropy strength s: alpha_across = mix(r^2, 1, s^2)"},
    {"twist", 1, {0.0, 0.0, 0.0}, -90.0, 90.0, true,
     "degrees; fibre axes rotated from warp (+u, mesh tangent) towards weft (+v)"},
    {"warp_share", 1, {0.5, 0.0, 0.0}, 0.0, 1.0, true,
     "fraction of the yarn specular on the warp lobe (the rest on the weft lobe)"},
    {"specular_f0", 1, {0.05, 0.0, 0.0}, 0.0, 1.0, true,
     "phase Fresnel at LoH = 1, as a fraction of specular_color"},
    {"forward_scattering", 1, {2.0, 0.0, 0.0}, 0.0, kMaxBeta, true,
     "beta of the phase Fresnel Fp = f0 + (1 - f0) exp(-2 beta LoH^2)"},
    {"sheen_color", 3, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "linear sRGB Charlie sheen (0 = off)"},
    {"sheen_roughness", 1, {0.6, 0.0, 0.0}, kMinRoughness, 1.0, true,
     "perceptual r_s, clamped to [0.045, 1]; alpha = r_s^2"},
    {"diffuse_roughness", 1, {0.0, 0.0, 0.0}, 0.0, 1.0, true,
     "Fujii improved Oren-Nayar sigma: f_d = base/pi A (1 + sigma s/t); 0 = Lambert"},
}};

// Flat vector (kParameterTable order) -> Params.
template <typename T>
inline Params<T> FromFlat(const T* x) {
  auto rgb = [&](int k) { return Rgb<T>(x[k], x[k + 1], x[k + 2]); };
  return {rgb(0), rgb(3), x[6], x[7], x[8], x[9], x[10], x[11], rgb(12), x[15], x[16]};
}

// --- Rough diffuse On (Fujii 2012; see the header comment) ---
inline constexpr double kOnAlbedoSlope = 0.5 - 2.0 / (3.0 * kPi);  // A = 1 / (1 + k sigma)

// s / t of On from the cosines (geometry only: never differentiated). NoV, NoL in [0, 1].
template <typename G>
inline G OnSOverT(const G& NoV, const G& NoL, const G& LoH) {
  // s = sin th_v sin th_l cos(phi) in [-1, 1] for consistent cosines; the floor keeps On >= 0
  // for inconsistent ones (the stress test's adversarial inputs)
  const G s = std::max((G(2.0) * LoH * LoH - G(1.0)) - NoL * NoV, G(-1.0));
  if (!(s > G(0.0))) return s;  // t = 1
  const G t = std::max(std::max(NoL, NoV), G(1e-6));
  return s / t;
}

// G(mu) of the albedo Eo(mu) = A (1 + sigma G(mu)): (1/pi) times the cosine-weighted
// hemispherical integral of s / t for a view at cos theta = mu,
//   G = [sin th (th - sin th cos th) + (2/3) sin th cos th (1 + sin th + sin^2 th) / (1 + sin th)
//        - (2/3) sin th] / pi
// (the second term is (2/3) tan th (1 - sin^3 th) written without the division by cos th).
// G(1) = 0, G(0) = (pi/2 - 2/3) / pi.
inline double OnAlbedoG(double mu) {
  const double c = std::clamp(mu, 0.0, 1.0);
  const double th = std::acos(c);
  const double sn = std::sqrt(std::max(0.0, 1.0 - c * c));
  return (sn * (th - sn * c) + (2.0 / 3.0) * sn * c * (1.0 + sn + sn * sn) / (1.0 + sn) -
          (2.0 / 3.0) * sn) /
         kPi;
}

// A(sigma) and A sigma, sigma saturated.
template <typename T>
struct OnTerms {
  T a, b;  // On = a + b s/t, Eo = a + b G
};
template <typename T>
inline OnTerms<T> PrepareOn(const T& diffuse_roughness) {
  const T sg = Saturate(diffuse_roughness);
  const T a = Const<T>(1.0) / (Const<T>(1.0) + Const<T>(kOnAlbedoSlope) * sg);
  return {a, a * sg};
}

template <typename T>
inline T ClampedRoughness(const T& r) {
  return Clamp(r, Const<T>(kMinRoughness), Const<T>(1.0));
}

// Per-pixel, light-independent quantities (the preview hoists them out of its light loop).
template <typename T>
struct Lobes {
  T alpha_a, alpha_c;  // along / across the fibre
  T r_e;               // effective isotropic perceptual roughness (alpha_a alpha_c)^(1/4)
  T r_s;               // clamped sheen roughness
  T cr, sr;            // cos / sin twist
  T f0, beta, m;       // clamped f0, beta, warp share
};

template <typename T>
inline Lobes<T> PrepareLobes(const Params<T>& p) {
  using std::cos;
  using std::sin;
  using std::sqrt;
  Lobes<T> o;
  const T r = ClampedRoughness(p.roughness);
  const T s = Saturate(p.anisotropy);
  o.alpha_a = r * r;
  o.alpha_c = o.alpha_a + (Const<T>(1.0) - o.alpha_a) * s * s;
  o.r_e = sqrt(sqrt(o.alpha_a * o.alpha_c));  // >= 0.045 > 0: finite derivative
  o.r_s = ClampedRoughness(p.sheen_roughness);
  const T rho = p.twist * Const<T>(kPi / 180.0);
  o.cr = cos(rho);
  o.sr = sin(rho);
  o.f0 = Saturate(p.specular_f0);
  o.beta = Clamp(p.forward_scattering, Const<T>(0.0), Const<T>(kMaxBeta));
  o.m = Saturate(p.warp_share);
  return o;
}

// IblMode::kBent's bent-normal weight w = (1 - s (1 - r_e))^4 (three.js getIBLAnisotropyRadiance
// with r_e as its roughness), s = saturate(anisotropy), r_e in [0, 1].
inline double BentNormalWeight(double anisotropy, double r_e) {
  const double s = std::clamp(anisotropy, 0.0, 1.0);
  const double q = 1.0 - s * (1.0 - r_e);
  return q * q * q * q;
}

// PT_beta(NoV, r_e): the phase table, linear in beta between the nodes.
template <typename T>
inline T PhaseAlbedo(const Table2D& phase, const T& NoV, const T& r_e, const T& beta) {
  const auto& b = lut::kWovenPhaseBetas;
  const double bs = ScalarPart(beta);
  int k = 0;
  while (k + 2 < int(b.size()) && !(bs < b[size_t(k) + 1])) ++k;
  const T t = Clamp((beta - Const<T>(b[size_t(k)])) / Const<T>(b[size_t(k) + 1] - b[size_t(k)]),
                    Const<T>(0.0), Const<T>(1.0));
  const T p0 = phase.Sample(NoV, r_e, k);
  const T p1 = phase.Sample(NoV, r_e, k + 1);
  return p0 + (p1 - p0) * t;
}

// Yarn directional albedo without ks: f0 PT_0 + (1 - f0) PT_beta.
template <typename T>
inline T YarnAlbedo(const Lobes<T>& lb, const Table2D& phase, const T& NoV) {
  return lb.f0 * phase.Sample(NoV, lb.r_e, 0) +
         (Const<T>(1.0) - lb.f0) * PhaseAlbedo(phase, NoV, lb.r_e, lb.beta);
}

// Sheen albedo scaling S(mu) (KHR_materials_sheen), Es = DFG.z (Charlie + Neubelt).
template <typename T>
inline T SheenScaling(const Params<T>& p, const Lobes<T>& lb, const Table2D& dfg, const T& mu) {
  return Saturate(Const<T>(1.0) - Max3(Saturate(p.sheen_color)) * dfg.Sample(mu, lb.r_s, 2));
}

template <typename T>
inline T YarnScaling(const Params<T>& p, const Options& o, const Lobes<T>& lb,
                     const Table2D& phase, const T& mu) {
  if (o.yarn_layer == YarnLayer::kAdditive) return Const<T>(1.0);
  return Saturate(Const<T>(1.0) - Max3(p.specular_color) * YarnAlbedo(lb, phase, mu));
}

// D V of one lobe with along axis a and across axis c, given the axis cosines.
template <typename T>
inline T LobeDV(const Lobes<T>& lb, const T& NoV, const T& NoL, const T& NoH, const T& AoV,
                const T& CoV, const T& AoL, const T& CoL, const T& AoH, const T& CoH) {
  return D_GGX_Anisotropic(lb.alpha_c, lb.alpha_a, NoH, CoH, AoH) *
         V_SmithGGXCorrelated_Anisotropic(lb.alpha_c, lb.alpha_a, NoV, NoL, CoV, AoV, CoL, AoL);
}

// Yarn specular without ks, Fp and glint: m tint_w L_w + (1 - m) tint_f L_f (per channel).
template <typename T>
inline Rgb<T> YarnLobes(const Lobes<T>& lb, const Options& o, const WeaveSample<T>& ws,
                        const T& NoV, const T& NoL, const T& NoH, const TangentCosines<T>& tc) {
  // warp axes: a_w = cr t + sr b, c_w = -sr t + cr b
  const T AoV = lb.cr * tc.ToV + lb.sr * tc.BoV, CoV = lb.cr * tc.BoV - lb.sr * tc.ToV;
  const T AoL = lb.cr * tc.ToL + lb.sr * tc.BoL, CoL = lb.cr * tc.BoL - lb.sr * tc.ToL;
  const T AoH = lb.cr * tc.ToH + lb.sr * tc.BoH, CoH = lb.cr * tc.BoH - lb.sr * tc.ToH;
  const T Lw = LobeDV(lb, NoV, NoL, NoH, AoV, CoV, AoL, CoL, AoH, CoH);
  // weft: a_f = c_w, c_f = -a_w (the sign is irrelevant: every cosine enters squared)
  const T Lf = LobeDV(lb, NoV, NoL, NoH, CoV, AoV, CoL, AoL, CoH, AoH);
  const T ww = lb.m * ws.warp * Lw;
  const T wf = (Const<T>(1.0) - lb.m) * ws.weft * Lf;
  return CastRgb<T>(o.tint_warp) * ww + CastRgb<T>(o.tint_weft) * wf;
}

// Reflected radiance per unit light colour (cosine included), see the header comment.
// `dfg`: lut::DefaultDfg() (channel 2 = Charlie albedo); `phase`: lut::DefaultWovenPhase().
template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Lobes<T>& lb,
                         const Cosines<T>& c, const TangentCosines<T>& tc,
                         const WeaveSample<T>& ws, const Table2D& dfg, const Table2D& phase) {
  const T NoV = Clamp(c.NoV, Const<T>(kMinNoV), Const<T>(1.0));
  const T NoL = Saturate(c.NoL);
  const T NoH = Saturate(c.NoH);
  const T LoH = Saturate(c.LoH);
  const Rgb<T> yarn = p.specular_color * YarnLobes(lb, o, ws, NoV, NoL, NoH, tc) *
                      (F_Phase(lb.f0, lb.beta, LoH) * ws.glint);
  const OnTerms<T> on = PrepareOn(p.diffuse_roughness);
  const T on_f = on.a + on.b * Const<T>(OnSOverT(ScalarPart(NoV), ScalarPart(NoL), ScalarPart(LoH)));
  const Rgb<T> diffuse = p.base_color * ws.kd * Fd_Lambert<T>() * on_f;
  const T y = Min(YarnScaling(p, o, lb, phase, NoV), YarnScaling(p, o, lb, phase, NoL));
  const T s = Min(SheenScaling(p, lb, dfg, NoV), SheenScaling(p, lb, dfg, NoL));
  const T dv = D_Charlie(lb.r_s * lb.r_s, NoH) * V_Neubelt(NoV, NoL);
  return (p.sheen_color * dv + (yarn + diffuse * y) * s) * NoL;
}

template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Cosines<T>& c,
                         const TangentCosines<T>& tc, const WeaveSample<T>& ws,
                         const Table2D& dfg, const Table2D& phase) {
  return EvalDirect(p, o, PrepareLobes(p), c, tc, ws, dfg, phase);
}

// Split-sum weights; the renderer computes
//   L = (warp + weft) L_pref(dominant(r_e), r_e) + sheen L_pref(dominant(r_s), r_s) + diffuse E_d.
template <typename T>
struct WovenIblWeights {
  Rgb<T> warp, weft, diffuse, sheen;
};

template <typename T>
inline WovenIblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const Lobes<T>& lb,
                                  const T& NoV_raw, const WeaveSample<T>& ws, const Table2D& dfg,
                                  const Table2D& phase) {
  const T NoV = Clamp(NoV_raw, Const<T>(kMinNoV), Const<T>(1.0));
  const T s = SheenScaling(p, lb, dfg, NoV);
  const Rgb<T> yarn = p.specular_color * (s * ws.glint * YarnAlbedo(lb, phase, NoV));
  WovenIblWeights<T> w;
  w.warp = yarn * CastRgb<T>(o.tint_warp) * (lb.m * ws.warp);
  w.weft = yarn * CastRgb<T>(o.tint_weft) * ((Const<T>(1.0) - lb.m) * ws.weft);
  w.sheen = p.sheen_color * dfg.Sample(NoV, lb.r_s, 2);
  const OnTerms<T> on = PrepareOn(p.diffuse_roughness);
  const T eo = on.a + on.b * Const<T>(OnAlbedoG(ScalarPart(NoV)));
  w.diffuse = p.base_color * ws.kd * (s * YarnScaling(p, o, lb, phase, NoV)) * eo;
  return w;
}

template <typename T>
inline WovenIblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV,
                                  const WeaveSample<T>& ws, const Table2D& dfg,
                                  const Table2D& phase) {
  return EvalIbl(p, o, PrepareLobes(p), NoV, ws, dfg, phase);
}

// ---------------------------------------------------------------------------------------------
// Split evaluation for renderers (render/preview's frame kernel). EvalDirect and EvalIbl above
// stay the definition; the functions below evaluate the SAME expressions in the same order,
// grouped by what they depend on: per frame (parameters only: FrameTerms), per pixel (view and
// weave sample: ViewTerms) and per light (EvalDirectLight). So a renderer does the view work
// once per pixel instead of once per light, and the parameter work once per frame.
//   - The cosines are of type G = T for float / double and double for a ceres::Jet: they carry
//     no derivative, and a Jet times a double is exactly the Jet times a constant Jet (value and
//     derivative; only the sign of a zero derivative can differ), at half the cost.
//   - Exact skips: with sheen_color exactly 0 (value and every derivative) the sheen lobe is
//     0 x finite = 0 and S(mu) = 1 - 0 = 1 exactly, so both are left out; with the additive
//     yarn layer Y = 1 exactly, so the multiplication by it is left out. A fit stage with the
//     sheen free (a non-zero derivative) evaluates the full sheen path.
// tests/test_woven_preview.cpp checks the results against EvalDirect / EvalIbl (bit equality in
// double and in the Jet's value and derivatives, sheen off and on).

// Geometry scalar type: T for float / double, double for a Jet.
template <typename T>
using GeomT = std::conditional_t<std::is_arithmetic_v<T>, T, double>;

// c (x) s for a geometry scalar s: for a Jet the scalar product (= times a constant Jet).
template <typename T>
inline Rgb<T> ScaleRgb(const Rgb<T>& c, const GeomT<T>& s) {
  return {c.r * s, c.g * s, c.b * s};
}

// Whether x is exactly zero, derivatives included.
template <typename T>
inline bool ExactlyZero(const T& x) {
  if constexpr (std::is_arithmetic_v<T>) {
    return x == T(0);
  } else {
    if (!(x.a == 0.0)) return false;
    for (int k = 0; k < x.v.size(); ++k)
      if (!(x.v[k] == 0.0)) return false;
    return true;
  }
}

// Table2D::Sample(u, v, c) split for a constant u (a cosine) and a v fixed per frame (a
// roughness): the row lookup (LocateRow) once per frame, the column lookup and the u blend in
// the geometry type per call. The same arithmetic as Table2D::Sample and its Locate.
template <typename T>
struct TableRow {
  int j0 = 0, j1 = 0;
  T fv, one_minus_fv;
};

template <typename T>
inline TableRow<T> LocateRow(const Table2D& t, const T& v) {
  TableRow<T> r;
  const T x = v * Const<T>(double(t.height)) - Const<T>(0.5);
  const double xs = ScalarPart(x);
  if (!(xs > 0.0)) {
    r.j0 = 0;
    r.fv = Const<T>(0.0);
  } else if (xs >= double(t.height - 1)) {
    r.j0 = t.height - 1;
    r.fv = Const<T>(0.0);
  } else {
    r.j0 = int(std::floor(xs));
    r.fv = x - Const<T>(double(r.j0));
  }
  r.j1 = r.j0 + 1 < t.height ? r.j0 + 1 : r.j0;
  r.one_minus_fv = Const<T>(1.0) - r.fv;
  return r;
}

template <typename T>
inline T SampleRow(const Table2D& t, const GeomT<T>& u, const TableRow<T>& r, int c) {
  using G = GeomT<T>;
  const G x = u * G(double(t.width)) - G(0.5);
  const double xs = double(x);
  int i0;
  G fu;
  if (!(xs > 0.0)) {
    i0 = 0;
    fu = G(0.0);
  } else if (xs >= double(t.width - 1)) {
    i0 = t.width - 1;
    fu = G(0.0);
  } else {
    i0 = int(std::floor(xs));
    fu = x - G(double(i0));
  }
  const int i1 = i0 + 1 < t.width ? i0 + 1 : i0;
  const G one = G(1.0);
  const G a = G(double(t.at(i0, r.j0, c))) * (one - fu) + G(double(t.at(i1, r.j0, c))) * fu;
  const G b = G(double(t.at(i0, r.j1, c))) * (one - fu) + G(double(t.at(i1, r.j1, c))) * fu;
  return a * r.one_minus_fv + b * r.fv;
}

template <typename T>
struct FrameTerms {
  Lobes<T> lb;
  T ac, aa;          // D_GGX_Anisotropic's floored alphas (across = its t, along = its b)
  T a2, inv_pi_a2;   // ac aa and kInvPi ac aa (D = kInvPi a2 Sq(a2 / q2) evaluates this first)
  T minus_2_beta;    // -2 beta (F_Phase evaluates this first)
  T one_minus_f0;
  T one_minus_m;
  Rgb<T> tint_w, tint_f;
  bool sheen_off;    // sheen_color exactly 0, derivatives included
  bool additive;     // o.yarn_layer == kAdditive: Y = 1
  // Table rows at the frame's roughnesses: the phase table at r_e, the DFG (Charlie albedo,
  // channel 2) at r_s; the phase table's beta nodes k, k + 1 and the blend t (PhaseAlbedo).
  TableRow<T> row_e, row_s;
  int phase_k = 0;
  T phase_t;
  T sheen_max;       // Max3(Saturate(sheen_color)) (SheenScaling)
  T spec_max;        // Max3(specular_color) (YarnScaling)
  T charlie_scale;   // 2 + 1 / alpha_s (D_Charlie), alpha_s = Max(r_s^2, kMinAlpha)
  T charlie_exp;     // (1 / alpha_s) 0.5
  OnTerms<T> on;     // rough diffuse A, A sigma
  bool lambert;      // diffuse_roughness exactly 0, derivatives included: On = 1, skipped
};

template <typename T>
inline FrameTerms<T> PrepareFrame(const Params<T>& p, const Options& o, const Table2D& dfg,
                                  const Table2D& phase) {
  FrameTerms<T> f;
  f.lb = PrepareLobes(p);
  f.ac = Max(f.lb.alpha_c, Const<T>(kMinAlpha));
  f.aa = Max(f.lb.alpha_a, Const<T>(kMinAlpha));
  f.a2 = f.ac * f.aa;
  f.inv_pi_a2 = Const<T>(kInvPi) * f.a2;
  f.minus_2_beta = Const<T>(-2.0) * f.lb.beta;
  f.one_minus_f0 = Const<T>(1.0) - f.lb.f0;
  f.one_minus_m = Const<T>(1.0) - f.lb.m;
  f.tint_w = CastRgb<T>(o.tint_warp);
  f.tint_f = CastRgb<T>(o.tint_weft);
  f.sheen_off = ExactlyZero(p.sheen_color.r) && ExactlyZero(p.sheen_color.g) &&
                ExactlyZero(p.sheen_color.b);
  f.additive = o.yarn_layer == YarnLayer::kAdditive;
  f.row_e = LocateRow(phase, f.lb.r_e);
  f.row_s = LocateRow(dfg, f.lb.r_s);
  {  // PhaseAlbedo's node search and blend
    const auto& b = lut::kWovenPhaseBetas;
    const double bs = ScalarPart(f.lb.beta);
    int k = 0;
    while (k + 2 < int(b.size()) && !(bs < b[size_t(k) + 1])) ++k;
    f.phase_k = k;
    f.phase_t = Clamp((f.lb.beta - Const<T>(b[size_t(k)])) /
                          Const<T>(b[size_t(k) + 1] - b[size_t(k)]),
                      Const<T>(0.0), Const<T>(1.0));
  }
  f.sheen_max = Max3(Saturate(p.sheen_color));
  f.spec_max = Max3(p.specular_color);
  const T alpha_s = Max(f.lb.r_s * f.lb.r_s, Const<T>(kMinAlpha));
  const T inv_alpha = Const<T>(1.0) / alpha_s;
  f.charlie_scale = Const<T>(2.0) + inv_alpha;
  f.charlie_exp = inv_alpha * Const<T>(0.5);
  f.on = PrepareOn(p.diffuse_roughness);
  f.lambert = ExactlyZero(p.diffuse_roughness);
  return f;
}

// YarnAlbedo (f0 PT_0 + (1 - f0) PT_beta) at a constant mu, from the frame's rows.
template <typename T>
inline T YarnAlbedoAt(const FrameTerms<T>& f, const Table2D& phase, const GeomT<T>& mu) {
  const T p0 = SampleRow(phase, mu, f.row_e, f.phase_k);
  const T p1 = SampleRow(phase, mu, f.row_e, f.phase_k + 1);
  return f.lb.f0 * SampleRow(phase, mu, f.row_e, 0) + f.one_minus_f0 * (p0 + (p1 - p0) * f.phase_t);
}
template <typename T>
inline T SheenScalingAt(const FrameTerms<T>& f, const Table2D& dfg, const GeomT<T>& mu) {
  return Saturate(Const<T>(1.0) - f.sheen_max * SampleRow(dfg, mu, f.row_s, 2));
}
template <typename T>
inline T YarnScalingAt(const FrameTerms<T>& f, const Table2D& phase, const GeomT<T>& mu) {
  return Saturate(Const<T>(1.0) - f.spec_max * YarnAlbedoAt(f, phase, mu));
}

template <typename T>
struct ViewTerms {
  GeomT<T> NoV;       // clamped to [kMinNoV, 1]
  T AoV, CoV;         // view cosines against the warp fibre axis a_w and across axis c_w
  T lv_w, lv_f;       // view halves of the anisotropic Smith V, warp and weft lobes
  T s_v;              // SheenScaling(NoV) (1 with the sheen off)
  T y_v;              // YarnScaling(NoV)
  T es_v;             // Es(NoV) = DFG.z(NoV, r_s) (0 with the sheen off)
  T ya_v;             // YarnAlbedo(NoV)
  T mw, mf;           // m ws.warp, (1 - m) ws.weft
  Rgb<T> base_kd;     // base (x) ws.kd
  Rgb<T> diffuse;     // base (x) ws.kd / pi
  T eo;               // Eo(NoV) = A (1 + sigma G(NoV)) (1, unused, with f.lambert)
};

template <typename T>
inline ViewTerms<T> PrepareView(const Params<T>& p, const FrameTerms<T>& f,
                                const GeomT<T>& NoV_raw, const GeomT<T>& ToV,
                                const GeomT<T>& BoV, const WeaveSample<T>& ws,
                                const Table2D& dfg, const Table2D& phase) {
  using std::sqrt;
  using G = GeomT<T>;
  const Lobes<T>& lb = f.lb;
  ViewTerms<T> w;
  w.NoV = Clamp(NoV_raw, G(kMinNoV), G(1.0));
  w.AoV = lb.cr * ToV + lb.sr * BoV;
  w.CoV = lb.cr * BoV - lb.sr * ToV;
  const G nv2 = Sq(w.NoV);
  // V_SmithGGXCorrelated_Anisotropic(alpha_c, alpha_a, ...): warp ToV = CoV, BoV = AoV; weft
  // swapped (its across axis is the warp's along axis).
  w.lv_w = sqrt(Sq(lb.alpha_c * w.CoV) + Sq(lb.alpha_a * w.AoV) + nv2 + G(1e-20));
  w.lv_f = sqrt(Sq(lb.alpha_c * w.AoV) + Sq(lb.alpha_a * w.CoV) + nv2 + G(1e-20));
  w.es_v = f.sheen_off ? Const<T>(0.0) : SampleRow(dfg, w.NoV, f.row_s, 2);
  w.s_v = f.sheen_off ? Const<T>(1.0) : Saturate(Const<T>(1.0) - f.sheen_max * w.es_v);
  w.ya_v = YarnAlbedoAt(f, phase, w.NoV);
  w.y_v = f.additive ? Const<T>(1.0) : Saturate(Const<T>(1.0) - f.spec_max * w.ya_v);
  w.mw = lb.m * ws.warp;
  w.mf = f.one_minus_m * ws.weft;
  w.base_kd = p.base_color * ws.kd;
  w.diffuse = w.base_kd * Fd_Lambert<T>();
  w.eo = f.lambert ? Const<T>(1.0) : f.on.a + f.on.b * G(OnAlbedoG(double(w.NoV)));
  return w;
}

// One light's reflected radiance per unit light colour (cosine included) = EvalDirect.
template <typename T>
inline Rgb<T> EvalDirectLight(const Params<T>& p, const FrameTerms<T>& f,
                              const ViewTerms<T>& w, const WeaveSample<T>& ws,
                              const GeomT<T>& NoL_raw, const GeomT<T>& NoH_raw,
                              const GeomT<T>& LoH_raw, const GeomT<T>& ToL, const GeomT<T>& BoL,
                              const GeomT<T>& ToH, const GeomT<T>& BoH, const Table2D& dfg,
                              const Table2D& phase) {
  using std::exp;
  using std::sqrt;
  using G = GeomT<T>;
  const Lobes<T>& lb = f.lb;
  const G NoL = Saturate(NoL_raw);
  const G NoH = Saturate(NoH_raw);
  const G LoH = Saturate(LoH_raw);
  const T AoL = lb.cr * ToL + lb.sr * BoL, CoL = lb.cr * BoL - lb.sr * ToL;
  const T AoH = lb.cr * ToH + lb.sr * BoH, CoH = lb.cr * BoH - lb.sr * ToH;
  // D_GGX_Anisotropic(alpha_c, alpha_a, NoH, ToH, BoH): warp (ToH, BoH) = (CoH, AoH), weft
  // (AoH, CoH).
  const T n2 = Sq(f.a2 * NoH);
  const T q2w = Max(Sq(f.aa * CoH) + Sq(f.ac * AoH) + n2, Const<T>(1e-12));
  const T q2f = Max(Sq(f.aa * AoH) + Sq(f.ac * CoH) + n2, Const<T>(1e-12));
  const T Dw = f.inv_pi_a2 * Sq(f.a2 / q2w);
  const T Df = f.inv_pi_a2 * Sq(f.a2 / q2f);
  const G nl2 = Sq(NoL);
  const T llw = sqrt(Sq(lb.alpha_c * CoL) + Sq(lb.alpha_a * AoL) + nl2 + G(1e-20));
  const T llf = sqrt(Sq(lb.alpha_c * AoL) + Sq(lb.alpha_a * CoL) + nl2 + G(1e-20));
  const T Vw = Const<T>(0.5) / Max(NoL * w.lv_w + w.NoV * llw, Const<T>(1e-6));
  const T Vf = Const<T>(0.5) / Max(NoL * w.lv_f + w.NoV * llf, Const<T>(1e-6));
  const T ww = w.mw * (Dw * Vw);
  const T wf = w.mf * (Df * Vf);
  const Rgb<T> lobes = f.tint_w * ww + f.tint_f * wf;
  const T Fp = lb.f0 + f.one_minus_f0 * exp(f.minus_2_beta * Sq(LoH));
  const Rgb<T> yarn = p.specular_color * lobes * (Fp * ws.glint);
  Rgb<T> inner = yarn;
  // On in double from the cosines, as EvalDirect (the same bits for float as well)
  const Rgb<T> diffuse =
      f.lambert ? w.diffuse
                : w.diffuse * (f.on.a + f.on.b * G(OnSOverT(double(w.NoV), double(NoL),
                                                            double(LoH))));
  if (!f.additive) {
    const T y = Min(w.y_v, YarnScalingAt(f, phase, NoL));
    inner = yarn + diffuse * y;
  } else {
    inner = yarn + diffuse;  // y = Min(1, 1) = 1 exactly
  }
  if (f.sheen_off) return ScaleRgb(inner, NoL);
  using std::pow;
  const T s = Min(w.s_v, SheenScalingAt(f, dfg, NoL));
  // D_Charlie(r_s^2, NoH) (engine clamp) x V_Neubelt(NoV, NoL) (kNone), the cosine parts in G
  const G sin2h = Max(G(1.0) - NoH * NoH, G(kCharlieMinSin2h));
  const T D = f.charlie_scale * pow(sin2h, f.charlie_exp) * Const<T>(0.5 * kInvPi);
  const G den = Max(G(4.0) * (NoL + w.NoV - NoL * w.NoV), G(1e-12));
  const G Vn = G(1.0) / den;
  const T dv = D * Vn;
  return ScaleRgb(p.sheen_color * dv + inner * s, NoL);
}

// The IBL weights = EvalIbl, from the view terms (sheen weight 0 and untouched with the sheen
// off: the caller skips the sheen radiance then).
template <typename T>
inline WovenIblWeights<T> EvalIblView(const Params<T>& p, const FrameTerms<T>& f,
                                      const ViewTerms<T>& w, const WeaveSample<T>& ws) {
  const Rgb<T> yarn = p.specular_color * (w.s_v * ws.glint * w.ya_v);
  WovenIblWeights<T> r;
  r.warp = yarn * f.tint_w * w.mw;
  r.weft = yarn * f.tint_f * w.mf;
  if (!f.sheen_off) r.sheen = p.sheen_color * w.es_v;
  r.diffuse = w.base_kd * (w.s_v * w.y_v);
  if (!f.lambert) r.diffuse = r.diffuse * w.eo;
  return r;
}

// Tangent cosines for callers that only have the four isotropic cosines (legacy flat
// evaluation, stress test): v in the t-n plane (t.v >= 0, b.v = 0), l at the azimuth that
// reproduces l.v = 2 LoH^2 - 1 (b.l >= 0), h = normalize(v + l). Computed in double from the
// scalar parts: the cosines are never differentiated.
template <typename T>
inline TangentCosines<T> TangentCosinesInPlane(const Cosines<T>& c) {
  const double nv = std::clamp(ScalarPart(c.NoV), -1.0, 1.0);
  const double nl = std::clamp(ScalarPart(c.NoL), -1.0, 1.0);
  const double loh = std::clamp(ScalarPart(c.LoH), 0.0, 1.0);
  const double sv = std::sqrt(std::max(0.0, 1.0 - nv * nv));
  const double sl = std::sqrt(std::max(0.0, 1.0 - nl * nl));
  const double lv = 2.0 * loh * loh - 1.0;
  const double den = sv * sl;
  const double cp = den > 1e-12 ? std::clamp((lv - nv * nl) / den, -1.0, 1.0) : 1.0;
  const double sp = std::sqrt(std::max(0.0, 1.0 - cp * cp));
  const Vec3<double> v(sv, 0.0, nv), l(sl * cp, sl * sp, nl);
  const TangentCosines<double> t = TangentCosinesFromDirections(v, l);
  return {Const<T>(t.ToV), Const<T>(t.BoV), Const<T>(t.ToL),
          Const<T>(t.BoL), Const<T>(t.ToH), Const<T>(t.BoH)};
}

}  // namespace clothfit::woven
