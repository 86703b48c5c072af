// brdf/gltf_sheen.h: glTF 2.0 metallic-roughness material with KHR_materials_sheen
// (ratified extension, Appendix B of the core spec for the base), evaluated as the Khronos
// glTF-Sample-Viewer does.
//
//   alpha = r^2 (base), alpha_s = r_s^2 (sheen), f0 = 0.04 (ior 1.5), f90 = 1
//   Base, direct:  F = Schlick pow5(f0, VoH)
//     dielectric = mix(c/pi, D_GGX V_Smith, F);  metal = Schlick(base, VoH) D_GGX V_Smith
//     base_brdf  = mix(dielectric, metal, metallic)   (V_Smith height-correlated, as the viewer)
//   Sheen, direct: sheen = sheenColor D_Charlie(alpha_s, NoH) V_Charlie(NoV, NoL, alpha_s)
//     out = NoL [sheen + base_brdf min(1 - max3(c_s) E(NoV), 1 - max3(c_s) E(NoL))]
//   IBL (split sum with Fdez-Aguera multiple scattering, the viewer's getIBLGGXFresnel):
//     (A, B) = DFG LUT (R, G) at (NoV, r); Fr = max(1 - r, F0) - F0
//     k_S = F0 + Fr (1 - NoV)^5; FssEss = k_S A + B; Ems = 1 - (A + B)
//     F_avg = F0 + (1 - F0)/21; Fib = FssEss + Ems FssEss F_avg / (1 - F_avg Ems)
//     specular weight = (1 - m) Fib(0.04) + m Fib(base)
//     diffuse weight  = (1 - m) c (1 - Fib(0.04))
//     sheen weight    = c_s E(NoV, r_s)    (on the Charlie-prefiltered radiance)
//     base weights x (1 - max3(c_s) E(NoV, r_s))
//   E(NoV, r_s) (read saturated, see SheenAlbedo): the sheen lobe's directional albedo int
//   D_Charlie V_Charlie cos, a table built by our own integrator (clothfit lut --sheen-out;
//   brdf/lut.h), not the viewer's (reported 10-50 % high). The viewer reads its Charlie LUT for the
//   IBL term and a separate albedo-scaling LUT; both are this same integral, so one table serves
//   both.
//
// Parameters (kParameterTable):
//   name             size default  range        diff  convention
//   base_color       3    1,1,1    [0, 1]       yes   linear sRGB (baseColorFactor)
//   roughness        1    1        [0, 1]       yes   perceptual; alpha = r^2 (floored 1e-8)
//   metallic         1    0        [0, 1]       yes   baselines lock to 0
//   sheen_color      3    0,0,0    [0, 1]       yes   linear sRGB (sheenColorFactor)
//   sheen_roughness  1    0        [1e-4, 1]    yes   sheenRoughnessFactor; alpha_s = r_s^2
//                                                    (viewer floors at 1e-6; we at 1e-4)
//
// References: KHR_materials_sheen specification; Conty & Kulla 2017 (Charlie Lambda fit);
// Estevez & Kulla 2017; glTF 2.0 spec Appendix B; Fdez-Aguera 2019.
#pragma once

#include <array>

#include "brdf/math.h"
#include "brdf/params.h"
#include "brdf/table.h"
#include "brdf/terms.h"

namespace clothfit::gltf_sheen {

inline constexpr std::string_view kEngine =
    "glTF 2.0 + KHR_materials_sheen (Khronos sample viewer)";
inline constexpr double kMinSheenRoughness = 1e-4;
inline constexpr double kF0 = 0.04;

struct Options {};

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  T roughness = Const<T>(1.0);
  T metallic = Const<T>(0.0);
  Rgb<T> sheen_color{Const<T>(0.0), Const<T>(0.0), Const<T>(0.0)};
  T sheen_roughness = Const<T>(0.0);
};

inline constexpr std::array<ParamInfo, 5> kParameterTable{{
    {"base_color", 3, {1.0, 1.0, 1.0}, 0.0, 1.0, true, "linear sRGB"},
    {"roughness", 1, {1.0, 0.0, 0.0}, 0.0, 1.0, true, "perceptual r; alpha = r^2"},
    {"metallic", 1, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "0 = dielectric"},
    {"sheen_color", 3, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "linear sRGB (sheenColorFactor)"},
    {"sheen_roughness",
     1,
     {0.0, 0.0, 0.0},
     kMinSheenRoughness,
     1.0,
     true,
     "sheenRoughnessFactor r_s, floored at 1e-4; alpha = r_s^2"},
}};

