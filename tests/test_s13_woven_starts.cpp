// Session 13: woven's cloth-basin start (fit/woven_fit.h, docs/fitting.md "Woven's starts
// (session 13)"): the options of the extra start, when it runs, and a synthetic fit whose
// truth lies in cloth's basin (yarn lobes off, broad sheen) and which the default woven fit
// must therefore recover.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "fit/image_fit.h"
#include "fit/woven_fit.h"
#include "render/preview/preview.h"
#include "tests/fit_fixtures.h"

namespace clothfit::fit {
namespace {
using render::ModelKind;

bool Locked(const FitOptions& o, const std::string& name) {
  return std::find(o.locked.begin(), o.locked.end(), name) != o.locked.end();
}

FitOptions WovenDefaults() {
  FitOptions o;
  o.start = render::DefaultPreset(ModelKind::kWoven);
  o.start_roughness = {0.6};  // clothfit fit's woven default
  return o;
}

TEST(S13WovenStarts, ClothBasinStartHasTheYarnLobesOffAndABroadSheen) {
  const FitOptions o = WovenDefaults();
  ASSERT_TRUE(UsesClothBasinStart(o));
  const FitOptions c = ClothBasinOptions(o);
  const int spec = c.start.Offset("specular_color");
  for (int k = 0; k < 3; ++k) EXPECT_EQ(c.start.values[size_t(spec + k)], 0.0);
  for (const char* n : {"specular_color", "roughness", "anisotropy", "twist", "warp_share",
                        "specular_f0", "forward_scattering"})
    EXPECT_TRUE(Locked(c, n)) << n;
  for (const char* n : {"base_color", "sheen_color", "sheen_roughness"})
    EXPECT_FALSE(Locked(c, n)) << n;
  EXPECT_TRUE(c.init_from_reference);
  ASSERT_EQ(c.start_roughness.size(), 1u);
  EXPECT_EQ(c.start_roughness[0], kClothBasinSheenRoughness);
  EXPECT_EQ(kClothBasinSheenRoughness, 1.0);  // the cloth preset's default (sheen) roughness
  EXPECT_EQ(render::DefaultPreset(ModelKind::kCloth).values[size_t(
                render::DefaultPreset(ModelKind::kCloth).Offset("roughness"))],
            kClothBasinSheenRoughness);

  // (b) starts from the basin's preset with the yarn colour back at the start preset's.
  render::MaterialPreset basin = c.start;
  basin.values[size_t(basin.Offset("sheen_roughness"))] = 0.93;
  const FitOptions from = FromClothBasin(o, basin);
  for (int k = 0; k < 3; ++k)
    EXPECT_EQ(from.start.values[size_t(spec + k)], o.start.values[size_t(spec + k)]);
  EXPECT_EQ(from.start.values[size_t(from.start.Offset("sheen_roughness"))], 0.93);
  EXPECT_FALSE(from.init_from_reference);
}

TEST(S13WovenStarts, ClothBasinStartRunsOnlyForReferenceStartsWithTheSheenFree) {
  FitOptions o = WovenDefaults();
  o.cloth_basin_start = false;
  EXPECT_FALSE(UsesClothBasinStart(o));
  o = WovenDefaults();
  o.init_from_reference = false;  // clothfit fit --start: exactly the given values
  EXPECT_FALSE(UsesClothBasinStart(o));
  for (const char* n : {"sheen_color", "sheen_roughness", "specular_color"}) {
    o = WovenDefaults();
    o.locked = {n};
    EXPECT_FALSE(UsesClothBasinStart(o)) << n;
  }
  o = WovenDefaults();
  o.start = render::DefaultPreset(ModelKind::kCloth);
  EXPECT_FALSE(UsesClothBasinStart(o));
}

// A sphere lit by a key light and a rim light from behind (grazing: the sheen and the rough
// diffuse's forward darkening both show) under a procedural sky, and woven references the
// preview itself renders from known parameters.
struct SyntheticWoven {
  render::Scene s = KeyRimSphereScene(32, 3.0);
  render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  Reference ref;
  // The woven defaults with `values` set (name -> values), rendered into `ref`.
  void Render(std::initializer_list<std::pair<const char*, std::vector<double>>> values) {
    render::MaterialPreset truth = render::DefaultPreset(ModelKind::kWoven);
    for (const auto& [name, v] : values)
      for (size_t k = 0; k < v.size(); ++k) truth.values[size_t(truth.Offset(name)) + k] = v[k];
    ref = PreviewReference(s, &env, truth);
  }
  std::vector<SceneInput> Inputs() const { return {{&s, &env, &ref, nullptr, "test"}}; }
  static FitOptions Options() {
    FitOptions o = WovenDefaults();
    o.level = 0;
    o.loss = Loss::kNone;
    return o;
  }
};

// A woven reference in cloth's basin: no yarn specular, dark base, a broad sheen lit from
// behind (the velvet situation). The default fit must reach it (RMSE ~0) and report the paths
// it ran; the answer is at least as good as every path's.
TEST(S13WovenStarts, SyntheticSheenDominatedReferenceIsRecovered) {
  SyntheticWoven w;
  w.Render({{"base_color", {0.02, 0.015, 0.012}},
            {"specular_color", {0.0, 0.0, 0.0}},
            {"sheen_color", {0.35, 0.3, 0.28}},
            {"sheen_roughness", {1.0}}});
  FitOptions o = SyntheticWoven::Options();
  const std::vector<SceneInput> in = w.Inputs();
  const FitResult r = FitWovenImages(in, o);
  ASSERT_TRUE(r.usable) << r.message;
  ASSERT_GE(r.candidates.size(), 2u);
  EXPECT_EQ(r.candidates[0].name, "two-stage");
  EXPECT_EQ(r.candidates[1].name, "cloth-basin");
  ASSERT_GE(r.candidates.size(), 4u);
  ASSERT_GE(r.candidates.size(), 5u);
  EXPECT_EQ(r.candidates[r.candidates.size() - 3].name, "rough-diffuse");  // session 18's stage
  EXPECT_EQ(r.candidates[r.candidates.size() - 2].name, "lobe-shape");     // session 25's two
  EXPECT_EQ(r.candidates.back().name, "lobe-shape+share");
  for (const auto& c : r.candidates) EXPECT_LE(r.rmse, c.rmse) << c.name;
  EXPECT_LT(r.rmse, 2e-3);

  o.cloth_basin_start = false;  // the session-5 stages alone (Lambert diffuse, anisotropy held)
  o.locked.push_back("diffuse_roughness");
  o.locked.push_back("anisotropy");
  const FitResult old = FitWovenImages(in, o);
  ASSERT_TRUE(old.usable);
  ASSERT_EQ(old.candidates.size(), 1u);
  EXPECT_LE(r.rmse, old.rmse);
  std::printf("synthetic cloth-basin truth: default rmse %.6f, two-stage alone %.6f\n", r.rmse,
              old.rmse);
}

// Session 18: a woven reference with a rough diffuse (sigma 0.6; the rim light darkens it): the
// default fit starts every stage at sigma 0 (Lambert) and its rough-diffuse stage must pull
// sigma off the bound to the truth; with diffuse_roughness locked (the Lambert model) the same
// images cannot be matched as well.
TEST(S18WovenRoughDiffuse, SyntheticRoughDiffuseReferenceIsRecovered) {
  SyntheticWoven w;
  w.Render({{"base_color", {0.12, 0.26, 0.31}},
            {"specular_color", {0.0, 0.0, 0.0}},
            {"diffuse_roughness", {0.6}}});
  FitOptions o = SyntheticWoven::Options();
  const std::vector<SceneInput> in = w.Inputs();
  const FitResult r = FitWovenImages(in, o);
  ASSERT_TRUE(r.usable) << r.message;
  ASSERT_GE(r.candidates.size(), 3u);
  EXPECT_EQ(r.candidates[r.candidates.size() - 3].name, "rough-diffuse");
  EXPECT_EQ(r.candidates.back().name, "lobe-shape+share");
  EXPECT_LT(r.rmse, 2e-3);
  const auto sigma = [](const FitResult& f) {
    return f.preset.values[size_t(f.preset.Offset("diffuse_roughness"))];
  };
  EXPECT_NEAR(sigma(r), 0.6, 0.05);

  o.locked.push_back("diffuse_roughness");
  const FitResult lambert = FitWovenImages(in, o);
  ASSERT_TRUE(lambert.usable);
  EXPECT_EQ(sigma(lambert), 0.0);
  EXPECT_GT(lambert.rmse, 3.0 * r.rmse);
  std::printf("synthetic rough diffuse: default rmse %.6f (sigma %.4f), Lambert %.6f\n", r.rmse,
              sigma(r), lambert.rmse);
}

// Session 25: the GGX yarn lobes' anisotropy, held at the default 0.7 by the stages above, is
// fitted by the lobe-shape stage. References from known parameters with another anisotropy:
// the default fit recovers it and matches the images far better than with it held (as before
// session 25); with it locked no lobe-shape candidate runs.
TEST(S25WovenLobeShape, SyntheticAnisotropyIsRecovered) {
  for (const double truth : {0.1, 1.0}) {
    SyntheticWoven w;
    w.Render({{"base_color", {0.1, 0.08, 0.06}},
              {"specular_color", {0.6, 0.6, 0.6}},
              {"roughness", {0.45}},
              {"anisotropy", {truth}}});
    FitOptions o = SyntheticWoven::Options();
    const std::vector<SceneInput> in = w.Inputs();
    const FitResult r = FitWovenImages(in, o);
    ASSERT_TRUE(r.usable) << r.message;
    EXPECT_EQ(r.candidates.back().name, "lobe-shape+share");
    const double a = r.preset.values[size_t(r.preset.Offset("anisotropy"))];
    EXPECT_NEAR(a, truth, 0.1) << "truth " << truth;

    o.locked.push_back("anisotropy");
    const FitResult held = FitWovenImages(in, o);
    ASSERT_TRUE(held.usable);
    for (const auto& c : held.candidates) EXPECT_EQ(c.name.find("lobe-shape"), std::string::npos);
    EXPECT_EQ(held.preset.values[size_t(held.preset.Offset("anisotropy"))], 0.7);
    EXPECT_LT(r.rmse, 0.5 * held.rmse) << "truth " << truth;
    std::printf("synthetic anisotropy %.2f: fitted %.4f rmse %.6f; held at 0.7: rmse %.6f\n",
                truth, a, r.rmse, held.rmse);
  }
}

}  // namespace
}  // namespace clothfit::fit
