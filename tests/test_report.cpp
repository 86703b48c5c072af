// Reports (fit/metrics/report.h): a small synthetic fit on disk -> HTML containing every expected
// image and number; JSON/CSV with the same numbers; non-finite inputs reported, never
// propagated; bad inputs give errors naming the file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <limits>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "fit/metrics/metrics.h"
#include "fit/metrics/report.h"
#include "render/scene/image_io.h"

namespace clothfit::report {
namespace {
namespace fs = std::filesystem;

constexpr int kW = 24, kH = 20;

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

// The page without its base64 payloads (so text searches do not hit image data).
std::string WithoutImages(const std::string& html) {
  return std::regex_replace(html, std::regex("base64,[A-Za-z0-9+/=]*"), "base64,");
}

class ReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("clothfit_test_report_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A smooth linear image with values in about [0.05, 0.8] times `gain`; the left 16 columns
  // are fabric when `coverage`.
  std::string WriteImage(const std::string& name, double gain, unsigned seed, bool coverage,
                         int w = kW, int h = kH) {
    io::Image img;
    img.width = w;
    img.height = h;
    img.channel_names = {"R", "G", "B"};
    if (coverage) img.channel_names.push_back("fabric");
    const size_t nc = img.channel_names.size();
    img.pixels.resize(size_t(w) * size_t(h) * nc);
    unsigned s = seed * 2654435761u + 7u;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        float* p = &img.pixels[(size_t(y) * size_t(w) + size_t(x)) * nc];
        for (int c = 0; c < 3; ++c) {
          s = s * 1664525u + 1013904223u;
          const double noise = 0.02 * double(s >> 8) / double(1u << 24);
          p[c] = float(gain * (0.4 + 0.3 * std::sin(0.3 * x + c) * std::cos(0.2 * y) + noise));
        }
        if (coverage) p[3] = x < 16 ? 1.0f : 0.0f;
      }
    const std::string path = (dir_ / name).string();
    io::WriteExr(path, img);
    return path;
  }

  // A preset as clothfit fit writes it (the fields the report reads).
  std::string WritePreset(const std::string& name, const std::string& model,
                          const std::vector<std::string>& previews, nlohmann::json parameters,
                          nlohmann::json final_cost = 0.125) {
    nlohmann::json scenes = nlohmann::json::array();
    for (size_t i = 0; i < previews.size(); ++i)
      scenes.push_back({{"scene", "datasets/scenes/scene" + std::to_string(i) + ".json"},
                        {"reference", refs_[i]},
                        {"reference2", refs2_[i]},
                        {"tone_mapping", "ACESFilmic"},
                        {"exposure", 1.0},
                        {"preview", previews[i]},
                        {"rmse", 0.01},
                        {"noise_floor", 0.004}});
    nlohmann::json j = {
        {"schema", "clothfit.preset"},
        {"version", 1},
        {"model", model},
        {"parameters", parameters},
        {"fit",
         {{"iterations", 17},
          {"starts", 2},
          {"initial_cost", 3.5},
          {"final_cost", final_cost},
          {"seconds", 1.25},
          {"setup_seconds", 0.5},
          {"termination", "CONVERGENCE"},
          {"space", "display"},
          {"loss", "huber"},
          {"block_pixels", 8},
          {"rmse", 0.0123},
          {"solver", "Ceres Solver Report: Iterations: 17"},
          {"env_sun", "panels"},
          {"scenes", scenes}}},
        {"provenance", {{"tool", "clothfit test"}, {"fabric", "datasets/fabrics/testcloth.json"}}}};
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << j.dump(2);
    return path;
  }

  // Two scenes, two models (cloth, standard).
  std::vector<std::string> MakeFit() {
    for (int i = 0; i < 2; ++i) {
      refs_.push_back(WriteImage("ref" + std::to_string(i) + ".exr", 1.0, 1 + unsigned(i), true));
      refs2_.push_back(
          WriteImage("ref2_" + std::to_string(i) + ".exr", 1.0, 11 + unsigned(i), true));
      cloth_.push_back(
          WriteImage("cloth" + std::to_string(i) + ".exr", 1.08, 21 + unsigned(i), false));
      standard_.push_back(
          WriteImage("std" + std::to_string(i) + ".exr", 0.8, 31 + unsigned(i), false));
    }
    return {
        WritePreset("standard.json", "standard", standard_,
                    {{"base_color", {0.5, 0.25, 0.125}}, {"roughness", 0.75}, {"metalness", 0.0}}),
        WritePreset("cloth.json", "cloth", cloth_,
                    {{"base_color", {0.2, 0.3, 0.4}},
                     {"sheen_color", {1.0, 1.0, 1.0}},
                     {"roughness", 0.6}})};
  }

