// brdf/standard.h: three.js MeshStandardMaterial, pinned to three.js r187
// (src/renderers/shaders/ShaderChunk/lights_physical_pars_fragment.glsl.js, bsdfs, common).
//
// GGX distribution, height-correlated Smith visibility, Schlick Fresnel in three.js's
// spherical-Gaussian form, Lambert diffuse, metalness workflow; r186+ energy terms:
//
//   alpha = r^2, r = min(max(roughness, 0.045) + geometryRoughness, 1)
//   f0 = mix(0.04, base, metalness), f90 = 1, c_diff = base (1 - metalness)
//   DFG: (A, B) = clothfit DFG LUT channels (R, G) at (NoV, r)  [three.js: its dfgLUT,
//        16x16 RG16F, the same integral; ours may be resampled to that grid by the preview]
//   Direct (per unit light colour, cosine included):
//     F = F_Schlick_SG(f0, 1, VoH); Ess = A + B
//     spec = D_GGX V_Smith F (1 + f0 (1/Ess - 1))              (Turquin 2019 compensation)
//     diff = c_diff / pi (1 - F_Schlick_SG(0.04, 1, VoH))
//     out  = NoL (spec + diff)
//   IBL (Fdez-Aguera 2019 multiple scattering), per Fresnel colour Fr:
//     FssEss = Fr A + B; Ems = 1 - (A + B); Favg = Fr + (1 - Fr)/21
//     Fms = FssEss Favg / (1 - Ems Favg); ms = Fms Ems
//     dielectric (Fr = 0.04) and metal (Fr = base) mixed by metalness;
//     specular weight = FssEss; diffuse weight = ms + c_diff (1 - (FssEss_d + ms_d)).
//
// Parameters (kParameterTable):
//   name        size default  range         diff  convention
//   base_color  3    1,1,1    [0, 1]        yes   linear sRGB
//   roughness   1    1        [0.045, 1]    yes   perceptual r; alpha = r^2
//   metalness   1    0        [0, 1]        yes   fitted baselines lock it to 0
//
// References: Walter et al. 2007 (GGX); Heitz 2014 (height-correlated Smith); Schlick 1994;
// Karis 2013 (split sum); Fdez-Aguera 2019 ("A Multiple-Scattering Microfacet Model for
// Real-Time Image-based Lighting"); Turquin 2019 (energy compensation).
#pragma once

#include <array>

#include "brdf/math.h"
#include "brdf/params.h"
#include "brdf/table.h"
#include "brdf/terms.h"

namespace clothfit::standard {

inline constexpr std::string_view kEngine = "three.js r187 MeshStandardMaterial";
inline constexpr double kMinRoughness = 0.045;  // three.js r187 (r180-r186: 0.0525)
inline constexpr double kDielectricF0 = 0.04;

struct Options {
  double geometry_roughness = 0.0;  // three.js adds max |dFdx(n)|, |dFdy(n)|; the preview
                                    // may supply it per pixel, 0 = flat G-buffer
};

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  T roughness = Const<T>(1.0);
  T metalness = Const<T>(0.0);
};

inline constexpr std::array<ParamInfo, 3> kParameterTable{{
    {"base_color", 3, {1.0, 1.0, 1.0}, 0.0, 1.0, true, "linear sRGB"},
    {"roughness",
     1,
     {1.0, 0.0, 0.0},
     kMinRoughness,
     1.0,
     true,
     "perceptual r, clamped to [0.045, 1]; alpha = r^2"},
    {"metalness", 1, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "0 = dielectric (f0 = 0.04)"},
}};

template <typename T>
inline T ClampedRoughness(const T& r, const Options& o) {
  return Min(Max(r, Const<T>(kMinRoughness)) + Const<T>(o.geometry_roughness), Const<T>(1.0));
}

