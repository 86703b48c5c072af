// brdf/cloth.h: the real-time cloth material. Two variants, selected and recorded:
//
//   kFilament     Filament's "cloth" shading model, current shader tree
//                 (shading/surface_shading_model_cloth.fs + light_indirect.fs): Charlie sheen
//                 distribution, unclamped Neubelt visibility (clamped on mobile), Lambert
//                 diffuse, optional wrapped-diffuse subsurface; no Fresnel on the sheen.
//   kSeedThreejs  The seed thesis's three.js MeshClothMaterial (chapter 5, listings 5.1-5.10):
//                 same lobes, three.js conventions (saturated cosines, V_Neubelt <= 1), the
//                 DFG table read at (NoV, r^2), a separate IBL wrap intensity s.
//
// Direct light (per light of colour E_L; EvalDirect returns out / E_L, cosine included):
//   Filament, no subsurface:   out = (c/pi + sheen D V) NoL                 (NoL = sat(n.l))
//   Filament, subsurface:      out = c/pi W(n.l, 0.5) sat(sub + NoL) + sheen D V NoL
//                              (not skipped for n.l <= 0: the wrap carries light past it)
//   seed:                      out = NoL [c/pi (W((n.l), 0.5) sat(sub + NoL) if SUBSURFACE)
//                                        + sheen D V]
//                              (three.js multiplies by irradiance = sat(n.l) E_L first, so
//                              the seed does not wrap light past the terminator; its
//                              `directDiffuse *= saturate(subsurface + dotNL)` also rescales
//                              earlier lights' diffuse: the preview emulates that, per light
//                              this header gives the single-light value).
//   D = D_Charlie(alpha = r^2, NoH), V = V_Neubelt(NoV, NoL).
//
// Image-based light (split sum; EvalIbl returns weights):
//   E = sheen * DFG.z(NoV, r)          (seed: DFG.z(NoV, r^2))
//   specular weight = E                multiplies the prefiltered radiance at the dominant
//                                      direction mix(reflect(-v, n), n, alpha^2), LOD
//                                      PrefilterLod(r)
//   diffuse weight  = c (1 - E) [W(NoV, w) sat(sub + NoV) if subsurface]
//                                      multiplies the Lambert-convolved irradiance
//                                      (1/pi) int L cos (what Filament's SH stores);
//                                      w = 0.5 (Filament) or subsurface_intensity (seed).
//   (1 - E) is negative at grazing angles for low roughness (DFG.z > 1): the engines do not
//   clamp it and neither do we; the sum E L + c (1 - E) L stays >= 0 under uniform light.
//
// Parameters (ClothParameterTable):
//   name              size default  range            diff  convention
//   base_color        3    1,1,1    [0, 1]           yes   linear sRGB (Filament baseColor,
//                                                          three.js color after decoding)
//   sheen_color       3    see SheenDefault [0, 1]   yes   linear sRGB
//   roughness         1    1        [0.045, 1] (desktop) yes  perceptual r; alpha = r^2;
//                                   [0.089, 1] mobile, [0.0525, 1] seed (three.js r12x)
//   subsurface_color  3    0,0,0    [0, 1]           yes   linear sRGB, used iff subsurface
//
// Sheen default (SheenDefault, recorded in every preset): Filament's docs say
// sqrt(baseColor) but its runtime default is white; the seed uses per-channel sqrt(color).
//
// References: Estevez & Kulla 2017 (Charlie); Neubelt & Pettineo 2013 (visibility);
// Filament "Physically Based Rendering in Filament", section 4.12 (cloth model);
// ../shared/reference/cloth-models.md sections 2, 3, 8 (the exact engine forms).
#pragma once

#include <array>
#include <string_view>

#include "brdf/math.h"
#include "brdf/params.h"
#include "brdf/table.h"
#include "brdf/terms.h"

