// brdf/physical_sheen.h: three.js MeshPhysicalMaterial with sheen, pinned to three.js r187
// (the sheen parts hold unchanged from r182 to r187: PR #32397's albedo fit, the
// max(E(NoV), E(NoL)) energy term, the [1e-4, 1] sheen roughness clamp).
//
// A sheen layer over the MeshStandardMaterial base (brdf/standard.h):
//   c_s = sheenColor * sheen (effective colour), r_s = clamp(sheenRoughness, 1e-4, 1)
//   Direct (per unit light colour, cosine included):
//     sheen = NoL c_s D_Charlie(r_s^2, NoH) V_Neubelt(NoV, NoL) with V <= 1 (saturate)
//     out   = sheen + base_direct (1 - max3(c_s) max(E^(NoV), E^(NoL)))
//   IBL:
//     sheen weight on the Lambert-convolved irradiance: c_s E^(NoV)
//       (three.js adds iblIrradiance c_s E^ / pi, iblIrradiance = pi x env at max LOD)
//     base weights x (1 - max3(c_s) E^(NoV))
//   E^ (three.js IBLSheenBRDF, r182+): q = 1/(r_s + 0.1),
//     a = -1.9362 + 1.0678 r + 0.4573 r^2 - 0.8469 q, b = -0.6014 + 0.5538 r - 0.4670 r^2 - 0.1255
//     q, E^ = saturate(exp(a NoV + b)).  It underestimates the true albedo at grazing angles (r =
//     0.3, NoV = 0.1: 0.313 vs 0.756; cloth-models.md section 4): tested, not fixed.
//
// Parameters (kParameterTable):
//   name             size default  range        diff  convention
//   base_color       3    1,1,1    [0, 1]       yes   linear sRGB
//   roughness        1    1        [0.045, 1]   yes   perceptual r (base GGX); alpha = r^2
//   metalness        1    0        [0, 1]       yes   baselines lock to 0
//   sheen_color      3    0,0,0    [0, 1]       yes   linear sRGB, = sheenColor x sheen
//   sheen_roughness  1    1        [1e-4, 1]    yes   perceptual; alpha = r_s^2
//
// References: Estevez & Kulla 2017; Neubelt & Pettineo 2013; three.js r187 sources.
#pragma once

#include <array>

#include "brdf/standard.h"

namespace clothfit::physical_sheen {

inline constexpr std::string_view kEngine = "three.js r187 MeshPhysicalMaterial (sheen)";
inline constexpr double kMinSheenRoughness = 1e-4;

using Options = standard::Options;

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  T roughness = Const<T>(1.0);
  T metalness = Const<T>(0.0);
  Rgb<T> sheen_color{Const<T>(0.0), Const<T>(0.0), Const<T>(0.0)};
  T sheen_roughness = Const<T>(1.0);

  standard::Params<T> Base() const { return {base_color, roughness, metalness}; }
};

inline constexpr std::array<ParamInfo, 5> kParameterTable{{
    {"base_color", 3, {1.0, 1.0, 1.0}, 0.0, 1.0, true, "linear sRGB"},
    {"roughness",
     1,
     {1.0, 0.0, 0.0},
     standard::kMinRoughness,
     1.0,
     true,
     "perceptual r, clamped to [0.045, 1]; alpha = r^2"},
    {"metalness", 1, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "0 = dielectric"},
    {"sheen_color", 3, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "linear sRGB; sheenColor x sheen"},
    {"sheen_roughness",
     1,
     {1.0, 0.0, 0.0},
     kMinSheenRoughness,
     1.0,
     true,
     "perceptual r_s, clamped to [1e-4, 1]; alpha = r_s^2"},
}};

template <typename T>
inline T ClampedSheenRoughness(const T& r) {
  return Clamp(r, Const<T>(kMinSheenRoughness), Const<T>(1.0));
}

// three.js r182+ IBLSheenBRDF: analytic fit of the sheen directional albedo.
template <typename T>
inline T SheenAlbedoFit(const T& NoV_raw, const T& r_s) {
  using std::exp;
  const T NoV = Saturate(NoV_raw);
  const T q = Const<T>(1.0) / (r_s + Const<T>(0.1));
  const T r2 = r_s * r_s;
  const T a =
      Const<T>(-1.9362) + Const<T>(1.0678) * r_s + Const<T>(0.4573) * r2 - Const<T>(0.8469) * q;
  const T b =
      Const<T>(-0.6014) + Const<T>(0.5538) * r_s - Const<T>(0.4670) * r2 - Const<T>(0.1255) * q;
  return Saturate(exp(a * NoV + b));
}

template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Cosines<T>& c,
                         const Table2D& dfg) {
  const T NoV = Saturate(c.NoV);
  const T NoL = Saturate(c.NoL);
  const T r_s = ClampedSheenRoughness(p.sheen_roughness);
  const T DV = D_Charlie(r_s * r_s, Saturate(c.NoH)) * V_Neubelt(NoV, NoL, NeubeltClamp::kOne);
  const Rgb<T> sheen = p.sheen_color * (DV * NoL);
  const T comp =
      Const<T>(1.0) - Max3(p.sheen_color) * Max(SheenAlbedoFit(NoV, r_s), SheenAlbedoFit(NoL, r_s));
  return sheen + standard::EvalDirect(p.Base(), o, c, dfg) * comp;
}

template <typename T>
inline IblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV_raw,
                             const Table2D& dfg) {
  const T r_s = ClampedSheenRoughness(p.sheen_roughness);
  const T E = SheenAlbedoFit(NoV_raw, r_s);
  const T comp = Const<T>(1.0) - Max3(p.sheen_color) * E;
  IblWeights<T> w = standard::EvalIbl(p.Base(), o, NoV_raw, dfg);
  w.specular = w.specular * comp;
  w.diffuse = w.diffuse * comp + p.sheen_color * E;
  return w;
}

}  // namespace clothfit::physical_sheen