// GGX specular for one light without the Fresnel colour: D V.
template <typename T>
inline T SpecularDV(const T& r_clamped, const T& NoV, const T& NoL, const T& NoH) {
  const T alpha = r_clamped * r_clamped;
  return D_GGX(alpha, NoH) * V_SmithGGXCorrelated(alpha, NoV, NoL);
}

template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Cosines<T>& c,
                         const Table2D& dfg) {
  const T r = ClampedRoughness(p.roughness, o);
  const T NoV = Saturate(c.NoV);
  const T NoL = Saturate(c.NoL);
  const T NoH = Saturate(c.NoH);
  const T one = Const<T>(1.0);
  const Rgb<T> dielectric = Rgb<T>::Splat(Const<T>(kDielectricF0));
  const Rgb<T> f0 = dielectric * (one - p.metalness) + p.base_color * p.metalness;
  const Rgb<T> F = F_Schlick(f0, one, c.LoH, FresnelForm::kSphericalGaussian);
  const T Ess = Max(dfg.Sample(NoV, r, 0) + dfg.Sample(NoV, r, 1), Const<T>(1e-4));
  const Rgb<T> comp = Rgb<T>::Splat(one) + f0 * (one / Ess - one);
  const Rgb<T> spec = F * comp * SpecularDV(r, NoV, NoL, NoH);
  const T Fd = F_SchlickWeight(c.LoH, FresnelForm::kSphericalGaussian);
  const T diffuse_fresnel = one - (Const<T>(kDielectricF0) * (one - Fd) + Fd);
  const Rgb<T> diff = p.base_color * (one - p.metalness) * (Fd_Lambert<T>() * diffuse_fresnel);
  return (spec + diff) * NoL;
}

// Fdez-Aguera single + multiple scattering for one Fresnel colour Fr and grazing value f90
// (three.js computeMultiscattering: FssEss = Fr A + f90 B; Ems = 1 - (A + B)).
template <typename T>
inline void MultiScatter(const Rgb<T>& Fr, const T& f90, const T& A, const T& B, Rgb<T>& ss,
                         Rgb<T>& ms) {
  const T one = Const<T>(1.0);
  const T Ems = one - (A + B);
  ss = Fr * A + Rgb<T>::Splat(f90 * B);
  const Rgb<T> Favg = Fr + (Rgb<T>::Splat(one) - Fr) * Const<T>(1.0 / 21.0);
  Rgb<T> Fms;
  for (int i = 0; i < 3; ++i) Fms[i] = ss[i] * Favg[i] / (one - Ems * Favg[i]);
  ms = Fms * Ems;
}

// The same with f90 = 1 (MeshStandardMaterial).
template <typename T>
inline void MultiScatter(const Rgb<T>& Fr, const T& A, const T& B, Rgb<T>& ss, Rgb<T>& ms) {
  MultiScatter(Fr, Const<T>(1.0), A, B, ss, ms);
}

template <typename T>
inline IblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV_raw,
                             const Table2D& dfg) {
  const T r = ClampedRoughness(p.roughness, o);
  const T NoV = Saturate(NoV_raw);
  const T A = dfg.Sample(NoV, r, 0);
  const T B = dfg.Sample(NoV, r, 1);
  const T one = Const<T>(1.0);
  Rgb<T> ss_d, ms_d, ss_m, ms_m;
  MultiScatter(Rgb<T>::Splat(Const<T>(kDielectricF0)), A, B, ss_d, ms_d);
  MultiScatter(p.base_color, A, B, ss_m, ms_m);
  const T m = p.metalness;
  const Rgb<T> ss = ss_d * (one - m) + ss_m * m;
  const Rgb<T> ms = ms_d * (one - m) + ms_m * m;
  const Rgb<T> c_diff = p.base_color * (one - m);
  const Rgb<T> diffuse = ms + c_diff * (Rgb<T>::Splat(one) - (ss_d + ms_d));
  return {ss, diffuse, Rgb<T>::Splat(Const<T>(0.0))};
}

}  // namespace clothfit::standard
