// Tone mapping and the sRGB transfer: fixed values derived by hand from the published
// formulas (three.js r187 tonemapping_pars_fragment, Khronos PBR Neutral, IEC 61966-2-1),
// monotonicity in exposure, and Jet derivatives against central differences.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "render/scene/tonemap.h"

namespace clothfit::render {
namespace {

struct Case {
  ToneMapping op;
  Rgb<double> in;
  double exposure;
  Rgb<double> expected;
  const char* derivation;
};

// Expected values: evaluated step by step from the formulas quoted in render/scene/tonemap.h (a
// short derivation per row; the matrices are the published ones, rows = GLSL columns). The
// numbers were produced with a separate 40-line script of those formulas, not with this code.
const Case kCases[] = {
    // Linear: saturate(e c).
    {ToneMapping::kLinear, {0.18, 0.18, 0.18}, 1.0, {0.18, 0.18, 0.18}, "0.18"},
    {ToneMapping::kLinear, {1.0, 1.0, 1.0}, 1.0, {1.0, 1.0, 1.0}, "1"},
    {ToneMapping::kLinear, {2.0, 0.5, 0.1}, 1.0, {1.0, 0.5, 0.1}, "2 clamps to 1"},
    {ToneMapping::kLinear, {0.5, 0.25, 0.05}, 2.0, {1.0, 0.5, 0.1}, "e = 2 doubles"},
    // Reinhard: x / (1 + x).
    {ToneMapping::kReinhard,
     {0.18, 0.18, 0.18},
     1.0,
     Rgb<double>::Splat(0.18 / 1.18),
     "0.18 / 1.18 = 0.1525424"},
    {ToneMapping::kReinhard, {1.0, 1.0, 1.0}, 1.0, {0.5, 0.5, 0.5}, "1 / 2"},
    {ToneMapping::kReinhard,
     {2.0, 0.5, 0.1},
     1.0,
     {2.0 / 3.0, 1.0 / 3.0, 0.1 / 1.1},
     "2/3, 0.5/1.5, 0.1/1.1"},
    {ToneMapping::kReinhard,
     {0.5, 0.25, 0.05},
     2.0,
     {0.5, 1.0 / 3.0, 0.1 / 1.1},
     "x = (1, 0.5, 0.1)"},
    // Cineon: x = e c - 0.004; (x (6.2 x + 0.5) / (x (6.2 x + 1.7) + 0.06))^2.2.
    // 0.18: x = 0.176, num = 0.176 * 1.5912 = 0.2800512, den = 0.176 * 2.7912 + 0.06 =
    // 0.5512512, ratio 0.5080282, ^2.2 = 0.2253997.
    {ToneMapping::kCineon, {0.18, 0.18, 0.18}, 1.0, Rgb<double>::Splat(0.2253997127), "0.18"},
    // 1: x = 0.996, num = 0.996 * 6.6752 = 6.6485, den = 0.996 * 7.8752 + 0.06 = 7.90370,
    // ratio 0.8411883, ^2.2 = 0.6835418.
    {ToneMapping::kCineon, {1.0, 1.0, 1.0}, 1.0, Rgb<double>::Splat(0.6835418008), "1"},
    {ToneMapping::kCineon,
     {2.0, 0.5, 0.1},
     1.0,
     {0.8181262845, 0.5006992230, 0.1156053265},
     "x = (1.996, 0.496, 0.096)"},
    {ToneMapping::kCineon,
     {0.5, 0.25, 0.05},
     2.0,
     {0.6835418008, 0.5006992230, 0.1156053265},
     "same x as above for g, b; r as the 1.0 grey"},
    // ACESFilmic: x = M_in (e c / 0.6); y = (x (x + 0.0245786) - 0.000090537) /
    // (x (0.983729 x + 0.4329510) + 0.238081); saturate(M_out y). M_in rows sum to 1 and
    // M_out rows to (1, 1, 0.99999), so a grey stays grey but for the last digit of blue.
    // 1: x = 1.666667, a = 1.666667 * 1.691245 - 0.0000905 = 2.818651, b = 1.666667 *
    // 2.072499 + 0.238081 = 3.692246, y = 0.7633974; blue 0.99999 y = 0.7633898.
    {ToneMapping::kAcesFilmic,
     {0.18, 0.18, 0.18},
     1.0,
     {0.2131054457, 0.2131054457, 0.2131033147},
     "x = 0.3"},
    {ToneMapping::kAcesFilmic,
     {1.0, 1.0, 1.0},
     1.0,
     {0.7633974416, 0.7633974416, 0.7633898076},
     "x = 1/0.6"},
    {ToneMapping::kAcesFilmic,
     {2.0, 0.5, 0.1},
     1.0,
     {0.9823039221, 0.6044062563, 0.2244292087},
     "x = M_in (3.333, 0.833, 0.167) = (2.2942, 1.0129, 0.3458)"},
    {ToneMapping::kAcesFilmic,
     {0.5, 0.25, 0.05},
     2.0,
     {0.7982760778, 0.5687912125, 0.1834558515},
     "e c / 0.6 = (1.667, 0.833, 0.167)"},
    // AgX: Rec.2020 (M_2020), inset, t = (log2(v) + 12.47393) / 16.499999, sigmoid polynomial,
    // outset, ^2.2, back to Rec.709, clamp. 0.18 grey: M_2020 rows sum to (1, 0.9999, 1),
    // inset rows to ~1, so log2(0.18) = -2.473931, t = 0.6060606, poly = 0.4967306, ^2.2 =
    // 0.2145191
    // before the outset / Rec.709 matrices move the channels by < 1e-4.
    {ToneMapping::kAgX,
     {0.18, 0.18, 0.18},
     1.0,
     {0.2145486287, 0.2145023562, 0.2144991653},
     "t = 0.6060"},
    {ToneMapping::kAgX,
     {1.0, 1.0, 1.0},
     1.0,
     {0.5902294418, 0.5901361200, 0.5901023436},
     "t = 0.7559958, poly = 0.7868557"},
    {ToneMapping::kAgX,
     {2.0, 0.5, 0.1},
     1.0,
     {0.8162769230, 0.4537943128, 0.2630606776},
     "chromatic"},
    {ToneMapping::kAgX,
     {0.5, 0.25, 0.05},
     2.0,
     {0.6141565524, 0.4190104858, 0.2085793023},
     "chromatic, e = 2"},
    // Neutral: offset = x - 6.25 x^2 if x = min(c) < 0.08 else 0.04; c -= offset; if peak <
    // 0.76 return c; new = 1 - 0.24^2 / (peak + 0.24 - 0.76); c *= new / peak;
    // g = 1 - 1 / (0.15 (peak - new) + 1); mix(c, new, g).
    {ToneMapping::kNeutral,
     {0.18, 0.18, 0.18},
     1.0,
     Rgb<double>::Splat(0.14),
     "0.18 - 0.04, below the knee"},
    {ToneMapping::kNeutral,
     {1.0, 1.0, 1.0},
     1.0,
     Rgb<double>::Splat(1.0 - 0.0576 / 0.44),
     "peak 0.96, new = 1 - 0.0576 / 0.44 = 0.8690909"},
    // (2, 0.5, 0.1): offset 0.04 -> (1.96, 0.46, 0.06); new = 1 - 0.0576 / 1.44 = 0.96;
    // c *= 0.96 / 1.96; g = 1 - 1 / 1.15 = 0.1304348; g = 0.46 * 0.96 / 1.96 = 0.2253061;
    // 0.2253061 + (0.96 - 0.2253061) g = 0.3211358.
    {ToneMapping::kNeutral, {2.0, 0.5, 0.1}, 1.0, {0.96, 0.3211357587, 0.1507719610}, "peak 1.96"},
    // e = 2: (1, 0.5, 0.1) -> (0.96, 0.46, 0.06), peak 0.96 as the white grey above.
    {ToneMapping::kNeutral,
     {0.5, 0.25, 0.05},
     2.0,
     {0.8690909091, 0.4225288762, 0.0652792499},
     "peak 0.96"},
};

TEST(ToneMap, MatchesHandDerivedValues) {
  for (const Case& c : kCases) {
    const Rgb<double> out = ToneMap(c.in, c.op, c.exposure);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(out[k], c.expected[k], 1e-9)
          << ToneMappingName(c.op) << " (" << c.derivation << ") channel " << k;
    }
  }
}

TEST(ToneMap, ParsesSceneCardNamesAndRejectsOthers) {
  for (size_t i = 0; i < kToneMappingNames.size(); ++i) {
    EXPECT_EQ(ParseToneMapping(kToneMappingNames[i]), static_cast<ToneMapping>(i));
    EXPECT_EQ(ToneMappingName(static_cast<ToneMapping>(i)), kToneMappingNames[i]);
  }
  try {
    ParseToneMapping("aces");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("\"aces\""), std::string::npos) << msg;
    EXPECT_NE(msg.find("Linear|Reinhard|Cineon|ACESFilmic|AgX|Neutral"), std::string::npos) << msg;
  }
}

