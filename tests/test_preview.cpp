// The preview renderer: agreement with brdf/ at each pixel, with the path tracer for a
// Lambertian material, Jet derivatives of a full frame, continuity in roughness, and the
// per-scene feature selection.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>

#include "brdf/cloth.h"
#include "brdf/lut.h"
#include "render/scene/embree_scene.h"
#include "render/scene/environment.h"
#include "render/scene/lights.h"
#include "render/reference/path_tracer.h"
#include "render/preview/preview.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

using Jet = ceres::Jet<double, 10>;

std::vector<double> ClothParams() {
  return {0.6, 0.35, 0.2, 0.8, 0.7, 0.5, 0.55, 0.3, 0.15, 0.05};
}

TEST(Preview, DirectLightEqualsBrdfTimesLightAtEveryPixel) {
  const Scene s = SphereWithLight(32);
  PreviewOptions o;
  o.model = ModelKind::kCloth;
  for (bool sub : {false, true}) {
    o.cloth.subsurface = sub;
    auto cache = PreviewCache::Build(s, nullptr, o);
    EXPECT_TRUE(cache->features.direct);
    EXPECT_FALSE(cache->features.ibl);
    EXPECT_EQ(cache->features.subsurface, sub);
    EXPECT_TRUE(cache->radiance.empty());  // no environment: no IBL data at all
    const auto x = ClothParams();
    std::vector<Rgb<double>> out;
    EvaluatePreview(*cache, x.data(), out);
    ASSERT_GT(out.size(), 300u);
    // Recompute independently at each pixel centre.
    cloth::Params<double> p{{x[0], x[1], x[2]}, {x[3], x[4], x[5]}, x[6], {x[7], x[8], x[9]}};
    int checked = 0;
    ForEachPixelGeometry(s, *cache, [&](size_t i, const PixelGeometry& g) {
      const Rgb<double> f = cloth::EvalDirect(p, o.cloth, g.cosines);
      for (int ch = 0; ch < 3; ++ch) {
        const double expected = f[ch] * g.light.scale * s.lights[0].color[size_t(ch)];
        EXPECT_NEAR(out[i][ch], expected, 1e-5 * std::abs(expected) + 1e-7) << "pixel " << i;
      }
      ++checked;
    });
    EXPECT_EQ(checked, int(cache->pixels.size()));
  }
}

TEST(Preview, LambertUnderConstantEnvironmentMatchesPathTracer) {
  Scene s = CameraScene(24, 24, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 96, 48, true, 0.f));
  const Environment env = Environment::Constant({0.9, 0.7, 0.5});
  PreviewOptions o;
  o.model = ModelKind::kCloth;
  auto cache = PreviewCache::Build(s, &env, o);
  EXPECT_FALSE(cache->features.direct);
  std::vector<double> x = ClothParams();
  x[3] = x[4] = x[5] = 0.0;  // no sheen: a Lambertian material
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  LambertBsdf lambert(Rgbd(x[0], x[1], x[2]));
  PathTracer pt(s, lambert, &env);
  RenderSettings st;
  st.spp = 64;
  const RenderResult ref = pt.Render(st);
  int compared = 0;
  for (size_t i = 0; i < cache->pixels.size(); ++i) {
    const size_t pix = size_t(cache->pixels[i]);
    if (ref.coverage[pix] < 1.0f) continue;  // silhouette pixels mix background
    for (int ch = 0; ch < 3; ++ch) {
      const double tol = 4.0 * double(ref.std_error[pix * 3 + size_t(ch)]) + 1e-3;
      EXPECT_NEAR(out[i][ch], double(ref.rgb[pix * 3 + size_t(ch)]), tol) << "pixel " << pix;
    }
    ++compared;
  }
  EXPECT_GT(compared, 100);
}

Scene FullScene() {
  Scene s = SphereWithLight(24);
  return s;
}

