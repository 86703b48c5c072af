// brdf/woven.h: the real-time woven-cloth material (issue 12). Yarn specular as two
// anisotropic GGX lobes aligned with the warp and weft yarns, under a "phase Fresnel" that
// carries the yarns' forward scattering; the cloth sheen lobe (Charlie + Neubelt) for fuzz;
// Lambert diffuse; sheen layered over everything by albedo scaling (KHR_materials_sheen).
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
//   f_d  = base (x) kd_ratio / pi                                          (Lambert)
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
//   diffuse = S(NoV) Y(NoV) base (x) kd_ratio              x Lambert irradiance E_d
//   PT = lut::DefaultWovenPhase() (our own integrator; beta interpolated linearly between the
//   nodes lut::kWovenPhaseBetas), read at the effective isotropic roughness
//   r_e = (alpha_a alpha_c)^(1/4) (geometric-mean alpha). The renderer looks both yarn lobes up
//   at the dominant direction of r_e (no bent normal yet: documented approximation).
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
//
// References: Irawan & Marschner 2012 ("Specular Reflection from Woven Cloth", ToG 31(1)); Burley
// 2012 (anisotropic GGX); Heitz 2014 (anisotropic Smith); Estevez & Kulla 2017 (Charlie);
// Neubelt & Pettineo 2013; KHR_materials_anisotropy and KHR_materials_sheen (albedo scaling);
// Karis 2013 (split sum).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <string_view>

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

struct Options {
  YarnLayer yarn_layer = YarnLayer::kAdditive;
  Rgb<double> tint_warp{1.0, 1.0, 1.0};  // per-lobe specular tints (weave bake; 1 = uniform)
  Rgb<double> tint_weft{1.0, 1.0, 1.0};
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
};

inline constexpr int kParameterCount = 16;

inline constexpr std::array<ParamInfo, 10> kParameterTable{{
    {"base_color", 3, {0.5, 0.5, 0.5}, 0.0, 1.0, true, "linear sRGB diffuse albedo (Lambert)"},
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
}};

// Flat vector (kParameterTable order) -> Params.
template <typename T>
inline Params<T> FromFlat(const T* x) {
  auto rgb = [&](int k) { return Rgb<T>(x[k], x[k + 1], x[k + 2]); };
  return {rgb(0), rgb(3), x[6], x[7], x[8], x[9], x[10], x[11], rgb(12), x[15]};
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
  const Rgb<T> diffuse = p.base_color * ws.kd * Fd_Lambert<T>();
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
  w.diffuse = p.base_color * ws.kd * (s * YarnScaling(p, o, lb, phase, NoV));
  return w;
}

template <typename T>
inline WovenIblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV,
                                  const WeaveSample<T>& ws, const Table2D& dfg,
                                  const Table2D& phase) {
  return EvalIbl(p, o, PrepareLobes(p), NoV, ws, dfg, phase);
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