constexpr std::array<ToneMapping, 6> kAll = {ToneMapping::kLinear, ToneMapping::kReinhard,
                                             ToneMapping::kCineon, ToneMapping::kAcesFilmic,
                                             ToneMapping::kAgX,    ToneMapping::kNeutral};

TEST(ToneMap, MonotonicInExposure) {
  const Rgb<double> colours[] = {{0.18, 0.18, 0.18}, {0.8, 0.3, 0.05}, {0.02, 0.4, 1.5}};
  for (ToneMapping op : kAll) {
    for (const Rgb<double>& c : colours) {
      // AgX mixes channels after clipping each channel's log encoding to [0, 1] (the inset
      // and outset matrices): where one channel clips while another still moves, the
      // outset's negative off-diagonal terms move the clipped one slightly the other way
      // (by up to 3e-5 at the toe and 1.5e-3 at the shoulder for these colours; three.js
      // does the same). So AgX is monotonic in luminance (Rec.709 Y of the encoded output)
      // for colours, and per channel for greys up to 1e-5 (the 4-digit Rec.2020 matrix's rows
      // sum to 1, 0.9999, 1, so a grey's channels clip 1e-4 apart: a 2e-6 dip near white).
      // Every other operator is monotonic per channel.
      const bool per_channel = op != ToneMapping::kAgX || (c.r == c.g && c.g == c.b);
      auto luminance = [](const Rgb<double>& x) {
        return 0.2126 * x.r + 0.7152 * x.g + 0.0722 * x.b;
      };
      Rgb<double> prev = ToDisplay(c, op, std::exp2(-10.0));
      for (double ev = -10.0 + 0.125; ev <= 10.0; ev += 0.125) {
        const Rgb<double> cur = ToDisplay(c, op, std::exp2(ev));
        if (per_channel) {
          for (int k = 0; k < 3; ++k) {
            EXPECT_GE(cur[k], prev[k] - (op == ToneMapping::kAgX ? 1e-5 : 1e-12))
                << ToneMappingName(op) << " channel " << k << " at EV " << ev;
          }
        } else {
          EXPECT_GE(luminance(cur), luminance(prev) - 1e-12)
              << ToneMappingName(op) << " luminance at EV " << ev;
        }
        prev = cur;
      }
    }
  }
}