  fs::path dir_;
  std::vector<std::string> refs_, refs2_, cloth_, standard_;
};

TEST(ReportHelpers, Base64KnownVectors) {
  // RFC 4648 section 10 test vectors.
  EXPECT_EQ(Base64(std::string("")), "");
  EXPECT_EQ(Base64(std::string("f")), "Zg==");
  EXPECT_EQ(Base64(std::string("fo")), "Zm8=");
  EXPECT_EQ(Base64(std::string("foo")), "Zm9v");
  EXPECT_EQ(Base64(std::string("foob")), "Zm9vYg==");
  EXPECT_EQ(Base64(std::string("fooba")), "Zm9vYmE=");
  EXPECT_EQ(Base64(std::string("foobar")), "Zm9vYmFy");
  EXPECT_EQ(Base64(std::string("\xff\xfe\x00", 3)), "//4A");
}

TEST(ReportHelpers, NumbersSwatchesEscaping) {
  EXPECT_EQ(FormatNumber(0.12345, 3), "0.123");
  EXPECT_EQ(FormatNumber(std::nan(""), 3), "n/a (not finite in input)");
  EXPECT_EQ(FormatNumber(std::numeric_limits<double>::infinity(), 3), "n/a (not finite in input)");
  EXPECT_EQ(FormatNumber(std::numeric_limits<double>::infinity(), 3, true), "inf");
  // Linear 0.5 is sRGB 1.055 * 0.5^(1/2.4) - 0.055 = 0.7354 -> 187.5 -> 188 = 0xbc; linear
  // 0.2 is sRGB 0.4845 -> 123.5 -> 124 = 0x7c; out-of-range values are clamped.
  EXPECT_EQ(SrgbHex(1.0, 0.0, 0.5), "#ff00bc");
  EXPECT_EQ(SrgbHex(0.2, 2.0, -1.0), "#7cff00");
  EXPECT_EQ(SrgbHex(std::nan(""), 0, 0), "");
  EXPECT_EQ(EscapeHtml("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
  EXPECT_EQ(PageName("canvas"), "canvas.html");
  EXPECT_EQ(PageName("a b/c"), "a_b_c.html");
  EXPECT_EQ(PageName("index"), "fabric-index.html");
}

TEST(ReportHelpers, PngEncodingInMemory) {
  const std::vector<float> rgb(3 * 4 * 2, 0.5f);
  const std::vector<unsigned char> png = io::EncodePng8(4, 2, rgb, "test");
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(std::string(png.begin(), png.begin() + 8), std::string("\x89PNG\r\n\x1a\n", 8));
}

TEST_F(ReportTest, HtmlContainsEveryImageAndNumber) {
  const std::vector<std::string> presets = MakeFit();
  const std::vector<FabricSpec> specs = FabricsFromPresets(presets);
  ASSERT_EQ(specs.size(), 1u);
  EXPECT_EQ(specs[0].name, "testcloth");
  ASSERT_EQ(specs[0].models.size(), 2u);
  EXPECT_EQ(specs[0].models[0].model, "cloth");  // canonical order, not argument order
  const FabricReport rep = BuildFabricReport(specs[0]);
  const std::string html = FabricHtml(rep);
  const std::string text = WithoutImages(html);

  // Per scene: reference, 2 previews, noise-floor FLIP, 2 model FLIP maps.
  EXPECT_EQ(Count(html, "src=\"data:image/png;base64,"), 2u * 6u);
  for (const char* alt : {"reference scene0", "cloth preview scene0", "standard preview scene1",
                          "FLIP noise floor scene1", "cloth FLIP scene0", "standard FLIP scene1"})
    EXPECT_NE(text.find("alt=\"" + std::string(alt) + "\""), std::string::npos) << alt;
  for (const char* title : {"reference", "cloth (Filament)", "MeshStandardMaterial", "noise floor",
                            "Fitted parameters", "Solver"})
    EXPECT_NE(text.find(title), std::string::npos) << title;

  // The numbers: computed independently with metrics::Compare over the fabric pixels.
  metrics::Map mask(kW, kH);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) mask.values[size_t(y * kW + x)] = x < 16 ? 1.0f : 0.0f;
  std::vector<double> flips;
  for (int i = 0; i < 2; ++i) {
    const metrics::RgbImage ref = metrics::ToRgb(io::ReadImage(refs_[size_t(i)]), "ref");
    const metrics::RgbImage test = metrics::ToRgb(io::ReadImage(cloth_[size_t(i)]), "cloth");
    metrics::CompareOptions o;
    o.hdr_range = metrics::AutomaticExposureRange(ref, &mask);
    const metrics::CompareResult r = metrics::Compare(ref, test, o, &mask);
    EXPECT_NEAR(rep.scenes[size_t(i)].models[0].numbers.rmse_display, r.rmse_display, 1e-12);
    EXPECT_NEAR(rep.scenes[size_t(i)].models[0].numbers.flip, r.flip, 1e-12);
    for (const std::string& v :
         {FormatNumber(r.rmse_display, 4), FormatNumber(r.psnr_display, 2), FormatNumber(r.ssim, 4),
          FormatNumber(r.flip, 4), FormatNumber(r.hdr_flip, 4),
          FormatNumber(r.ciede2000_display_mean, 2), FormatNumber(r.ciede2000_display_p95, 2),
          FormatNumber(r.rmse_linear, 4)})
      EXPECT_NE(text.find("<td>" + v + "</td>"), std::string::npos) << "scene " << i << ": " << v;
    flips.push_back(r.flip);
  }
  EXPECT_EQ(rep.scenes[0].fabric_pixels, 16 * kH);
  EXPECT_TRUE(rep.scenes[0].mask_from_coverage);
  // Mean over scenes.
  EXPECT_NE(text.find("<td>" + FormatNumber(0.5 * (flips[0] + flips[1]), 4) + "</td>"),
            std::string::npos);
  // Parameters (linear values, sRGB swatches) and the solver summary.
  EXPECT_NE(text.find("(0.5000, 0.2500, 0.1250)"), std::string::npos);
  EXPECT_NE(text.find("background:" + SrgbHex(0.5, 0.25, 0.125)), std::string::npos);
  EXPECT_NE(text.find("#ffffff"), std::string::npos);  // sheen_color (1, 1, 1)
  EXPECT_NE(text.find("0.7500"), std::string::npos);
  EXPECT_NE(text.find("<td>17</td>"), std::string::npos);
  EXPECT_NE(text.find("CONVERGENCE"), std::string::npos);
  EXPECT_NE(text.find("<td>0.1250</td>"), std::string::npos);  // final cost
  EXPECT_NE(text.find("<td>0.0040</td>"), std::string::npos);  // fit noise floor
  EXPECT_NE(text.find("<td class=\"l\">panels</td>"), std::string::npos);  // fit.env_sun (s21)
  EXPECT_EQ(text.find("nan"), std::string::npos);
  EXPECT_EQ(text.find("n/a"), std::string::npos);  // nothing missing here

  // Index, JSON, CSV, terminal: the same numbers.
  const std::vector<FabricReport> all = {rep};
  const std::string index = IndexHtml(all);
  EXPECT_NE(index.find("href=\"testcloth.html\""), std::string::npos);
  EXPECT_NE(index.find(FormatNumber(rep.model_means[0].flip, 4)), std::string::npos);
  EXPECT_NE(index.find("<script>"), std::string::npos);
  // Session 27: "Which model" in words: the lowest fit error (fit.rmse, both 0.0123 here: the
  // first in canonical order) and the lowest per-pixel FLIP.
  const size_t which = index.find("<h2>Which model</h2>");
  ASSERT_NE(which, std::string::npos);
  EXPECT_NE(index.find("has the lowest fit error (block RMSE 0.0123", which), std::string::npos);
  const double flip_min = std::min(rep.model_means[0].flip, rep.model_means[1].flip);
  EXPECT_NE(index.find("lowest per-pixel FLIP (" + FormatNumber(flip_min, 3) + ")", which),
            std::string::npos)
      << index.substr(which, 600);
  const nlohmann::json j = ReportJson(all);
  EXPECT_DOUBLE_EQ(j["fabrics"][0]["scenes"][1]["models"]["cloth"]["flip"].get<double>(), flips[1]);
  EXPECT_DOUBLE_EQ(j["fabrics"][0]["models"][0]["mean"]["flip"].get<double>(),
                   rep.model_means[0].flip);
  const std::string csv = ReportCsv(all);
  EXPECT_EQ(Count(csv, "\n"), 1u + 2u * 3u + 3u);  // header, 2 scenes x 3 rows, 3 mean rows
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", flips[0]);
  EXPECT_NE(csv.find(buf), std::string::npos);
  const std::string table = TerminalTable(all);
  EXPECT_NE(table.find("noise floor"), std::string::npos);
  EXPECT_NE(table.find(FormatNumber(rep.model_means[1].rmse_display, 4)), std::string::npos);
  // Every line the same length whatever the names (session 27: a 24-character fabric name
  // pushed its numbers out of their columns).
  std::vector<FabricReport> long_name = all;
  long_name[0].spec.name = "a_fabric_with_a_long_name";
  for (const auto& [t, name] : {std::pair{table, all[0].spec.name},
                                 std::pair{TerminalTable(long_name), long_name[0].spec.name}}) {
    std::istringstream lines(t);
    std::string line, first;
    std::getline(lines, first);
    int rows = 0;
    while (std::getline(lines, line))
      if (line.rfind(name + " ", 0) == 0) {
        EXPECT_EQ(line.size(), first.size()) << t;
        ++rows;
      }
    EXPECT_EQ(rows, 3) << t;  // noise floor and two models
  }

  // Written atomically to a directory.
  const std::string index_path = WriteReport(all, (dir_ / "out").string());
  EXPECT_TRUE(fs::exists(index_path));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "testcloth.html"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "report.json"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "report.csv"));
}

