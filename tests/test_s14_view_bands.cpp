// Session 14: view-dependent weave maps (render/preview/weave_maps.h view bands; fit/weave_maps.h
// view_bands; docs/preview.md "View-dependent weave maps").
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "fit/weave_maps.h"
#include "render/preview/weave_maps.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/scene/image_io.h"

namespace clothfit::render {
namespace {

namespace fs = std::filesystem;
constexpr int C = WeaveMaps::kChannels;

std::vector<float> Level0(int size, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.1f, 2.0f);
  std::vector<float> v(size_t(size) * size_t(size) * C);
  for (float& x : v) x = u(rng);
  return v;
}

WeaveMaps WithViews() {
  WeaveMaps m = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 1));
  m.SetViews({0.9, 0.5, 0.1}, {Level0(8, 2), Level0(8, 3), Level0(8, 4)});
  return m;
}

// The blend is piecewise linear in NoV between the cosines and clamped outside; each band is
// sampled by the main maps' own filter (a one-band WeaveMaps built from that band's level 0
// gives the same value), isotropic and anisotropic footprints alike.
TEST(S14ViewBands, BlendIsLinearInNoVBetweenTheBandsAndClamped) {
  const WeaveMaps m = WithViews();
  ASSERT_TRUE(m.has_views());
  const WeaveMaps b0 = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 2));
  const WeaveMaps b1 = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 3));
  const WeaveMaps b2 = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 4));
  for (const WeaveMaps::Footprint fp :
       {WeaveMaps::Footprint{0.0, 1, 0.0, 0.0}, WeaveMaps::Footprint{1.3, 1, 0.0, 0.0},
        WeaveMaps::Footprint{0.4, 4, 0.002, 0.0005}}) {
    const double u = 0.0123, v = 0.0377;
    const auto s0 = b0.Sample(u, v, fp), s1 = b1.Sample(u, v, fp), s2 = b2.Sample(u, v, fp);
    const auto at = [&](double nov) { return m.SampleView(u, v, fp, nov); };
    for (int c = 0; c < C; ++c) {
      EXPECT_NEAR(at(0.9)[c], s0[c], 1e-12);
      EXPECT_NEAR(at(1.0)[c], s0[c], 1e-12);   // clamped above the frontal band
      EXPECT_NEAR(at(0.5)[c], s1[c], 1e-12);
      EXPECT_NEAR(at(0.1)[c], s2[c], 1e-12);
      EXPECT_NEAR(at(0.0)[c], s2[c], 1e-12);   // clamped below the grazing band
      EXPECT_NEAR(at(0.7)[c], 0.5 * s0[c] + 0.5 * s1[c], 1e-12);
      EXPECT_NEAR(at(0.2)[c], 0.25 * s1[c] + 0.75 * s2[c], 1e-12);
    }
  }
  for (double nov : {-1.0, 0.0, 0.05, 0.3, 0.77, 0.95, 2.0, std::nan("")}) {
    double sum = 0.0;
    for (double w : m.ViewWeights(nov)) {
      EXPECT_GE(w, 0.0);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-15) << nov;
  }
  // Without bands SampleView is Sample.
  const WeaveMaps plain = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 1));
  const WeaveMaps::Footprint fp{0.7, 1, 0.0, 0.0};
  EXPECT_EQ(plain.SampleView(0.01, 0.02, fp, 0.3), plain.Sample(0.01, 0.02, fp));
  // Bad bands are refused before anything is set.
  WeaveMaps bad = WeaveMaps::FromLevel0(8, 40.0, Level0(8, 1));
  EXPECT_THROW(bad.SetViews({0.5, 0.9}, {Level0(8, 2), Level0(8, 3)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({0.9}, {Level0(8, 2)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({1.5, 0.5}, {Level0(8, 2), Level0(8, 3)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({0.9, 0.5}, {Level0(8, 2), Level0(4, 3)}), std::invalid_argument);
  EXPECT_FALSE(bad.has_views());
}

// File: the bands and their cosines round-trip; the preset draws them only when it names the
// same cosines; a file whose metadata is malformed or whose band channels are missing is refused
// naming the file and what is wrong.
TEST(S14ViewBands, FileAndPresetRoundTripAndErrorsNameTheField) {
  const fs::path dir = fs::temp_directory_path() / "clothfit_s14_view_bands";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const WeaveMaps m = WithViews();
  const std::string path = (dir / "v.weave.exr").string();
  WriteWeaveMaps(path, m);
  const WeaveMaps r = ReadWeaveMaps(path);
  ASSERT_EQ(r.view_cosines.size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(r.view_cosines[k], m.view_cosines[k]);
    ASSERT_EQ(r.view_levels[k][0].size(), m.view_levels[k][0].size());
    for (size_t t = 0; t < r.view_levels[k][0].size(); ++t)
      EXPECT_NEAR(r.view_levels[k][0][t], m.view_levels[k][0][t], 1e-6);
  }

  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  p.extra["weave_maps"] = WeaveMapsPresetField(path, m);
  ASSERT_TRUE(p.extra["weave_maps"].contains("view_cosines"));
  EXPECT_TRUE(LoadPresetWeaveMaps(p)->has_views());
  auto expect_field_error = [&](const char* what) {
    try {
      LoadPresetWeaveMaps(p);
      ADD_FAILURE() << "no error: " << what;
    } catch (const MaterialError& e) {
      EXPECT_NE(std::string(e.what()).find("weave_maps.view_cosines"), std::string::npos) << e.what();
    }
  };
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.4, 0.1};
  expect_field_error("cosines differ from the file's");
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.5};
  expect_field_error("fewer bands than the file");
  p.extra["weave_maps"]["view_cosines"] = {0.5, 0.9, 0.1};
  expect_field_error("not decreasing");
  p.extra["weave_maps"]["view_cosines"] = "0.9 0.5 0.1";
  expect_field_error("not an array");
  p.extra["weave_maps"].erase("view_cosines");
  EXPECT_FALSE(LoadPresetWeaveMaps(p)->has_views());  // not named: not drawn

  // A file without bands but a preset that names them.
  const std::string plain_path = (dir / "plain.weave.exr").string();
  WriteWeaveMaps(plain_path, WeaveMaps::FromLevel0(8, 40.0, Level0(8, 1)));
  p.extra["weave_maps"]["file"] = plain_path;
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.5, 0.1};
  expect_field_error("the file has no bands");

  // Malformed metadata, missing channels (written with the generic EXR writer).
  io::Image img = io::ReadImage(path);
  auto expect_file_error = [&](const std::string& name, const char* needle) {
    const std::string q = (dir / name).string();
    io::WriteExr(q, img);
    try {
      ReadWeaveMaps(q);
      ADD_FAILURE() << "no error for " << name;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  const auto good = img.metadata["clothfit:view_cosines"];
  img.metadata["clothfit:view_cosines"] = "0.9 0.5x 0.1";
  expect_file_error("garbage.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.9";
  expect_file_error("one.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.9 0.8 0.7 0.6 0.5 0.4 0.3 0.2 0.1";
  expect_file_error("nine.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.1 0.5 0.9";
  expect_file_error("increasing.weave.exr", "decreasing");
  img.metadata["clothfit:view_cosines"] = good + " 0.05";
  expect_file_error("fourbands.weave.exr", "view3.warp");
  fs::remove_all(dir);
}

// The bake: one map per view cosine, each a ratio map (tile mean 1), stored by decreasing
// cosine. Measured property of the canvas weave (docs/flip.md, session 14): the yarn lobes'
// per-texel contrast grows towards grazing views, which the all-views map averages away.
TEST(S14ViewBands, BakedBandsAreRatioMapsWhoseYarnContrastGrowsTowardsGrazing) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const Fabric f = LoadFabric((fabrics / "canvas.json").string());
  const auto* irawan = dynamic_cast<const IrawanBsdf*>(f.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  fit::WeaveBakeOptions o;
  o.size = 16;
  o.view_bands = true;
  const fit::WeaveBakeResult r = fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o);
  ASSERT_EQ(r.maps.view_cosines.size(), 3u);
  EXPECT_NEAR(r.maps.view_cosines[0], 0.5 * (1.0 + std::sqrt(0.6)), 1e-12);
  EXPECT_NEAR(r.maps.view_cosines[1], 0.5, 1e-12);
  EXPECT_NEAR(r.maps.view_cosines[2], 0.5 * (1.0 - std::sqrt(0.6)), 1e-12);
  // The main maps are the all-views bake, unchanged by the option.
  fit::WeaveBakeOptions plain = o;
  plain.view_bands = false;
  EXPECT_EQ(fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), plain).maps.levels[0],
            r.maps.levels[0]);
  std::vector<double> spread;
  for (const auto& band : r.maps.view_levels) {
    const std::vector<float>& l0 = band[0];
    double mean[C] = {0, 0, 0, 0, 0}, var = 0.0;
    const size_t n = l0.size() / C;
    for (size_t t = 0; t < n; ++t)
      for (int c = 0; c < C; ++c) mean[c] += l0[t * C + size_t(c)] / double(n);
    for (int c = 0; c < C; ++c) EXPECT_NEAR(mean[c], 1.0, 1e-5);
    for (size_t t = 0; t < n; ++t) var += (l0[t * C] - 1.0) * (l0[t * C] - 1.0) / double(n);
    spread.push_back(std::sqrt(var));  // the warp weight's standard deviation
  }
  EXPECT_LT(spread[0], spread[1]);
  EXPECT_LT(spread[1], spread[2]);
  o.relief = true;
  EXPECT_THROW(fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o), std::invalid_argument);
}

}  // namespace
}  // namespace clothfit::render
