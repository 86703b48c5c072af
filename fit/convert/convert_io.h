// fit/convert/convert_io.h: readers and writers of `clothfit convert` (docs/convert.md).
//
// Readers turn one input file into one or more source materials: an analytic model with its
// parameters (clothfit preset, glTF 2.0 material, seed SurfaceMaterial / TextureStack side), a
// measured MERL table, or a woven fabric definition. Errors throw ConvertError whose message
// is "<file>: <field>: <reason>".
//
// Maps. Colour maps (base colour, sheen colour) are sRGB-encoded, decoded to linear before any
// use; normal maps are linear (tangent space, +Y up, as glTF). Each map is carried over by
// reference (its path relative to the output directory when possible, else absolute) with its
// colour space. For the fit, a colour map's mean linear texel value multiplies the colour
// factor; scalar maps (roughness, metalness, sheen roughness, specular) are reduced to their
// mean over texels times the factor and are NOT carried over (the targets get the fitted
// scalar). Normal maps do not enter the BRDF-space fit (it is taken on a flat surface).
// Writers emit the carried maps with factor = fitted colour / map mean (per channel, clamped
// to [0, 1]), so factor x mean(map) reproduces the fitted colour.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "fit/brdf_fit.h"
#include "fit/convert/merl.h"
#include "fit/convert/weave_textures.h"
#include "render/reference/fabric.h"
#include "render/scene/material.h"
#include "render/scene/input_limits.h"

