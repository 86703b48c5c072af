// brdf/physical_aniso.h: three.js MeshPhysicalMaterial with sheen + anisotropy + specular
// intensity/colour, pinned to three.js r187 (0.187.0: ShaderChunk/lights_physical_fragment,
// lights_physical_pars_fragment, lights_fragment_begin, envmap_physical_pars_fragment). The
// honest extra baseline of issue 12: the same lobes a web page gets from MeshPhysicalMaterial,
// fitted with the same weave maps as `woven` (docs/fitting.md, "The honest baseline").
//
// Material setup (lights_physical_fragment, IOR defined, USE_SPECULAR, USE_ANISOTROPY):
//   r = min(max(roughness, 0.045) + geometryRoughness, 1), alpha = r^2
//   specularColor  = min(0.04 specular_color, 1) specular_intensity      (ior 1.5: 0.04)
//   f90            = mix(specular_intensity, 1, metalness)
//   f0 (blended)   = mix(specularColor, base_color, metalness)
//   anisotropy vector: strength (cos rot, sin rot); with an anisotropy map (RG = direction in
//     [-1, 1] after 2x - 1, B = strength), V = strength R(rot) normalize(dir) B
//   anisotropy = saturate(|V|); alpha_t = mix(alpha, 1, anisotropy^2); alpha_b = alpha
//   T = t V.x + b V.y, B = b V.x - t V.y (V normalised; t, b: the mesh tangent frame)
// Direct (per unit light colour, cosine included):
//   spec  = F_Schlick(f0, f90, VoH) V_aniso(alpha_t, alpha_b) D_aniso(alpha_t, alpha_b)
//           x (1 + f0 (1/Ess - 1))   (Turquin; Ess = DFG A + B at (NoV, r))
//   diff  = base (1 - metalness) / pi x (1 - F_Schlick(specularColor, f90, VoH))
//   sheen = c_s D_Charlie(r_s^2) V_Neubelt (<= 1), as brdf/physical_sheen.h
//   out   = NoL [sheen + (spec + diff)(1 - max3(c_s) max(E^(NoV), E^(NoL)))]
// IBL (split sum, Fdez-Aguera): the weights of brdf/physical_sheen.h with Fr = specularColor
//   and f90: FssEss = Fr A + f90 B (the DFG of the geometric normal and r, NOT anisotropic);
//   the specular radiance is looked up along three.js's bent normal (BentNormal below), the
//   only place anisotropy enters the IBL.
//
// Reduction: with anisotropy 0 (alpha_t = alpha_b), specular_intensity 1 and specular_color 1
// the model equals brdf/physical_sheen.h (tests/test_physical_aniso.cpp, to 1e-12).
//
// Parameters (kParameterTable):
//   name                size default  range        diff  convention
//   base_color          3    1,1,1    [0, 1]       yes   linear sRGB (x the kd map, if any)
//   roughness           1    1        [0.045, 1]   yes   perceptual r; alpha = r^2
//   metalness           1    0        [0, 1]       yes   the fit locks it to 0
//   sheen_color         3    0,0,0    [0, 1]       yes   linear sRGB, sheenColor x sheen
//   sheen_roughness     1    1        [1e-4, 1]    yes   perceptual; alpha = r_s^2
//   anisotropy_strength 1    0        [0, 1]       yes   three.js anisotropy (x map B)
//   anisotropy_rotation 1    0        [-pi, pi]    yes   radians, from the tangent toward b
//   specular_intensity  1    1        [0, 1]       yes   three.js specularIntensity
//   specular_color      3    1,1,1    [0, 25]      yes   three.js specularColor (f0 = 0.04 x)
//
// References: Burley 2012 (anisotropic GGX), Heitz 2014 (anisotropic Smith), Kulla & Conty
// 2017 / Filament (alpha_t from anisotropy, bent normal for IBL), Estevez & Kulla 2017,
// Neubelt & Pettineo 2013, Fdez-Aguera 2019, Turquin 2019; three.js r187 sources (read, not
// copied).
#pragma once