namespace clothfit::cloth {

enum class Variant { kFilament, kSeedThreejs };
enum class SheenDefault { kExplicit, kSqrtBaseColor, kWhite };

inline std::string_view ToString(Variant v) {
  return v == Variant::kFilament ? "filament" : "seed-threejs";
}
inline std::string_view ToString(SheenDefault s) {
  switch (s) {
    case SheenDefault::kExplicit: return "explicit";
    case SheenDefault::kSqrtBaseColor: return "sqrt-base-color";
    case SheenDefault::kWhite: return "white";
  }
  return "?";
}

// The seed's LUT coordinate and clamp are three.js r12x's, for the thesis's fork.
inline constexpr double kSeedMinRoughness = 0.0525;

struct Options {
  Variant variant = Variant::kFilament;
  SheenDefault sheen_default = SheenDefault::kExplicit;  // kExplicit: use sheen_color as given
  bool subsurface = false;                               // MATERIAL_HAS_SUBSURFACE_COLOR
  Platform platform = Platform::kDesktop;                // Filament only
  double seed_subsurface_intensity = 0.5;                // seed's subsurfaceIntensity (IBL wrap)
};

template <typename T>
struct Params {
  Rgb<T> base_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  Rgb<T> sheen_color{Const<T>(1.0), Const<T>(1.0), Const<T>(1.0)};
  T roughness = Const<T>(1.0);
  Rgb<T> subsurface_color{Const<T>(0.0), Const<T>(0.0), Const<T>(0.0)};
};

inline constexpr std::array<ParamInfo, 4> kParameterTable{{
    {"base_color", 3, {1.0, 1.0, 1.0}, 0.0, 1.0, true, "linear sRGB"},
    {"sheen_color",
     3,
     {1.0, 1.0, 1.0},
     0.0,
     1.0,
     true,
     "linear sRGB; when absent, derived per sheen_default (explicit/sqrt-base-color/white)"},
    {"roughness",
     1,
     {1.0, 0.0, 0.0},
     kMinPerceptualRoughnessDesktop,
     1.0,
     true,
     "perceptual r, clamped to [0.045, 1] desktop, [0.089, 1] mobile, [0.0525, 1] seed; "
     "alpha = r^2"},
    {"subsurface_color", 3, {0.0, 0.0, 0.0}, 0.0, 1.0, true, "linear sRGB; only with subsurface"},
}};

inline double MinRoughness(const Options& o) {
  if (o.variant == Variant::kSeedThreejs) return kSeedMinRoughness;
  return o.platform == Platform::kMobile ? kMinPerceptualRoughnessMobile
                                         : kMinPerceptualRoughnessDesktop;
}

// Perceptual roughness after the engine's clamp.
template <typename T>
inline T ClampedRoughness(const T& r, const Options& o) {
  return Clamp(r, Const<T>(MinRoughness(o)), Const<T>(1.0));
}

// The sheen colour the engine uses.
template <typename T>
inline Rgb<T> EffectiveSheen(const Params<T>& p, const Options& o) {
  switch (o.sheen_default) {
    case SheenDefault::kExplicit: return p.sheen_color;
    case SheenDefault::kSqrtBaseColor: return Sqrt(p.base_color, 1e-12);
    case SheenDefault::kWhite: return Rgb<T>::Splat(Const<T>(1.0));
  }
  return p.sheen_color;
}

// The n.v the engine shades with: Filament clampNoV (>= 1e-4), three.js saturate().
template <typename T>
inline T ShadingNoV(const T& NoV, const Options& o) {
  if (o.variant == Variant::kFilament) return Clamp(NoV, Const<T>(kMinNoV), Const<T>(1.0));
  return Saturate(NoV);
}

inline NeubeltClamp VisibilityClamp(const Options& o) {
  if (o.variant == Variant::kSeedThreejs) return NeubeltClamp::kOne;
  return o.platform == Platform::kMobile ? NeubeltClamp::kMobile : NeubeltClamp::kNone;
}

// Sheen lobe without the colour: D_Charlie(alpha, NoH) V_Neubelt(NoV, NoL).
template <typename T>
inline T SheenDV(const T& r_clamped, const T& NoV, const T& NoL, const T& NoH, const Options& o) {
  const T alpha = r_clamped * r_clamped;
  return D_Charlie(alpha, Saturate(NoH)) * V_Neubelt(NoV, NoL, VisibilityClamp(o));
}

// Reflected radiance per unit light colour (cosine included), see the header comment.
template <typename T>
inline Rgb<T> EvalDirect(const Params<T>& p, const Options& o, const Cosines<T>& c) {
  const T r = ClampedRoughness(p.roughness, o);
  const T NoV = ShadingNoV(c.NoV, o);
  const T NoL = Saturate(c.NoL);
  const Rgb<T> sheen = EffectiveSheen(p, o);
  const Rgb<T> Fr = sheen * SheenDV(r, NoV, NoL, c.NoH, o);
  const T lambert = Fd_Lambert<T>();
  if (!o.subsurface) return (p.base_color * lambert + Fr) * NoL;

  const T wrap = Fd_Wrap(c.NoL, Const<T>(0.5));
  const Rgb<T> sss = Saturate(p.subsurface_color + Rgb<T>::Splat(NoL));
  const Rgb<T> Fd = p.base_color * (lambert * wrap) * sss;
  if (o.variant == Variant::kFilament) return Fd + Fr * NoL;
  return (Fd + Fr) * NoL;  // seed: three.js irradiance = sat(n.l) E_L multiplies both
}

// DFG.z lookup coordinate along the roughness axis: r (Filament), r^2 (seed).
template <typename T>
inline T DfgRoughnessCoordinate(const T& r_clamped, const Options& o) {
  return o.variant == Variant::kSeedThreejs ? r_clamped * r_clamped : r_clamped;
}

// `dfg`: the DFG LUT (clothfit lut), channel 2 = cloth DG, u = NoV, v = perceptual r.
template <typename T>
inline IblWeights<T> EvalIbl(const Params<T>& p, const Options& o, const T& NoV_raw,
                             const Table2D& dfg) {
  const T r = ClampedRoughness(p.roughness, o);
  const T NoV = ShadingNoV(NoV_raw, o);
  const T dg = dfg.Sample(NoV, DfgRoughnessCoordinate(r, o), 2);
  const Rgb<T> E = EffectiveSheen(p, o) * dg;
  Rgb<T> diffuse = p.base_color * (Rgb<T>::Splat(Const<T>(1.0)) - E);
  if (o.subsurface) {
    const T w = Const<T>(o.variant == Variant::kSeedThreejs ? o.seed_subsurface_intensity : 0.5);
    const Rgb<T> sss = Saturate(p.subsurface_color + Rgb<T>::Splat(NoV));
    diffuse = diffuse * Fd_Wrap(NoV, w) * sss;
  }
  return {E, diffuse, Rgb<T>::Splat(Const<T>(0.0))};
}

// Prefiltered-radiance LOD: Filament perceptualRoughnessToLod, lod = n r (2 - r).
template <typename T>
inline T PrefilterLod(const T& r_clamped, double lods_for_roughness_one) {
  return Const<T>(lods_for_roughness_one) * r_clamped * (Const<T>(2.0) - r_clamped);
}

// Mix factor towards n for the dominant specular direction: alpha^2 = r^4 (Filament
// getSpecularDominantDirection(n, reflect, pixel.roughness = alpha)).
template <typename T>
inline T DominantDirectionMix(const T& r_clamped) {
  return Sq(r_clamped * r_clamped);
}

}  // namespace clothfit::cloth
