// The preview's exact (Monte Carlo) image-based light, PreviewOptions::exact_ibl_samples and
// exact_irradiance_samples (render/preview/preview.h; docs/fitting.md "The sphere's error
// decomposed"): white-furnace checks against closed forms and against the woven model's own
// split-sum albedo table, determinism, and the fit's sampled cache giving the same pixels as a
// full frame.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <vector>

#include "brdf/lut.h"
#include "brdf/woven.h"
#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "render/scene/image_io.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

// Lambert in a white furnace: sum_j (n.l_j / pi) L / pdf_mix(l_j) must integrate to 1, so the
// exact IBL returns the base colour at every pixel (a wrong mixture pdf is off by a factor).
TEST(S7ExactIbl, LambertWhiteFurnaceReturnsTheBaseColour) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.exact_ibl_samples = 1024;
  std::unique_ptr<PreviewCache> cache;
  const auto out = PreviewFrame(
      s, env, o, WovenFlat({0.6, 0.5, 0.4}, {0, 0, 0}, 0.6, 0.7, 0.5, 0.05, 2.0), &cache);
  ASSERT_GT(out.size(), 500u);
  EXPECT_FALSE(cache->features.ibl);  // the split-sum path is off
  EXPECT_TRUE(cache->features.direct);
  EXPECT_TRUE(cache->radiance.empty());
  double worst = 0.0;
  for (const auto& px : out) {
    worst = std::max({worst, std::abs(px.r / 0.6 - 1.0), std::abs(px.g / 0.5 - 1.0),
                      std::abs(px.b / 0.4 - 1.0)});
  }
  EXPECT_LT(worst, 0.01) << "max relative error of the furnace over the sphere";
}

// The exact irradiance (diffuse only through Monte Carlo) in the furnace: E_d / pi = 1.
TEST(S7ExactIbl, ExactIrradianceWhiteFurnace) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::Constant({0.7, 0.7, 0.7});
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.exact_irradiance_samples = 512;
  auto cache = PreviewCache::Build(s, &env, o);
  ASSERT_GT(cache->pixels.size(), 500u);
  EXPECT_TRUE(cache->features.ibl);
  for (size_t i = 0; i < cache->pixels.size(); ++i)
    ASSERT_NEAR(cache->irradiance[i * 3], 0.7, 0.007) << "pixel " << i;
}

// Isotropic yarn lobes (anisotropy 0, so r_e = r and the split sum's only approximation in a
// constant environment is the albedo table): the exact integral of the woven direct BRDF must
// equal the split-sum weight f0 PT_0 + (1 - f0) PT_beta from lut::DefaultWovenPhase() (our own
// integrator) to the table's accuracy. Pixels with n.v > 0.2 (the table's coarse grazing rows
// aside).
TEST(S7ExactIbl, IsotropicYarnFurnaceMatchesThePhaseTable) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  const auto x = WovenFlat({0, 0, 0}, {1, 1, 1}, 0.5, 0.0, 0.5, 0.3, 2.0);
  PreviewOptions split;
  split.model = ModelKind::kWoven;
  PreviewOptions exact = split;
  exact.exact_ibl_samples = 2048;
  std::unique_ptr<PreviewCache> cs, ce;
  const auto a = PreviewFrame(s, env, split, x, &cs);
  const auto b = PreviewFrame(s, env, exact, x, &ce);
  ASSERT_EQ(cs->pixels, ce->pixels);
  int n = 0;
  double sum_rel = 0.0, worst = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (cs->NoV[i] < 0.2f) continue;
    const double rel = b[i].g / a[i].g - 1.0;
    sum_rel += rel;
    worst = std::max(worst, std::abs(rel));
    ++n;
  }
  ASSERT_GT(n, 300);
  EXPECT_LT(std::abs(sum_rel / n), 0.01) << "mean relative difference exact / split - 1";
  EXPECT_LT(worst, 0.04) << "max relative difference";
}

// Anisotropic lobes (the fitted twill's shape, anisotropy 0.7): the split sum's isotropic r_e
// is an approximation, so exact and split differ; this checks the test above could fail.
TEST(S7ExactIbl, AnisotropicYarnFurnaceDiffersFromTheSplitSum) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  const auto x = WovenFlat({0, 0, 0}, {1, 1, 1}, 0.65, 0.7, 0.88, 0.07, 0.95);
  PreviewOptions split;
  split.model = ModelKind::kWoven;
  PreviewOptions exact = split;
  exact.exact_ibl_samples = 1024;
  const auto a = PreviewFrame(s, env, split, x);
  const auto b = PreviewFrame(s, env, exact, x);
  double worst = 0.0;
  for (size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::abs(b[i].g / a[i].g - 1.0));
  EXPECT_GT(worst, 0.05);
}

