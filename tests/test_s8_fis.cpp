// Filtered importance sampling (FIS) of the three.js PMREM for the woven yarn lobes and the
// diffuse irradiance (render/preview/threejs_ibl.h FisGgxRadiance / FisIrradianceOverPi; the
// preview's woven "ibl": "fis"; docs/fitting.md "Filtered importance sampling for woven's IBL
// (session 8)"): constant environments, a compact bright source judged by the exact-IBL Monte
// Carlo (PreviewOptions::exact_ibl_samples, tests/test_s7_ibl_exact.cpp's machinery), the
// split-sum woven preview unchanged, and the preset keys.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "brdf/woven.h"
#include "render/preview/preview.h"
#include "render/preview/threejs_ibl.h"
#include "render/scene/environment.h"
#include "render/scene/image_io.h"
#include "render/scene/material.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

using V3 = Vec3<double>;

PreviewOptions WovenThreejs(woven::IblMode mode, int taps = 16, int diffuse_taps = 16) {
  PreviewOptions o = WovenThreejsOptions(mode);
  o.woven.fis_taps = taps;
  o.woven.fis_diffuse_taps = diffuse_taps;
  return o;
}

// A compact bright source (a disc of 6 degrees radius, radiance 40) above and in front of the
// sphere on a dim sky (0.05): the case where one prefiltered read at the dominant direction
// misplaces the light a rough lobe gathers.
Environment CompactSource() {
  return DiscEnvironment(512, 256, Normalize(V3(0.35, 0.55, 0.75)), 6.0, {40.0, 36.0, 30.0},
                         {0.05, 0.05, 0.06});
}

// In a constant environment every PMREM texel is the constant (fp16-exact values here), so
// FIS's normalised tap sum is the constant for any tap count, roughness and direction, and so
// is E_fis / pi.
TEST(S8Fis, ConstantEnvironmentGivesTheConstant) {
  const Environment env = Environment::Constant({0.5, 0.25, 0.125});
  const auto pmrem = SharedThreejsPmrem(env);
  const V3 ns[] = {Normalize(V3(0.2, 0.9, 0.3)), V3(0, 0, 1), V3(0, 0, -1),
                   Normalize(V3(-0.7, -0.1, 0.7))};
  for (int taps : {1, 3, 16, 64}) {
    const FisPattern p(taps);
    for (const V3& n : ns) {
      for (double r : {0.0, 0.3, 0.65, 1.0}) {
        const V3 v = Normalize(n * 0.8 + V3(0.3, -0.2, 0.1) * 0.6);
        int used = 0;
        const Rgb<double> L = FisGgxRadiance(*pmrem, p, n, v, r, &used);
        ASSERT_GT(used, 0);
        EXPECT_NEAR(L.r, 0.5, 1e-6) << taps << " taps, r " << r;
        EXPECT_NEAR(L.g, 0.25, 1e-6);
        EXPECT_NEAR(L.b, 0.125, 1e-6);
      }
      const Rgb<double> E = FisIrradianceOverPi(*pmrem, p, n);
      EXPECT_NEAR(E.r, 0.5, 1e-6) << taps << " taps";
      EXPECT_NEAR(E.b, 0.125, 1e-6);
    }
  }
  // The preview's tables: every node of the FIS yarn table and the irradiance.
  const Scene s = UnlitSphere();
  auto cache = PreviewCache::Build(s, &env, WovenThreejs(woven::IblMode::kFis, 8, 4));
  ASSERT_GT(cache->pixels.size(), 500u);
  ASSERT_EQ(cache->yarn_radiance.size(), cache->radiance.size());
  for (size_t k = 0; k < cache->yarn_radiance.size(); k += 3) {
    ASSERT_NEAR(cache->yarn_radiance[k], 0.5, 1e-6) << k;
    ASSERT_NEAR(cache->yarn_radiance[k + 2], 0.125, 1e-6) << k;
  }
  for (size_t i = 0; i < cache->pixels.size(); ++i)
    ASSERT_NEAR(cache->irradiance[i * 3 + 1], 0.25, 1e-6) << i;
}

