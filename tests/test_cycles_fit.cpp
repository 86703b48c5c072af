// End to end through a foreign renderer (issue 15, acceptance): scripts/cycles-reference renders
// a tiny Lambert sphere with Blender Cycles (sphere card at 32 x 32: studio environment and two
// suns; RGBA, premultiplied, transparent film, no fabric or stderr channels) and the image fit
// reads it with the default reference options (alpha auto = premultiplied, coverage from A,
// noise estimated from the image) and recovers the Lambert albedo within 2 % per channel.
//
// Model: cloth with its sheen colour locked at 0, i.e. a Lambert diffuse lobe (Filament's cloth
// without sheen: base_color / pi; SH9 irradiance for the environment) plus roughness, which no
// longer enters. The three.js baselines add a GGX layer with F0 = 0.04 that a Lambert
// reference does not have, so their base colour is biased low by the fit (that is a model
// difference, not a reader one, and not what this test checks).
// Skipped without blender (Debian `blender`) or the studio map (scripts/fetch-data).
//
// Real yarns (issue 15, acceptance "a woven Cycles reference with yarn gaps keeps >= 90 % of
// its interior blocks at the auto level"): scripts/cycles-reference --yarns replaces the
// fabric mesh by warp and weft tubes (canvas plain weave) whose holes show the transparent
// film; the fit at the auto level (weave period 1 / uv_repeats in UV, as --weave-period
// 0.125uv) must keep >= 90 % of the blocks that are fully inside the preview's fabric
// silhouette (kept / (kept + dropped for coverage)). Two cards: the swatch seen from straight
// above (written here; the gaps show the film, the hard case; 64 px, uv_repeats 16: yarns of
// ~2 px, holes of ~0.5 px, level 3) and the canonical sphere (96 px, uv_repeats 24; a closed
// surface: most holes show its far side). 4 spp, max depth 4: coverage needs no converged
// radiance. The full-size figures are in docs/references.md.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "fit/image_fit.h"
#include "fit/reference.h"
#include "fit/woven_fit.h"
#include "render/scene/environment.h"
#include "render/scene/scene.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;

const std::string kSource = CLOTHFIT_TEST_SOURCE_DIR;

bool HaveBlenderForFit() { return std::system("command -v blender >/dev/null 2>&1") == 0; }

// Renders `card` with scripts/cycles-reference at size x size, one thread, seed 1, max depth 8;
// `material` is "--fabric 'F'" or "--principled ...". *exr = the image, written in `dir`.
void RenderCycles(const std::string& card, const std::string& material, int spp, int size,
                  const fs::path& dir, std::string* exr) {
  *exr = (dir / "cycles.exr").string();
  const std::string cmd = "'" + kSource + "/scripts/cycles-reference' --scene '" + card + "' " +
                          material + " --spp " + std::to_string(spp) +
                          " --max-depth 8 --threads 1 --seed 1 --width " + std::to_string(size) +
                          " --height " + std::to_string(size) + " --out '" + *exr + "' >'" +
                          (dir / "log").string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd << " (see " << dir << "/log)";
}

// The environment a scene card names (its map must be installed).
render::Environment CardEnvironment(const render::Scene& scene) {
  const render::EnvironmentSpec& e = *scene.card.environment;
  return render::Environment::Load(e.path, e.intensity, e.rotation_y, {});
}