// Same seed: bit-identical; another seed: different directions, the same integral to MC noise.
// And the fit's sampled cache (sample_mask) gives the same pixels as the full frame: the
// directions are seeded by the pixel index, not by the cache position.
TEST(S7ExactIbl, DeterministicPerPixelAndSampleMaskInvariant) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  const auto x = WovenFlat({0.4, 0.3, 0.2}, {0.3, 0.3, 0.3}, 0.6, 0.7, 0.3, 0.05, 1.5);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.exact_ibl_samples = 256;
  std::unique_ptr<PreviewCache> c1, c2, c3, cm;
  const auto a = PreviewFrame(s, env, o, x, &c1);
  const auto b = PreviewFrame(s, env, o, x, &c2);
  PreviewOptions o2 = o;
  o2.exact_ibl_seed = 7;
  const auto c = PreviewFrame(s, env, o2, x, &c3);
  int differ = 0;
  double mean_a = 0.0, mean_c = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].r, b[i].r);
    ASSERT_EQ(a[i].b, b[i].b);
    differ += a[i].r != c[i].r;
    mean_a += a[i].g;
    mean_c += c[i].g;
  }
  EXPECT_GT(differ, int(a.size()) / 2);
  EXPECT_NEAR(mean_c / mean_a, 1.0, 0.01);

  PreviewOptions om = o;
  om.sample_mask.assign(size_t(s.card.width) * size_t(s.card.height), 0);
  for (size_t p = 0; p < om.sample_mask.size(); p += 3) om.sample_mask[p] = 1;
  const auto m = PreviewFrame(s, env, om, x, &cm);
  ASSERT_GT(cm->pixels.size(), 100u);
  std::map<int, size_t> full_index;
  for (size_t i = 0; i < c1->pixels.size(); ++i) full_index[c1->pixels[i]] = i;
  for (size_t i = 0; i < cm->pixels.size(); ++i) {
    const size_t j = full_index.at(cm->pixels[i]);
    ASSERT_EQ(m[i].r, a[j].r) << "pixel " << cm->pixels[i];
    ASSERT_EQ(m[i].g, a[j].g);
  }
}

TEST(S7ExactIbl, RejectsOutOfRangeSampleCounts) {
  const Scene s = UnlitSphere();
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.exact_ibl_samples = -1;
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
  o.exact_ibl_samples = 0;
  o.exact_irradiance_samples = 70000;
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
}

// The exact IBL's cache holds N samples per sampled pixel; a frame whose total exceeds the
// budget (2^28 samples) is refused before anything is allocated (and before light_begin's int
// offsets could wrap). 80 x 80 pixels x 65536 samples = 2^28.6.
TEST(S7ExactIbl, RefusesACacheOverTheSampleBudget) {
  Scene s = CameraScene(80, 80, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 16, 8, true, 0.f));
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.exact_ibl_samples = 1 << 16;
  try {
    PreviewCache::Build(s, &env, o);
    ADD_FAILURE() << "expected invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("exact_ibl_samples 65536 x 6400 sampled pixels exceeds"),
              std::string::npos)
        << e.what();
  }
}

// A non-uniform sky whose irradiance SH9 represents exactly: radiance 1 + 0.9 d_y (bands 0
// and 1 only; 19:1 between zenith and nadir, so the environment sampler's pdf varies as much).
// The exact irradiance and the exact IBL of a Lambert surface must then agree with the split
// sum's SH9 irradiance; a Sample/Pdf mismatch (which the constant furnaces above cannot see,
// their pdf being uniform in luminance) would bias them by the luminance ratio.
TEST(S7ExactIbl, LinearSkyMatchesSh9Irradiance) {
  const Environment env = EnvironmentFrom(256, 128, [](const Vec3<double>& d) {
    const double v = 1.0 + 0.9 * d.y;
    return Rgb<double>{v, v, v};
  });
  const Scene s = UnlitSphere();
  const auto x = WovenFlat({0.5, 0.5, 0.5}, {0, 0, 0}, 0.6, 0.0, 0.5, 0.05, 2.0);
  PreviewOptions split;
  split.model = ModelKind::kWoven;
  PreviewOptions irr = split, exact = split;
  irr.exact_irradiance_samples = 1024;
  exact.exact_ibl_samples = 1024;
  auto cs = PreviewCache::Build(s, &env, split);
  auto ci = PreviewCache::Build(s, &env, irr);
  ASSERT_EQ(cs->pixels, ci->pixels);
  ASSERT_GT(cs->pixels.size(), 500u);
  double lo = 1e9, hi = 0.0, worst = 0.0;
  for (size_t k = 0; k < cs->irradiance.size(); ++k) {
    lo = std::min(lo, double(cs->irradiance[k]));
    hi = std::max(hi, double(cs->irradiance[k]));
    worst = std::max(worst, std::abs(double(ci->irradiance[k]) / double(cs->irradiance[k]) - 1.0));
  }
  EXPECT_GT(hi / lo, 2.0) << "the sky must light the sphere unevenly";
  EXPECT_LT(worst, 0.02) << "exact irradiance vs SH9, max relative difference";
  RecordProperty("irradiance_max_rel_diff", std::to_string(worst));
  const auto a = PreviewFrame(s, env, split, x);
  const auto b = PreviewFrame(s, env, exact, x);
  ASSERT_EQ(a.size(), b.size());
  double worst_frame = 0.0;
  for (size_t k = 0; k < a.size(); ++k)
    if (a[k].g > 1e-3) worst_frame = std::max(worst_frame, std::abs(b[k].g / a[k].g - 1.0));
  EXPECT_LT(worst_frame, 0.03) << "exact IBL vs split sum for a Lambert surface";
}

}  // namespace
}  // namespace clothfit::render