// FIS's building blocks: Duff et al.'s frame is orthonormal with t1 x t2 = n (also at n.z = -1),
// and the tap pattern is the spec's (u1 = (i + 1/2) / N, phi = 2 pi radical-inverse(i)).
TEST(S8Fis, FrameAndPattern) {
  for (const V3& n : {V3(0, 0, 1), V3(0, 0, -1), Normalize(V3(1, 2, 3)), Normalize(V3(-1, 0.2, -0.01))}) {
    V3 t1, t2;
    FisFrame(n, &t1, &t2);
    EXPECT_NEAR(Dot(t1, t1), 1.0, 1e-12);
    EXPECT_NEAR(Dot(t2, t2), 1.0, 1e-12);
    EXPECT_NEAR(Dot(t1, t2), 0.0, 1e-12);
    EXPECT_NEAR(Dot(t1, n), 0.0, 1e-12);
    const V3 c = Cross(t1, t2);
    EXPECT_NEAR(Dot(c, n), 1.0, 1e-12);
  }
  const FisPattern p(4);
  EXPECT_DOUBLE_EQ(p.u1[1], 0.375);
  EXPECT_NEAR(p.cos_phi[1], -1.0, 1e-15);  // radical inverse of 1 = 1/2
  EXPECT_NEAR(p.sin_phi[2], 1.0, 1e-15);   // of 2 = 1/4
  EXPECT_THROW(FisPattern(0), std::invalid_argument);
}

// The lobe integral FIS approximates, by brute force on the raw environment: the GGX-sampled,
// n.l-weighted mean of L over 2^16 stratified taps (the spec's distribution, no prefiltering),
// under a compact bright source (a 6-degree disc, 800:1), at view directions from normal to
// 63 degrees off the normal. FIS is a consistent estimator of it: its error falls with the tap
// count and at 4096 taps is well under the split sum's single read at the dominant direction.
// NOT asserted, because it is false (measured; docs/fitting.md, session 8): that 16 taps beat
// the split sum here. On a lone compact source the 16 taps alias it (rms error 0.02-0.03
// against the split sum's 0.005-0.016); the recorded properties keep the figures.
TEST(S8Fis, CompactSourceLobeRadianceConvergesToBruteForce) {
  const Environment env = CompactSource();
  const auto pmrem = SharedThreejsPmrem(env);
  const FisPattern p16(16), p256(256), p4k(4096), brute(1 << 16);
  double e16 = 0.0, e256 = 0.0, e4k = 0.0, esplit = 0.0;
  int n_cases = 0;
  for (int a = 0; a < 24; ++a) {
    const double th = 0.1 + 0.05 * a, ph = 0.9 * a;
    const V3 n = Normalize(V3(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph) + 0.8));
    V3 t1, t2;
    FisFrame(n, &t1, &t2);
    for (double tilt : {0.0, 0.6, 1.1}) {
      const V3 v = Normalize(n * std::cos(tilt) + t1 * std::sin(tilt));
      for (double r : {0.4, 0.55, 0.7}) {
        const double a2 = std::pow(r, 4.0);
        Rgb<double> sum(0, 0, 0);
        double w = 0.0;
        for (int i = 0; i < brute.n; ++i) {
          const double u1 = brute.u1[size_t(i)];
          const double ch = std::sqrt((1 - u1) / (1 + (a2 - 1) * u1)), sh = std::sqrt(1 - ch * ch);
          const V3 h = t1 * (sh * brute.cos_phi[size_t(i)]) + t2 * (sh * brute.sin_phi[size_t(i)]) + n * ch;
          const double VoH = Dot(v, h);
          const V3 l = h * (2 * VoH) - v;
          const double NoL = Dot(n, l);
          if (NoL <= 0 || VoH <= 0) continue;
          sum += env.Eval(l) * NoL;
          w += NoL;
        }
        const double exact = sum.g / w;
        int used = 0;
        auto sq = [&](double x) { return (x - exact) * (x - exact); };
        e16 += sq(FisGgxRadiance(*pmrem, p16, n, v, r, &used).g);
        e256 += sq(FisGgxRadiance(*pmrem, p256, n, v, r, &used).g);
        e4k += sq(FisGgxRadiance(*pmrem, p4k, n, v, r, &used).g);
        const V3 R = n * (2 * Dot(n, v)) - v;
        const double t = std::pow(r, 4.0);
        esplit += sq(pmrem->Sample(Normalize(R * (1 - t) + n * t), pmrem->MipForRoughness(r)).g);
        ++n_cases;
      }
    }
  }
  ASSERT_EQ(n_cases, 24 * 9);
  const double r16 = std::sqrt(e16 / n_cases), r256 = std::sqrt(e256 / n_cases),
               r4k = std::sqrt(e4k / n_cases), rsplit = std::sqrt(esplit / n_cases);
  RecordProperty("rms_fis16", std::to_string(r16));
  RecordProperty("rms_fis256", std::to_string(r256));
  RecordProperty("rms_fis4096", std::to_string(r4k));
  RecordProperty("rms_split", std::to_string(rsplit));
  EXPECT_LT(r256, 0.6 * r16) << r256 << " vs " << r16;
  EXPECT_LT(r4k, 0.6 * r256) << r4k << " vs " << r256;
  EXPECT_LT(r4k, 0.5 * rsplit) << "FIS 4096 taps " << r4k << " vs split " << rsplit;
}

