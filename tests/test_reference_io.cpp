// References from other renderers (docs/references.md): alpha layouts, coverage weights, the
// image-based noise estimate, weave periods, and the convergence / at-bound assessment.
// Cycles-layout files are made synthetically: RGBA, premultiplied, transparent film, no
// `fabric` or `stderr.*` channels, coverage gaps between "yarns".
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "fit/convergence.h"
#include "fit/image_fit.h"
#include "fit/reference.h"
#include "render/scene/image_io.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;

// A W x H Cycles-layout EXR: radiance `rad` (per channel) with relative Gaussian noise
// `rel_noise`, coverage 0 outside a disc, and inside it yarn gaps (coverage 0.2) on every
// `gap_period`-th row and column (0: no gaps). Premultiplied unless `straight`.
std::string CyclesLayout(const std::string& name, int W, int H, const float rad[3],
                         double rel_noise, int gap_period, bool straight = false) {
  io::Image img;
  img.width = W;
  img.height = H;
  img.channel_names = {"R", "G", "B", "A"};
  img.pixels.assign(size_t(W) * size_t(H) * 4, 0.f);
  std::mt19937 rng(3);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const double dx = x + 0.5 - W / 2.0, dy = y + 0.5 - H / 2.0;
      float a = dx * dx + dy * dy < 0.16 * W * W ? 1.f : 0.f;
      if (a > 0.f && gap_period > 0 && (x % gap_period == 0 || y % gap_period == 0)) a = 0.2f;
      float* p = &img.pixels[(size_t(y) * size_t(W) + size_t(x)) * 4];
      for (int c = 0; c < 3; ++c) {
        const float v = float(double(rad[c]) * (1.0 + rel_noise * n01(rng)));
        p[c] = a > 0.f ? (straight ? v : v * a) : 0.f;
      }
      p[3] = a;
    }
  const std::string path = (fs::temp_directory_path() / name).string();
  io::WriteExr(path, img);
  return path;
}

TEST(ReferenceIo, PremultipliedCyclesLayoutIsUnpremultipliedWithCoverageWeights) {
  const float rad[3] = {0.4f, 0.3f, 0.2f};
  const std::string path = CyclesLayout("clothfit_cycles_premult.exr", 64, 64, rad, 0.0, 4);
  const Reference r = ReadReference(path, ReferenceOptions{});
  EXPECT_NE(r.layout.find("premultiplied"), std::string::npos) << r.layout;
  size_t gaps = 0, covered = 0;
  for (size_t p = 0; p < r.weight.size(); ++p) {
    if (r.weight[p] <= 0.f) continue;
    ++covered;
    if (r.weight[p] < 0.5f) ++gaps;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(r.rgb[p * 3 + size_t(c)], rad[c], 1e-6);
  }
  EXPECT_GT(gaps, covered / 5);  // the gap rows and columns are there, with weight 0.2
  // Straight: the same numbers without the division.
  const std::string spath = CyclesLayout("clothfit_cycles_straight.exr", 64, 64, rad, 0.0, 4, true);
  ReferenceOptions so;
  so.alpha = AlphaMode::kStraight;
  const Reference s = ReadReference(spath, so);
  for (size_t p = 0; p < s.weight.size(); ++p)
    if (s.weight[p] > 0.f) {
      EXPECT_NEAR(s.rgb[p * 3], rad[0], 1e-6);
    }
  // "none": every pixel weighs 1.
  ReferenceOptions no;
  no.coverage_channel = "none";
  const Reference n = ReadReference(path, no);
  for (float w : n.weight) EXPECT_EQ(w, 1.f);
  no.coverage_channel = "mask";
  EXPECT_THROW(ReadReference(path, no), FitError);
}

TEST(ReferenceIo, ImageNoiseEstimateRecoversKnownRelativeNoise) {
  const float rad[3] = {0.5f, 0.25f, 1.0f};
  for (double noise : {0.01, 0.05}) {
    const std::string path = CyclesLayout("clothfit_cycles_noise.exr", 128, 128, rad, noise, 0);
    const Reference r = ReadReference(path, ReferenceOptions{});
    EXPECT_NE(r.noise.find("Immerkaer"), std::string::npos);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(EstimateRelativeNoise(r, c), noise, 0.1 * noise) << "channel " << c;
    }
    // The per-pixel standard error follows: sigma = k x radiance.
    const size_t centre = (64 * 128 + 64) * 3;
    const double v = double(r.rgb[centre]);
    EXPECT_NEAR(double(r.std_error[centre]), noise * v, 0.15 * noise * v);
    ReferenceOptions none;
    none.noise = NoiseMode::kNone;
    EXPECT_EQ(ReadReference(path, none).std_error[centre], 0.f);
  }
}

TEST(ReferenceIo, WeavePeriodInMetresOrUvUnits) {
  EXPECT_DOUBLE_EQ(ParseWeavePeriod("0.002").value, 0.002);
  EXPECT_DOUBLE_EQ(ParseWeavePeriod("2mm").value, 0.002);
  EXPECT_DOUBLE_EQ(ParseWeavePeriod("0.2cm").value, 0.002);
  EXPECT_FALSE(ParseWeavePeriod("2mm").uv);
  EXPECT_TRUE(ParseWeavePeriod("0.05uv").uv);
  for (const char* bad : {"", "mm", "-1mm", "0", "2 mm", "2inch", "nan"})
    EXPECT_THROW(ParseWeavePeriod(bad), std::invalid_argument) << bad;
  render::Scene s;
  s.card.uv_metres_per_unit = 0.5;
  EXPECT_DOUBLE_EQ(WeavePeriodUv(ParseWeavePeriod("2mm"), s, "card"), 0.004);
  EXPECT_DOUBLE_EQ(WeavePeriodUv(ParseWeavePeriod("0.05uv"), s, "card"), 0.05);
  s.card.uv_metres_per_unit = 0.0;
  EXPECT_THROW(WeavePeriodUv(ParseWeavePeriod("2mm"), s, "card"), std::invalid_argument);
}

TEST(ReferenceIo, ParametersAtBoundsAreReportedAndOnlyDegenerateOnesFlagged) {
  render::MaterialPreset p = render::DefaultPreset(render::ModelKind::kPhysicalSheen);
  // base_color, roughness, metalness, sheen_color, sheen_roughness
  p.values = {0.5, 0.4, 0.0, 0.7, 0.0, 1.0, 0.0, 0.3, 0.5};
  const auto b = ParametersAtBounds(p, {"metalness"});
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b[0].name, "base_color[2]");  // a colour at 0: reported, not flagged
  EXPECT_FALSE(b[0].flagged);
  EXPECT_EQ(b[1].name, "sheen_color[0]");  // saturated at 1: flagged
  EXPECT_TRUE(b[1].flagged);
  EXPECT_TRUE(b[1].upper);
  EXPECT_EQ(b[2].name, "sheen_color[1]");
  EXPECT_TRUE(Converged("CONVERGENCE"));
  EXPECT_FALSE(Converged("NO_CONVERGENCE"));
}

}  // namespace
}  // namespace clothfit::fit