TEST_F(ReportTest, NonFiniteInputsAreReportedNotPropagated) {
  std::vector<std::string> presets = MakeFit();
  // Scene 0 of the cloth preview: a few NaN/Inf pixels. Scene 1: every pixel NaN.
  io::Image some = io::ReadImage(cloth_[0]);
  some.metadata.clear();
  some.pixels[0] = std::numeric_limits<float>::quiet_NaN();
  some.pixels[3 * 5 + 1] = std::numeric_limits<float>::infinity();
  io::WriteExr(cloth_[0], some);
  io::Image all = io::ReadImage(cloth_[1]);
  all.metadata.clear();
  for (float& v : all.pixels) v = std::numeric_limits<float>::quiet_NaN();
  io::WriteExr(cloth_[1], all);
  // The preset: a NaN final cost (JSON null, as nlohmann writes NaN) and a null colour channel.
  presets[1] = WritePreset("cloth.json", "cloth", cloth_,
                           {{"base_color", {0.2, nullptr, 0.4}}, {"roughness", nullptr}}, nullptr);
  const FabricReport rep = BuildFabricReport(FabricsFromPresets(presets)[0]);
  const Numbers& partial = rep.scenes[0].models[0].numbers;
  ASSERT_TRUE(partial.ok);
  EXPECT_EQ(partial.counts.nonfinite_test, 2);
  EXPECT_TRUE(std::isfinite(partial.flip));
  const Numbers& none = rep.scenes[1].models[0].numbers;
  EXPECT_FALSE(none.ok);
  EXPECT_EQ(none.why, "NaN/Inf in input");
  EXPECT_FALSE(rep.model_means[0].ok);  // the mean names the scene
  EXPECT_NE(rep.model_means[0].why.find("scene1"), std::string::npos);
  EXPECT_TRUE(rep.model_means[1].ok);  // the other model is unaffected

  const std::string text = WithoutImages(FabricHtml(rep));
  EXPECT_NE(text.find("n/a (NaN/Inf in input)"), std::string::npos);
  EXPECT_NE(text.find("NaN/Inf pixels excluded: preview 2"), std::string::npos);
  EXPECT_NE(text.find("n/a (not finite in input)"), std::string::npos);  // cost, parameters
  // No "nan" or "inf" token anywhere in the text of the page or the tables.
  const std::regex bad("\\b(nan|inf|-inf|NaN|Infinity)\\b");
  std::string stripped = std::regex_replace(text, std::regex("NaN/Inf"), "");
  EXPECT_FALSE(std::regex_search(stripped, bad)) << "page";
  const std::vector<FabricReport> reps = {rep};
  EXPECT_FALSE(std::regex_search(
      std::regex_replace(WithoutImages(IndexHtml(reps)), std::regex("NaN/Inf"), ""), bad))
      << "index";
  const std::string json = ReportJson(reps).dump();
  EXPECT_EQ(json.find("nan"), std::string::npos);
  EXPECT_NE(json.find("\"flip\":null"), std::string::npos);
  const std::string csv = std::regex_replace(ReportCsv(reps), std::regex("NaN/Inf"), "");
  EXPECT_FALSE(std::regex_search(csv, bad)) << csv;
  EXPECT_FALSE(
      std::regex_search(std::regex_replace(TerminalTable(reps), std::regex("NaN/Inf"), ""), bad));
}

