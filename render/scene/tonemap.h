// render/scene/tonemap.h: the display transform of the preview, as three.js r187 applies it:
// exposure, one of six tone mappers, a clamp to [0, 1], then the sRGB transfer function.
//
// Every function is templated on the scalar T (double, ceres::Jet) so a fitter can
// differentiate through the display transform. Formulas follow three.js r187
// src/renderers/shaders/ShaderChunk/tonemapping_pars_fragment.glsl.js (reimplemented here from
// its published formulas and constants; docs/preview-ibl.md section 4 lists every source):
//
//   Linear     saturate(e c)
//   Reinhard   saturate(x / (1 + x)),  x = e c            (Reinhard et al. 2002)
//   Cineon     x = max(0, e c - 0.004);
//              (x (6.2 x + 0.5) / (x (6.2 x + 1.7) + 0.06))^2.2
//              (Hejl & Burgess-Dawson's optimised filmic curve; its output already carries a
//              display gamma of ~1/2.2, so three.js raises it to 2.2 to return linear values
//              that the sRGB transfer then re-encodes)
//   ACESFilmic x = M_in (e c / 0.6); y = (x (x + 0.0245786) - 0.000090537) /
//              (x (0.983729 x + 0.4329510) + 0.238081); saturate(M_out y)
//              (Stephen Hill's RRT+ODT fit; 1/0.6 is three.js's brightness choice, #19621)
//   AgX        Blender AgX as approximated by Filament / iolite (Rec.2020 working space,
//              inset matrix, log2 encoding over [-12.47393, 4.026069] EV, a 6th-order
//              polynomial sigmoid, outset matrix, 2.2 power, back to Rec.709, clamp)
//   Neutral    Khronos PBR Neutral (start of compression 0.8 - 0.04, desaturation 0.15)
//
// GLSL mat3 constructors are column-major; the matrices below are written row by row in the
// mathematical sense (out_i = sum_j M[i][j] in_j), i.e. transposed from the GLSL listing.
// three.js evaluates in fp32; this header evaluates in T (double): results agree to ~1e-6.
#pragma once

#include <array>
#include <stdexcept>
#include <string>
#include <string_view>

#include "brdf/math.h"

