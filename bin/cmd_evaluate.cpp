// clothfit evaluate: the block error of a fitted preset against references, without refitting.
//
// The error is the fit's own (fit/image_fit.h): the same blocks (the preset's fit.level and
// fit.pixel_stride, coverage rule of docs/references.md), the same residual space
// (fit.space), the same unweighted block RMSE. It is computed by FitImages with every
// parameter locked at the preset's values (Ceres then has no free parameter and returns at
// once), so "evaluate" and "fit" cannot drift apart. Without --references the preset's own
// fit.scenes (scene card + reference) are evaluated: the in-sample error, which must equal
// fit.rmse. With --references/--scenes: out-of-sample (e.g. scripts/cross-env: the same
// fabric under another environment).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <fstream>
#include <memory>
#include <optional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "render/scene/sun.h"
#include "bin/visibility_flags.h"
#include "fit/image_fit.h"
#include "fit/reference.h"
#include "fit/yarn_farfield.h"
#include "render/preview/weave_maps.h"
#include "render/scene/input_limits.h"
#include "render/scene/material.h"

namespace clothfit::cli {

void AddEvaluateCommand(CLI::App& app, const Globals& g, int& exit_code);

namespace {

struct EvaluateArgs {
  std::string preset, references, scenes;
  int level = -1, stride = -1;
  int exact_ibl = 0, exact_irradiance = 0;
  unsigned exact_ibl_seed = 1;
  // s10-velvet sheen nap prototype (docs/velvet.md): NaN = the preset's fit.sheen_tilt_degrees
  // (0 without it).
  double sheen_tilt = std::numeric_limits<double>::quiet_NaN();
  bool json = false;
  std::string ibl_engine = "preset";  // preset: the fit's recorded fit.ibl_engine (else filament)
  std::string env_sun = "preset";  // s10-sun: preset = fit.env_sun, else the cards' (else off)
  VisibilityFlags visibility;  // --shadows, --ao, --indirect (docs/visibility.md)
};

int RunEvaluate(const EvaluateArgs& a, bool quiet) {
  std::ifstream in(a.preset);
  if (!in) throw std::runtime_error(a.preset + ": cannot open the preset");
  const nlohmann::json pj = nlohmann::json::parse(in, nullptr, true);
  render::MaterialPreset preset = render::ReadPreset(a.preset);
  // weave_maps "uri" resolved against the preset file's directory (render/preview/weave_maps.h)
  render::ResolvePresetWeaveMapPaths(&preset, a.preset);
  if (!pj.contains("fit") || !pj["fit"].is_object())
    throw std::runtime_error(a.preset + ": field 'fit': missing (evaluate needs a fitted preset)");
  const nlohmann::json& fj = pj["fit"];
  // Session 11 measurement fits (clothfit fit --yarn-lobe): drawn with the same lobe from
  // fit.yarn_lobe_settings (fit/yarn_farfield.h); without the settings, refused.
  std::optional<fit::YarnLobeSettings> yarn_lobe;
  if (fj.contains("yarn_lobe")) {
    if (!fj.contains("yarn_lobe_settings"))
      throw std::runtime_error(a.preset + ": field 'fit.yarn_lobe_settings': missing (fitted with "
                               "the far-field yarn lobe, a measurement: its colours scale that "
                               "lobe, which evaluate needs the settings to draw)");
    yarn_lobe = fit::YarnLobeSettingsFromJson(fj["yarn_lobe_settings"],
                                              a.preset + ": field fit.yarn_lobe_settings");
  }
  std::vector<std::string> scenes = SplitList(a.scenes), refs = SplitList(a.references);
  if (refs.empty() != scenes.empty())
    throw std::invalid_argument("give both --references and --scenes, or neither");
  if (refs.empty()) {
    if (!fj.contains("scenes") || !fj["scenes"].is_array())
      throw std::runtime_error(a.preset + ": field 'fit.scenes': missing");
    for (const auto& s : fj["scenes"]) {
      scenes.push_back(s.at("scene").get<std::string>());
      refs.push_back(s.at("reference").get<std::string>());
    }
  }
  if (refs.size() != scenes.size())
    throw std::invalid_argument(std::to_string(refs.size()) + " references but " +
                                std::to_string(scenes.size()) + " scenes");

  fit::FitOptions o;
  o.start = preset;
  for (const auto& p : render::ParameterTable(preset.model)) o.locked.emplace_back(p.name);
  o.level = a.level >= 0 ? a.level : fj.value("level", 4);
  o.pixel_stride = a.stride >= 0 ? a.stride : fj.value("pixel_stride", 0);
  o.space = fit::ParseSpace(fj.value("space", std::string("display")));
  o.start_roughness = {0.5};  // one "start": every parameter is locked at the preset's value
  o.init_from_reference = false;
  o.exact_ibl_samples = a.exact_ibl;
  o.exact_ibl_seed = a.exact_ibl_seed;
  o.exact_irradiance_samples = a.exact_irradiance;
  o.sheen_tilt_degrees = a.sheen_tilt;
  if (std::isnan(a.sheen_tilt)) {
    o.sheen_tilt_degrees = 0.0;
    if (fj.contains("sheen_tilt_degrees")) {
      if (!fj["sheen_tilt_degrees"].is_number())
        throw std::runtime_error(a.preset + ": field 'fit.sheen_tilt_degrees': expected a number");
      o.sheen_tilt_degrees = fj["sheen_tilt_degrees"].get<double>();
      // Named here, before the preview's own (unnamed) checks: the file and the field.
      const double t = o.sheen_tilt_degrees;
      const std::string field = a.preset + ": field 'fit.sheen_tilt_degrees': ";
      if (!std::isfinite(t) || std::abs(t) > 90.0)
        throw std::runtime_error(field + "expected degrees in [-90, 90], got " + std::to_string(t));
      if (t != 0.0 && preset.model != render::ModelKind::kCloth &&
          preset.model != render::ModelKind::kWoven)
        throw std::runtime_error(field + "a sheen tilt applies to the cloth and woven models only, "
                                 "not " + render::ToString(preset.model));
      if (t != 0.0 && preset.model == render::ModelKind::kCloth && preset.cloth.subsurface)
        throw std::runtime_error(field + "a sheen tilt is not implemented for cloth with subsurface");
    }
  }
  ApplyVisibilityFlags(a.visibility, &o);
  if (yarn_lobe) {
    if (yarn_lobe->mode == "farfield" && a.exact_ibl <= 0)
      throw std::runtime_error(a.preset + ": field 'fit.yarn_lobe_settings.mode': \"farfield\" "
                               "needs --exact-ibl N");
    const std::string line = fit::ApplyYarnLobe(*yarn_lobe, &o);
    if (!line.empty() && !quiet) std::printf("evaluate: %s\n", line.c_str());
  }
  // s10-sun: the environment's sun (docs/sun.md): --env-sun, else the fit's fit.env_sun
  // ("auto" / "off": that mode; "card": each card's environment.sun, else auto), else (a preset
  // fitted before session 10, without the field) each card's environment.sun, else off: as fitted.
  o.env_sun_default = render::SunMode::kOff;
  if (a.env_sun != "preset") {
    o.env_sun = render::ParseSunMode(a.env_sun, "--env-sun");
  } else if (fj.contains("env_sun")) {
    const std::string field = a.preset + ": field 'fit.env_sun'";
    if (!fj["env_sun"].is_string())
      throw std::runtime_error(field + ": expected \"auto\", \"off\", \"panels\" or \"card\"");
    const std::string v = fj["env_sun"].get<std::string>();
    if (v == "card") o.env_sun_default = render::kCliDefaultSunMode;
    else if (v == "auto" || v == "off" || v == "panels") o.env_sun = render::ParseSunMode(v, field);
    else  // the value is escaped by the command's error handler (main.cpp)
      throw std::runtime_error(field + ": expected \"auto\", \"off\", \"panels\" or \"card\", got \"" + v + "\"");
  }
  // The IBL engine: as the fit recorded it (fit.ibl_engine; presets before session 8 were
  // fitted on Filament's), or --ibl-engine. The woven IBL mode is the preset's "woven" object.
  std::string engine = a.ibl_engine;
  if (engine == "preset") {
    engine = "filament";
    if (fj.contains("ibl_engine")) {
      if (!fj["ibl_engine"].is_string() ||
          (fj["ibl_engine"] != "threejs" && fj["ibl_engine"] != "filament"))
        throw std::runtime_error(a.preset + ": field 'fit.ibl_engine': expected \"threejs\" or "
                                 "\"filament\"");
      engine = fj["ibl_engine"].get<std::string>();
    }
  }
  o.ibl_engine = engine == "threejs"    ? render::IblEngine::kThreejs
                 : engine == "filament" ? render::IblEngine::kFilament
                                        : render::IblEngine::kAuto;
  // What is applied (review s8): auto resolved to its engine; woven FIS only on the three.js
  // engine and without the exact-IBL measurement (render/preview/preview.h UsesWovenFis).
  bool fis_applied = false;
  // Woven "ibl": "bent" (session 10): on either engine, not with the exact-IBL measurement.
  const bool bent_applied = preset.model == render::ModelKind::kWoven && a.exact_ibl <= 0 &&
                            preset.woven.ibl == woven::IblMode::kBent;
  {
    render::PreviewOptions po;
    po.model = preset.model;
    po.cloth = preset.cloth;
    po.woven = render::PreviewWovenOptions(preset);
    po.ibl_engine = o.ibl_engine;
    engine = render::UsesThreejsIbl(po) ? "threejs" : "filament";
    fis_applied = preset.model == render::ModelKind::kWoven && a.exact_ibl <= 0 &&
                  render::UsesWovenFis(po);
    if (preset.model == render::ModelKind::kWoven && preset.woven.ibl == woven::IblMode::kFis &&
        !fis_applied && !quiet)
      std::fprintf(stderr,
                   "clothfit: note: %s asks for woven \"ibl\": \"fis\"; FIS exists on the three.js "
                   "IBL engine only (and not with --exact-ibl): evaluating with the split sum\n",
                   limits::EscapeForMessage(a.preset).c_str());
  }

  std::vector<render::Scene> loaded;
  std::vector<std::unique_ptr<render::Environment>> envs;
  std::vector<fit::Reference> references;
  loaded.reserve(scenes.size());
  references.reserve(refs.size());
  // A preset's own fit.scenes name files of the machine that fitted it (the reference cache):
  // a missing one keeps its error, with a hint (session 27).
  const bool own_scenes = SplitList(a.references).empty();
  const auto with_hint = [&](auto load, const std::string& path, size_t i, const char* field) {
    try {
      return load();
    } catch (const std::exception& e) {
      std::error_code ec;
      if (!own_scenes || std::filesystem::exists(path, ec)) throw;
      const auto prov = pj.find("provenance");
      const std::string fabric =
          prov != pj.end() && prov->is_object() && prov->contains("fabric") &&
                  (*prov)["fabric"].is_string()
              ? (*prov)["fabric"].get<std::string>()
              : std::string("FABRIC");
      throw std::runtime_error(
          std::string(e.what()) + " (hint: " + a.preset + ": field 'fit.scenes[" +
          std::to_string(i) + "]." + field + "' names a file that is not on this machine, e.g. " +
          "the reference cache where the preset was fitted: render the references here with " +
          "`clothfit fit --fabric " + fabric + " ...` or `clothfit render-references`, or "
          "evaluate against references you have with --references and --scenes)");
    }
  };
  for (size_t i = 0; i < scenes.size(); ++i) {
    loaded.push_back(
        with_hint([&] { return render::LoadScene(scenes[i]); }, scenes[i], i, "scene"));
    envs.push_back(LoadSceneEnvironment(loaded.back(), quiet));
    references.push_back(with_hint(
        [&] { return fit::ReadReference(refs[i], fit::ReferenceOptions{}); }, refs[i], i,
        "reference"));
  }
  std::vector<fit::SceneInput> inputs;
  for (size_t i = 0; i < scenes.size(); ++i)
    inputs.push_back({&loaded[i], envs[i].get(), &references[i], nullptr, scenes[i]});
  const fit::FitResult r = fit::FitImages(inputs, o);
  if (!r.usable) throw std::runtime_error("evaluation failed: " + r.message);
  for (size_t i = 0; i < r.preset.values.size(); ++i)
    if (r.preset.values[i] != preset.values[i])
      throw std::logic_error("evaluate: a locked parameter moved (internal error)");

  if (a.json) {
    nlohmann::json j;
    j["preset"] = a.preset;
    j["model"] = render::ToString(preset.model);
    j["level"] = o.level;
    j["pixel_stride"] = o.pixel_stride;
    j["space"] = fit::ToString(o.space);
    j["ibl"] = a.exact_ibl > 0 ? "exact (" + std::to_string(a.exact_ibl) + " samples, seed " +
                                     std::to_string(a.exact_ibl_seed) + ")"
               : a.exact_irradiance > 0
                   ? "split sum with exact irradiance (" + std::to_string(a.exact_irradiance) +
                         " samples, seed " + std::to_string(a.exact_ibl_seed) + ")"
                   : "split sum";
    j["ibl_engine"] = engine;
    j["env_sun"] = o.env_sun ? render::SunModeName(*o.env_sun)  // s10-sun
                             : std::string("card, else ") + render::SunModeName(o.env_sun_default);
    if (preset.model == render::ModelKind::kWoven)
      j["woven_ibl"] = fis_applied ? "fis" : bent_applied ? "bent" : "split";
    if (o.shadows || o.visibility.enabled()) j["visibility"] = VisibilityJson(o);
    j["rmse"] = r.rmse;
    if (fj.contains("rmse")) j["fit_rmse"] = fj["rmse"];
    j["scenes"] = nlohmann::json::array();
    for (const auto& s : r.scenes)
      j["scenes"].push_back({{"scene", s.scene}, {"reference", s.reference}, {"blocks", s.blocks},
                             {"rmse", s.rmse}});
    std::printf("%s\n", limits::DumpJson(j).c_str());
  } else {
    std::printf("evaluate: %s (%s), level %d, stride %d, %s space, %s IBL", a.preset.c_str(),
                render::ToString(preset.model).c_str(), o.level, o.pixel_stride,
                fit::ToString(o.space).c_str(), engine.c_str());
    if (fis_applied)
      std::printf(" (woven FIS, %d / %d taps)", preset.woven.fis_taps,
                  preset.woven.fis_diffuse_taps);
    if (bent_applied) std::printf(" (woven bent-normal yarn IBL)");
    if (o.sheen_tilt_degrees != 0.0) std::printf(", sheen tilt %g degrees", o.sheen_tilt_degrees);
    if (a.exact_ibl > 0)
      std::printf(", exact IBL (%d samples per pixel, seed %u)", a.exact_ibl, a.exact_ibl_seed);
    else if (a.exact_irradiance > 0)
      std::printf(", split sum with exact irradiance (%d samples per pixel, seed %u)",
                  a.exact_irradiance, a.exact_ibl_seed);
    if (o.shadows || o.visibility.enabled())
      std::printf(", visibility %s", VisibilityJson(o).dump().c_str());
    std::printf("\n");
    for (const auto& s : r.scenes)
      std::printf("evaluate:   %s: %d blocks, block rmse %.5f\n", s.scene.c_str(), s.blocks,
                  s.rmse);
    std::printf("evaluate: block rmse %.5f", r.rmse);
    if (fj.contains("rmse") && fj["rmse"].is_number())
      std::printf(" (the fit's in-sample rmse: %.5f)", fj["rmse"].get<double>());
    std::printf("\n");
  }
  return 0;
}

}  // namespace

void AddEvaluateCommand(CLI::App& app, const Globals& g, int& exit_code) {
  auto args = std::make_shared<EvaluateArgs>();
  CLI::App* cmd = app.add_subcommand(
      "evaluate",
      "block error of a fitted preset against references, without refitting (the fit's own "
      "error at the preset's values; default: its own fit.scenes)");
  cmd->add_option("--preset", args->preset, "fitted preset (written by clothfit fit)")->required();
  cmd->add_option("--references", args->references,
                  "comma-separated reference EXRs (default: the preset's fit.scenes)");
  cmd->add_option("--scenes", args->scenes, "comma-separated scene cards, one per reference");
  cmd->add_option("--level", args->level, "block level (default: the preset's fit.level)");
  cmd->add_option("--stride", args->stride,
                  "pixel stride per block axis (default: the preset's fit.pixel_stride)");
  cmd->add_option("--exact-ibl", args->exact_ibl,
                  "measurement: integrate the environment exactly (Monte Carlo, this many "
                  "directions per pixel, no split sum; docs/fitting.md \"The sphere's error "
                  "decomposed\"); 0 = the engine's split sum (default)")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--exact-irradiance", args->exact_irradiance,
                  "measurement: split sum, but the diffuse irradiance integrated exactly (Monte "
                  "Carlo, this many directions per pixel) instead of SH9")
      ->check(CLI::Range(0, 65536));
  cmd->add_option("--exact-ibl-seed", args->exact_ibl_seed, "seed of --exact-ibl's directions (default 1)");
  cmd->add_option("--sheen-tilt", args->sheen_tilt,
                  "measurement (cloth, woven): the sheen lobe's normal tilted this many degrees "
                  "towards the mesh tangent +u (docs/velvet.md); default: the preset's "
                  "fit.sheen_tilt_degrees, else 0")
      ->check(CLI::Range(-90.0, 90.0));
  cmd->add_option("--env-sun", args->env_sun,
                  "s10-sun: the environment's sun as a directional light (docs/sun.md): preset "
                  "(default: the fit's fit.env_sun; presets without it: each card's "
                  "environment.sun, else off, as they were fitted), auto, off or panels (auto, then "
                  "broad bright sources such as softboxes as more lights)");
  cmd->add_option("--ibl-engine", args->ibl_engine,
                  "whose image-based lighting: preset (default: the fit's recorded "
                  "fit.ibl_engine, filament for presets without it), auto, threejs or filament")
      ->check(CLI::IsMember({"preset", "auto", "threejs", "filament"}));
  AddVisibilityFlags(cmd, args->visibility);
  cmd->add_flag("--json", args->json, "print the result as JSON");
  cmd->callback([args, &g, &exit_code]() {
    try {
      exit_code = RunEvaluate(*args, g.quiet);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit evaluate: error: %s\n",
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