// Session 27: presets fitted to the user's own references (no provenance.fabric) are grouped by
// those references, named from the words their file stems share, whatever the presets' own file
// names; another set of references with the same name is another fabric, not an error.
TEST_F(ReportTest, OwnReferencesAreGroupedByTheirReferences) {
  const std::vector<std::string> presets = MakeFit();
  const auto strip = [&](const std::string& path, const std::string& out,
                         const std::vector<std::string>& refs) {
    nlohmann::json j = nlohmann::json::parse(std::ifstream(path));
    j.erase("provenance");
    for (size_t i = 0; i < refs.size(); ++i) j["fit"]["scenes"][i]["reference"] = refs[i];
    const std::string o = (dir_ / out).string();
    std::ofstream(o) << j.dump();
    return o;
  };
  // Stems glos_sphere_s1 / glos_swatch_s1 share the word "glos".
  fs::create_directories(dir_ / "a");
  fs::create_directories(dir_ / "b");
  std::vector<std::string> ra, rb;
  for (int i = 0; i < 2; ++i) {
    const std::string stem = i == 0 ? "glos_sphere_s1.exr" : "glos_swatch_s1.exr";
    fs::copy_file(refs_[size_t(i)], dir_ / "a" / stem);
    fs::copy_file(refs2_[size_t(i)], dir_ / "b" / stem);
    ra.push_back((dir_ / "a" / stem).string());
    rb.push_back((dir_ / "b" / stem).string());
  }
  const std::vector<FabricSpec> specs = FabricsFromPresets(
      {strip(presets[0], "woven.json", ra), strip(presets[1], "physical-sheen.json", ra),
       strip(presets[1], "other.json", rb)});
  ASSERT_EQ(specs.size(), 2u);
  EXPECT_EQ(specs[0].name, "glos");
  EXPECT_EQ(specs[0].models.size(), 2u);  // one page, both models
  EXPECT_EQ(specs[1].name, "glos-2");     // the same name, other references
  EXPECT_EQ(specs[1].models.size(), 1u);
  EXPECT_EQ(specs[1].scenes[0].reference, rb[0]);
}