template <typename T>
inline T ClampedRoughness(const T& r) {
  return Saturate(r);
}
template <typename T>
inline T ClampedSheenRoughness(const T& r) {
  return Clamp(r, Const<T>(kMinSheenRoughness), Const<T>(1.0));
}

// Sheen albedo E(NoV, r_s) from the table (u = NoV, v = r_s), saturated: the integral
// exceeds 1 at grazing angles for low sheen roughness (1.46 at NoV = 0.016, r_s = 0.05),
// which would make the albedo scaling negative; the sample viewer stores E in an 8-bit PNG,
// so it reads min(E, 1) too.
template <typename T>
inline T SheenAlbedo(const Table2D& e, const T& NoV, const T& r_s) {
  return Saturate(e.Sample(NoV, r_s, 0));
}

template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options&, const Cosines<T>& c,
                         const Table2D& sheen_albedo) {
  const T one = Const<T>(1.0);
  const T NoV = Saturate(c.NoV);
  const T NoL = Saturate(c.NoL);
  const T NoH = Saturate(c.NoH);
  const T r = ClampedRoughness(p.roughness);
  const T alpha = r * r;
  const T spec = D_GGX(alpha, NoH) * V_SmithGGXCorrelated(alpha, NoV, NoL);
  const T Fw = F_SchlickWeight(c.LoH, FresnelForm::kPow5);
  const T F = Const<T>(kF0) * (one - Fw) + Fw;
  const Rgb<T> dielectric = p.base_color * (Fd_Lambert<T>() * (one - F)) + Rgb<T>::Splat(spec * F);
  const Rgb<T> metal_f = p.base_color * (one - Fw) + Rgb<T>::Splat(Fw);
  const Rgb<T> base = dielectric * (one - p.metallic) + metal_f * (spec * p.metallic);

  const T r_s = ClampedSheenRoughness(p.sheen_roughness);
  const T alpha_s = r_s * r_s;
  const T sheen_dv = D_Charlie(alpha_s, NoH, false) * V_Charlie(NoV, NoL, alpha_s);
  const T m = Max3(p.sheen_color);
  const T scale = Min(one - m * SheenAlbedo(sheen_albedo, NoV, r_s),
                      one - m * SheenAlbedo(sheen_albedo, NoL, r_s));
  return (p.sheen_color * sheen_dv + base * scale) * NoL;
}

template <typename T>
inline Rgb<T> IblFresnel(const Rgb<T>& F0, const T& r, const T& NoV, const T& A, const T& B) {
  const T one = Const<T>(1.0);
  Rgb<T> out;
  for (int i = 0; i < 3; ++i) {
    const T Fr = Max(one - r, F0[i]) - F0[i];
    const T kS = F0[i] + Fr * Pow5(one - NoV);
    const T FssEss = kS * A + B;
    const T Ems = one - (A + B);
    const T Favg = F0[i] + (one - F0[i]) * Const<T>(1.0 / 21.0);
    out[i] = FssEss + Ems * FssEss * Favg / (one - Favg * Ems);
  }
  return out;
}

// `dfg`: clothfit DFG LUT (R, G used); `sheen_albedo`: E table (channel 0).
template <typename T>
inline IblWeights<T> EvalIbl(const Params<T>& p, const Options&, const T& NoV_raw,
                             const Table2D& dfg, const Table2D& sheen_albedo) {
  const T one = Const<T>(1.0);
  const T NoV = Saturate(NoV_raw);
  const T r = ClampedRoughness(p.roughness);
  const T A = dfg.Sample(NoV, r, 0);
  const T B = dfg.Sample(NoV, r, 1);
  const Rgb<T> Fd = IblFresnel(Rgb<T>::Splat(Const<T>(kF0)), r, NoV, A, B);
  const Rgb<T> Fm = IblFresnel(p.base_color, r, NoV, A, B);
  const T m = p.metallic;
  const T r_s = ClampedSheenRoughness(p.sheen_roughness);
  const T E = SheenAlbedo(sheen_albedo, NoV, r_s);
  const T scale = one - Max3(p.sheen_color) * E;
  IblWeights<T> w;
  w.specular = (Fd * (one - m) + Fm * m) * scale;
  w.diffuse = p.base_color * (Rgb<T>::Splat(one) - Fd) * ((one - m) * scale);
  w.sheen = p.sheen_color * E;
  return w;
}

}  // namespace clothfit::gltf_sheen