// The FIS table feeds the yarn lobes only (the spec: "only the radiance the yarn lobes
// multiply changes"): under a non-uniform environment a woven frame with FIS differs from the
// split-sum frame when the yarn lobes are on, and equals it bit for bit when they are off
// (specular_color 0), diffuse and sheen (which keeps the split sum) on.
TEST(S8Fis, FisTableFeedsTheYarnLobesOnly) {
  const Environment env = CompactSource();
  const Scene s = UnlitSphere(32);
  auto yarn = WovenFlat({0.3, 0.2, 0.1}, {0.4, 0.4, 0.4}, 0.65, 0.7, 0.5, 0.07, 0.95);
  auto no_yarn = WovenFlat({0.3, 0.2, 0.1}, {0, 0, 0}, 0.65, 0.7, 0.5, 0.07, 0.95);
  no_yarn[12] = no_yarn[13] = no_yarn[14] = 0.3;  // sheen on
  for (const auto* x : {&yarn, &no_yarn}) {
    const auto a = PreviewFrame(s, env, WovenThreejs(woven::IblMode::kSplit), *x);
    const auto b = PreviewFrame(s, env, WovenThreejs(woven::IblMode::kFis, 16, 0), *x);
    ASSERT_EQ(a.size(), b.size());
    int differ = 0;
    for (size_t i = 0; i < a.size(); ++i)
      differ += a[i].r != b[i].r || a[i].g != b[i].g || a[i].b != b[i].b;
    if (x == &yarn)
      EXPECT_GT(differ, int(a.size()) / 2);
    else
      EXPECT_EQ(differ, 0);
  }
}

// The split-sum woven preview (no "ibl", or "ibl": "split") is the one before FIS existed, bit
// for bit, on both engines: the frame's sum and three pixels, recorded from main 14238e2 (the
// commit this branch started from) with this very test body. FIS on the Filament engine is not
// applied (UsesWovenFis): the same frame again.
TEST(S8Fis, SplitSumWovenPreviewUnchanged) {
  Scene s = UnlitSphere(32);
  Light key;
  key.type = Light::Type::kDirectional;
  key.intensity = 2.0;
  key.direction = {0.4, -0.5, -0.768};
  s.lights = {key};
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  const auto x = WovenFlat({0.2, 0.3, 0.1}, {0.3, 0.35, 0.25}, 0.65, 0.7, 0.8, 0.07, 0.95);
  struct Case {
    IblEngine engine;
    double sum, p0, p1, p2;
  };
  // Recorded values (%.17g): a program linking main 14238e2's libclothfit_preview.a, this
  // scene, environment, parameters and sum (556 fabric pixels).
  const Case cases[] = {
      {IblEngine::kFilament, 953.93695761400897, 0.50289633286877544, 0.188032088781451,
       0.063772856100512601},
      {IblEngine::kThreejs, 663.61201537545048, 0.13851352271229672, 0.23842369186931495,
       0.21726769318032713},
  };
  for (const Case& c : cases) {
    for (woven::IblMode mode : {woven::IblMode::kSplit, woven::IblMode::kFis}) {
      if (mode == woven::IblMode::kFis && c.engine == IblEngine::kThreejs) continue;
      PreviewOptions o;
      o.model = ModelKind::kWoven;
      o.ibl_engine = c.engine;
      o.woven.ibl = mode;
      const auto f = PreviewFrame(s, env, o, x);
      ASSERT_GT(f.size(), 300u);
      double sum = 0.0;
      for (const auto& px : f) sum += px.r + 2.0 * px.g + 3.0 * px.b;
      // Same-toolchain golden: bit-identical with this repository's build (Release, no
      // -ffast-math); a relative 1e-12 leaves room for another compiler's FMA contraction
      // only, far below any change of the shading (which moves these by > 1e-6).
      auto near = [](double got, double want) { return std::abs(got - want) <= 1e-12 * std::abs(want); };
      EXPECT_TRUE(near(sum, c.sum)) << sum << " vs " << c.sum;
      EXPECT_TRUE(near(f[0].g, c.p0)) << f[0].g << " vs " << c.p0;
      EXPECT_TRUE(near(f[f.size() / 2].r, c.p1)) << f[f.size() / 2].r << " vs " << c.p1;
      EXPECT_TRUE(near(f[f.size() - 1].b, c.p2)) << f[f.size() - 1].b << " vs " << c.p2;
    }
  }
}

