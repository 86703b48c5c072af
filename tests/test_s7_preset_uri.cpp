// Presets that can move (issue 12, s7-gen): a preset's weave_maps "uri" is resolved against the
// directory of the preset FILE first; "file" (absolute) is read only when there is no "uri".
// A bad "uri" (absolute, escaping the preset's directory, a scheme, a symlink out, missing,
// not a string) fails naming the preset file and the field, with untrusted bytes escaped.
// render/preview/weave_maps.h (ResolvePresetWeaveMapPaths, LoadPresetWeaveMaps,
// AddPresetWeaveMapUris); docs/preset-format.md, "Weave maps".
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <string>

#include "fit/convert/convert_io.h"
#include "render/preview/preview.h"
#include "render/preview/weave_maps.h"
#include "render/scene/material.h"
#include "tests/preview_fixtures.h"

namespace clothfit::render {
namespace {

namespace fs = std::filesystem;
constexpr int C = WeaveMaps::kChannels;

fs::path FreshDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("clothfit_s7_preset_uri_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

WeaveMaps RandomMaps(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.1f, 2.0f);
  std::vector<float> v(size_t(16) * 16 * C);
  for (float& x : v) x = u(rng);
  return WeaveMaps::FromLevel0(16, 10.0, std::move(v));
}

std::vector<double> WovenParams() {
  return {0.47, 0.41, 0.31, 0.54, 0.51, 0.46, 0.6, 0.75, -9.0, 0.54, 0.07, 1.6, 0.1, 0.05, 0.02, 0.6,
          0.0};  // diffuse_roughness (session 18; all 17 woven values, session 19)
}

// The preview's pixels of a woven preset read from `preset_path` (as clothfit render-preview
// reads it: ReadPreset, then the maps with the preset's path).
std::vector<Rgb<double>> PreviewOf(const std::string& preset_path) {
  const MaterialPreset p = ReadPreset(preset_path);
  PreviewOptions o;
  o.model = p.model;
  o.weave_maps = LoadPresetWeaveMaps(p, preset_path);
  EXPECT_NE(o.weave_maps, nullptr);
  auto cache = PreviewCache::Build(SphereWithLight(32), nullptr, o);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, WovenParams().data(), out);
  return out;
}

// A woven preset `dir`/woven.json with its maps `dir`/woven.weave.exr, written as clothfit
// fit writes it ("file" absolute, "uri" beside it). Returns the preset's path.
std::string WritePresetDir(const fs::path& dir, const WeaveMaps& maps) {
  const std::string exr = (dir / "woven.weave.exr").string();
  WriteWeaveMaps(exr, maps);
  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  p.extra["weave_maps"] = WeaveMapsPresetField(exr, maps);
  const std::string path = (dir / "woven.json").string();
  AddPresetWeaveMapUris(&p, path);
  WritePreset(path, p);
  return path;
}

double Diff(const std::vector<Rgb<double>>& a, const std::vector<Rgb<double>>& b) {
  double d = 0;
  for (size_t i = 0; i < a.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) d += std::abs(a[i][ch] - b[i][ch]);
  return d / double(std::max<size_t>(a.size(), 1));
}

TEST(PresetUri, FitStylePresetsCarryARelativeUri) {
  const fs::path d = FreshDir("carry");
  fs::create_directories(d / "elsewhere");
  const std::string path = WritePresetDir(d, RandomMaps(1));
  const MaterialPreset back = ReadPreset(path);
  EXPECT_EQ(back.extra.at("weave_maps").at("uri"), "woven.weave.exr");
  EXPECT_TRUE(fs::path(back.extra.at("weave_maps").at("file").get<std::string>()).is_absolute());
  // Maps outside the preset's directory get no uri (there is no relative path to write).
  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  p.extra["weave_maps"] = WeaveMapsPresetField((d / "woven.weave.exr").string(), RandomMaps(1));
  AddPresetWeaveMapUris(&p, (d / "elsewhere" / "p.json").string());
  EXPECT_FALSE(p.extra.at("weave_maps").contains("uri"));
  fs::remove_all(d);
}

// The acceptance of task A: the directory moved elsewhere previews the same pixels, and the
// stale absolute "file" is not read even when a different map now sits at that path.
TEST(PresetUri, AMovedPresetDirectoryPreviewsTheSamePixels) {
  const fs::path root = FreshDir("move");
  const WeaveMaps maps = RandomMaps(2);
  fs::create_directories(root / "a");
  const std::string before_path = WritePresetDir(root / "a", maps);
  const auto before = PreviewOf(before_path);

  // The maps matter in this scene (else the equality below would prove nothing).
  PreviewOptions uniform_o;
  uniform_o.model = ModelKind::kWoven;
  auto cache = PreviewCache::Build(SphereWithLight(32), nullptr, uniform_o);
  std::vector<Rgb<double>> uniform;
  EvaluatePreview(*cache, WovenParams().data(), uniform);
  ASSERT_GT(Diff(before, uniform), 1e-3);

  fs::rename(root / "a", root / "b" );
  const std::string moved = (root / "b" / "woven.json").string();
  // A decoy at the old absolute path: other maps; "file" still names it.
  fs::create_directories(root / "a");
  WriteWeaveMaps((root / "a" / "woven.weave.exr").string(), RandomMaps(99));
  ASSERT_EQ(ReadPreset(moved).extra.at("weave_maps").at("file").get<std::string>(),
            fs::absolute(root / "a" / "woven.weave.exr").lexically_normal().string());

  const auto after = PreviewOf(moved);
  ASSERT_EQ(before.size(), after.size());
  for (size_t i = 0; i < before.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(before[i][ch], after[i][ch]) << "pixel " << i;

  // Remove the decoy: still the same (nothing reads "file" when there is a "uri").
  fs::remove_all(root / "a");
  const auto after2 = PreviewOf(moved);
  for (size_t i = 0; i < before.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(before[i][ch], after2[i][ch]) << "pixel " << i;

  // evaluate's path: the field resolved in place names the moved copy.
  MaterialPreset p = ReadPreset(moved);
  ResolvePresetWeaveMapPaths(&p, moved);
  EXPECT_EQ(fs::path(p.extra.at("weave_maps").at("file").get<std::string>()),
            fs::weakly_canonical(root / "b" / "woven.weave.exr"));
  EXPECT_FALSE(p.extra.at("weave_maps").contains("uri"));
  EXPECT_NE(LoadPresetWeaveMaps(p), nullptr);

  // convert's reader agrees.
  const auto mats = fit::ReadMaterials(moved);
  ASSERT_EQ(mats.size(), 1u);
  ASSERT_TRUE(mats[0].weave_maps);
  EXPECT_EQ(mats[0].weave_maps->levels[0], maps.levels[0]);
  fs::remove_all(root);
}

TEST(PresetUri, UnresolvedUriIsRefusedByTheOneArgumentReader) {
  const fs::path d = FreshDir("unresolved");
  const MaterialPreset p = ReadPreset(WritePresetDir(d, RandomMaps(3)));
  try {
    LoadPresetWeaveMaps(p);
    FAIL() << "the one-argument reader read a preset with an unresolved uri";
  } catch (const MaterialError& e) {
    EXPECT_NE(std::string(e.what()).find("weave_maps.uri"), std::string::npos) << e.what();
  }
  fs::remove_all(d);
}

TEST(PresetUri, FileIsReadWhenThereIsNoUri) {
  const fs::path d = FreshDir("file_only");
  const WeaveMaps maps = RandomMaps(4);
  const std::string exr = (d / "m.weave.exr").string();
  WriteWeaveMaps(exr, maps);
  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  p.extra["weave_maps"] = WeaveMapsPresetField(exr, maps);
  const std::string path = (d / "sub" / "p.json").string();
  fs::create_directories(d / "sub");
  WritePreset(path, p);
  const auto loaded = LoadPresetWeaveMaps(ReadPreset(path), path);
  ASSERT_NE(loaded, nullptr);
  EXPECT_EQ(loaded->levels[0], maps.levels[0]);
  // A uri that stays inside the directory through ".." is fine.
  p.extra["weave_maps"]["uri"] = "sub2/../m.weave.exr";
  const std::string path2 = (d / "p2.json").string();
  WritePreset(path2, p);
  EXPECT_NE(LoadPresetWeaveMaps(ReadPreset(path2), path2), nullptr);
  fs::remove_all(d);
}

// Each bad uri: MaterialError naming the preset file and the field, no raw control byte.
TEST(PresetUri, EachBadUriGivesItsError) {
  const fs::path root = FreshDir("bad");
  fs::create_directories(root / "p");
  const WeaveMaps maps = RandomMaps(5);
  WriteWeaveMaps((root / "p" / "m.weave.exr").string(), maps);
  WriteWeaveMaps((root / "outside.weave.exr").string(), maps);  // exists, but outside
  std::error_code ec;
  fs::create_symlink(root / "outside.weave.exr", root / "p" / "link.weave.exr", ec);
  const bool have_symlink = !ec;

  struct Case {
    std::string key;
    nlohmann::json value;
    std::string expect;  // a substring of the message
  };
  const std::string abs_inside = fs::absolute(root / "p" / "m.weave.exr").string();
  std::vector<Case> cases = {
      {"uri", abs_inside, "is an absolute path"},
      {"uri", "/etc/passwd", "is an absolute path"},
      {"uri", "../outside.weave.exr", "escapes the preset's directory"},
      {"uri", "sub/../../outside.weave.exr", "escapes the preset's directory"},
      {"uri", "nope.weave.exr", "no such file"},
      {"uri", "file:///etc/passwd", "scheme"},
      {"uri", "", "empty path"},
      {"uri", "m\x1b[31m.exr", "control byte"},
      {"uri", 7, "expected a string"},
      {"glint_uri", "/tmp/g.glint.exr", "is an absolute path"},
      {"glint_uri", "../../g.exr", "escapes the preset's directory"},
  };
  if (have_symlink) cases.push_back({"uri", "link.weave.exr", "outside the preset's directory"});

  const std::string preset_path = (root / "p" / "bad\x07name.json").string();
  const std::string shown_preset = (root / "p" / "bad\\x07name.json").string();
  for (const Case& c : cases) {
    MaterialPreset p = DefaultPreset(ModelKind::kWoven);
    p.extra["weave_maps"] = WeaveMapsPresetField((root / "p" / "m.weave.exr").string(), maps);
    p.extra["weave_maps"]["uri"] = "m.weave.exr";  // valid unless the case replaces it
    p.extra["weave_maps"][c.key] = c.value;
    WritePreset(preset_path, p);
    const MaterialPreset back = ReadPreset(preset_path);
    std::string what;
    try {
      LoadPresetWeaveMaps(back, preset_path);
    } catch (const MaterialError& e) {
      what = e.what();
    }
    SCOPED_TRACE(c.key + " = " + c.value.dump());
    ASSERT_FALSE(what.empty()) << "no error";
    EXPECT_NE(what.find(shown_preset), std::string::npos) << what;
    EXPECT_NE(what.find("weave_maps." + c.key), std::string::npos) << what;
    EXPECT_NE(what.find(c.expect), std::string::npos) << what;
    for (unsigned char ch : what) EXPECT_GE(ch, 0x20) << "raw control byte in: " << what;
  }
  // The escaped uri is shown (\x1B for ESC), so the user sees what is wrong.
  {
    MaterialPreset p = DefaultPreset(ModelKind::kWoven);
    p.extra["weave_maps"] = WeaveMapsPresetField((root / "p" / "m.weave.exr").string(), maps);
    p.extra["weave_maps"]["uri"] = "../x\x1b.exr";
    try {
      ResolvePresetWeaveMapPaths(&p, preset_path);
      FAIL() << "no error";
    } catch (const MaterialError& e) {
      const std::string w = e.what();
      EXPECT_TRUE(w.find("\\x1B") != std::string::npos || w.find("\\x1b") != std::string::npos) << w;
    }
  }
  // convert's reader gives the same error (its message names the preset and the field).
  {
    MaterialPreset p = DefaultPreset(ModelKind::kWoven);
    p.extra["weave_maps"] = WeaveMapsPresetField((root / "p" / "m.weave.exr").string(), maps);
    p.extra["weave_maps"]["uri"] = "../outside.weave.exr";
    const std::string cp = (root / "p" / "c.json").string();
    WritePreset(cp, p);
    try {
      fit::ReadMaterials(cp);
      FAIL() << "convert read an escaping uri";
    } catch (const std::exception& e) {
      const std::string w = e.what();
      EXPECT_NE(w.find("c.json"), std::string::npos) << w;
      EXPECT_NE(w.find("weave_maps.uri"), std::string::npos) << w;
      EXPECT_NE(w.find("escapes"), std::string::npos) << w;
    }
  }
  fs::remove_all(root);
}

}  // namespace
}  // namespace clothfit::render
