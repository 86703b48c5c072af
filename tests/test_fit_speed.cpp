// Fit speed (docs/fitting.md, "Fit speed"): the preview cache built only for the pixels the fit's
// blocks sample must hold exactly what the full cache holds at those pixels, and keep every
// pixel's fabric flag, so restricting the build changes no fitted number.
#include <gtest/gtest.h>

#include <cmath>

#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "render/scene/material.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

TEST(FitSpeed, SampleMaskedCacheEqualsTheFullCacheAtTheSampledPixels) {
  Scene s = CameraScene(48, 48, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 48, 24, true, 0.f));
  Light key;
  key.type = Light::Type::kDirectional;
  key.intensity = 2.0;
  key.direction = {0.4, -0.5, -0.768};
  s.lights = {key};
  const Environment env = Environment::ProceduralSky(1.0, 0.0, 64);
  for (ModelKind m : {ModelKind::kStandard, ModelKind::kGltfSheen}) {
    PreviewOptions full_o;
    full_o.model = m;
    PreviewOptions masked_o = full_o;
    masked_o.sample_mask.assign(48 * 48, 0);
    for (int y = 1; y < 48; y += 4)
      for (int x = 2; x < 48; x += 4) masked_o.sample_mask[size_t(y * 48 + x)] = 1;
    const auto full = PreviewCache::Build(s, &env, full_o);
    const auto masked = PreviewCache::Build(s, &env, masked_o);
    // Same fabric flags everywhere; cached pixels = fabric AND mask.
    ASSERT_EQ(full->fabric_mask, masked->fabric_mask);
    size_t expected = 0;
    for (int p : full->pixels) expected += masked_o.sample_mask[size_t(p)];
    ASSERT_EQ(masked->pixels.size(), expected);
    ASSERT_GT(expected, 20u);
    ASSERT_LT(masked->pixels.size(), full->pixels.size() / 8);
    const MaterialPreset preset = DefaultPreset(m);
    std::vector<Rgb<double>> a, b;
    EvaluatePreview(*full, preset.values.data(), a);
    EvaluatePreview(*masked, preset.values.data(), b);
    size_t j = 0;
    for (size_t i = 0; i < full->pixels.size(); ++i) {
      if (!masked_o.sample_mask[size_t(full->pixels[i])]) continue;
      ASSERT_EQ(masked->pixels[j], full->pixels[i]);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(b[j][c], a[i][c]) << "pixel " << full->pixels[i];
      ++j;
    }
  }
  PreviewOptions bad;
  bad.sample_mask.assign(10, 1);
  EXPECT_THROW(PreviewCache::Build(s, &env, bad), std::invalid_argument);
}

}  // namespace
}  // namespace clothfit::render