nlohmann::json WovenPreset(const nlohmann::json& woven) {
  nlohmann::json j = {{"schema", "clothfit.preset"}, {"version", 1}, {"model", "woven"},
                      {"parameters", nlohmann::json::object()}};
  if (!woven.is_null()) j["woven"] = woven;
  return j;
}

void ExpectError(const nlohmann::json& j, const std::string& field, const std::string& words) {
  try {
    ParsePreset(j, "p.json");
    ADD_FAILURE() << "expected an error naming " << field << " for " << j.dump();
  } catch (const MaterialError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("p.json"), std::string::npos) << m;
    EXPECT_NE(m.find(field), std::string::npos) << m;
    EXPECT_NE(m.find(words), std::string::npos) << m;
  }
}

TEST(S8Fis, PresetKeysRoundTripAndDefaults) {
  const MaterialPreset d = ParsePreset(WovenPreset(nullptr), "p.json");
  EXPECT_EQ(d.woven.ibl, woven::IblMode::kSplit);  // missing: split (old presets unchanged)
  const nlohmann::json dj = PresetToJson(d);
  EXPECT_EQ(dj["woven"]["ibl"], "split");
  EXPECT_FALSE(dj["woven"].contains("fis_taps"));  // tap counts only with fis

  const MaterialPreset p = ParsePreset(
      WovenPreset({{"ibl", "fis"}, {"fis_taps", 8}, {"fis_diffuse_taps", 0}}), "p.json");
  EXPECT_EQ(p.woven.ibl, woven::IblMode::kFis);
  EXPECT_EQ(p.woven.fis_taps, 8);
  EXPECT_EQ(p.woven.fis_diffuse_taps, 0);
  const nlohmann::json j = PresetToJson(p);
  EXPECT_EQ(j["woven"]["ibl"], "fis");
  EXPECT_EQ(j["woven"]["fis_taps"], 8);
  EXPECT_EQ(j["woven"]["fis_diffuse_taps"], 0);
  const MaterialPreset q = ParsePreset(j, "q.json");
  EXPECT_EQ(q.woven.ibl, p.woven.ibl);
  EXPECT_EQ(q.woven.fis_taps, 8);
  EXPECT_EQ(q.woven.fis_diffuse_taps, 0);
  const MaterialPreset f = ParsePreset(WovenPreset({{"ibl", "fis"}}), "p.json");
  EXPECT_EQ(f.woven.fis_taps, woven::kDefaultFisTaps);
  EXPECT_EQ(f.woven.fis_diffuse_taps, woven::kDefaultFisDiffuseTaps);
}

TEST(S8Fis, BadPresetValuesNameTheField) {
  ExpectError(WovenPreset({{"ibl", "exact"}}), "woven.ibl", "\"split\", \"fis\" or \"bent\"");
  ExpectError(WovenPreset({{"ibl", 1}}), "woven.ibl", "\"split\", \"fis\" or \"bent\"");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_taps", 0}}), "woven.fis_taps", "[1, 64]");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_taps", 65}}), "woven.fis_taps", "[1, 64]");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_taps", 16.5}}), "woven.fis_taps", "integer");
  // An unsigned value above LLONG_MAX is reported as written, not wrapped to a negative number.
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_taps", 18446744073709551615ull}}), "woven.fis_taps",
              "got 18446744073709551615");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_taps", "16"}}), "woven.fis_taps", "integer");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_diffuse_taps", -1}}), "woven.fis_diffuse_taps",
              "[0, 64]");
  ExpectError(WovenPreset({{"ibl", "fis"}, {"fis_diffuse_taps", 100}}), "woven.fis_diffuse_taps",
              "[0, 64]");
  ExpectError(WovenPreset({{"fis_taps", 16}}), "woven.fis_taps", "only allowed with");
  ExpectError(WovenPreset({{"ibl", "split"}, {"fis_diffuse_taps", 16}}), "woven.fis_diffuse_taps",
              "only allowed with");
  ExpectError(WovenPreset({{"fis", true}}), "woven.fis", "unknown key");
}

// The preview refuses tap counts out of range (options set in code, not through a preset).
TEST(S8Fis, PreviewRejectsBadTapCounts) {
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  const Scene s = UnlitSphere(16);
  EXPECT_THROW(PreviewCache::Build(s, &env, WovenThreejs(woven::IblMode::kFis, 0, 16)),
               std::invalid_argument);
  EXPECT_THROW(PreviewCache::Build(s, &env, WovenThreejs(woven::IblMode::kFis, 16, 65)),
               std::invalid_argument);
}

}  // namespace
}  // namespace clothfit::render
