// bin/visibility_flags.h: the light-visibility measurement flags shared by `clothfit evaluate`
// and `clothfit fit` (docs/visibility.md): ray-traced shadows, the AO map and the one-bounce
// light map of render/preview/visibility.h. All off by default (the preview unchanged).
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fit/image_fit.h"

namespace clothfit::cli {

struct VisibilityFlags {
  bool shadows = false, ao = false, indirect = false, no_card_visibility = false;
  int samples = 64, hit_samples = 8, bounces = 1, uv_size = 0;
  double max_distance = 0.0;
  unsigned seed = 1;
  std::string fabric_albedo;  // "r,g,b" (empty: the fabric mesh's glTF base colour)
  std::string ao_weighting = "cosine";
};

inline void AddVisibilityFlags(CLI::App* cmd, VisibilityFlags& f) {
  cmd->add_flag("--shadows", f.shadows,
                "measurement: ray-traced light visibility in the preview (a perfect shadow map)");
  cmd->add_flag("--ao", f.ao,
                "measurement: a ray-traced ambient-occlusion map, applied as three.js's aoMap "
                "(docs/visibility.md)");
  cmd->add_flag("--indirect", f.indirect,
                "measurement: a ray-traced one-bounce indirect-irradiance light map, applied as "
                "three.js's lightMap");
  cmd->add_flag("--no-card-visibility", f.no_card_visibility,
                "ignore the scene cards' \"visibility\" blocks (their shadows and light maps; "
                "docs/scene-card.md)");
  cmd->add_option("--ao-weighting", f.ao_weighting,
                  "--ao: how the AO map is baked: cosine (default: the visible fraction of the "
                  "cosine-weighted hemisphere) or environment (weighted by the environment's "
                  "luminance: an environment-specific bake)")
      ->check(CLI::IsMember({"cosine", "environment"}));
  cmd->add_option("--vis-samples", f.samples,
                  "--ao / --indirect: cosine-weighted directions per pixel (default 64)")
      ->check(CLI::Range(1, 65536));
  cmd->add_option("--vis-hit-samples", f.hit_samples,
                  "--indirect: AO directions at each bounce hit point (default 8; 0 = none)")
      ->check(CLI::Range(0, 4096));
  cmd->add_option("--vis-bounces", f.bounces,
                  "--indirect: light-map bounces (default 1; each further bounce gathers over "
                  "--vis-hit-samples directions at the hit points)")
      ->check(CLI::Range(1, 4));
  cmd->add_option("--vis-max-distance", f.max_distance,
                  "--ao / --indirect: occluders farther than this (scene units) are ignored "
                  "(default 0 = infinite)")
      ->check(CLI::Range(0.0, 1e30));
  cmd->add_option("--vis-uv-size", f.uv_size,
                  "--ao / --indirect: bake the fabric's terms into an N x N texture over its uv "
                  "(the aoMap / lightMap an engine draws) and sample it bilinearly per pixel; "
                  "0 (default) = per pixel")
      ->check(CLI::Range(0, 2048));
  cmd->add_option("--vis-seed", f.seed, "--ao / --indirect: seed of the directions (default 1)");
  cmd->add_option("--indirect-albedo", f.fabric_albedo,
                  "--indirect: linear albedo r,g,b of fabric bounce points (default: the fabric "
                  "mesh's glTF base colour)");
}

inline void ApplyVisibilityFlags(const VisibilityFlags& f, fit::FitOptions* o) {
  // Options that would be ignored are errors (a value equal to the default changes nothing).
  const VisibilityFlags d;
  const auto unused = [](const char* flag, const char* needs) {
    throw std::invalid_argument(std::string(flag) + ": only with " + needs);
  };
  if (!f.ao && f.ao_weighting != d.ao_weighting) unused("--ao-weighting", "--ao");
  if (!f.indirect) {
    if (f.hit_samples != d.hit_samples) unused("--vis-hit-samples", "--indirect");
    if (f.bounces != d.bounces) unused("--vis-bounces", "--indirect");
    if (!f.fabric_albedo.empty()) unused("--indirect-albedo", "--indirect");
  }
  if (!f.ao && !f.indirect) {
    if (f.samples != d.samples) unused("--vis-samples", "--ao or --indirect");
    if (f.max_distance != d.max_distance) unused("--vis-max-distance", "--ao or --indirect");
    if (f.seed != d.seed) unused("--vis-seed", "--ao or --indirect");
    if (f.uv_size != d.uv_size) unused("--vis-uv-size", "--ao or --indirect");
  }
  o->shadows = f.shadows;
  o->card_visibility = !f.no_card_visibility;
  o->visibility.ao = f.ao;
  o->visibility.indirect = f.indirect;
  o->visibility.weighting = f.ao_weighting == "environment"
                                ? render::VisibilityOptions::Weighting::kEnvironment
                                : render::VisibilityOptions::Weighting::kCosine;
  o->visibility.samples = f.samples;
  o->visibility.hit_samples = f.hit_samples;
  o->visibility.bounces = f.bounces;
  o->visibility.max_distance = f.max_distance;
  o->visibility.seed = f.seed;
  o->visibility.uv_size = f.uv_size;
  if (!f.fabric_albedo.empty()) {
    std::vector<double> v;
    std::string item;
    std::stringstream ss(f.fabric_albedo);
    while (std::getline(ss, item, ',')) {
      try {
        size_t used = 0;
        v.push_back(std::stod(item, &used));
        if (used != item.size()) throw std::invalid_argument("trailing characters");
      } catch (const std::exception&) {
        throw std::invalid_argument("--indirect-albedo: '" + f.fabric_albedo +
                                    "' is not r,g,b (three numbers in [0, 1])");
      }
    }
    if (v.size() != 3 || v[0] < 0 || v[1] < 0 || v[2] < 0 || v[0] > 1 || v[1] > 1 || v[2] > 1)
      throw std::invalid_argument("--indirect-albedo: '" + f.fabric_albedo +
                                  "' is not r,g,b (three numbers in [0, 1])");
    o->visibility.fabric_albedo = {v[0], v[1], v[2]};
  }
}

// What a fit / evaluation used (null when nothing is on).
inline nlohmann::json VisibilityJson(const fit::FitOptions& o) {
  if (!o.shadows && !o.visibility.enabled()) return nullptr;
  nlohmann::json j{{"shadows", o.shadows}, {"ao", o.visibility.ao},
                   {"indirect", o.visibility.indirect}};
  if (o.visibility.enabled()) {
    j["ao_weighting"] = o.visibility.weighting == render::VisibilityOptions::Weighting::kEnvironment
                            ? "environment" : "cosine";
    j["samples"] = o.visibility.samples;
    j["hit_samples"] = o.visibility.hit_samples;
    j["bounces"] = o.visibility.bounces;
    j["max_distance"] = o.visibility.max_distance;
    j["seed"] = o.visibility.seed;
    j["uv_size"] = o.visibility.uv_size;  // 0: per pixel; N: an N x N uv texture (session 13)
    if (o.visibility.fabric_albedo[0] >= 0)
      j["fabric_albedo"] = {o.visibility.fabric_albedo[0], o.visibility.fabric_albedo[1],
                            o.visibility.fabric_albedo[2]};
  }
  return j;
}

}  // namespace clothfit::cli