TEST(Preview, FullFrameJetDerivativesMatchCentralDifferences) {
  const Scene s = FullScene();
  const Environment env = Environment::ProceduralSky(1.0, 0.4);
  PreviewOptions o;
  o.model = ModelKind::kCloth;
  o.cloth.subsurface = true;
  auto cache = PreviewCache::Build(s, &env, o);
  ASSERT_TRUE(cache->features.direct && cache->features.ibl && cache->features.subsurface);
  std::vector<double> x = ClothParams();
  x[6] = 0.5546875;  // between LUT texel centres and radiance-table nodes
  std::vector<Jet> xj(10);
  for (int k = 0; k < 10; ++k) xj[size_t(k)] = Jet(x[size_t(k)], k);
  std::vector<Rgb<Jet>> jets;
  EvaluatePreview(*cache, xj.data(), jets);
  const double h = 1e-6;
  for (int k = 0; k < 10; ++k) {
    std::vector<double> xp = x, xm = x;
    xp[size_t(k)] += h;
    xm[size_t(k)] -= h;
    std::vector<Rgb<double>> fp, fm;
    EvaluatePreview(*cache, xp.data(), fp);
    EvaluatePreview(*cache, xm.data(), fm);
    double max_err = 0, max_d = 0;
    for (size_t i = 0; i < jets.size(); ++i)
      for (int ch = 0; ch < 3; ++ch) {
        const double fd = (fp[i][ch] - fm[i][ch]) / (2 * h);
        max_err = std::max(max_err, std::abs(fd - jets[i][ch].v[k]));
        max_d = std::max(max_d, std::abs(fd));
      }
    EXPECT_LE(max_err, 1e-5 * max_d + 1e-7) << "parameter " << k;
  }
}

TEST(Preview, ContinuousAcrossRoughnessTableAndLutBoundaries) {
  const Scene s = FullScene();
  const Environment env = Environment::ProceduralSky(1.0, 0.0);
  PreviewOptions o;
  auto cache = PreviewCache::Build(s, &env, o);
  std::vector<double> x = ClothParams();
  std::vector<Rgb<double>> prev, cur;
  std::vector<Rgb<Jet>> dprev;
  const double step = 2e-3;
  auto derivative = [&](std::vector<Rgb<Jet>>& d) {
    std::vector<Jet> xj(10);
    for (int k = 0; k < 10; ++k) xj[size_t(k)] = Jet(x[size_t(k)], k);
    EvaluatePreview(*cache, xj.data(), d);
  };
  x[6] = 0.30;
  EvaluatePreview(*cache, x.data(), prev);
  derivative(dprev);
  double worst_ratio = 0.0;
  for (int i = 1; i <= 150; ++i) {  // r from 0.30 to 0.60, crossing nodes and texel centres
    x[6] = 0.30 + step * i;
    EvaluatePreview(*cache, x.data(), cur);
    std::vector<Rgb<Jet>> d;
    derivative(d);
    for (size_t p = 0; p < cur.size(); ++p)
      for (int ch = 0; ch < 3; ++ch) {
        // The function is piecewise smooth (cubic between radiance nodes, bilinear between
        // LUT texels): over one step its change stays within a small multiple of the larger
        // end-point slope x step (a cubic's interior slope can exceed its end slopes a
        // little); a jump does not shrink with the step and shows as a large ratio.
        const double change = std::abs(cur[p][ch] - prev[p][ch]);
        const double predicted =
            std::max(std::abs(d[p][ch].v[6]), std::abs(dprev[p][ch].v[6])) * step;
        // a step much larger than the derivative predicts is a discontinuity
        if (change > 1e-5) worst_ratio = std::max(worst_ratio, change / (predicted + 1e-6));
      }
    prev = cur;
    dprev = d;
  }
  EXPECT_LT(worst_ratio, 3.0);
}

TEST(Preview, NoLightsMeansNoDirectPath) {
  Scene s = CameraScene(16, 16, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 32, 16, true, 0.f));
  const Environment env = Environment::Constant({1, 1, 1});
  auto cache = PreviewCache::Build(s, &env, {});
  EXPECT_FALSE(cache->features.direct);
  EXPECT_TRUE(cache->light_samples.empty());
  EXPECT_TRUE(cache->features.ibl);
}

TEST(Preview, ShadowsOptionTracesVisibility) {
  Scene s = SphereWithLight(24);
  // A blocker between the light and the sphere.
  Mesh blocker = SphereMesh(0.3, 16, 8, false, 0.5f);
  for (auto& p : blocker.positions) {
    p[0] -= 0.4f * 1.5f;
    p[1] += 0.5f * 1.5f;
    p[2] += 0.768f * 1.5f;
  }
  s.meshes.push_back(blocker);
  PreviewOptions o;
  auto lit = PreviewCache::Build(s, nullptr, o);
  o.shadows = true;
  auto shadowed = PreviewCache::Build(s, nullptr, o);
  EXPECT_LT(shadowed->light_samples.size(), lit->light_samples.size());
}

}  // namespace
}  // namespace clothfit::render
