// brdf/params.h: the parameter tables every model publishes, and the shading cosines.
//
// A model's parameter table is the single place that lists its parameters: name, size
// (1 scalar or 3 for an RGB colour), default, range, whether a fitter may differentiate it,
// and the convention it is stated in. The fitter builds Ceres parameter blocks and bounds
// from it, the stress tester draws inputs from it, the CLI documents it (style.md 6).
#pragma once

#include <array>
#include <span>
#include <string_view>

#include "brdf/math.h"

namespace clothfit {

struct ParamInfo {
  std::string_view name;        // key in presets and on the command line
  int size;                     // 1 (scalar) or 3 (linear RGB colour)
  std::array<double, 3> def;    // default value (first `size` entries used)
  double lower;                 // documented lower bound (inclusive)
  double upper;                 // documented upper bound (inclusive)
  bool differentiable;          // may be a Ceres parameter
  std::string_view convention;  // e.g. "linear sRGB", "perceptual roughness r; alpha = r^2"
};

// Cosines of the shading configuration, as the engines compute them from unit vectors
// n, v, l and h = normalize(v + l). They are passed raw (possibly negative or slightly above
// one); each model applies its engine's own clamping, so the stress test can feed edge cases.
template <typename T>
struct Cosines {
  T NoV;  // n.v
  T NoL;  // n.l
  T NoH;  // n.h
  T LoH;  // l.h (= v.h)
};

// Cosines from directions in the shading frame (n = +z). v and l need not be normalised.
template <typename T>
inline Cosines<T> CosinesFromDirections(const Vec3<T>& v_in, const Vec3<T>& l_in) {
  const Vec3<T> v = Normalize(v_in);
  const Vec3<T> l = Normalize(l_in);
  const Vec3<T> h = Normalize(v + l);
  return {v.z, l.z, h.z, Dot(l, h)};
}

template <typename T>
inline Cosines<T> SwapViewLight(const Cosines<T>& c) {
  return {c.NoL, c.NoV, c.NoH, c.LoH};
}

// Raw cosines against the mesh tangent frame, for anisotropic models (brdf/woven.h):
// t = the mesh tangent (+u, the warp direction), b = tangent_sign (n x t) (+v, the weft), as
// the reference renderer builds them (render/reference/path_tracer.cpp) and after the
// two-sided flip of n towards the viewer. Like Cosines they are passed raw.
template <typename T>
struct TangentCosines {
  T ToV, BoV;  // per pixel
  T ToL, BoL;  // per light
  T ToH, BoH;  // per light
};

// Tangent cosines from directions in the shading frame (t = +x, b = +y, n = +z).
template <typename T>
inline TangentCosines<T> TangentCosinesFromDirections(const Vec3<T>& v_in, const Vec3<T>& l_in) {
  const Vec3<T> v = Normalize(v_in);
  const Vec3<T> l = Normalize(l_in);
  const Vec3<T> h = Normalize(v + l);
  return {v.x, v.y, l.x, l.y, h.x, h.y};
}

// Image-based lighting as split-sum weights; the renderer multiplies them with its
// environment lookups and sums:  out = specular * L_ggx + diffuse * E_d + sheen * L_charlie.
//   L_ggx     : GGX-prefiltered radiance at the model's dominant direction and LOD
//   E_d       : Lambert-convolved irradiance (1/pi) int L(l) max(n.l, 0) dl (Filament's SH)
//   L_charlie : Charlie-prefiltered radiance (glTF sheen only; zero weight elsewhere)
template <typename T>
struct IblWeights {
  Rgb<T> specular;
  Rgb<T> diffuse;
  Rgb<T> sheen;
};

// Engine platform: Filament clamps perceptual roughness to 0.045 on desktop, 0.089 on
// mobile (fp16), and clamps the Neubelt denominator on mobile.
enum class Platform { kDesktop, kMobile };

inline constexpr double kMinPerceptualRoughnessDesktop = 0.045;
inline constexpr double kMinPerceptualRoughnessMobile = 0.089;
// Filament MIN_N_DOT_V: n.v is clamped to at least this before shading.
inline constexpr double kMinNoV = 1e-4;

}  // namespace clothfit
