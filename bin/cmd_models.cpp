// clothfit models: every model's engine release and parameter table; --json writes the same as
// JSON (schema "clothfit.models"), which web/clothfit.js's preset checks are tested against.
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <span>

#include "bin/commands.h"
#include "brdf/models.h"
#include "render/scene/material.h"

namespace clothfit::cli {
namespace {
void PrintTable(const char* title, std::span<const ParamInfo> table) {
  std::printf("%s\n", title);
  std::printf("  %-19s %4s %-16s %-20s %-5s %s\n", "name", "size", "default", "range", "diff",
              "convention");
  for (const ParamInfo& p : table) {
    char def[64], range[64];
    if (p.size == 3)
      std::snprintf(def, sizeof def, "%g,%g,%g", p.def[0], p.def[1], p.def[2]);
    else
      std::snprintf(def, sizeof def, "%g", p.def[0]);
    std::snprintf(range, sizeof range, "[%g, %g]", p.lower, p.upper);
    std::printf("  %-19.*s %4d %-16s %-20s %-5s %.*s\n", int(p.name.size()), p.name.data(), p.size,
                def, range, p.differentiable ? "yes" : "no", int(p.convention.size()),
                p.convention.data());
  }
}

// Every preset model's table as JSON: the values a preset may give ("preset_range",
// render::PresetRange: roughness may go below the engine clamp, down to 0) next to the table's
// documented range.
nlohmann::json ModelsJson() {
  using render::ModelKind;
  nlohmann::json models = nlohmann::json::object();
  for (ModelKind m : {ModelKind::kCloth, ModelKind::kStandard, ModelKind::kPhysicalSheen,
                      ModelKind::kGltfSheen, ModelKind::kWoven, ModelKind::kPhysicalAniso}) {
    nlohmann::json params = nlohmann::json::array();
    for (const ParamInfo& p : render::ParameterTable(m)) {
      const auto [lo, hi] = render::PresetRange(p);
      nlohmann::json def = nlohmann::json::array();
      for (int c = 0; c < p.size; ++c) def.push_back(p.def[size_t(c)]);
      params.push_back({{"name", std::string(p.name)},
                        {"size", p.size},
                        {"default", p.size == 1 ? nlohmann::json(p.def[0]) : def},
                        {"range", {p.lower, p.upper}},
                        {"preset_range", {lo, hi}},
                        {"differentiable", p.differentiable},
                        {"convention", std::string(p.convention)}});
    }
    models[render::ToString(m)] = {{"engine", render::EngineOf(m)}, {"parameters", params}};
  }
  return {{"schema", "clothfit.models"}, {"version", 1}, {"models", models}};
}
}  // namespace

void AddModelsCommand(CLI::App& app, const Globals&, int& exit_code) {
  CLI::App* cmd = app.add_subcommand("models", "list the models and their parameter tables");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json,
                "write the preset models' tables as JSON (schema clothfit.models): name, size, "
                "default, range, preset_range (what a preset may give), differentiable, "
                "convention");
  cmd->callback([&exit_code, json]() {
    if (*json) {
      std::printf("%s\n", ModelsJson().dump(1).c_str());
      exit_code = 0;
      return;
    }
    PrintTable("cloth (Filament cloth / seed MeshClothMaterial; see brdf/cloth.h)",
               cloth::kParameterTable);
    PrintTable("standard (three.js r187 MeshStandardMaterial)", standard::kParameterTable);
    PrintTable("physical-sheen (three.js r187 MeshPhysicalMaterial sheen)",
               physical_sheen::kParameterTable);
    PrintTable("gltf-sheen (glTF 2.0 + KHR_materials_sheen)", gltf_sheen::kParameterTable);
    PrintTable("woven (warp/weft anisotropic GGX x phase Fresnel + Charlie sheen + rough diffuse; "
               "see brdf/woven.h)",
               woven::kParameterTable);
    std::printf("  yarn lobes: a preset's \"woven\": {\"yarn_lobe\"} replaces the GGX lobes by the "
                "fabric's far field (brdf/yarn_lobe.h; fit's default with --fabric):\n"
                "    irawan-far-field        Irawan-Marschner yarn specular averaged over the weave "
                "(irawan fabrics)\n"
                "    sadeghi-microcylinder   the microcylinder BSDF in closed form, surface white + "
                "volume x tint_weft (sadeghi fabrics)\n\n");
    PrintTable("physical-aniso (three.js r187 MeshPhysicalMaterial sheen + anisotropy + specular; "
               "see brdf/physical_aniso.h)",
               physical_aniso::kParameterTable);
    exit_code = 0;
  });
}

}  // namespace clothfit::cli