#include <array>
#include <cmath>

#include "brdf/physical_sheen.h"
#include "brdf/standard.h"

namespace clothfit::physical_aniso {

inline constexpr std::string_view kEngine =
    "three.js r187 MeshPhysicalMaterial (sheen + anisotropy + specular)";
inline constexpr int kParameterCount = 15;
inline constexpr double kBaseF0 = 0.04;  // ((ior - 1)/(ior + 1))^2 at three.js's ior 1.5

using Options = standard::Options;

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  T roughness = Const<T>(1.0);
  T metalness = Const<T>(0.0);
  Rgb<T> sheen_color{Const<T>(0.0), Const<T>(0.0), Const<T>(0.0)};
  T sheen_roughness = Const<T>(1.0);
  T anisotropy_strength = Const<T>(0.0);
  T anisotropy_rotation = Const<T>(0.0);
  T specular_intensity = Const<T>(1.0);
  Rgb<T> specular_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
};

// The first five entries are physical-sheen's (the same parameters, same order and ranges:
// with anisotropy 0 and the specular defaults this model IS physical-sheen).
inline constexpr std::array<ParamInfo, 9> kParameterTable{{
    physical_sheen::kParameterTable[0],
    physical_sheen::kParameterTable[1],
    physical_sheen::kParameterTable[2],
    physical_sheen::kParameterTable[3],
    physical_sheen::kParameterTable[4],
    {"anisotropy_strength",
     1,
     {0.0, 0.0, 0.0},
     0.0,
     1.0,
     true,
     "three.js anisotropy; alpha_t = mix(alpha, 1, strength^2)"},
    {"anisotropy_rotation",
     1,
     {0.0, 0.0, 0.0},
     -kPi,
     kPi,
     true,
     "radians, counter-clockwise from the tangent toward the bitangent"},
    {"specular_intensity", 1, {1.0, 0.0, 0.0}, 0.0, 1.0, true, "three.js specularIntensity"},
    {"specular_color",
     3,
     {1.0, 1.0, 1.0},
     0.0,
     25.0,
     true,
     "three.js specularColor (linear); f0 = min(0.04 c, 1) x intensity"},
}};

// Flat vector (table order) -> Params.
template <typename T>
inline Params<T> FromFlat(const T* x) {
  Params<T> p;
  p.base_color = Rgb<T>(x[0], x[1], x[2]);
  p.roughness = x[3];
  p.metalness = x[4];
  p.sheen_color = Rgb<T>(x[5], x[6], x[7]);
  p.sheen_roughness = x[8];
  p.anisotropy_strength = x[9];
  p.anisotropy_rotation = x[10];
  p.specular_intensity = x[11];
  p.specular_color = Rgb<T>(x[12], x[13], x[14]);
  return p;
}

// One texel of a three.js anisotropyMap, already decoded: direction (dx, dy) in the tangent
// frame (unit or zero) and strength b in [0, 1]. The default is "no map": direction (1, 0),
// b = 1 (three.js then uses anisotropyVector itself).
template <typename T>
struct AnisoSample {
  T dx = Const<T>(1.0), dy = Const<T>(0.0), b = Const<T>(1.0);
};

// The anisotropy frame of a pixel: the unit direction in (t, b) and the saturated strength.
template <typename T>
struct AnisoFrame {
  T ux, uy;        // T = t ux + b uy, B = b ux - t uy
  T anisotropy;    // saturate(|V|)
};

