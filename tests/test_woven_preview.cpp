// The woven model in the preview: the cached tangent frame is the reference renderer's
// (t Gram-Schmidt'd against the viewer-side n, b = tangent_sign n x t), the direct light equals
// brdf/woven.h at every pixel, and the Jet frame with 10 free parameters is finite.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>

#include "brdf/lut.h"
#include "brdf/woven.h"
#include "render/preview/preview.h"
#include "render/scene/embree_scene.h"
#include "render/scene/lights.h"
#include "tests/preview_fixtures.h"

namespace clothfit::render {
namespace {

std::vector<double> WovenParams() {
  return {0.47, 0.41, 0.31, 0.54, 0.51, 0.46, 0.6, 0.75, -9.0, 0.54, 0.07, 1.6, 0.1, 0.05, 0.02, 0.6};
}

TEST(WovenPreview, DirectLightUsesTheReferenceTangentFrame) {
  const Scene s = SphereWithLight(32);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto cache = PreviewCache::Build(s, nullptr, o);
  ASSERT_EQ(cache->tangent_v.size(), cache->pixels.size() * 2);
  ASSERT_EQ(cache->light_tangent.size(), cache->light_samples.size() * 4);
  const auto x = WovenParams();
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  ASSERT_GT(out.size(), 300u);
  const woven::Params<double> p = woven::FromFlat(x.data());
  ForEachPixelGeometry(s, *cache, [&](size_t i, const PixelGeometry& g) {
    const Cosines<double>& c = g.cosines;
    const TangentCosines<double>& tc = g.tangent_cosines;
    const LightSample& ls = g.light;
    EXPECT_NEAR(cache->tangent_v[i * 2], tc.ToV, 1e-6);
    EXPECT_NEAR(cache->tangent_v[i * 2 + 1], tc.BoV, 1e-6);
    Rgb<double> expected(0, 0, 0);
    if (c.NoL > 0)
      expected = woven::EvalDirect(p, {}, c, tc, woven::WeaveSample<double>{}, lut::DefaultDfg(),
                                   lut::DefaultWovenPhase());
    for (int ch = 0; ch < 3; ++ch) {
      const double e = expected[ch] * ls.scale * s.lights[0].color[size_t(ch)];
      EXPECT_NEAR(out[i][ch], e, 1e-5 * std::abs(e) + 1e-6) << "pixel " << i;
    }
  });
}

TEST(WovenPreview, JetFrameWithTenFreeParametersIsFinite) {
  const Scene s = SphereWithLight(24);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto cache = PreviewCache::Build(s, nullptr, o);
  using Jet = ceres::Jet<double, 10>;
  const auto x = WovenParams();
  std::vector<Jet> xj(x.size());
  for (size_t k = 0; k < x.size(); ++k) xj[k] = k < 10 ? Jet(x[k], int(k)) : Jet(x[k]);
  std::vector<Rgb<Jet>> out;
  EvaluatePreview(*cache, xj.data(), out);
  for (const auto& px : out)
    for (int ch = 0; ch < 3; ++ch) ASSERT_TRUE(ceres::isfinite(px[ch]));
}

}  // namespace
}  // namespace clothfit::render