TEST(ToneMap, JetDerivativesMatchCentralDifferences) {
  using J = ceres::Jet<double, 3>;
  // Points away from the kinks (clamps, Neutral's knee at peak 0.76 and its x = 0.08 switch).
  const Rgb<double> points[] = {{0.3, 0.6, 0.9}, {0.05, 0.2, 0.4}, {0.7, 0.5, 0.3}};
  const double exposures[] = {1.0, 0.5};
  for (ToneMapping op : kAll) {
    for (const Rgb<double>& p : points) {
      for (double e : exposures) {
        const Rgb<J> in(J(p.r, 0), J(p.g, 1), J(p.b, 2));
        const Rgb<J> out = ToDisplay(in, op, e);
        for (int j = 0; j < 3; ++j) {
          const double h = 1e-6;
          Rgb<double> lo = p, hi = p;
          lo[j] -= h;
          hi[j] += h;
          const Rgb<double> flo = ToDisplay(lo, op, e), fhi = ToDisplay(hi, op, e);
          for (int k = 0; k < 3; ++k) {
            const double fd = (fhi[k] - flo[k]) / (2.0 * h);
            EXPECT_NEAR(out[k].v[j], fd, 1e-6 * std::max(1.0, std::abs(fd)))
                << ToneMappingName(op) << " d out" << k << " / d in" << j << " at (" << p.r << ", "
                << p.g << ", " << p.b << ") e " << e;
          }
          EXPECT_NEAR(out[j].a, ToDisplay(p, op, e)[j], 1e-14);
        }
      }
    }
  }
}

TEST(ToneMap, SrgbEncodeMatchesIec61966) {
  // 12.92 x below 0.0031308, 1.055 x^(1/2.4) - 0.055 above.
  EXPECT_EQ(SrgbEncode(0.0), 0.0);
  EXPECT_NEAR(SrgbEncode(0.0031308), 12.92 * 0.0031308, 1e-15);  // 0.040449936
  EXPECT_NEAR(SrgbEncode(0.5), 0.735356983052, 1e-11);           // 1.055 * 0.7491535 - 0.055
  EXPECT_NEAR(SrgbEncode(1.0), 1.0, 1e-15);                      // 1.055 - 0.055
  // The two branches meet at the knee (to the standard's 4 digits: < 1e-7 apart).
  EXPECT_NEAR(1.055 * std::pow(0.0031308, 1.0 / 2.4) - 0.055, SrgbEncode(0.0031308), 1e-7);
  // Clamped outside [0, 1], with a zero (finite) derivative there.
  EXPECT_EQ(SrgbEncode(-0.5), 0.0);
  EXPECT_NEAR(SrgbEncode(7.0), 1.0, 1e-15);
  using J = ceres::Jet<double, 1>;
  const J below = SrgbEncode(J(-0.1, 0));
  EXPECT_EQ(below.v[0], 0.0);
  const J knee = SrgbEncode(J(0.001, 0));
  EXPECT_NEAR(knee.v[0], 12.92, 1e-12);
  const J mid = SrgbEncode(J(0.5, 0));
  EXPECT_NEAR(mid.v[0], 1.055 / 2.4 * std::pow(0.5, 1.0 / 2.4 - 1.0), 1e-12);
}

TEST(ToneMap, ToDisplayIsSrgbOfClampedToneMap) {
  const Rgb<double> c(3.0, 0.4, 0.01);
  for (ToneMapping op : kAll) {
    const Rgb<double> t = ToneMap(c, op, 1.5);
    const Rgb<double> d = ToDisplay(c, op, 1.5);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(d[k], SrgbEncode(std::clamp(t[k], 0.0, 1.0))) << ToneMappingName(op);
      EXPECT_GE(d[k], 0.0);
      EXPECT_LE(d[k], 1.0);
    }
  }
}

}  // namespace
}  // namespace clothfit::render