TEST(CyclesFit, LambertSphereAlbedoWithinTwoPercentPerChannel) {
  if (!HaveBlenderForFit()) GTEST_SKIP() << "blender not installed (Debian 'blender')";
  const std::string card = kSource + "/datasets/scenes/sphere.json";
  render::Scene scene = render::LoadScene(card);
  ASSERT_TRUE(scene.card.environment.has_value());
  if (!scene.card.environment->found) GTEST_SKIP() << "studio map not installed (scripts/fetch-data)";
  const int size = 32;
  const fs::path dir = fs::temp_directory_path() / ("clothfit_cycles_fit_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::string exr;
  ASSERT_NO_FATAL_FAILURE(RenderCycles(
      card, "--fabric '" + kSource + "/datasets/materials/lambert.json'", 128, size, dir, &exr));

  const Reference ref = ReadReference(exr, ReferenceOptions{});
  scene.card.width = scene.card.height = size;
  const render::Environment env = CardEnvironment(scene);

  FitOptions o;
  o.start = render::DefaultPreset(render::ModelKind::kCloth);
  o.start.cloth.sheen_default = cloth::SheenDefault::kExplicit;
  const auto table = render::ParameterTable(render::ModelKind::kCloth);
  int off = 0;
  for (const ParamInfo& p : table) {  // sheen colour 0: a Lambert lobe
    if (p.name == "sheen_color")
      for (int c = 0; c < 3; ++c) o.start.values[size_t(off + c)] = 0.0;
    off += p.size;
  }
  o.locked = {"sheen_color"};
  o.level = 2;  // smooth reference: any block size; 4 x 4 keeps enough blocks at 32 px
  const FitResult r = FitImages({{&scene, &env, &ref, nullptr, card}}, o);
  ASSERT_TRUE(r.usable) << r.message;
  const double truth[3] = {0.6, 0.45, 0.3};  // datasets/materials/lambert.json
  std::printf("[cycles fit] %d blocks; base_color %.4f %.4f %.4f (truth 0.6 0.45 0.3); rmse %.4f; %s\n",
              r.scenes.empty() ? 0 : r.scenes[0].blocks, r.preset.values[0], r.preset.values[1],
              r.preset.values[2], r.rmse, r.termination.c_str());
  EXPECT_GT(r.scenes.at(0).blocks, 10);
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(r.preset.values[size_t(c)] / truth[c], 1.0, 0.02) << "channel " << c;
  fs::remove_all(dir);
}

// The swatch card with its camera straight above the swatch (looking down -Y, 2.48 m up: the
// 1 m swatch fills ~90 % of the frame), at size x size; returns the card path.
std::string FrontalSwatchCard(const fs::path& dir, int size) {
  std::ifstream in(kSource + "/datasets/scenes/swatch.gltf");
  nlohmann::json g = nlohmann::json::parse(in);
  for (auto& n : g["nodes"])
    if (n.value("name", "") == "camera") {
      n["translation"] = {0.0, 2.48, 0.0};
      n["rotation"] = {-0.70710678, 0.0, 0.0, 0.70710678};  // -90 degrees about x
    }
  std::ofstream(dir / "swatch-front.gltf") << g.dump();
  std::ifstream cin(kSource + "/datasets/scenes/swatch.json");
  nlohmann::json c = nlohmann::json::parse(cin);
  c["gltf"] = (dir / "swatch-front.gltf").string();
  c["width"] = c["height"] = size;
  std::ofstream(dir / "swatch-front.json") << c.dump(2);
  return (dir / "swatch-front.json").string();
}

// Renders the real-yarn reference of `card` (already at `size` px) and fits it at the auto
// level; returns {kept fraction of the interior blocks, fraction of covered pixels with
// coverage < 0.999}.
void RealYarnFit(const std::string& card, int size, int repeats, const fs::path& dir,
                 double* kept, double* gappy, int* level) {
  render::Scene scene = render::LoadScene(card);
  ASSERT_TRUE(scene.card.environment.has_value());
  if (!scene.card.environment->found) GTEST_SKIP() << "studio map not installed (scripts/fetch-data)";
  scene.card.width = scene.card.height = size;
  const std::string exr = (dir / "yarns.exr").string();
  const std::string cmd = "'" + kSource + "/scripts/cycles-reference' --scene '" + card +
                          "' --fabric '" + kSource + "/datasets/fabrics/canvas.json'" +
                          " --yarns --uv-repeats " + std::to_string(repeats) + " --spp 4 --max-depth 4 --threads 1 --seed 1" +
                          " --width " + std::to_string(size) + " --height " +
                          std::to_string(size) + " --out '" + exr + "' >'" +
                          (dir / "log").string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd << " (see " << dir << "/log)";
  const Reference ref = ReadReference(exr, ReferenceOptions{});
  size_t covered = 0, partial = 0;
  for (float w : ref.weight) {
    covered += w > 0.f;
    partial += w > 0.f && w < 0.999f;
  }
  *gappy = double(partial) / double(std::max<size_t>(covered, 1));
  const render::Environment env = CardEnvironment(scene);
  const std::vector<SceneInput> inputs = {{&scene, &env, &ref, nullptr, card}};
  FitOptions o;
  o.start = render::DefaultPreset(render::ModelKind::kCloth);
  o.level = *level = AutoLevel(inputs, 1.0 / repeats);  // = fit --weave-period <1/repeats>uv
  const FitResult r = FitImages(inputs, o);
  ASSERT_TRUE(r.usable) << r.message;
  const SceneError& s = r.scenes.at(0);
  *kept = double(s.blocks) / double(std::max(s.blocks + s.dropped_coverage, 1));
  std::printf("[real yarns] %s: level %d; %d blocks kept, dropped %d (preview) %d (coverage);"
              " kept %.1f %% of the interior; %.1f %% of covered pixels have coverage < 0.999;"
              " rmse %.4f\n",
              fs::path(card).filename().c_str(), o.level, s.blocks, s.dropped_preview,
              s.dropped_coverage, 100.0 * *kept, 100.0 * *gappy, r.rmse);
  EXPECT_GE(s.blocks, 4);
}

TEST(CyclesFit, RealYarnGapsKeepNinetyPercentOfInteriorBlocksFrontalSwatch) {
  if (!HaveBlenderForFit()) GTEST_SKIP() << "blender not installed (Debian 'blender')";
  const fs::path dir =
      fs::temp_directory_path() / ("clothfit_cycles_yarns_front_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const int size = 64;
  double kept = 0.0, gappy = 0.0;
  int level = 0;
  RealYarnFit(FrontalSwatchCard(dir, size), size, 16, dir, &kept, &gappy, &level);
  if (HasFatalFailure() || IsSkipped()) return;
  EXPECT_GE(level, 2);
  EXPECT_GE(gappy, 0.10);  // the gaps are real: the film shows through the holes
  EXPECT_GE(kept, 0.90);
  fs::remove_all(dir);
}

TEST(CyclesFit, RealYarnGapsKeepNinetyPercentOfInteriorBlocksSphere) {
  if (!HaveBlenderForFit()) GTEST_SKIP() << "blender not installed (Debian 'blender')";
  const fs::path dir =
      fs::temp_directory_path() / ("clothfit_cycles_yarns_sphere_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const int size = 96;
  double kept = 0.0, gappy = 0.0;
  int level = 0;
  RealYarnFit(kSource + "/datasets/scenes/sphere.json", size, 24, dir, &kept, &gappy, &level);
  if (HasFatalFailure() || IsSkipped()) return;
  EXPECT_GE(kept, 0.90);
  fs::remove_all(dir);
}

// Session 26 (docs/fitting.md "A start for glossy references"): a glossy Principled BSDF
// (roughness 0.1, specular 0.5: F0 0.04; Blender's roughness squares to alpha as three.js's
// does; sheen 0.1) on the swatch card at its full 256 x 256, fitted at clothfit fit's level 4
// with three.js's IBL (--ibl-engine auto). The standard fit with the default starts finds the
// glossy basin (roughness within 0.03 of 0.1); from session 25's starts (0.6, 0.9) it stops in
// the broad one (roughness 0.80, RMSE 0.22, in the log line). On the sphere card, or the swatch
// at 64 or 128 px, the old starts find it too.
TEST(CyclesFit, GlossySwatchRoughnessIsFoundByTheDefaultStarts) {
  if (!HaveBlenderForFit()) GTEST_SKIP() << "blender not installed (Debian 'blender')";
  const std::string card = kSource + "/datasets/scenes/swatch.json";
  render::Scene scene = render::LoadScene(card);
  ASSERT_TRUE(scene.card.environment.has_value());
  if (!scene.card.environment->found) GTEST_SKIP() << "studio map not installed (scripts/fetch-data)";
  const int size = 256;  // at 64 and 128 px even the old starts find the glossy basin
  const fs::path dir = fs::temp_directory_path() / ("clothfit_cycles_glossy_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::string exr;
  ASSERT_NO_FATAL_FAILURE(RenderCycles(
      card, "--principled base_color=0.5:0.15:0.1,roughness=0.1,specular=0.5,sheen=0.1", 64, size,
      dir, &exr));
  const Reference ref = ReadReference(exr, ReferenceOptions{});
  scene.card.width = scene.card.height = size;
  const render::Environment env = CardEnvironment(scene);
  FitOptions o;
  o.start = render::DefaultPreset(render::ModelKind::kStandard);
  ApplyModelDefaults(&o);  // metalness locked, as clothfit fit
  o.ibl_engine = render::IblEngine::kAuto;  // as clothfit fit: three.js r187 for standard
  o.level = 4;  // clothfit fit's level without a weave period
  const std::vector<SceneInput> in = {{&scene, &env, &ref, nullptr, card}};
  const FitResult r = FitImages(in, o);
  ASSERT_TRUE(r.usable) << r.message;
  const double rough = r.preset.values[size_t(r.preset.Offset("roughness"))];
  o.start_roughness = {0.6, 0.9};  // session 25's starts, for the log
  const FitResult old = FitImages(in, o);
  std::printf("[cycles glossy] default starts: roughness %.4f rmse %.4f; starts 0.6,0.9: "
              "roughness %.4f rmse %.4f\n",
              rough, r.rmse, old.usable ? old.preset.values[size_t(old.preset.Offset("roughness"))] : -1.0,
              old.usable ? old.rmse : -1.0);
  EXPECT_NEAR(rough, 0.1, 0.03);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace clothfit::fit