// Session 28: a fit to the user's own references whose name (from the reference stems) is a
// fabric's name: both orders of the arguments give the same pages, the fabric keeps its name
// and the references' fit becomes "NAME-2". Before, the fabric given second was refused ("its
// scenes or references differ") or given first, named the other fit's page.
TEST_F(ReportTest, OwnReferencesNamedLikeAFabricDoNotDependOnArgumentOrder) {
  const std::vector<std::string> presets = MakeFit();
  const std::string fabric_name = "testcloth";  // MakeFit's provenance.fabric
  fs::create_directories(dir_ / "c");
  nlohmann::json j = nlohmann::json::parse(std::ifstream(presets[1]));
  j.erase("provenance");
  for (size_t i = 0; i < j["fit"]["scenes"].size(); ++i) {
    const fs::path ref = dir_ / "c" / (fabric_name + "_" + std::to_string(i) + ".exr");
    fs::copy_file(refs2_[i], ref);
    j["fit"]["scenes"][i]["reference"] = ref.string();
  }
  const std::string own = (dir_ / "own.json").string();
  std::ofstream(own) << j.dump();
  for (const bool own_first : {true, false}) {
    const std::vector<FabricSpec> specs =
        FabricsFromPresets(own_first ? std::vector<std::string>{own, presets[0]}
                                     : std::vector<std::string>{presets[0], own});
    ASSERT_EQ(specs.size(), 2u) << "own first: " << own_first;
    const FabricSpec& fabric = specs[own_first ? 1 : 0];
    const FabricSpec& mine = specs[own_first ? 0 : 1];
    EXPECT_EQ(fabric.name, fabric_name) << "own first: " << own_first;
    EXPECT_FALSE(fabric.fabric_path.empty());
    EXPECT_EQ(mine.name, fabric_name + "-2") << "own first: " << own_first;
    EXPECT_TRUE(mine.fabric_path.empty());
  }
}

