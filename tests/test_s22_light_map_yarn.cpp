// s22-lm: woven's yarn lobes reflect the light map's bounce light (render/preview/preview.h
// PreviewCache::light_map; web/clothfit.js does the same with three.js's lightMap). Checks, in a
// constant environment of radiance c, where every split-sum read of the yarn lobes returns c: a
// yarn-only woven preset (no diffuse, no sheen) lit by the environment and a light map gives
// (c + E_ind / pi) / c times the frame without the light map, pixel by pixel, for the GGX yarn
// lobes and for far-field lobes (PreviewOptions::yarn_ibl); before session 22 the ratio was 1
// (the light map reached the diffuse only). The cache's light_map is the light map's part of
// `irradiance`, and it is empty for the baselines.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "render/scene/scene.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

constexpr double kC = 0.7;  // the environment's radiance

// A fabric sphere above a large grey non-fabric sphere (the "floor" whose bounce the light map
// carries).
Scene SphereAboveFloor() {
  Scene s = CameraScene(40, 40, {0, 0.2, 3}, {0, -0.07, -1}, 0.5);
  Mesh sphere = SphereMesh(0.5, 48, 24, true, 0.f);
  // SphereMesh winds its triangles inwards; the three.js engine takes the facing from the
  // winding (gl_FrontFacing) and would flip the near side's normals inwards. Wind them out.
  for (size_t t = 0; t + 2 < sphere.indices.size(); t += 3)
    std::swap(sphere.indices[t + 1], sphere.indices[t + 2]);
  s.meshes.push_back(sphere);
  Mesh floor = SphereMesh(20.0, 64, 32, false, 0.8f);
  for (auto& p : floor.positions) p[1] -= 20.6f;
  s.meshes.push_back(floor);
  s.card.environment = EnvironmentSpec{};
  return s;
}

PreviewOptions LightMapOptions(bool light_map) {
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.visibility.indirect = light_map;
  o.visibility.samples = 64;
  o.visibility.hit_samples = 4;
  return o;
}

// max |with / without - (1 + lm / c)| over the pixels and channels, and max lm / c.
void CompareRatios(const std::vector<Rgb<double>>& with, const std::vector<Rgb<double>>& without,
                   const PreviewCache& c, double* worst, double* lm_max) {
  ASSERT_EQ(with.size(), without.size());
  ASSERT_EQ(c.light_map.size(), 3 * with.size());
  *worst = 0.0;
  *lm_max = 0.0;
  for (size_t i = 0; i < with.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) {
      const double lm = double(c.light_map[i * 3 + size_t(ch)]) / kC;
      *lm_max = std::max(*lm_max, lm);
      if (!(without[i][ch] > 1e-6)) continue;
      *worst = std::max(*worst, std::abs(with[i][ch] / without[i][ch] - (1.0 + lm)));
    }
}

// The GGX yarn lobes through each of their IBL paths: the split sum (fast kernel), the generic
// per-light kernel (woven_reference_kernel), FIS taps and the bent-normal tables (three.js
// engine); in a constant environment each read returns c.
TEST(S22LightMapYarn, GgxYarnLobesReflectTheLightMap) {
  const Scene s = SphereAboveFloor();
  const Environment env =
      EnvironmentFrom(64, 32, [](const Vec3<double>&) { return Rgb<double>(kC, kC, kC); });
  // yarn only: base colour 0, specular colour 1, sheen off (WovenFlat)
  const auto x = WovenFlat({0, 0, 0}, {1, 1, 1}, 0.5, 0.6, 0.5, 0.04, 2.0);
  for (const char* variant : {"split", "reference kernel", "fis", "bent"}) {
    auto options = [&](bool light_map) {
      PreviewOptions o = LightMapOptions(light_map);
      const std::string v = variant;
      if (v == "reference kernel") o.woven_reference_kernel = true;
      if (v == "fis" || v == "bent") o.ibl_engine = IblEngine::kThreejs;
      if (v == "fis") o.woven.ibl = ::clothfit::woven::IblMode::kFis;
      if (v == "bent") {
        o.woven.ibl = ::clothfit::woven::IblMode::kBent;
        o.woven.bent_anisotropy = 0.6;  // x's anisotropy and twist
        o.woven.bent_twist = 0.0;
      }
      return o;
    };
    std::unique_ptr<PreviewCache> cw, co;
    const auto with = PreviewFrame(s, env, options(true), x, &cw);
    const auto without = PreviewFrame(s, env, options(false), x, &co);
    EXPECT_TRUE(co->light_map.empty());
    // the cache's light_map is the light map's part of the irradiance
    ASSERT_EQ(cw->irradiance.size(), co->irradiance.size());
    double part = 0.0;
    for (size_t i = 0; i < cw->irradiance.size(); ++i)
      part = std::max(part, std::abs(double(cw->irradiance[i]) - double(co->irradiance[i]) -
                                     double(cw->light_map[i])));
    EXPECT_LT(part, 1e-5) << variant;
    double worst, lm_max;
    CompareRatios(with, without, *cw, &worst, &lm_max);
    std::printf("S22LightMapYarn GGX, %s: max |ratio - (1 + lm / c)| %.2g, max lm / c %.3f\n",
                variant, worst, lm_max);
    EXPECT_GT(lm_max, 0.05) << variant;  // the floor bounces light onto the sphere
    // FIS and the bent tables read the PMREM's constant to its float precision
    EXPECT_LT(worst, 1e-3) << variant;
  }
}

TEST(S22LightMapYarn, FarFieldLobesReflectTheLightMap) {
  const Scene s = SphereAboveFloor();
  const Environment env =
      EnvironmentFrom(64, 32, [](const Vec3<double>&) { return Rgb<double>(kC, kC, kC); });
  const auto x = WovenFlat({0, 0, 0}, {1, 1, 1}, 0.5, 0.6, 0.5, 0.04, 2.0);
  auto far_field = [](PreviewOptions o) {
    o.yarn_lobe = [](const Vec3<double>&, const Vec3<double>&, double out[2]) {
      out[0] = 0.2;
      out[1] = 0.1;
    };
    o.yarn_ibl = SyntheticYarnIbl;
    return o;
  };
  std::unique_ptr<PreviewCache> cw, co;
  const auto with = PreviewFrame(s, env, far_field(LightMapOptions(true)), x, &cw);
  const auto without = PreviewFrame(s, env, far_field(LightMapOptions(false)), x, &co);
  ASSERT_EQ(cw->yarn_albedo.size(), 2 * with.size());
  double worst, lm_max;
  CompareRatios(with, without, *cw, &worst, &lm_max);
  std::printf("S22LightMapYarn far field: max |ratio - (1 + lm / c)| %.2g, max lm / c %.3f\n",
              worst, lm_max);
  EXPECT_GT(lm_max, 0.05);
  EXPECT_LT(worst, 1e-4);
}

TEST(S22LightMapYarn, BaselinesKeepTheLightMapInTheDiffuse) {
  const Scene s = SphereAboveFloor();
  const Environment env =
      EnvironmentFrom(64, 32, [](const Vec3<double>&) { return Rgb<double>(kC, kC, kC); });
  for (ModelKind m : {ModelKind::kStandard, ModelKind::kCloth, ModelKind::kPhysicalAniso}) {
    PreviewOptions o = LightMapOptions(true);
    o.model = m;
    EXPECT_TRUE(PreviewCache::Build(s, &env, o)->light_map.empty()) << ToString(m);
  }
}

}  // namespace
}  // namespace clothfit::render
