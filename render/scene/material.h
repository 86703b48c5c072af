// render/scene/material.h: the material preset format (JSON, versioned): what the preview renders,
// what the fitter writes, what `clothfit convert` will emit. docs/preset-format.md.
//
//   {
//     "schema": "clothfit.preset", "version": 1,
//     "model": "cloth" | "standard" | "physical-sheen" | "gltf-sheen" | "woven" | "physical-aniso",
//     "engine": "<engine release the parameters are meant for>"        (written, informative)
//     "cloth": {"variant": "filament" | "seed-threejs",
//               "sheen_default": "explicit" | "sqrt-base-color" | "white",
//               "subsurface": true | false, "platform": "desktop" | "mobile"}   (cloth only)
//     "woven": {"yarn_layer": "additive" | "albedo-scaled",
//               "tint_warp": [r, g, b], "tint_weft": [r, g, b],
//               "ibl": "split" | "fis" | "bent", "fis_taps": 1..64, "fis_diffuse_taps": 0..64}
//               (woven only; brdf/woven.h woven::Options; tints linear, >= 0, default
//               [1, 1, 1]; "ibl" missing = "split"; the tap counts (integers; defaults 16 and
//               0) only with "ibl": "fis" (filtered importance sampling of the three.js PMREM
//               for the yarn lobes; the writer writes "ibl" always and the taps with "fis");
//               web/clothfit.js reads the same keys;
//               "yarn_lobe": {...}: the far-field yarn lobe, brdf/yarn_lobe.h FarField, with
//               "yarn_layer": "additive" and "ibl": "split" only; docs/preset-format.md)
//     "conventions": {"colour_space": "linear sRGB (Rec.709 primaries)",
//                     "roughness": "perceptual r; alpha = r^2"}          (written, informative)
//     "parameters": {"<name>": number | [r, g, b], ...}   names from the model's parameter
//                   table (brdf/*.h kParameterTable); missing ones take the table default
//                   (sheen_color of a cloth preset with sheen_default != explicit is ignored)
//     ... any further top-level keys (e.g. "fit", "provenance") are kept but not interpreted
//   }
// Reading validates every field and range and throws MaterialError naming the file and the
// field; unknown parameter names and unknown keys inside "cloth"/"woven"/"parameters" are errors.
#pragma once

#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "brdf/cloth.h"
#include "brdf/params.h"
#include "brdf/woven.h"
#include "brdf/yarn_lobe.h"

namespace clothfit::render {

class MaterialError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class ModelKind { kCloth, kStandard, kPhysicalSheen, kGltfSheen, kWoven, kPhysicalAniso };

std::string ToString(ModelKind m);
ModelKind ParseModelKind(const std::string& s);  // throws std::invalid_argument
std::span<const ParamInfo> ParameterTable(ModelKind m);
std::string EngineOf(ModelKind m);
// The values a preset may give for a parameter: the table's range, except that roughness
// parameters (name containing "roughness") may go below the engine clamp down to 0 (the engine
// clamps them). ParsePreset checks this; `clothfit models --json` writes it as "preset_range"
// and web/clothfit.js checks the same (tests/browser/unit.mjs compares the two).
std::pair<double, double> PresetRange(const ParamInfo& p);

struct MaterialPreset {
  ModelKind model = ModelKind::kCloth;
  cloth::Options cloth;                             // used when model == kCloth
  ::clothfit::woven::Options woven;                 // used when model == kWoven ("woven")
  // "woven": {"yarn_lobe"} (woven only; null: none): the far-field yarn lobe that replaces the
  // model's GGX yarn lobes (brdf/yarn_lobe.h; render/preview/preview.h ApplyPresetYarnLobe).
  std::shared_ptr<const yarn_lobe::FarField> yarn_lobe;
  std::vector<double> values;                       // flat, in parameter-table order
  nlohmann::json extra = nlohmann::json::object();  // uninterpreted top-level keys

  // Flat index of a named parameter (throws std::invalid_argument).
  int Offset(const std::string& name) const;
};

// Defaults of a model (parameter-table defaults).
MaterialPreset DefaultPreset(ModelKind m);

// The woven renderer options a preview of preset `p` uses: p.woven with the lobe frame of
// "ibl": "bent" (bent_anisotropy, bent_twist) taken from p's `anisotropy` and `twist` values
// (p.woven unchanged for other models).
::clothfit::woven::Options PreviewWovenOptions(const MaterialPreset& p);

MaterialPreset ReadPreset(const std::string& path);
MaterialPreset ParsePreset(const nlohmann::json& j, const std::string& where);
nlohmann::json PresetToJson(const MaterialPreset& p);
// Writes atomically; refuses non-finite values (nlohmann would write them as null).
void WritePreset(const std::string& path, const MaterialPreset& p);

// The file a preset's relative "uri" field names (docs/preset-format.md "Weave maps: `uri` and
// `file`"): `uri` is relative to the directory of `preset_path`. Throws MaterialError naming
// the preset and `field` when it is empty, has a control byte or a scheme, is absolute,
// escapes the preset's directory (by "..", or by a symbolic link), is missing or is not a
// regular file. Returns the canonical path. Used by the preview's map loader
// (render/preview/weave_maps.cpp) and the report's map thumbnails (fit/metrics/report.cpp).
std::string ResolvePresetRelativeUri(const std::string& preset_path, const std::string& field,
                                     const std::string& uri);

}  // namespace clothfit::render