namespace clothfit::fit {

class ConvertError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One of clothfit's own JSON documents that is not a material (a `clothfit report`
// report.json, the model list of `clothfit models`, a convert log), found next to the presets
// of a fit folder: `convert` skips it with this note ("<file>: not a material: ...") instead
// of failing. An unknown schema is still a ConvertError.
class NotAMaterial : public ConvertError {
 public:
  using ConvertError::ConvertError;
};

inline constexpr int kSeedSchemaVersion = 1;

struct MapRef {
  std::string attribute;            // "base_color", "normal", "sheen_color" (carried)
  std::string path;                 // resolved file path (as found on disk)
  std::string colour_space;         // "srgb" or "linear"
  Rgb<double> mean{1.0, 1.0, 1.0};  // mean linear texel value (colour maps)
};

struct SourceMaterial {
  std::string file;  // the input file
  std::string name;  // material name, unique within the file
  std::string kind;  // preset, gltf, merl, fabric, surface-material, texture-stack
  std::optional<render::MaterialPreset> analytic;
  std::shared_ptr<const MerlTable> merl;
  std::shared_ptr<const render::Fabric> fabric;
  std::vector<MapRef> maps;               // carried over
  std::vector<std::string> notes;         // what was averaged, dropped or not modelled
  std::vector<std::string> dependencies;  // further files whose content the output depends on
  // Two-sidedness: a glTF material's doubleSided (glTF default false); every other source
  // (presets, fabrics, surface materials, texture stacks) is a thin sheet seen from both
  // sides, so true. The three.js outputs write it as "side" (DoubleSide 2 / FrontSide 0), the
  // glTF output as doubleSided.
  bool double_sided = true;
  // A woven or physical-aniso preset's weave maps (top-level "weave_maps": the EXR its "uri"
  // names relative to the preset's directory (render::ResolvePresetWeaveMapPaths), else its
  // "file", confined like every map path), or null.
  std::shared_ptr<const render::WeaveMaps> weave_maps;
  std::string weave_maps_file;  // the resolved EXR path ("" without maps)
  std::string glint_file;       // the resolved glint EXR ("" without one)
};

// Every input file kind, chosen by extension and, for .json, by its "schema"/"format" field.
// `policy`: where map and buffer paths may point (docs/reliability.md, "Paths"). An empty root
// confines them to the file's own directory.
std::vector<SourceMaterial> ReadMaterials(const std::string& path,
                                          const limits::PathPolicy& policy = {});
// The source's BRDF on the canonical directions.
BrdfSamples SampleSource(const SourceMaterial& m);

// Mean linear RGB of an image file (colour maps decoded from sRGB when `srgb`).
Rgb<double> MeanTexel(const std::string& path, bool srgb);
double SrgbToLinear(double s);
double LinearToSrgb(double l);

// ---- writers (all atomic). `maps` are written relative to the output file's directory. ----
struct Converted {
  std::string name;
  render::MaterialPreset cloth;                          // always
  std::optional<render::MaterialPreset> physical_sheen;  // three.js target
  std::optional<render::MaterialPreset> gltf_sheen;      // glTF target
  // The seed's MeshClothMaterial (cloth/seed-threejs, explicit sheen) for the three.js target,
  // when `cloth` is another variant; WriteThreejsCloth falls back to `cloth`.
  std::optional<render::MaterialPreset> seed_cloth;
  // The source itself when it is a physical-aniso preset: three.js MeshPhysicalMaterial with
  // sheen + anisotropy + specular, which the three.js and glTF targets carry exactly (no
  // fit; docs/convert.md, "physical-aniso").
  std::optional<render::MaterialPreset> physical_aniso;
  std::vector<MapRef> maps;
  nlohmann::json provenance = nlohmann::json::object();
  bool double_sided = true;  // SourceMaterial::double_sided
  // A physical-aniso source with weave maps: the baked textures (fit/convert/weave_textures.h)
  // and the PNG files they were written to (absolute; the writers reference them relatively).
  std::optional<WeaveTextures> weave;
  std::string base_color_png, anisotropy_png;
};

void WriteClothPreset(const std::string& path, const Converted& c);
// three.js r187 MaterialLoader JSON (MeshPhysicalMaterial with sheen; with anisotropy and
// specular when `physical_aniso` is set).
void WriteThreejsPhysical(const std::string& path, const Converted& c);
// The seed's MeshClothMaterial parameters (same layout, type "MeshClothMaterial").
void WriteThreejsCloth(const std::string& path, const Converted& c);
// glTF 2.0 (materials only) with KHR_materials_sheen; with KHR_materials_anisotropy and
// KHR_materials_specular when `physical_aniso` is set; with `weave`, a baseColorTexture and an
// anisotropyTexture (KHR_texture_transform scale, REPEAT, trilinear sampler).
// WriteThreejsPhysical with `weave` adds "map" / "anisotropyMap" (texture uuids) and the
// ObjectLoader-format "textures" / "images" arrays (docs/convert.md gives the loader snippet).
void WriteGltf(const std::string& path, const Converted& c);
// Filament material source (.mat) for shadingModel: cloth.
void WriteFilamentMat(const std::string& path, const Converted& c);

// Writes an 8-bit PNG atomically (render/scene/png.h); `srgb`: with an sRGB chunk.
void WritePngFile(const std::string& path, int width, int height, int channels,
                  const std::vector<unsigned char>& pixels, bool srgb);
// The `preset-maps` target: the source preset itself, its weave maps (and glint map) copied
// next to it as <stem>.weave.exr (<stem>.glint.exr); "weave_maps" names the copies ("uri":
// relative to the preset's directory, what every C++ reader resolves first, so a relocated
// directory loads; "file": absolute, read only without a "uri"; web/ derives the URL from
// "file", see docs/preset-format.md). Returns the files written.
std::vector<std::string> WritePresetWithMaps(const std::string& path, const SourceMaterial& m,
                                             const nlohmann::json& provenance);

// Readers of our own outputs (round trips; the glTF reader is ReadMaterials).
render::MaterialPreset ReadThreejsPhysical(const std::string& path);
render::MaterialPreset ReadThreejsCloth(const std::string& path);
render::MaterialPreset ReadFilamentMat(const std::string& path);

}  // namespace clothfit::fit