TEST_F(ReportTest, BadInputsNameTheFile) {
  const std::vector<std::string> presets = MakeFit();
  // Missing preset.
  const std::string missing = (dir_ / "nope.json").string();
  try {
    FabricsFromPresets({missing});
    FAIL() << "missing preset accepted";
  } catch (const ReportError& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos) << e.what();
  }
  // Malformed JSON.
  const std::string broken = (dir_ / "broken.json").string();
  std::ofstream(broken) << "{\"model\": ";
  EXPECT_THROW(FabricsFromPresets({broken}), ReportError);
  // A preset without previews (fit without --images).
  nlohmann::json j = nlohmann::json::parse(std::ifstream(presets[0]));
  j["fit"]["scenes"][0].erase("preview");
  const std::string no_preview = (dir_ / "nopreview.json").string();
  std::ofstream(no_preview) << j.dump();
  try {
    FabricsFromPresets({no_preview});
    FAIL() << "preset without preview accepted";
  } catch (const ReportError& e) {
    EXPECT_NE(std::string(e.what()).find("nopreview.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("preview"), std::string::npos) << e.what();
  }
  // Missing preview file.
  fs::remove(standard_[1]);
  try {
    BuildFabricReport(FabricsFromPresets(presets)[0]);
    FAIL() << "missing preview accepted";
  } catch (const ReportError& e) {
    EXPECT_NE(std::string(e.what()).find(standard_[1]), std::string::npos) << e.what();
  }
  // Size mismatch.
  WriteImage("std1.exr", 1.0, 3, false, kW, kH + 1);
  try {
    BuildFabricReport(FabricsFromPresets(presets)[0]);
    FAIL() << "size mismatch accepted";
  } catch (const ReportError& e) {
    EXPECT_NE(std::string(e.what()).find(standard_[1]), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("differs"), std::string::npos) << e.what();
  }
  // Corrupt EXR (a valid magic number, then garbage).
  std::ofstream(standard_[1], std::ios::binary) << std::string("\x76\x2f\x31\x01garbage", 11);
  try {
    BuildFabricReport(FabricsFromPresets(presets)[0]);
    FAIL() << "corrupt EXR accepted";
  } catch (const ReportError& e) {
    EXPECT_NE(std::string(e.what()).find(standard_[1]), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace clothfit::report

namespace clothfit::report {
namespace {

// Issue 13: each fitted preset links to web/viewer.html with its scene card and preset.
// Session 27: absolute links to serve.mjs's address (kViewerOrigin), the preset and card as URL
// paths on that server: /<path in the repository>, or /fs/<absolute path> for a file outside it,
// with the --root directories serve.mjs then needs named on the page.
TEST_F(ReportTest, FittedPresetsLinkToTheViewerWithExistingCardAndPreset) {
  // A repository-like tree: dir_/repo/web/viewer.html, dir_/repo/datasets/scenes/scene{0,1}.json
  // (the paths the presets name, relative), the presets in dir_ (outside the repository), the
  // report in dir_/repo/out.
  const fs::path repo = dir_ / "repo";
  fs::create_directories(repo / "web");
  std::ofstream(repo / "web" / "viewer.html") << "<!doctype html>\n";
  fs::create_directories(repo / "datasets" / "scenes");
  for (int i = 0; i < 2; ++i)
    std::ofstream(repo / "datasets" / "scenes" / ("scene" + std::to_string(i) + ".json")) << "{}";
  const std::vector<FabricReport> all = {BuildFabricReport(FabricsFromPresets(MakeFit())[0])};
  WriteReport(all, (repo / "out").string());
  std::ifstream in(repo / "out" / "testcloth.html");
  const std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::regex link("<a class=\"viewer\" href=\"([^\"?]*)\\?preset=([^\"&]*)&amp;card=([^\"]*)\">");
  size_t n = 0;
  std::set<std::string> presets;
  // serve.mjs's mapping: /fs/<absolute> -> the file, /<rel> -> repo/<rel>
  const auto served = [&](const std::string& url_path) {
    return url_path.rfind("/fs/", 0) == 0 ? fs::path(url_path.substr(3))
                                           : repo / url_path.substr(1);
  };
  for (auto it = std::sregex_iterator(html.begin(), html.end(), link); it != std::sregex_iterator();
       ++it, ++n) {
    EXPECT_EQ((*it)[1].str(), std::string(kViewerOrigin) + "/web/viewer.html");
    EXPECT_TRUE(fs::exists(served((*it)[2].str()))) << (*it)[2].str();
    EXPECT_TRUE(fs::exists(served((*it)[3].str()))) << (*it)[3].str();
    EXPECT_EQ((*it)[3].str().rfind("/datasets/scenes/scene", 0), 0u) << (*it)[3].str();
    presets.insert((*it)[2].str());
  }
  EXPECT_EQ(n, 4u);  // 2 models x 2 scenes
  const std::string d = fs::absolute(dir_).lexically_normal().generic_string();
  EXPECT_EQ(presets, (std::set<std::string>{"/fs" + d + "/standard.json", "/fs" + d + "/cloth.json"}));
  // a '#' or '%' in a file name reaches the server as part of the name: encoded in the path
  // segment, then once more as a query value (the viewer's URLSearchParams undoes the second)
  const std::string odd = (dir_ / "st#d%.json").string();
  fs::copy_file(dir_ / "standard.json", odd);
  const std::string href = ViewerLink((repo / "out").string(), "datasets/scenes/scene0.json", odd);
  EXPECT_NE(href.find("?preset=/fs" + d + "/st%2523d%2525.json&card=/datasets/scenes/scene0.json"),
            std::string::npos)
      << href;
  // the page names the server command with the one outside directory
  EXPECT_NE(html.find("node web/serve.mjs --root " + d + "</code>"), std::string::npos)
      << html.substr(html.find("three.js viewer"), 300);
}

// Session 28: the page's --root list also names the directories of the files the viewer
// fetches through the preset and the cards: a weave map named relative to the preset, a card's
// glTF and an environment given as a path (before: only the preset's and the cards' own).
TEST_F(ReportTest, ViewerRootsNameTheMapsMeshAndEnvironmentDirectories) {
  const fs::path repo = dir_ / "repo";
  fs::create_directories(repo / "web");
  std::ofstream(repo / "web" / "viewer.html") << "<!doctype html>\n";
  for (const char* d : {"presets", "maps", "cards", "meshes", "env"})
    fs::create_directories(dir_ / d);
  std::ofstream(dir_ / "maps" / "m.weave.exr") << "x";
  std::ofstream(dir_ / "meshes" / "m.gltf") << "{}";
  std::ofstream(dir_ / "env" / "e.exr") << "x";
  std::ofstream(dir_ / "cards" / "c.json")
      << R"({"gltf": "../meshes/m.gltf", "environment": {"path": "../env/e.exr"}})";
  std::ofstream(dir_ / "cards" / "named.json")
      << R"({"gltf": "../meshes/m.gltf", "environment": {"path": "studio"}})";
  std::ofstream(dir_ / "presets" / "p.json") << R"({"weave_maps": {"file": "../maps/m.weave.exr"}})";
  const auto abs = [](const fs::path& p) {
    return fs::absolute(p).lexically_normal().generic_string();
  };
  const std::vector<std::string> roots =
      ViewerRoots((repo / "out").string(), (dir_ / "presets" / "p.json").string(),
                  {(dir_ / "cards" / "c.json").string(), (dir_ / "cards" / "named.json").string()});
  const std::set<std::string> got(roots.begin(), roots.end());
  EXPECT_EQ(got, (std::set<std::string>{abs(dir_ / "presets"), abs(dir_ / "maps"),
                                        abs(dir_ / "cards"), abs(dir_ / "meshes"),
                                        abs(dir_ / "env")}));
  EXPECT_EQ(roots.size(), got.size());  // each directory once
  // A corrupt card or a missing one is no error here (the viewer reports it): its own
  // directory, nothing else.
  fs::create_directories(dir_ / "bad");
  std::ofstream(dir_ / "bad" / "c.json") << "{\"gltf\": ";
  const std::vector<std::string> bad =
      ViewerRoots((repo / "out").string(), (dir_ / "bad" / "c.json").string(),
                  {(dir_ / "bad" / "c.json").string(), (dir_ / "bad" / "none.json").string()});
  EXPECT_EQ(bad, std::vector<std::string>{abs(dir_ / "bad")});
}

}  // namespace
}  // namespace clothfit::report
