// BRDF-space fitting (fit/brdf_fit.h) and the MERL reader (fit/convert/merl.h): the direction set,
// self-conversion of every model, glTF sheen -> cloth within the stated error, recovery of an
// analytic BRDF from a synthetic MERL file, and reader errors naming file and field.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "fit/brdf_fit.h"
#include "fit/convert/merl.h"
#include "render/reference/fabric.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;
using render::ModelKind;

render::MaterialPreset Cloth(Rgb<double> base, Rgb<double> sheen, double r) {
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kCloth);
  for (int c = 0; c < 3; ++c) {
    p.values[size_t(c)] = base[c];
    p.values[size_t(3 + c)] = sheen[c];
  }
  p.values[6] = r;
  return p;
}

TEST(BrdfFit, DirectionSetIsFixedNormalisedAndCoversGrazing) {
  const auto& d = CanonicalDirections();
  ASSERT_EQ(d.size(), size_t(kDirNodes * kDirNodes * kAzimuths));
  double sum = 0.0, min_mu = 1.0;
  for (const auto& p : d) {
    sum += p.weight;
    EXPECT_GT(p.weight, 0.0);
    min_mu = std::min({min_mu, p.v.z, p.l.z});
    EXPECT_NEAR(p.cos.NoV, p.v.z, 1e-12);
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_LT(min_mu, 0.05);  // reaches ~87 degrees
  // Weighted by 2 mu_v: the most normal view (first) outweighs the most grazing one (last).
  ASSERT_GT(d.front().v.z, 0.95);
  ASSERT_LT(d.back().v.z, 0.05);
  EXPECT_GT(d.front().weight, 10 * d.back().weight);
}

TEST(BrdfFit, ClothConvertsToItselfFromGenericStarts) {
  const render::MaterialPreset truth = Cloth({0.45, 0.3, 0.2}, {0.8, 0.7, 0.6}, 0.55);
  BrdfFitOptions o;  // no source start: the roughness starts must find it
  const BrdfFitResult r = FitBrdf(SampleAnalytic(truth), o);
  ASSERT_TRUE(r.usable) << r.message;
  for (size_t i = 0; i < 7; ++i) EXPECT_NEAR(r.preset.values[i], truth.values[i], 2e-3) << i;
  EXPECT_LT(r.error, 1e-5);
}

TEST(BrdfFit, EveryModelConvertsToItself) {
  for (ModelKind m : {ModelKind::kStandard, ModelKind::kPhysicalSheen, ModelKind::kGltfSheen}) {
    render::MaterialPreset p = render::DefaultPreset(m);
    p.values[0] = 0.5, p.values[1] = 0.35, p.values[2] = 0.2, p.values[3] = 0.6;
    if (m != ModelKind::kStandard) {
      p.values[5] = 0.7, p.values[6] = 0.6, p.values[7] = 0.5, p.values[8] = 0.45;
    }
    BrdfFitOptions o;
    o.model = m;
    const BrdfFitResult r = FitBrdf(SampleAnalytic(p), o);
    ASSERT_TRUE(r.usable) << render::ToString(m);
    EXPECT_LT(r.error, 2e-3) << render::ToString(m);
    EXPECT_NEAR(r.preset.values[3], 0.6, 0.03) << render::ToString(m);
  }
}

// The stated error of a glTF sheen -> cloth conversion (docs/convert.md): a dielectric
// glTF sheen fabric (GGX base with rough base roughness) converts to a cloth preset within
// 0.02 cube-root units on the canonical set, and the cloth keeps the base colour's hue.
TEST(BrdfFit, GltfSheenConvertsToClothWithinStatedError) {
  render::MaterialPreset g = render::DefaultPreset(ModelKind::kGltfSheen);
  const double v[9] = {0.5, 0.25, 0.15, 0.85, 0.0, 0.6, 0.5, 0.45, 0.5};
  g.values.assign(v, v + 9);
  const BrdfSamples s = SampleAnalytic(g);
  const BrdfFitResult r = FitBrdf(s, {});
  ASSERT_TRUE(r.usable);
  std::printf("gltf-sheen -> cloth: error %.4f, roughness %.3f\n", r.error, r.preset.values[6]);
  EXPECT_LT(r.error, 0.02);
  EXPECT_GT(r.preset.values[0], r.preset.values[1]);
  EXPECT_GT(r.preset.values[1], r.preset.values[2]);
  // And the untouched default cloth is far worse: the fit did something.
  EXPECT_GT(BrdfError(s, render::DefaultPreset(ModelKind::kCloth)), 3 * r.error);
}

TEST(Merl, SyntheticTableOfAnAnalyticClothRecoversItsParameters) {
  const render::MaterialPreset truth = Cloth({0.3, 0.5, 0.25}, {0.6, 0.75, 0.9}, 0.7);
  const MerlTable t =
      TabulateMerl(90, 90, 180, [&](const Vec3<double>& wi, const Vec3<double>& wo) {
        const Cosines<double> c = CosinesFromDirections(wo, wi);
        return EvalDirectFlat(ModelKind::kCloth, truth.cloth, truth.values.data(), c) *
               (1.0 / wi.z);
      });
  const fs::path dir = fs::temp_directory_path() / "clothfit_test_merl";
  fs::create_directories(dir);
  const std::string path = (dir / "cloth.binary").string();
  WriteMerl(path, t);
  EXPECT_EQ(fs::file_size(path), size_t(12 + 3 * 90 * 90 * 180 * 8));
  const MerlTable back = ReadMerl(path);
  const BrdfFitResult r = FitBrdf(SampleMerl(back), {});
  ASSERT_TRUE(r.usable);
  std::printf("MERL cloth recovery: error %.4f\n", r.error);
  for (size_t i = 0; i < 7; ++i) EXPECT_NEAR(r.preset.values[i], truth.values[i], 0.03) << i;
  fs::remove_all(dir);
}

TEST(Merl, LookupFindsTheCellItWasTabulatedAt) {
  MerlTable t = TabulateMerl(16, 16, 32, [](const Vec3<double>& wi, const Vec3<double>& wo) {
    return Rgb<double>(wi.z, wo.z, 0.5);
  });
  for (int ih : {0, 7, 15})
    for (int id : {0, 5, 15})
      for (int ip : {0, 13, 31}) {
        Vec3<double> wi, wo;
        if (!MerlCellDirections(t, ih, id, ip, wi, wo)) continue;
        Rgb<double> f;
        ASSERT_TRUE(t.Lookup(wi, wo, f));
        EXPECT_NEAR(f[0], wi.z, 1e-9);
        EXPECT_NEAR(f[2], 0.5, 1e-9);
        ASSERT_TRUE(t.Lookup(wo, wi, f));  // reciprocity: the same cell
        EXPECT_NEAR(f[2], 0.5, 1e-9);
      }
}

TEST(Merl, BadFilesNameFileAndField) {
  const fs::path dir = fs::temp_directory_path() / "clothfit_test_merl_bad";
  fs::create_directories(dir);
  const std::string p = (dir / "short.binary").string();
  {
    std::ofstream f(p, std::ios::binary);
    const int32_t dims[3] = {90, 90, 180};
    f.write(reinterpret_cast<const char*>(dims), 12);
    f << "abc";
  }
  try {
    ReadMerl(p);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(p + ": data:"), std::string::npos) << e.what();
  }
  {
    std::ofstream f(p, std::ios::binary);
    const int32_t dims[3] = {90, -1, 180};
    f.write(reinterpret_cast<const char*>(dims), 12);
  }
  try {
    ReadMerl(p);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("header.n_theta_d"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

TEST(BrdfFit, WovenFabricAveragedOverTheWeaveConverts) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const render::Fabric f = render::LoadFabric((fabrics / "canvas.json").string());
  const BrdfSamples s = SampleBsdf(*f.bsdf, f.weave_period_uv, 3, 2);
  const BrdfFitResult r = FitBrdf(s, {});
  ASSERT_TRUE(r.usable);
  std::printf("canvas -> cloth: error %.4f\n", r.error);
  EXPECT_LT(r.error, BrdfError(s, render::DefaultPreset(ModelKind::kCloth)));
}

}  // namespace
}  // namespace clothfit::fit
