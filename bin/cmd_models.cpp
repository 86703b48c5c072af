// clothfit models: every model's engine release and parameter table.
#include <cstdio>
#include <span>

#include "bin/commands.h"
#include "brdf/models.h"

namespace clothfit::cli {
namespace {
void PrintTable(const char* title, std::span<const ParamInfo> table) {
  std::printf("%s\n", title);
  std::printf("  %-17s %4s %-16s %-18s %-5s %s\n", "name", "size", "default", "range", "diff",
              "convention");
  for (const ParamInfo& p : table) {
    char def[64], range[64];
    if (p.size == 3)
      std::snprintf(def, sizeof def, "%g,%g,%g", p.def[0], p.def[1], p.def[2]);
    else
      std::snprintf(def, sizeof def, "%g", p.def[0]);
    std::snprintf(range, sizeof range, "[%g, %g]", p.lower, p.upper);
    std::printf("  %-17.*s %4d %-16s %-18s %-5s %.*s\n", int(p.name.size()), p.name.data(), p.size,
                def, range, p.differentiable ? "yes" : "no", int(p.convention.size()),
                p.convention.data());
  }
}
}  // namespace

void AddModelsCommand(CLI::App& app, const Globals&, int& exit_code) {
  CLI::App* cmd = app.add_subcommand("models", "list the models and their parameter tables");
  cmd->callback([&exit_code]() {
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
