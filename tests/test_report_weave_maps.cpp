// Report pages show a preset's weave maps (issue 12, item 5; fit/metrics/report.h,
// WeaveMapThumbnails): thumbnails tile the period, the display normalisation is the documented
// one, untrusted strings stay escaped, and a missing map is a note, not a failed report.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "fit/metrics/report.h"
#include "render/scene/image_io.h"

namespace clothfit::report {
namespace {
namespace fs = std::filesystem;

// Decodes nothing: the thumbnails are checked through a second encoding of the expected pixels
// (EncodePng8 is deterministic), so the test compares the exact picture.
std::string ExpectedPng(int w, int h, const std::vector<float>& rgb) {
  return Base64(io::EncodePng8(w, h, rgb, "expected"));
}

io::Image Maps(int n) {
  io::Image img;
  img.width = img.height = n;
  img.channel_names = {"warp", "weft", "kd.R", "kd.G", "kd.B"};
  img.pixels.resize(size_t(n) * n * 5);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      float* p = &img.pixels[(size_t(y) * n + x) * 5];
      p[0] = float(x);          // warp: 0 .. n-1, max n-1
      p[1] = float(y) * 2.0f;   // weft: 0 .. 2(n-1)
      p[2] = 1.0f + 0.1f * float(x == 0);  // kd.R: 1.1 in the first column
      p[3] = 1.0f - 0.2f * float(y == 0);  // kd.G: 0.8 in the first row -> s = 0.2
      p[4] = 1.0f;
    }
  return img;
}

TEST(ReportWeaveMaps, ThumbnailsTileThePeriodWithTheDocumentedNormalisation) {
  const int n = 4;
  const WeaveMapPictures w = WeaveMapThumbnails(Maps(n), "maps.exr", 2);
  EXPECT_TRUE(w.note.empty()) << w.note;
  ASSERT_EQ(w.pictures.size(), 3u);
  EXPECT_EQ(w.pictures[0].title, "warp weight");
  EXPECT_DOUBLE_EQ(w.pictures[0].max, 3.0);
  EXPECT_DOUBLE_EQ(w.pictures[0].scale, 3.0);
  EXPECT_DOUBLE_EQ(w.pictures[1].max, 6.0);
  EXPECT_NEAR(w.pictures[2].scale, 0.2, 1e-6);
  // Expected pixels: 2 x 2 periods of n x n.
  std::vector<float> warp(size_t(2 * n) * (2 * n) * 3), kd(warp.size());
  for (int y = 0; y < 2 * n; ++y)
    for (int x = 0; x < 2 * n; ++x) {
      const size_t i = (size_t(y) * (2 * n) + x) * 3;
      for (int k = 0; k < 3; ++k) warp[i + k] = float(x % n) / 3.0f;
      const float r = 1.0f + 0.1f * float(x % n == 0), g = 1.0f - 0.2f * float(y % n == 0);
      const double s = w.pictures[2].scale;
      kd[i] = float(0.5 + 0.5 * (double(r) - 1.0) / s);
      kd[i + 1] = float(0.5 + 0.5 * (double(g) - 1.0) / s);
      kd[i + 2] = 0.5f;
    }
  EXPECT_EQ(w.pictures[0].png, ExpectedPng(2 * n, 2 * n, warp));
  EXPECT_EQ(w.pictures[2].png, ExpectedPng(2 * n, 2 * n, kd));

  io::Image partial = Maps(n);
  partial.channel_names[1] = "other";
  const WeaveMapPictures p = WeaveMapThumbnails(partial, "maps.exr", 2);
  EXPECT_EQ(p.pictures.size(), 2u);
  EXPECT_NE(p.note.find("weft"), std::string::npos);
}

// Session 15: a file with view bands (view{k}.warp/weft/kd.R/G/B, session 14) gets three
// pictures per band, each normalised on its own, tagged with its band; a band with a missing
// channel is a note naming it.
io::Image MapsWithViews(int n, int bands) {
  const io::Image main = Maps(n);
  io::Image img;
  img.width = img.height = n;
  img.channel_names = main.channel_names;
  for (int k = 0; k < bands; ++k)
    for (const char* c : {"warp", "weft", "kd.R", "kd.G", "kd.B"})
      img.channel_names.push_back("view" + std::to_string(k) + "." + c);
  const size_t nc = img.channel_names.size();
  img.pixels.resize(size_t(n) * n * nc);
  for (size_t t = 0; t < size_t(n) * n; ++t)
    for (size_t c = 0; c < nc; ++c)  // band k: the main maps times (k + 2) (warp max 3 (k + 2))
      img.pixels[t * nc + c] = main.pixels[t * 5 + c % 5] * (c < 5 ? 1.0f : float((c - 5) / 5 + 2));
  return img;
}

TEST(ReportWeaveMaps, ViewBandsGetTheirOwnPictures) {
  const int n = 4;
  const WeaveMapPictures w = WeaveMapThumbnails(MapsWithViews(n, 3), "maps.exr", 2);
  EXPECT_TRUE(w.note.empty()) << w.note;
  EXPECT_EQ(w.view_bands, 3);
  ASSERT_EQ(w.pictures.size(), 12u);
  for (size_t i = 0; i < w.pictures.size(); ++i) {
    EXPECT_EQ(w.pictures[i].band, int(i / 3) - 1) << i;
    EXPECT_EQ(w.pictures[i].title, w.pictures[i % 3].title) << i;
  }
  for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(w.pictures[size_t(3 + 3 * k)].max, 3.0 * (k + 2));
  // Normalised on its own: band 0's warp (the main warp x 2, white = its max) is the same
  // picture as the main warp.
  EXPECT_EQ(w.pictures[3].png, w.pictures[0].png);
  io::Image broken = MapsWithViews(n, 2);
  broken.channel_names[5 + 5 + 1] = "view1.other";  // band 1 without its weft
  const WeaveMapPictures b = WeaveMapThumbnails(broken, "maps.exr", 2);
  EXPECT_EQ(b.view_bands, 2);
  EXPECT_EQ(b.pictures.size(), 8u);
  EXPECT_NE(b.note.find("view1.weft"), std::string::npos) << b.note;
}

class ReportWeaveMapPage : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("clothfit_test_report_maps_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(ReportWeaveMapPage, PageShowsTheMapsAndTheModelWithEscapedStrings) {
  io::Image img;
  img.width = img.height = 8;
  img.channel_names = {"R", "G", "B", "fabric"};
  img.pixels.assign(8 * 8 * 4, 0.5f);
  for (size_t i = 3; i < img.pixels.size(); i += 4) img.pixels[i] = 1.0f;  // all fabric
  const std::string ref = (dir_ / "ref.exr").string(), prev = (dir_ / "prev.exr").string();
  io::WriteExr(ref, img);
  io::WriteExr(prev, img);
  io::WriteExr((dir_ / "m.weave.exr").string(), Maps(8));
  io::WriteExr((dir_ / "v.weave.exr").string(), MapsWithViews(8, 3));
  auto preset = [&](const std::string& model, const nlohmann::json& maps) {
    nlohmann::json j = {
        {"schema", "clothfit.preset"}, {"version", 1}, {"model", model},
        {"parameters", {{"roughness", 0.5}}},
        {"fit", {{"scenes", {{{"scene", "s.json"}, {"reference", ref}, {"tone_mapping", "Linear"},
                              {"exposure", 1.0}, {"preview", prev}}}}}},
        {"provenance", {{"fabric", "datasets/fabrics/canvas.json"}}}};
    if (!maps.is_null()) j["weave_maps"] = maps;
    const std::string p = (dir_ / (model + ".json")).string();
    std::ofstream(p) << j.dump();
    return p;
  };
  const std::vector<std::string> presets = {
      preset("standard", nullptr),
      preset("woven", {{"file", "v.weave.exr"}, {"colour_space", "<script>x</script>"},
                       {"uv_repeats", 60.0}, {"view_cosines", {0.887, 0.5, 0.113}}}),
      preset("physical-aniso", {{"file", "missing<b>.exr"}}),
      preset("cloth", {{"file", "v.weave.exr"}, {"view_cosines", {0.887, 0.5, 0.113}}}),
      preset("physical-sheen", {{"file", "m.weave.exr"}, {"view_cosines", {0.887, 0.5, 0.113}}})};
  const auto fabrics = FabricsFromPresets(presets);
  const FabricReport rep = BuildFabricReport(fabrics.at(0));
  ASSERT_EQ(rep.weave_maps.size(), 5u);
  // The report orders the models its own way: look them up by name.
  auto maps_of = [&](const std::string& model) -> const std::optional<WeaveMapPictures>& {
    for (size_t i = 0; i < rep.spec.models.size(); ++i)
      if (rep.spec.models[i].model == model) return rep.weave_maps.at(i);
    ADD_FAILURE() << "no model " << model;
    return rep.weave_maps.at(0);
  };
  EXPECT_FALSE(maps_of("standard").has_value());  // standard: no maps, no section entry
  ASSERT_TRUE(maps_of("woven").has_value());
  EXPECT_EQ(maps_of("woven")->pictures.size(), 12u);
  ASSERT_TRUE(maps_of("physical-aniso").has_value());
  EXPECT_TRUE(maps_of("physical-aniso")->pictures.empty());
  EXPECT_NE(maps_of("physical-aniso")->note.find("missing<b>.exr"), std::string::npos);
  const std::string html = FabricHtml(rep);
  EXPECT_NE(html.find("<h2>Weave maps</h2>"), std::string::npos);
  EXPECT_NE(html.find("(model <code>woven</code>)"), std::string::npos);
  EXPECT_NE(html.find("(model <code>physical-aniso</code>)"), std::string::npos);
  EXPECT_NE(html.find("alt=\"woven warp weight\""), std::string::npos);
  EXPECT_NE(html.find("linear ratio to its tile mean"), std::string::npos);
  EXPECT_EQ(html.find("<script>x"), std::string::npos);
  EXPECT_NE(html.find("&lt;script&gt;x"), std::string::npos);
  EXPECT_EQ(html.find("missing<b>"), std::string::npos);
  // View bands: pictures per band; woven's cosines from its preset. Another model's bands are
  // shown as not drawn even when its preset names cosines (only woven draws them); a file
  // without bands shows none.
  EXPECT_EQ(maps_of("woven")->view_cosines.size(), 3u);
  EXPECT_NE(html.find("alt=\"woven view band 2 warp weight\""), std::string::npos);
  EXPECT_NE(html.find("view band 1 at NoV = 0.5"), std::string::npos);
  ASSERT_TRUE(maps_of("cloth").has_value());
  EXPECT_EQ(maps_of("cloth")->pictures.size(), 12u);
  EXPECT_TRUE(maps_of("cloth")->view_cosines.empty());
  EXPECT_NE(html.find("alt=\"cloth view band 0 weft weight\""), std::string::npos);
  EXPECT_NE(html.find("Only woven draws view bands"), std::string::npos);
  size_t at_nov = 0;
  for (size_t pos = html.find(" at NoV = "); pos != std::string::npos;
       pos = html.find(" at NoV = ", pos + 1))
    ++at_nov;
  EXPECT_EQ(at_nov, 3u);  // woven's three bands only
  ASSERT_TRUE(maps_of("physical-sheen").has_value());
  EXPECT_EQ(maps_of("physical-sheen")->pictures.size(), 3u);
  EXPECT_EQ(maps_of("physical-sheen")->view_bands, 0);
  // Out-of-range cosines (2 is not a view cosine; the preview's loader refuses them) are not
  // claimed as drawn: the bands show, unlabelled, as not drawn.
  const std::string bad = preset("woven", {{"file", "v.weave.exr"}, {"view_cosines", {2.0, 0.5, 0.113}}});
  const FabricReport one = BuildFabricReport(FabricsFromPresets({bad}).at(0));
  ASSERT_TRUE(one.weave_maps.at(0).has_value());
  EXPECT_EQ(one.weave_maps[0]->view_bands, 3);
  EXPECT_TRUE(one.weave_maps[0]->view_cosines.empty());
  const std::string bad_html = FabricHtml(one);
  EXPECT_NE(bad_html.find("names no matching weave_maps.view_cosines"), std::string::npos);
  EXPECT_EQ(bad_html.find(" at NoV = "), std::string::npos);
}

// The report reads a preset's maps as every reader does: "uri" first (relative to the preset
// file), "file" only without a "uri" (docs/preset-format.md "Weave maps: `uri` and `file`").
TEST_F(ReportWeaveMapPage, ThumbnailsComeFromTheUriNotTheFile) {
  io::Image img;
  img.width = img.height = 8;
  img.channel_names = {"R", "G", "B", "fabric"};
  img.pixels.assign(8 * 8 * 4, 0.5f);
  for (size_t i = 3; i < img.pixels.size(); i += 4) img.pixels[i] = 1.0f;
  const std::string ref = (dir_ / "ref.exr").string();
  io::WriteExr(ref, img);
  fs::create_directories(dir_ / "p");
  io::WriteExr((dir_ / "p" / "m.weave.exr").string(), Maps(8));
  io::WriteExr((dir_ / "outside.weave.exr").string(), Maps(8));
  auto preset = [&](const std::string& model, const nlohmann::json& maps) {
    nlohmann::json j = {
        {"schema", "clothfit.preset"}, {"version", 1}, {"model", model},
        {"parameters", {{"roughness", 0.5}}},
        {"fit", {{"scenes", {{{"scene", "s.json"}, {"reference", ref}, {"tone_mapping", "Linear"},
                              {"exposure", 1.0}, {"preview", ref}}}}}},
        {"provenance", {{"fabric", "datasets/fabrics/canvas.json"}}}, {"weave_maps", maps}};
    const std::string p = (dir_ / "p" / (model + ".json")).string();
    std::ofstream(p) << j.dump();
    return p;
  };
  const std::vector<std::string> presets = {
      preset("woven", {{"uri", "m.weave.exr"}, {"file", "/nonexistent/decoy.weave.exr"}}),
      preset("physical-aniso", {{"uri", "../outside.weave.exr"}, {"file", "m.weave.exr"}})};
  const FabricReport rep = BuildFabricReport(FabricsFromPresets(presets).at(0));
  ASSERT_EQ(rep.weave_maps.size(), 2u);
  ASSERT_TRUE(rep.weave_maps[0].has_value());
  EXPECT_EQ(rep.weave_maps[0]->pictures.size(), 3u) << rep.weave_maps[0]->note;
  ASSERT_TRUE(rep.weave_maps[1].has_value());
  EXPECT_TRUE(rep.weave_maps[1]->pictures.empty());  // the escaping uri, not the readable file
  EXPECT_NE(rep.weave_maps[1]->note.find("weave_maps.uri"), std::string::npos);
  EXPECT_NE(rep.weave_maps[1]->note.find("escapes"), std::string::npos);
}

}  // namespace
}  // namespace clothfit::report