template <typename T>
inline AnisoFrame<T> MakeFrame(const Params<T>& p, const AnisoSample<T>& s) {
  using std::cos;
  using std::sin;
  const T c = cos(p.anisotropy_rotation), sn = sin(p.anisotropy_rotation);
  // |V| = strength |dir| b with |dir| = 1 (or 0: three.js then takes (1, 0) and anisotropy 0).
  const T dl2 = s.dx * s.dx + s.dy * s.dy;
  AnisoFrame<T> f;
  if (!(ScalarPart(dl2) > 0.0)) {
    f.ux = Const<T>(1.0);
    f.uy = Const<T>(0.0);
    f.anisotropy = Const<T>(0.0);
    return f;
  }
  using std::sqrt;
  const T inv = Const<T>(1.0) / sqrt(dl2);
  const T dx = s.dx * inv, dy = s.dy * inv;
  f.ux = c * dx - sn * dy;
  f.uy = sn * dx + c * dy;
  f.anisotropy = Saturate(p.anisotropy_strength * s.b);
  return f;
}

// Tangent-frame cosines of the mesh frame (t, b) -> those of the anisotropy frame (T, B).
template <typename T>
inline TangentCosines<T> Rotate(const TangentCosines<T>& tc, const AnisoFrame<T>& f) {
  auto toT = [&](const T& t, const T& b) { return t * f.ux + b * f.uy; };
  auto toB = [&](const T& t, const T& b) { return b * f.ux - t * f.uy; };
  return {toT(tc.ToV, tc.BoV), toB(tc.ToV, tc.BoV), toT(tc.ToL, tc.BoL),
          toB(tc.ToL, tc.BoL), toT(tc.ToH, tc.BoH), toB(tc.ToH, tc.BoH)};
}

// Dielectric specular colour (three.js material.specularColor) and f90.
template <typename T>
inline Rgb<T> SpecularColor(const Params<T>& p) {
  Rgb<T> f;
  for (int i = 0; i < 3; ++i)
    f[i] = Min(Const<T>(kBaseF0) * p.specular_color[i], Const<T>(1.0)) * p.specular_intensity;
  return f;
}
template <typename T>
inline T SpecularF90(const Params<T>& p) {
  return p.specular_intensity + (Const<T>(1.0) - p.specular_intensity) * p.metalness;
}

template <typename T>
inline T AlphaT(const T& alpha, const T& anisotropy) {
  return Max(Mix(alpha, Const<T>(1.0), anisotropy * anisotropy), alpha);
}

// Direct light. `tc`: cosines against the MESH tangent frame (t, b); the anisotropy frame
// (map direction, rotation) is applied here.
template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Cosines<T>& c,
                         const TangentCosines<T>& tc, const AnisoSample<T>& s,
                         const Table2D& dfg) {
  const T one = Const<T>(1.0);
  const T NoV = Saturate(c.NoV);
  const T NoL = Saturate(c.NoL);
  const T r = standard::ClampedRoughness(p.roughness, o);
  const T alpha = r * r;
  const AnisoFrame<T> f = MakeFrame(p, s);
  const TangentCosines<T> a = Rotate(tc, f);
  const T alpha_t = AlphaT(alpha, f.anisotropy);
  const T V = V_SmithGGXCorrelated_Anisotropic(alpha_t, alpha, NoV, NoL, a.ToV, a.BoV, a.ToL,
                                               a.BoL);
  const T D = D_GGX_Anisotropic(alpha_t, alpha, Saturate(c.NoH), a.ToH, a.BoH);
  const Rgb<T> spec_d = SpecularColor(p);
  const T f90 = SpecularF90(p);
  const Rgb<T> f0 = spec_d * (one - p.metalness) + p.base_color * p.metalness;
  const Rgb<T> F = F_Schlick(f0, f90, c.LoH, FresnelForm::kSphericalGaussian);
  const T Ess = Max(dfg.Sample(NoV, r, 0) + dfg.Sample(NoV, r, 1), Const<T>(1e-4));
  const Rgb<T> comp = Rgb<T>::Splat(one) + f0 * (one / Ess - one);
  const Rgb<T> spec = F * comp * (D * V);
  const Rgb<T> Fd = F_Schlick(spec_d, f90, c.LoH, FresnelForm::kSphericalGaussian);
  const Rgb<T> diff = p.base_color * (one - p.metalness) * Fd_Lambert<T>() *
                      (Rgb<T>::Splat(one) - Fd);
  const T r_s = physical_sheen::ClampedSheenRoughness(p.sheen_roughness);
  const T DV = D_Charlie(r_s * r_s, Saturate(c.NoH)) * V_Neubelt(NoV, NoL, NeubeltClamp::kOne);
  const Rgb<T> sheen = p.sheen_color * (DV * NoL);
  const T sc = one - Max3(p.sheen_color) * Max(physical_sheen::SheenAlbedoFit(NoV, r_s),
                                               physical_sheen::SheenAlbedoFit(NoL, r_s));
  return sheen + (spec + diff) * (NoL * sc);
}

