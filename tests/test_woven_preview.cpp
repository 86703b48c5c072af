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
  EmbreeScene bvh(s);
  const woven::Params<double> p = woven::FromFlat(x.data());
  for (size_t i = 0; i < cache->pixels.size(); ++i) {
    const int px = cache->pixels[i] % s.card.width, py = cache->pixels[i] / s.card.width;
    std::array<double, 3> org, dir;
    s.CameraRay(px + 0.5, py + 0.5, org, dir);
    const Hit h = bvh.Intersect(org, dir);
    ASSERT_TRUE(h.valid);
    const SurfaceAttributes a = bvh.Attributes(h);
    Vec3<double> n(a.normal[0], a.normal[1], a.normal[2]);
    const Vec3<double> v(-dir[0], -dir[1], -dir[2]);
    if (Dot(n, v) < 0) n = n * -1.0;
    Vec3<double> t(a.tangent[0], a.tangent[1], a.tangent[2]);
    t = Normalize(t - n * Dot(t, n));
    const Vec3<double> b = Cross(n, t) * a.tangent_sign;
    const LightSample ls =
        EvaluateLight(s.lights[0], Vec3<double>(a.position[0], a.position[1], a.position[2]));
    const Vec3<double> hv = Normalize(v + ls.wi);
    const Cosines<double> c{Dot(n, v), Dot(n, ls.wi), Dot(n, hv), Dot(ls.wi, hv)};
    const TangentCosines<double> tc{Dot(t, v), Dot(b, v), Dot(t, ls.wi),
                                    Dot(b, ls.wi), Dot(t, hv), Dot(b, hv)};
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
  }
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