namespace clothfit::render {

enum class ToneMapping { kLinear, kReinhard, kCineon, kAcesFilmic, kAgX, kNeutral };

// The scene-card names, in enum order.
inline constexpr std::array<std::string_view, 6> kToneMappingNames = {
    "Linear", "Reinhard", "Cineon", "ACESFilmic", "AgX", "Neutral"};

inline std::string_view ToneMappingName(ToneMapping t) {
  return kToneMappingNames[static_cast<size_t>(t)];
}

// Parses a scene-card name (exact, case-sensitive). Throws std::invalid_argument naming the
// value and listing the valid names.
inline ToneMapping ParseToneMapping(std::string_view name) {
  for (size_t i = 0; i < kToneMappingNames.size(); ++i) {
    if (name == kToneMappingNames[i]) return static_cast<ToneMapping>(i);
  }
  std::string valid;
  for (size_t i = 0; i < kToneMappingNames.size(); ++i) {
    valid += (i ? "|" : "");
    valid += kToneMappingNames[i];
  }
  throw std::invalid_argument("tone_mapping: unknown value \"" + std::string(name) +
                              "\"; valid values are " + valid);
}

namespace tonemap_detail {

using Mat3 = std::array<std::array<double, 3>, 3>;  // row-major: out_i = sum_j m[i][j] in_j

template <typename T>
inline Rgb<T> Mul(const Mat3& m, const Rgb<T>& c) {
  Rgb<T> out;
  for (int i = 0; i < 3; ++i) {
    const auto& row = m[static_cast<size_t>(i)];
    out[i] = Const<T>(row[0]) * c.r + Const<T>(row[1]) * c.g + Const<T>(row[2]) * c.b;
  }
  return out;
}

template <typename T, typename F>
inline Rgb<T> PerChannel(const Rgb<T>& c, F f) {
  return {f(c.r), f(c.g), f(c.b)};
}

// ACES: sRGB -> XYZ -> D65_2_D60 -> AP1 -> RRT_SAT, and ODT_SAT -> XYZ -> D60_2_D65 -> sRGB
// (Stephen Hill's fit, as listed by three.js; rows here = GLSL columns).
inline constexpr Mat3 kAcesInput = {
    {{0.59719, 0.35458, 0.04823}, {0.07600, 0.90834, 0.01566}, {0.02840, 0.13383, 0.83777}}};
inline constexpr Mat3 kAcesOutput = {
    {{1.60475, -0.53108, -0.07367}, {-0.10208, 1.10813, -0.00605}, {-0.00327, -0.07276, 1.07602}}};

// Rec.709 <-> Rec.2020 primaries (ITU-R BT.2407-2017, 4-digit values as three.js lists them).
inline constexpr Mat3 kSrgbToRec2020 = {
    {{0.6274, 0.3293, 0.0433}, {0.0691, 0.9195, 0.0113}, {0.0164, 0.0880, 0.8956}}};
inline constexpr Mat3 kRec2020ToSrgb = {
    {{1.6605, -0.5876, -0.0728}, {-0.1246, 1.1329, -0.0083}, {-0.0182, -0.1006, 1.1187}}};

// AgX inset and outset matrices (Blender AgX via Filament PR 7236; the outset is the explicit
// inverse of Filament's AgXOutsetMatrixInv, as three.js lists it).
inline constexpr Mat3 kAgXInset = {{{0.856627153315983, 0.0951212405381588, 0.0482516061458583},
                                    {0.137318972929847, 0.761241990602591, 0.101439036467562},
                                    {0.11189821299995, 0.0767994186031903, 0.811302368396859}}};
inline constexpr Mat3 kAgXOutset = {
    {{1.1271005818144368, -0.11060664309660323, -0.016493938717834573},
     {-0.1413297634984383, 1.157823702216272, -0.016493938717834257},
     {-0.14132976349843826, -0.11060664309660294, 1.2519364065950405}}};

// log2(2^-10 * 0.18) and log2(2^6.5 * 0.18): the EV range AgX encodes.
inline constexpr double kAgXMinEv = -12.47393;
inline constexpr double kAgXMaxEv = 4.026069;

// AgX default-contrast sigmoid, a 6th-order polynomial fit (iolite "minimal AgX",
// mean squared error 3.67e-6), on x in [0, 1].
template <typename T>
inline T AgXContrast(const T& x) {
  const T x2 = x * x;
  const T x4 = x2 * x2;
  return Const<T>(15.5) * x4 * x2 - Const<T>(40.14) * x4 * x + Const<T>(31.96) * x4 -
         Const<T>(6.868) * x2 * x + Const<T>(0.4298) * x2 + Const<T>(0.1191) * x -
         Const<T>(0.00232);
}

}  // namespace tonemap_detail

// Tone maps a linear (Rec.709 / linear-sRGB) colour with the given exposure multiplier, as
// three.js r187 does. The result is linear and (for every operator but Neutral, whose output
// three.js does not clamp) already in [0, 1].
//
// Jet guards (docs/conventions.md section 5): Cineon's pow(x, 2.2) and AgX's pow(max(0, x),
// 2.2) have a finite derivative (0) at 0; AgX's log2 input is floored at 1e-10 (three.js's
// own guard). The ratio in Cineon has a denominator >= 0.06, ACES's >= 0.238 - 0.048 > 0 for
// every x (its discriminant is negative), Reinhard's >= 1 for non-negative input.
template <typename T>
inline Rgb<T> ToneMap(const Rgb<T>& linear, ToneMapping op, double exposure) {
  namespace d = tonemap_detail;
  using std::log2;
  using std::pow;
  const T e = Const<T>(exposure);
  const T zero = Const<T>(0.0), one = Const<T>(1.0);
  switch (op) {
    case ToneMapping::kLinear: return Saturate(linear * e);
    case ToneMapping::kReinhard:
      return d::PerChannel(linear * e, [&](const T& x) { return Saturate(x / (one + x)); });
    case ToneMapping::kCineon:
      return d::PerChannel(linear * e, [&](const T& c) {
        const T x = Max(zero, c - Const<T>(0.004));
        const T y = (x * (Const<T>(6.2) * x + Const<T>(0.5))) /
                    (x * (Const<T>(6.2) * x + Const<T>(1.7)) + Const<T>(0.06));
        return pow(y, 2.2);
      });
    case ToneMapping::kAcesFilmic: {
      const Rgb<T> x = d::Mul(d::kAcesInput, linear * Const<T>(exposure / 0.6));
      const Rgb<T> y = d::PerChannel(x, [&](const T& v) {
        const T a = v * (v + Const<T>(0.0245786)) - Const<T>(0.000090537);
        const T b = v * (Const<T>(0.983729) * v + Const<T>(0.4329510)) + Const<T>(0.238081);
        return a / b;
      });
      return Saturate(d::Mul(d::kAcesOutput, y));
    }
    case ToneMapping::kAgX: {
      Rgb<T> c = d::Mul(d::kSrgbToRec2020, linear * e);
      c = d::Mul(d::kAgXInset, c);
      c = d::PerChannel(c, [&](const T& v) {
        const T ev = log2(Max(v, Const<T>(1e-10)));  // three.js: avoid log2 of 0 or < 0
        const T t = Saturate((ev - Const<T>(d::kAgXMinEv)) / Const<T>(d::kAgXMaxEv - d::kAgXMinEv));
        return d::AgXContrast(t);
      });
      c = d::Mul(d::kAgXOutset, c);
      c = d::PerChannel(c, [&](const T& v) { return pow(Max(zero, v), 2.2); });
      return Saturate(d::Mul(d::kRec2020ToSrgb, c));  // three.js: "gamut mapping" by clamp
    }
    case ToneMapping::kNeutral: {
      // Khronos PBR Neutral (KhronosGroup/ToneMapping, PBR_Neutral spec).
      const double start_compression = 0.8 - 0.04;
      const double desaturation = 0.15;
      Rgb<T> c = linear * e;
      const T x = Min(c.r, Min(c.g, c.b));
      const T offset = x < Const<T>(0.08) ? x - Const<T>(6.25) * x * x : Const<T>(0.04);
      c = c - Rgb<T>::Splat(offset);
      const T peak = Max(c.r, Max(c.g, c.b));
      if (peak < Const<T>(start_compression)) return c;
      const double dd = 1.0 - start_compression;
      const T new_peak = one - Const<T>(dd * dd) / (peak + Const<T>(dd - start_compression));
      c = c * (new_peak / peak);
      const T g = one - one / (Const<T>(desaturation) * (peak - new_peak) + one);
      return c + (Rgb<T>::Splat(new_peak) - c) * g;
    }
  }
  return linear;  // unreachable: every enumerator returns above
}

// sRGB transfer function (IEC 61966-2-1 OETF), linear -> encoded, on [0, 1]:
//   12.92 x                     for x <= 0.0031308
//   1.055 x^(1/2.4) - 0.055     otherwise.
// The input is clamped to [0, 1] first (the engines write to a UNORM target), so pow never
// sees 0 or a negative value on its branch. three.js writes the exponent as 0.41666
// (relative difference < 4e-5 at the knee); the standard's 1/2.4 is used here.
template <typename T>
inline T SrgbEncode(const T& linear) {
  using std::pow;
  const T x = Saturate(linear);
  return x <= Const<T>(0.0031308) ? Const<T>(12.92) * x
                                  : Const<T>(1.055) * pow(x, 1.0 / 2.4) - Const<T>(0.055);
}

template <typename T>
inline Rgb<T> SrgbEncode(const Rgb<T>& linear) {
  return {SrgbEncode(linear.r), SrgbEncode(linear.g), SrgbEncode(linear.b)};
}

// The full display transform of a three.js canvas: sRGB(clamp(ToneMap(c))).
template <typename T>
inline Rgb<T> ToDisplay(const Rgb<T>& linear, ToneMapping op, double exposure) {
  return SrgbEncode(Saturate(ToneMap(linear, op, exposure)));
}

}  // namespace clothfit::render