// IBL weights: specular (on the radiance along the bent-normal reflection), diffuse (on the
// Lambert-convolved irradiance), as brdf/physical_sheen.h.
template <typename T>
inline IblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV_raw,
                             const Table2D& dfg) {
  const T one = Const<T>(1.0);
  const T r = standard::ClampedRoughness(p.roughness, o);
  const T NoV = Saturate(NoV_raw);
  const T A = dfg.Sample(NoV, r, 0);
  const T B = dfg.Sample(NoV, r, 1);
  const T f90 = SpecularF90(p);
  Rgb<T> ss_d, ms_d, ss_m, ms_m;
  standard::MultiScatter(SpecularColor(p), f90, A, B, ss_d, ms_d);  // f90 = specularIntensity
  standard::MultiScatter(p.base_color, f90, A, B, ss_m, ms_m);
  const T m = p.metalness;
  const Rgb<T> ss = ss_d * (one - m) + ss_m * m;
  const Rgb<T> ms = ms_d * (one - m) + ms_m * m;
  const Rgb<T> c_diff = p.base_color * (one - m);
  const Rgb<T> diffuse = ms + c_diff * (Rgb<T>::Splat(one) - (ss_d + ms_d));
  const T r_s = physical_sheen::ClampedSheenRoughness(p.sheen_roughness);
  const T E = physical_sheen::SheenAlbedoFit(NoV_raw, r_s);
  const T comp = one - Max3(p.sheen_color) * E;
  return {ss * comp, diffuse * comp + p.sheen_color * E, Rgb<T>::Splat(Const<T>(0.0))};
}

// three.js getIBLAnisotropyRadiance's bent normal (Filament's anisotropic IBL approximation):
//   bn = normalize(cross(cross(B, v), B)); w = (1 - anisotropy (1 - r))^4;
//   bent = normalize(mix(bn, n, w))      (w = 1, i.e. anisotropy 0: bent = n exactly)
// `B`: the anisotropy bitangent (world), r: the clamped perceptual roughness.
template <typename T>
inline T BentNormalWeight(const T& anisotropy, const T& r) {
  return Sq(Sq(Const<T>(1.0) - anisotropy * (Const<T>(1.0) - r)));
}
template <typename T>
inline Vec3<T> BentNormal(const Vec3<T>& n, const Vec3<T>& v, const Vec3<T>& B, const T& w) {
  if (!(ScalarPart(w) < 1.0)) return n;  // mix(bn, n, 1) = n: the isotropic lookup
  const Vec3<T> bn = Normalize(Cross(Cross(B, v), B));
  return Normalize(bn * (Const<T>(1.0) - w) + n * w);
}
// three.js getIBLRadiance's lookup direction about a normal: normalize(mix(reflect(-v, n), n,
// r^4)) (the same mix as cloth::DominantDirectionMix).
template <typename T>
inline Vec3<T> IblDirection(const Vec3<T>& n, const Vec3<T>& v, const T& r) {
  const Vec3<T> R = n * (Const<T>(2.0) * Dot(n, v)) - v;
  const T t = Sq(Sq(r));
  return Normalize(R * (Const<T>(1.0) - t) + n * t);
}

}  // namespace clothfit::physical_aniso
