#include "fit/convert/convert_io.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include "fit/metrics/metrics.h"
#include "render/scene/png.h"
#include "render/scene/gltf_tinygltf.h"
#include "render/scene/image_io.h"
#include "render/scene/tonemap.h"
#include "render/scene/input_limits.h"

namespace clothfit::fit {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using render::ModelKind;

[[noreturn]] void Fail(const std::string& file, const std::string& field, const std::string& msg) {
  // `field` is built from keys of the input file (parameters.<key>): escape it like every
  // untrusted text in a message (docs/reliability.md; found by fuzz_convert_json).
  throw ConvertError(file + ": " + limits::EscapeForMessage(field, 200) + ": " + msg);
}

json ReadJson(const std::string& path) {
  std::string text;
  try {  // bounded read, then the nesting limit before the DOM (docs/reliability.md)
    text = limits::ReadFileBounded(path, limits::kMaxJsonFileBytes, "JSON file");
    limits::CheckJsonDepth(text, path);
  } catch (const limits::InputError& e) {
    throw ConvertError(e.what());
  }
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    const size_t at = std::min(size_t(e.byte), text.size());
    const long line = 1 + std::count(text.begin(), text.begin() + long(at), '\n');
    Fail(path, "line " + std::to_string(line),
         "malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  } catch (const json::out_of_range& e) {  // 406: a number beyond double (1e400) while parsing
    Fail(path, "JSON", "malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  }
}

std::string Lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// ---- maps ----

// Means of the first three channels (a one-channel image is replicated), sRGB-decoded texel by
// texel when `srgb`, and of the fourth channel (alpha; 1 when absent).
std::array<double, 4> ChannelMeans(const std::string& path, bool srgb) {
  const io::Image img = io::ReadImage(path);
  const int nc = img.channels();
  std::array<double, 4> sum{0, 0, 0, 0};
  const size_t np = size_t(img.width) * size_t(img.height);
  for (size_t p = 0; p < np; ++p) {
    const float* px = &img.pixels[p * size_t(nc)];
    for (int c = 0; c < 3; ++c) {
      const double v = double(px[std::min(c, nc - 1)]);
      sum[size_t(c)] += srgb ? SrgbToLinear(v) : v;
    }
    sum[3] += nc >= 4 ? double(px[3]) : 1.0;
  }
  for (double& s : sum) s /= double(std::max<size_t>(np, 1));
  return sum;
}

// The path policy of the ReadMaterials call running on this thread (maps and glTF buffers stay
// inside the input tree unless --allow-outside-paths); null: the file's own directory.
thread_local const limits::PathPolicy* t_policy = nullptr;

limits::PathPolicy PolicyFor(const std::string& file) {
  if (t_policy && !t_policy->root.empty()) return *t_policy;
  limits::PathPolicy p;
  p.root = fs::path(file).parent_path();
  if (p.root.empty()) p.root = ".";
  p.allow_outside = t_policy && t_policy->allow_outside;
  return p;
}

std::string ResolveUri(const std::string& file, const std::string& field, const std::string& uri) {
  if (uri.empty()) Fail(file, field, "empty uri");
  if (uri.rfind("data:", 0) == 0) Fail(file, field, "embedded data URIs are not supported");
  const fs::path p = fs::path(file).parent_path() / uri;
  std::error_code ec;
  if (!fs::exists(p, ec))
    Fail(file, field, "map file not found: " + limits::EscapeForMessage(p.string(), 400));
  try {
    return limits::ResolveConfined(file, field, uri, PolicyFor(file)).string();
  } catch (const limits::InputError& e) {
    throw ConvertError(e.what());
  }
}

// ---- the seed's shared parametrisation (docs/convert.md) ----

struct SharedName {
  const char* shared;
  const char* param;  // clothfit parameter name; "metalness" maps to glTF's "metallic"
  int size;
};
constexpr SharedName kShared[] = {
    {"color", "base_color", 3},
    {"roughness", "roughness", 1},
    {"metalness", "metalness", 1},
    {"sheenColor", "sheen_color", 3},
    {"sheenRoughness", "sheen_roughness", 1},
    {"subsurfaceColor", "subsurface_color", 3},
};
constexpr const char* kSharedList =
    "color, roughness, metalness, sheenColor, sheenRoughness, subsurfaceColor";
constexpr const char* kMapList =
    "color, normal, roughness, metalness, sheenColor, sheenRoughness, specular";

double CheckedNumber(const json& v, const std::string& file, const std::string& field, double lo,
                     double hi) {
  if (!v.is_number()) Fail(file, field, "expected a number, got " + std::string(v.type_name()));
  const double x = v.get<double>();
  if (!std::isfinite(x) || x < lo || x > hi)
    Fail(file, field,
         "value " + std::to_string(x) + " outside [" + std::to_string(lo) + ", " +
             std::to_string(hi) + "]");
  return x;
}

void SetParam(render::MaterialPreset& p, const std::string& name, const double* v, int n) {
  std::string key = name;
  if (p.model == ModelKind::kGltfSheen && key == "metalness") key = "metallic";
  const int off = p.Offset(key);
  for (int c = 0; c < n; ++c) p.values[size_t(off + c)] = v[c];
}

bool HasParam(ModelKind m, std::string name) {
  if (m == ModelKind::kGltfSheen && name == "metalness") name = "metallic";
  for (const ParamInfo& info : render::ParameterTable(m))
    if (info.name == name) return true;
  return false;
}

// The "parameters" object of a surface body, into the preset p (unused ones: a note in m).
void ApplySurfaceParameters(const json& params, ModelKind model, const std::string& file,
                            const std::string& at, render::MaterialPreset& p, SourceMaterial& m) {
  for (const auto& [key, v] : params.items()) {
    const SharedName* s = nullptr;
    for (const SharedName& n : kShared)
      if (key == n.shared) s = &n;
    const std::string field = at + "parameters." + key;
    if (!s) Fail(file, field, std::string("unknown parameter (valid: ") + kSharedList + ")");
    double x[3];
    if (s->size == 3) {
      if (!v.is_array() || v.size() != 3) Fail(file, field, "expected [r, g, b] (linear sRGB)");
      for (int c = 0; c < 3; ++c)
        x[c] = CheckedNumber(v[size_t(c)], file, field + "[" + std::to_string(c) + "]", 0, 1);
    } else {
      x[0] = CheckedNumber(v, file, field, 0, 1);
    }
    if (!HasParam(model, s->param)) {
      m.notes.push_back(field + " not used by brdf " + render::ToString(model));
      continue;
    }
    if (model == ModelKind::kCloth && key == "subsurfaceColor") p.cloth.subsurface = true;
    SetParam(p, s->param, x, s->size);
  }
}

// One entry of the "maps" object at JSON path `field`: a colour map scales its colour by the
// map's mean, a scalar map is reduced to its mean, a normal map is carried as is.
void ApplySurfaceMap(const std::string& attr, const json& v, ModelKind model,
                     const std::string& file, const std::string& field, render::MaterialPreset& p,
                     SourceMaterial& m) {
  static const std::vector<std::string> kMaps = {
      "color", "normal", "roughness", "metalness", "sheenColor", "sheenRoughness", "specular"};
  if (std::find(kMaps.begin(), kMaps.end(), attr) == kMaps.end())
    Fail(file, field, std::string("unknown map attribute (valid: ") + kMapList + ")");
  if (!v.is_object() || !v.contains("uri") || !v["uri"].is_string())
    Fail(file, field, "expected {\"uri\": \"...\", \"colorSpace\": \"srgb\"|\"linear\"}");
  const bool colour = attr == "color" || attr == "sheenColor";
  if (v.contains("colorSpace") && !v["colorSpace"].is_string())
    Fail(file, field + ".colorSpace", "expected \"srgb\" or \"linear\"");
  const std::string cs = v.value("colorSpace", colour ? "srgb" : "linear");
  if (cs != "srgb" && cs != "linear")
    Fail(file, field + ".colorSpace",
         "'" + limits::EscapeForMessage(cs, 40) + "' is not srgb or linear");
  const std::string path = ResolveUri(file, field + ".uri", v["uri"].get<std::string>());
  m.dependencies.push_back(path);
  if (attr == "normal") {
    m.maps.push_back({"normal", path, cs, {1, 1, 1}});
    return;
  }
  std::array<double, 4> mean;
  try {
    mean = ChannelMeans(path, cs == "srgb");
  } catch (const std::exception& e) {
    Fail(file, field + ".uri", e.what());
  }
  if (colour) {
    const std::string param = attr == "color" ? "base_color" : "sheen_color";
    if (!HasParam(model, param)) {
      m.notes.push_back(field + " not used by brdf " + render::ToString(model));
      return;
    }
    const int off = p.Offset(param);
    for (int c = 0; c < 3; ++c) p.values[size_t(off + c)] *= mean[size_t(c)];
    m.maps.push_back({param, path, cs, {mean[0], mean[1], mean[2]}});
  } else if (attr == "specular") {
    m.notes.push_back(field + ": specular map read (mean " + std::to_string(mean[0]) +
                      ") but not modelled (F0 fixed at 0.04)");
  } else {
    const std::string param = attr == "roughness"   ? "roughness"
                              : attr == "metalness" ? "metalness"
                                                    : "sheen_roughness";
    if (!HasParam(model, param)) {
      m.notes.push_back(field + " not used by brdf " + render::ToString(model));
      return;
    }
    double x =
        p.values[size_t(p.Offset(
            param == "metalness" && model == ModelKind::kGltfSheen ? "metallic" : param))] *
        mean[0];
    SetParam(p, param, &x, 1);
    m.notes.push_back(field + ": reduced to its mean over texels (" + std::to_string(mean[0]) +
                      "), not carried over");
  }
}

// One SurfaceMaterial-like body: brdf + parameters + maps, at JSON path `at`.
SourceMaterial ParseSurface(const json& body, ModelKind model, const std::string& file,
                            const std::string& at, const std::string& name,
                            const std::string& kind) {
  SourceMaterial m;
  m.file = file;
  m.name = name;
  m.kind = kind;
  render::MaterialPreset p = render::DefaultPreset(model);
  if (model == ModelKind::kGltfSheen || model == ModelKind::kPhysicalSheen) {
    // Absent sheen means no sheen.
    const int off = p.Offset("sheen_color");
    for (int c = 0; c < 3; ++c) p.values[size_t(off + c)] = 0.0;
  }
  const json params = body.value("parameters", json::object());
  if (!params.is_object()) Fail(file, at + "parameters", "expected an object");
  ApplySurfaceParameters(params, model, file, at, p, m);
  const json maps = body.value("maps", json::object());
  if (!maps.is_object()) Fail(file, at + "maps", "expected an object");
  for (const auto& [attr, v] : maps.items())
    ApplySurfaceMap(attr, v, model, file, at + "maps." + attr, p, m);
  m.analytic = p;
  return m;
}

ModelKind ParseBrdf(const json& j, const std::string& file, const std::string& field) {
  if (!j.contains("brdf") || !j["brdf"].is_string())
    Fail(file, field,
         "missing or not a string (valid: cloth, standard, physical-sheen, gltf-sheen)");
  try {
    return render::ParseModelKind(j["brdf"].get<std::string>());
  } catch (const std::invalid_argument& e) {
    Fail(file, field, e.what());
  }
}

void CheckSchema(const json& j, const std::string& file, const std::string& schema) {
  if (!j.contains("version") || !j["version"].is_number_integer())
    Fail(file, "version", "missing or not an integer");
  const int v = j["version"].get<int>();
  if (v != kSeedSchemaVersion)
    Fail(file, "version",
         std::to_string(v) + " not supported (this build reads " + schema + " " +
             std::to_string(kSeedSchemaVersion) + ")");
}

std::vector<SourceMaterial> ReadSurfaceMaterial(const json& j, const std::string& file) {
  CheckSchema(j, file, "seed.SurfaceMaterial");
  for (const char* k : {"id", "name"})
    if (!j.contains(k) || !j[k].is_string()) Fail(file, k, "missing or not a string");
  if (j.contains("metadata") && !j["metadata"].is_object())
    Fail(file, "metadata", "expected an object");
  const ModelKind model = ParseBrdf(j, file, "brdf");
  return {ParseSurface(j, model, file, "", j["name"].get<std::string>(), "surface-material")};
}

std::vector<SourceMaterial> ReadTextureStack(const json& j, const std::string& file) {
  CheckSchema(j, file, "seed.TextureStack");
  for (const char* k : {"id", "fabricId", "name"})
    if (!j.contains(k) || !j[k].is_string()) Fail(file, k, "missing or not a string");
  const ModelKind model = ParseBrdf(j, file, "brdf");
  if (!j.contains("sides") || !j["sides"].is_object() || j["sides"].empty())
    Fail(file, "sides", "missing or empty (expected {\"front\": {...}, \"back\": {...}})");
  std::vector<SourceMaterial> out;
  for (const auto& [side, body] : j["sides"].items()) {
    if (side != "front" && side != "back") Fail(file, "sides." + side, "not front or back");
    if (!body.is_object()) Fail(file, "sides." + side, "expected an object");
    out.push_back(ParseSurface(body, model, file, "sides." + side + ".",
                               j["name"].get<std::string>() + "-" + side, "texture-stack"));
  }
  return out;
}

// A path a preset names ("uri" relative to the preset, else "file", absolute as clothfit fit
// writes it or relative to the preset), confined like every map path (docs/reliability.md).
std::string ResolvePresetPath(const std::string& file, const std::string& field,
                              const std::string& value) {
  std::string uri = value;
  if (fs::path(value).is_absolute()) {
    std::error_code ec;
    const fs::path base = fs::absolute(fs::path(file), ec).parent_path();
    const fs::path rel = fs::path(value).lexically_normal().lexically_relative(base);
    if (!ec && !rel.empty()) uri = rel.generic_string();  // "../x" when outside: then confined
  }
  try {
    return limits::ResolveConfined(file, field, uri, PolicyFor(file), limits::kMaxImageFileBytes)
        .string();
  } catch (const limits::InputError& e) {
    throw ConvertError(e.what());
  }
}

// The "weave_maps" field of a woven or physical-aniso preset: reads the EXR (and the glint
// map), with the preset's uv_repeats, exactly as render::LoadPresetWeaveMaps does.
void ReadPresetWeaveMaps(const std::string& file, SourceMaterial* m) {
  const render::MaterialPreset& p = *m->analytic;
  if (p.model != ModelKind::kWoven && p.model != ModelKind::kPhysicalAniso) return;
  const auto it = p.extra.find("weave_maps");
  if (it == p.extra.end() || it->is_null()) return;
  if (!it->is_object()) Fail(file, "weave_maps", "expected an object");
  // "uri" first, by the preview's rules (relative, inside the preset's directory, existing:
  // render::ResolvePresetWeaveMapPaths), else "file"; then confined like every map path.
  render::MaterialPreset local = p;  // the resolved paths, for the shared reader
  try {
    render::ResolvePresetWeaveMapPaths(&local, file);
  } catch (const std::exception& e) {
    throw ConvertError(e.what());
  }
  json& lf = local.extra["weave_maps"];
  auto path_of = [&](const char* uri_key, const char* file_key) -> std::string {
    if (!lf.contains(file_key)) return "";
    const std::string field = std::string("weave_maps.") + (it->contains(uri_key) ? uri_key : file_key);
    if (!lf[file_key].is_string()) Fail(file, field, "expected a string");
    return ResolvePresetPath(file, field, lf[file_key].get<std::string>());
  };
  m->weave_maps_file = path_of("uri", "file");
  if (m->weave_maps_file.empty()) Fail(file, "weave_maps.file", "missing");
  m->glint_file = path_of("glint_uri", "glint_file");
  lf["file"] = m->weave_maps_file;
  if (!m->glint_file.empty()) lf["glint_file"] = m->glint_file;
  try {
    m->weave_maps = render::LoadPresetWeaveMaps(local);
  } catch (const std::exception& e) {
    Fail(file, "weave_maps", e.what());
  }
  m->dependencies.push_back(m->weave_maps_file);
  if (!m->glint_file.empty()) m->dependencies.push_back(m->glint_file);
}

std::vector<SourceMaterial> ReadPresetFile(const std::string& file) {
  SourceMaterial m;
  m.file = file;
  m.name = fs::path(file).stem().string();
  m.kind = "preset";
  try {
    m.analytic = render::ReadPreset(file);
  } catch (const std::exception& e) {
    throw ConvertError(e.what());
  }
  ReadPresetWeaveMaps(file, &m);
  return {m};
}

std::vector<SourceMaterial> ReadFabricFile(const std::string& file, const json& j) {
  SourceMaterial m;
  m.file = file;
  m.name = j.contains("name") && j["name"].is_string() ? j["name"].get<std::string>()
                                                       : fs::path(file).stem().string();
  m.kind = "fabric";
  try {
    m.fabric = std::make_shared<render::Fabric>(render::LoadFabric(file));
  } catch (const std::exception& e) {
    throw ConvertError(e.what());
  }
  if (m.fabric->model == "irawan") {
    const std::string weave = j.contains("weave_file") && j["weave_file"].is_string()
                                  ? j["weave_file"].get<std::string>()
                                  : "../weaves/" + m.fabric->preset + ".weave";
    m.dependencies.push_back((fs::path(file).parent_path() / weave).string());
  }
  const int n = SourceSampleCount(*m.fabric);
  m.notes.push_back(
      m.fabric->model == "irawan"
          ? "woven BSDF averaged over " + std::to_string(n) + " (point, azimuth) draws in " +
                std::to_string(int(kSourcePeriods)) + " x " + std::to_string(int(kSourcePeriods)) +
                " weave periods, each pair also mirrored; fineness glints by their mean"
          : "BSDF (the same at every point) averaged over " + std::to_string(n) +
                " azimuths, each pair also mirrored");
  return {m};
}

// ---- glTF ----

double GltfNumber(const tinygltf::Value& v, const std::string& file, const std::string& field,
                  double lo, double hi) {
  if (!v.IsNumber() && !v.IsInt()) Fail(file, field, "expected a number");
  const double x = v.GetNumberAsDouble();
  if (!std::isfinite(x) || x < lo || x > hi)
    Fail(file, field,
         "value " + std::to_string(x) + " outside [" + std::to_string(lo) + ", " +
             std::to_string(hi) + "]");
  return x;
}

void CheckRange(double x, const std::string& file, const std::string& field) {
  if (!std::isfinite(x) || x < 0.0 || x > 1.0)
    Fail(file, field, "value " + std::to_string(x) + " outside [0, 1]");
}

// The file behind a texture index, or "" (with a note) when it cannot be carried.
std::string GltfTexturePath(const tinygltf::Model& g, int index, const std::string& file,
                            const std::string& field, SourceMaterial& m) {
  if (index < 0 || index >= int(g.textures.size()))
    Fail(file, field + ".index", std::to_string(index) + " out of range");
  const int src = g.textures[size_t(index)].source;
  if (src < 0 || src >= int(g.images.size())) Fail(file, field, "texture has no image source");
  const std::string& uri = g.images[size_t(src)].uri;
  if (uri.empty() || uri.rfind("data:", 0) == 0) {
    m.notes.push_back(field + ": embedded image not carried over, not averaged");
    return "";
  }
  return ResolveUri(file, "images[" + std::to_string(src) + "].uri", uri);
}

// pbrMetallicRoughness: the factors, then the base colour and metallic-roughness textures
// reduced to their means (the base colour map is carried over).
void ReadGltfPbr(const tinygltf::Model& g, const tinygltf::Material& gm, const std::string& file,
                 const std::string& at, render::MaterialPreset& p, SourceMaterial& m) {
  const auto& pbr = gm.pbrMetallicRoughness;
  if (pbr.baseColorFactor.size() != 4)
    Fail(file, at + ".pbrMetallicRoughness.baseColorFactor", "expected 4 numbers");
  for (int c = 0; c < 3; ++c) {
    CheckRange(pbr.baseColorFactor[size_t(c)], file,
               at + ".pbrMetallicRoughness.baseColorFactor[" + std::to_string(c) + "]");
    p.values[size_t(c)] = pbr.baseColorFactor[size_t(c)];
  }
  CheckRange(pbr.roughnessFactor, file, at + ".pbrMetallicRoughness.roughnessFactor");
  CheckRange(pbr.metallicFactor, file, at + ".pbrMetallicRoughness.metallicFactor");
  p.values[3] = pbr.roughnessFactor;
  p.values[4] = pbr.metallicFactor;
  for (int c = 0; c < 3; ++c) p.values[size_t(5 + c)] = 0.0;  // no sheen unless extended
  p.values[8] = 0.0;
  if (pbr.baseColorTexture.index >= 0) {
    const std::string f = at + ".pbrMetallicRoughness.baseColorTexture";
    const std::string path = GltfTexturePath(g, pbr.baseColorTexture.index, file, f, m);
    if (!path.empty()) {
      const auto mean = ChannelMeans(path, true);  // glTF: baseColor textures are sRGB
      for (int c = 0; c < 3; ++c) p.values[size_t(c)] *= mean[size_t(c)];
      m.maps.push_back({"base_color", path, "srgb", {mean[0], mean[1], mean[2]}});
      m.dependencies.push_back(path);
    }
  }
  if (pbr.metallicRoughnessTexture.index >= 0) {
    const std::string f = at + ".pbrMetallicRoughness.metallicRoughnessTexture";
    const std::string path = GltfTexturePath(g, pbr.metallicRoughnessTexture.index, file, f, m);
    if (!path.empty()) {
      const auto mean = ChannelMeans(path, false);  // G = roughness, B = metalness (linear)
      p.values[3] *= mean[1];
      p.values[4] *= mean[2];
      m.dependencies.push_back(path);
      m.notes.push_back(f + ": reduced to its mean over texels (roughness " +
                        std::to_string(mean[1]) + ", metalness " + std::to_string(mean[2]) +
                        "), not carried over");
    }
  }
}

// The texture path behind an extension's texture-info object (index -1 when absent).
std::string GltfExtensionTexturePath(const tinygltf::Model& g, const tinygltf::Value& t,
                                     const std::string& file, const std::string& field,
                                     SourceMaterial& m) {
  return GltfTexturePath(g, t.Has("index") ? t.Get("index").GetNumberAsInt() : -1, file, field,
                         m);
}

// KHR_materials_sheen (object `s` at JSON path `f`): factors, colour map (carried over) and
// roughness map (reduced to its mean).
void ReadGltfSheen(const tinygltf::Model& g, const tinygltf::Value& s, const std::string& file,
                   const std::string& f, render::MaterialPreset& p, SourceMaterial& m) {
  if (s.Has("sheenColorFactor")) {
    const tinygltf::Value& c = s.Get("sheenColorFactor");
    if (!c.IsArray() || c.ArrayLen() != 3)
      Fail(file, f + ".sheenColorFactor", "expected 3 numbers");
    for (int k = 0; k < 3; ++k)
      p.values[size_t(5 + k)] =
          GltfNumber(c.Get(k), file, f + ".sheenColorFactor[" + std::to_string(k) + "]", 0, 1);
  }
  if (s.Has("sheenRoughnessFactor"))
    p.values[8] =
        GltfNumber(s.Get("sheenRoughnessFactor"), file, f + ".sheenRoughnessFactor", 0, 1);
  if (s.Has("sheenColorTexture")) {
    const std::string path =
        GltfExtensionTexturePath(g, s.Get("sheenColorTexture"), file, f + ".sheenColorTexture", m);
    if (!path.empty()) {
      const auto mean = ChannelMeans(path, true);
      for (int c = 0; c < 3; ++c) p.values[size_t(5 + c)] *= mean[size_t(c)];
      m.maps.push_back({"sheen_color", path, "srgb", {mean[0], mean[1], mean[2]}});
      m.dependencies.push_back(path);
    }
  }
  if (s.Has("sheenRoughnessTexture")) {
    const std::string path = GltfExtensionTexturePath(g, s.Get("sheenRoughnessTexture"), file,
                                                      f + ".sheenRoughnessTexture", m);
    if (!path.empty()) {
      const auto mean = ChannelMeans(path, false);  // spec: the alpha channel
      p.values[8] *= mean[3];
      m.dependencies.push_back(path);
      m.notes.push_back(f + ".sheenRoughnessTexture: reduced to its mean over texels");
    }
  }
}

// KHR_materials_specular (object `s` at JSON path `f`): validated, then only noted.
void ReadGltfSpecular(const tinygltf::Value& s, const std::string& file, const std::string& f,
                      SourceMaterial& m) {
  double factor = 1.0;
  if (s.Has("specularFactor"))
    factor = GltfNumber(s.Get("specularFactor"), file, f + ".specularFactor", 0, 1);
  if (s.Has("specularColorFactor")) {
    const tinygltf::Value& c = s.Get("specularColorFactor");
    if (!c.IsArray() || c.ArrayLen() != 3)
      Fail(file, f + ".specularColorFactor", "expected 3 numbers");
    for (int k = 0; k < 3; ++k)
      GltfNumber(c.Get(k), file, f + ".specularColorFactor[" + std::to_string(k) + "]", 0, 1e6);
  }
  m.notes.push_back(f + ": read (specularFactor " + std::to_string(factor) +
                    ") but not modelled: the glTF sheen model keeps F0 = 0.04");
}

// Material i of the glTF as a gltf-sheen source; `seen` counts names to make them unique.
SourceMaterial ReadGltfMaterial(const tinygltf::Model& g, size_t i, const std::string& file,
                                std::map<std::string, int>& seen) {
  const tinygltf::Material& gm = g.materials[i];
  const std::string at = "materials[" + std::to_string(i) + "]";
  SourceMaterial m;
  m.file = file;
  m.kind = "gltf";
  m.double_sided = gm.doubleSided;
  m.name = gm.name.empty() ? "material" + std::to_string(i) : gm.name;
  if (seen[m.name]++ > 0) m.name += "-" + std::to_string(i);
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kGltfSheen);
  ReadGltfPbr(g, gm, file, at, p, m);
  if (gm.normalTexture.index >= 0) {
    const std::string path =
        GltfTexturePath(g, gm.normalTexture.index, file, at + ".normalTexture", m);
    if (!path.empty()) {
      m.maps.push_back({"normal", path, "linear", {1, 1, 1}});
      m.dependencies.push_back(path);
    }
  }
  if (auto it = gm.extensions.find("KHR_materials_sheen"); it != gm.extensions.end())
    ReadGltfSheen(g, it->second, file, at + ".extensions.KHR_materials_sheen", p, m);
  if (auto it = gm.extensions.find("KHR_materials_specular"); it != gm.extensions.end())
    ReadGltfSpecular(it->second, file, at + ".extensions.KHR_materials_specular", m);
  m.analytic = p;
  return m;
}

std::vector<SourceMaterial> ReadGltf(const std::string& file) {
  tinygltf::Model g;
  std::string err, warn;
  const limits::PathPolicy policy = PolicyFor(file);
  if (!render::LoadGltfModel(file, &g, &err, &warn, &policy)) Fail(file, "glTF", err);
  if (g.materials.empty()) Fail(file, "materials", "the file has no materials");
  std::vector<SourceMaterial> out;
  std::map<std::string, int> seen;
  for (size_t i = 0; i < g.materials.size(); ++i)
    out.push_back(ReadGltfMaterial(g, i, file, seen));
  return out;
}

// ---- writers ----

std::string Relative(const std::string& target, const std::string& out_file) {
  std::error_code ec;
  const fs::path base = fs::absolute(fs::path(out_file).parent_path(), ec);
  const fs::path rel = fs::relative(fs::absolute(target, ec), base, ec);
  return ec || rel.empty() ? fs::absolute(target, ec).string() : rel.generic_string();
}

int Hex(const Rgb<double>& linear) {
  int h = 0;
  for (int c = 0; c < 3; ++c) {
    const double s = LinearToSrgb(std::clamp(linear[c], 0.0, 1.0));
    h = (h << 8) | int(std::lround(s * 255.0));
  }
  return h;
}

Rgb<double> FromHex(const json& v, const std::string& file, const std::string& field) {
  if (!v.is_number_integer() || v.get<long long>() < 0 || v.get<long long>() > 0xffffff)
    Fail(file, field, "expected an integer colour 0x000000..0xffffff");
  const long long h = v.get<long long>();
  return {SrgbToLinear(double((h >> 16) & 255) / 255.0),
          SrgbToLinear(double((h >> 8) & 255) / 255.0), SrgbToLinear(double(h & 255) / 255.0)};
}

Rgb<double> Colour(const render::MaterialPreset& p, const std::string& name) {
  const int o = p.Offset(name);
  return {p.values[size_t(o)], p.values[size_t(o + 1)], p.values[size_t(o + 2)]};
}

// The cloth sheen colour the engine sees, whatever the sheen default.
Rgb<double> EffectiveSheen(const render::MaterialPreset& p) {
  const cloth::Params<double> q{Colour(p, "base_color"), Colour(p, "sheen_color"), p.values[6],
                                Colour(p, "subsurface_color")};
  return cloth::EffectiveSheen(q, p.cloth);
}

const MapRef* FindMap(const Converted& c, const std::string& attr) {
  for (const MapRef& m : c.maps)
    if (m.attribute == attr) return &m;
  return nullptr;
}

// factor x mean(map) = fitted colour.
Rgb<double> Factor(const Rgb<double>& fitted, const MapRef* map) {
  if (!map) return fitted;
  Rgb<double> f;
  for (int c = 0; c < 3; ++c) f[c] = std::clamp(fitted[c] / std::max(map->mean[c], 1e-6), 0.0, 1.0);
  return f;
}

json MapsJson(const Converted& c, const std::string& out_file) {
  json maps = json::object();
  for (const MapRef& m : c.maps)
    maps[m.attribute] = {
        {"uri", Relative(m.path, out_file)},
        {"colour_space", m.colour_space == "srgb" ? "sRGB (decode to linear)" : "linear"}};
  return maps;
}

json Arr(const Rgb<double>& c) { return json::array({c[0], c[1], c[2]}); }

std::string Num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", x);
  std::string s = buf;
  if (s.find_first_of(".e") == std::string::npos) s += ".0";
  return s;
}

}  // namespace

// The IEC 61966-2-1 transfer functions, shared with the metrics and the tone mapper.
double SrgbToLinear(double s) { return metrics::flip_detail::SrgbToLinear(s); }
double LinearToSrgb(double l) { return render::SrgbEncode(l); }

Rgb<double> MeanTexel(const std::string& path, bool srgb) {
  const auto m = ChannelMeans(path, srgb);
  return {m[0], m[1], m[2]};
}

std::vector<SourceMaterial> ReadMaterials(const std::string& path,
                                          const limits::PathPolicy& policy) {
  struct Scope {  // the policy holds for this call only, on this thread
    const limits::PathPolicy* saved;
    explicit Scope(const limits::PathPolicy* p) : saved(t_policy) { t_policy = p; }
    ~Scope() { t_policy = saved; }
  } scope(&policy);
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) Fail(path, "file", "not found or not a regular file");
  const std::string ext = Lower(fs::path(path).extension().string());
  if (ext == ".gltf" || ext == ".glb") return ReadGltf(path);
  if (ext == ".binary" || ext == ".merl") {
    SourceMaterial m;
    m.file = path;
    m.name = fs::path(path).stem().string();
    m.kind = "merl";
    m.merl = std::make_shared<MerlTable>(ReadMerl(path));
    m.notes.push_back("MERL table, nearest-cell lookups on the canonical directions");
    return {m};
  }
  if (ext == ".zip")
    Fail(path, "file",
         "zipped TextureStacks are not read: unpack the zip (the "
         "descriptor JSON and its maps) into a folder first");
  if (ext != ".json")
    Fail(path, "file",
         "unknown input type '" + ext +
             "' (valid: .json, .gltf, "
             ".glb, .binary, .merl)");
  const json j = ReadJson(path);
  if (!j.is_object()) Fail(path, "(root)", "expected a JSON object");
  const std::string schema =
      j.contains("schema") && j["schema"].is_string()
          ? j["schema"].get<std::string>()
          : (j.contains("format") && j["format"].is_string() ? j["format"].get<std::string>() : "");
  if (schema == "clothfit.preset") return ReadPresetFile(path);
  // clothfit's own documents that are not materials (NotAMaterial, convert_io.h).
  const char* what = nullptr;
  if (schema == "clothfit.report") what = "a clothfit report (schema clothfit.report)";
  if (schema == "clothfit.models") what = "the model list of `clothfit models` (schema clothfit.models)";
  if (schema.empty() && j.contains("tool") && j["tool"].is_string() &&
      j["tool"].get<std::string>().rfind("clothfit", 0) == 0 && j.contains("items"))
    what = "a clothfit convert log";
  if (what) throw NotAMaterial(path + ": not a material: " + what);
  if (schema == "clothfit-fabric") return ReadFabricFile(path, j);
  if (schema == "seed.SurfaceMaterial") return ReadSurfaceMaterial(j, path);
  if (schema == "seed.TextureStack") return ReadTextureStack(j, path);
  Fail(path, "schema",
       "'" + limits::EscapeForMessage(schema, 80) +
           "' is not a known input (valid: clothfit.preset, "
           "clothfit-fabric (\"format\"), seed.SurfaceMaterial, seed.TextureStack)");
}

BrdfSamples SampleSource(const SourceMaterial& m) {
  if (m.analytic) return SampleAnalytic(*m.analytic);
  if (m.merl) return SampleMerl(*m.merl);
  if (m.fabric) return SampleFabric(*m.fabric);
  throw ConvertError(m.file + ": " + m.name + ": no BRDF to sample");
}

void WriteClothPreset(const std::string& path, const Converted& c) {
  render::MaterialPreset p = c.cloth;
  p.extra["provenance"] = c.provenance;
  if (!c.maps.empty()) {
    json maps = MapsJson(c, path);
    if (const MapRef* m = FindMap(c, "base_color"))
      maps["base_color"]["factor"] = Arr(Factor(Colour(p, "base_color"), m));
    if (const MapRef* m = FindMap(c, "sheen_color"))
      maps["sheen_color"]["factor"] = Arr(Factor(Colour(p, "sheen_color"), m));
    p.extra["maps"] = maps;
  }
  render::WritePreset(path, p);
}

namespace {
double Value(const render::MaterialPreset& p, const char* name) {
  return p.values[size_t(p.Offset(name))];
}
// three.js MaterialLoader reads colours as sRGB hex (components in [0, 1]); a specular colour
// above 1 (allowed by the parameter table) cannot be written that way.
// What the weave textures encode and how exactly (fit/convert/weave_textures.h): written into
// the outputs so a reader of the file sees the convention and the measured quantisation.
json WeaveTexturesJson(const WeaveTextures& w, const char* target) {
  return {{"target", target},
          {"size", w.size},
          {"uv_repeats", w.uv_repeats},
          {"max_anisotropy", w.max_anisotropy},
          {"max_anisotropy_convention",
           "the preset's weave_maps.anisotropy: three.js texture.anisotropy "
           "(EXT_texture_filter_anisotropic max anisotropy, 1 = isotropic); a viewer clamps it "
           "to renderer.capabilities.getMaxAnisotropy()"},
          {"base_color",
           "texel (8-bit sRGB) x factor = preset base_color x weave kd ratio; factor = the "
           "smallest 8-bit sRGB value >= base_color x max ratio"},
          {"anisotropy",
           "R, G = direction (d + 1) / 2 in the tangent frame (warp: t, weft: b; stored axes "
           "turned by -atan(1/255), compensated in the rotation); B = strength / its max; "
           "anisotropy strength = preset strength x max strength"},
          {"kd_max", Arr(w.kd_max)},
          {"strength_max", w.strength_max},
          {"measured_max_abs_error",
           {{"base_color_linear", w.base_max_abs_error},
            {"base_color_relative", w.base_max_rel_error},
            {"anisotropy_strength", w.strength_max_abs_error},
            {"direction_radians", w.direction_max_angle_error}}},
          {"clipped_texels", w.clipped_texels}};
}

// The carried colour maps in the three.js JSON (session 27; before, they sat only in
// userData while `color` held fitted / mean(map), so a loader drew the divided factor, near
// white). ObjectLoader format (Texture.toJSON / Source.toJSON of r187): MaterialLoader
// resolves "map" / "sheenColorMap" by uuid from setTextures(...), built by
// ObjectLoader.parseImagesAsync + parseTextures (the snippet of docs/convert.md). The map is
// the file the glTF output names as baseColorTexture / sheenColorTexture, with the same uv
// convention (glTF: v = 0 at the image's top row, so flipY false), sRGB, REPEAT (glTF's
// default sampler), trilinear. Normal maps stay in userData only: three.js's normalScale.y
// sign depends on whether the mesh has tangents (GLTFLoader flips it without), which a
// material file cannot know.
struct ThreejsMaps {
  json images = json::array(), textures = json::array();
  // Adds the colour map of `attr`, if carried, under material key `slot`.
  void Add(json& material, const Converted& c, const std::string& attr, const char* slot,
           const std::string& uuid, const std::string& out_file) {
    const MapRef* m = FindMap(c, attr);
    if (!m) return;
    const std::string id = uuid + "-" + attr;
    images.push_back({{"uuid", id + "-i"}, {"url", Relative(m->path, out_file)}});
    textures.push_back({{"uuid", id + "-t"},
                        {"name", attr},
                        {"image", id + "-i"},
                        {"mapping", 300},  // UVMapping
                        {"channel", 0},    // TEXCOORD_0 / uv
                        {"repeat", {1, 1}},
                        {"offset", {0, 0}},
                        {"center", {0, 0}},
                        {"rotation", 0},
                        {"wrap", {1000, 1000}},  // RepeatWrapping
                        {"colorSpace", m->colour_space == "srgb" ? "srgb" : ""},
                        {"minFilter", 1008},  // LinearMipmapLinearFilter
                        {"magFilter", 1006},  // LinearFilter
                        {"anisotropy", 1},
                        {"flipY", false},
                        {"generateMipmaps", true}});
    material[slot] = id + "-t";
  }
  void WriteInto(json& material) const {
    if (textures.empty()) return;
    for (const json& t : textures) material["textures"].push_back(t);
    for (const json& i : images) material["images"].push_back(i);
  }
};

// What userData records about the colours and maps of a three.js output: the un-divided
// fitted colours (for a loader that drops the textures) and, where the factor fitted / mean
// had to be clamped at 1 (a hex colour holds at most 1), how far below the fitted colour the
// attached map's mean then falls (relative, worst channel).
json ThreejsColourNote(const Converted& c, const Rgb<double>& base, const Rgb<double>& sheen,
                       bool sheen_map_attached) {
  json j = {{"mean_color", Hex(base)}};
  if (sheen_map_attached) j["mean_sheenColor"] = Hex(sheen);
  auto shortfall = [&](const Rgb<double>& fitted, const MapRef* m) {
    const Rgb<double> f = Factor(fitted, m);
    double worst = 0.0;
    for (int k = 0; k < 3; ++k)
      if (fitted[k] > 0.0) worst = std::max(worst, 1.0 - f[k] * m->mean[k] / fitted[k]);
    return worst;
  };
  const MapRef* bm = FindMap(c, "base_color");
  if (bm && shortfall(base, bm) > 1e-9) j["map_mean_shortfall"] = shortfall(base, bm);
  const MapRef* sm = FindMap(c, "sheen_color");
  if (sheen_map_attached && shortfall(sheen, sm) > 1e-9)
    j["sheenColorMap_mean_shortfall"] = shortfall(sheen, sm);
  j["convention"] =
      bm || sheen_map_attached
          ? "color (sheenColor) x the mean linear texel of map (sheenColorMap) = the fitted "
            "colour, up to the clamp of the factor at 1 (*_mean_shortfall): the maps are "
            "attached as textures (uuid references into textures[] / images[], ObjectLoader "
            "format; docs/convert.md). A loader that drops the textures must use mean_color "
            "(mean_sheenColor) instead, the fitted colour itself."
          : "no colour map: color is the fitted colour";
  return j;
}

void CheckHexable(const Rgb<double>& c, const std::string& path, const char* field) {
  for (int k = 0; k < 3; ++k)
    if (!(c[k] >= 0.0 && c[k] <= 1.0))
      throw ConvertError(path + ": " + field + ": component " + std::to_string(k) + " = " +
                         std::to_string(c[k]) +
                         " is outside [0, 1], which a three.js hex colour cannot hold");
}
}  // namespace

void WriteThreejsPhysical(const std::string& path, const Converted& c) {
  if (!c.physical_sheen && !c.physical_aniso)
    throw ConvertError(path + ": no physical-sheen fit to write");
  const render::MaterialPreset& p = c.physical_aniso ? *c.physical_aniso : *c.physical_sheen;
  json j;
  j["metadata"] = {{"version", 4.6}, {"type", "Material"}, {"generator", "clothfit convert"}};
  j["uuid"] = c.provenance.value("uuid", "00000000-0000-4000-8000-000000000000");
  j["type"] = "MeshPhysicalMaterial";
  j["name"] = c.name;
  j["color"] = Hex(Factor(Colour(p, "base_color"), FindMap(c, "base_color")));
  j["roughness"] = p.values[size_t(p.Offset("roughness"))];
  j["metalness"] = p.values[size_t(p.Offset("metalness"))];
  j["sheen"] = 1.0;  // sheen_color = sheenColor x sheen
  j["sheenColor"] = Hex(Factor(Colour(p, "sheen_color"), FindMap(c, "sheen_color")));
  j["sheenRoughness"] = p.values[size_t(p.Offset("sheen_roughness"))];
  if (c.physical_aniso) {
    // Exact: the model is MeshPhysicalMaterial's own (brdf/physical_aniso.h). anisotropy and
    // anisotropyRotation (radians, from the tangent toward the bitangent), specularIntensity
    // and specularColor (f0 = min(0.04 specularColor, 1) specularIntensity).
    j["anisotropy"] = Value(p, "anisotropy_strength");
    j["anisotropyRotation"] = Value(p, "anisotropy_rotation");
    j["specularIntensity"] = Value(p, "specular_intensity");
    CheckHexable(Colour(p, "specular_color"), path, "specular_color");
    j["specularColor"] = Hex(Colour(p, "specular_color"));
  }
  // The carried colour maps, attached (ThreejsMaps). A weave-baked texture takes "map".
  if (c.physical_aniso && c.weave && FindMap(c, "base_color"))
    throw ConvertError(path + ": map: the preset has both a carried colour map and weave maps; "
                              "only one base colour texture can be written");
  ThreejsMaps carried;
  const std::string material_uuid = j["uuid"].get<std::string>();
  carried.Add(j, c, "base_color", "map", material_uuid, path);
  carried.Add(j, c, "sheen_color", "sheenColorMap", material_uuid, path);
  carried.WriteInto(j);
  if (c.physical_aniso && c.weave) {
    // The weave maps (fit/convert/weave_textures.h): color = the texture's factor (an exact
    // 8-bit sRGB value, so the hex holds it exactly), map = the kd texture, anisotropyMap =
    // the direction/strength texture, anisotropy / anisotropyRotation = the texture's.
    // Textures and images in ObjectLoader's format (Texture.toJSON / Source.toJSON of r187):
    // MaterialLoader resolves "map" / "anisotropyMap" by uuid from setTextures(...), which
    // ObjectLoader.parseImagesAsync + parseTextures build from these arrays.
    const WeaveTextures& w = *c.weave;
    const std::string uuid = j["uuid"].get<std::string>();
    auto tex_uuid = [&](int k) { return uuid + (k == 0 ? "-weave-kd" : "-weave-anisotropy"); };
    j["color"] = Hex(w.base_factor);
    j["anisotropy"] = w.anisotropy_strength;
    j["anisotropyRotation"] = w.anisotropy_rotation;
    j["map"] = tex_uuid(0) + "-t";
    j["anisotropyMap"] = tex_uuid(1) + "-t";
    json images = json::array(), textures = json::array();
    const std::pair<const std::string*, const char*> tex[2] = {{&c.base_color_png, "srgb"},
                                                               {&c.anisotropy_png, ""}};
    for (int k = 0; k < 2; ++k) {
      images.push_back({{"uuid", tex_uuid(k) + "-i"}, {"url", Relative(*tex[k].first, path)}});
      textures.push_back({{"uuid", tex_uuid(k) + "-t"},
                          {"name", k == 0 ? "weave kd (base colour)" : "weave anisotropy"},
                          {"image", tex_uuid(k) + "-i"},
                          {"mapping", 300},  // UVMapping
                          {"channel", 0},    // TEXCOORD_0 / uv
                          {"repeat", {w.uv_repeats, w.uv_repeats}},
                          {"offset", {0, 0}},
                          {"center", {0, 0}},
                          {"rotation", 0},
                          {"wrap", {1000, 1000}},  // RepeatWrapping
                          {"colorSpace", tex[k].second},  // "srgb" / NoColorSpace ""
                          {"minFilter", 1008},            // LinearMipmapLinearFilter
                          {"magFilter", 1006},            // LinearFilter
                          {"anisotropy", w.max_anisotropy},  // the preset's maps' filter
                          {"flipY", false},  // glTF uv convention: v = 0 at the image's top row
                          {"generateMipmaps", true}});
    }
    for (const json& t : textures) j["textures"].push_back(t);  // after any carried map
    for (const json& i : images) j["images"].push_back(i);
  }
  j["side"] = c.double_sided ? 2 : 0;  // THREE.DoubleSide : THREE.FrontSide (back faces culled)
  j["userData"] = {{"clothfit",
                    {{"engine", render::EngineOf(p.model)},
                     {"colour",
                      "color/sheenColor are sRGB hex (three.js getHex); "
                      "MaterialLoader decodes them to linear"},
                     {"colour_maps", ThreejsColourNote(c, Colour(p, "base_color"),
                                                       Colour(p, "sheen_color"),
                                                       FindMap(c, "sheen_color") != nullptr)},
                     {"maps", MapsJson(c, path)},
                     {"provenance", c.provenance}}}};
  if (c.physical_aniso && c.weave)
    j["userData"]["clothfit"]["weave_textures"] = WeaveTexturesJson(*c.weave, "three.js");
  io::WriteTextAtomic(path, j.dump(2) + "\n");
}

void WriteThreejsCloth(const std::string& path, const Converted& c) {
  const render::MaterialPreset& p = c.seed_cloth ? *c.seed_cloth : c.cloth;
  json j;
  j["metadata"] = {{"version", 4.6}, {"type", "Material"}, {"generator", "clothfit convert"}};
  j["type"] = "MeshClothMaterial";
  j["name"] = c.name;
  j["color"] = Hex(Factor(Colour(p, "base_color"), FindMap(c, "base_color")));
  // The sheen is the fitted colour itself: no sheen map is attached to MeshClothMaterial.
  j["sheen"] = Hex(EffectiveSheen(p));
  ThreejsMaps carried;
  carried.Add(j, c, "base_color", "map",
              c.provenance.value("uuid", "00000000-0000-4000-8000-000000000000") + "-cloth",
              path);
  carried.WriteInto(j);
  j["roughness"] = p.values[6];
  j["side"] = c.double_sided ? 2 : 0;  // THREE.DoubleSide : THREE.FrontSide (back faces culled)
  if (p.cloth.subsurface) {
    j["subsurface"] = true;
    j["subsurfaceColor"] = Hex(Colour(p, "subsurface_color"));
  }
  j["userData"] = {{"clothfit",
                    {{"note",
                      "the seed's MeshClothMaterial (three.js fork): color, "
                      "sheen, subsurfaceColor as sRGB hex; roughness "
                      "perceptual"},
                     {"colour_maps", ThreejsColourNote(c, Colour(p, "base_color"),
                                                       EffectiveSheen(p), false)},
                     {"maps", MapsJson(c, path)},
                     {"provenance", c.provenance}}}};
  io::WriteTextAtomic(path, j.dump(2) + "\n");
}

void WriteGltf(const std::string& path, const Converted& c) {
  if (!c.gltf_sheen && !c.physical_aniso) throw ConvertError(path + ": no glTF sheen fit to write");
  const render::MaterialPreset& p = c.physical_aniso ? *c.physical_aniso : *c.gltf_sheen;
  json j;
  j["asset"] = {{"version", "2.0"}, {"generator", "clothfit convert"}};
  j["extensionsUsed"] = c.physical_aniso
                            ? json::array({"KHR_materials_sheen", "KHR_materials_anisotropy",
                                           "KHR_materials_specular"})
                            : json::array({"KHR_materials_sheen"});
  json m;
  m["name"] = c.name;
  m["doubleSided"] = c.double_sided;
  const Rgb<double> base = Factor(Colour(p, "base_color"), FindMap(c, "base_color"));
  m["pbrMetallicRoughness"] = {{"baseColorFactor", {base[0], base[1], base[2], 1.0}},
                               {"roughnessFactor", Value(p, "roughness")},
                               {"metallicFactor", Value(p, c.physical_aniso ? "metalness" : "metallic")}};
  m["extensions"]["KHR_materials_sheen"] = {
      {"sheenColorFactor", Arr(Factor(Colour(p, "sheen_color"), FindMap(c, "sheen_color")))},
      {"sheenRoughnessFactor", Value(p, "sheen_roughness")}};
  if (c.physical_aniso) {
    // KHR_materials_anisotropy: alpha_t = mix(alpha, 1, strength^2), rotation in radians
    // from the tangent, as three.js r187 (GLTFLoader maps it onto MeshPhysicalMaterial
    // .anisotropy / .anisotropyRotation). KHR_materials_specular: f0 = min(0.04
    // specularColorFactor, 1) specularFactor, f90 = specularFactor (three.js's
    // specularIntensity / specularColor). Exact for three.js; the Khronos sample viewer's
    // sheen visibility (Charlie) differs from three.js's (Neubelt): docs/convert.md.
    m["extensions"]["KHR_materials_anisotropy"] = {
        {"anisotropyStrength", Value(p, "anisotropy_strength")},
        {"anisotropyRotation", Value(p, "anisotropy_rotation")}};
    if (c.weave) {  // fit/convert/weave_textures.h: the texture's strength and rotation
      m["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"] = c.weave->anisotropy_strength;
      m["extensions"]["KHR_materials_anisotropy"]["anisotropyRotation"] = c.weave->anisotropy_rotation;
    }
    m["extensions"]["KHR_materials_specular"] = {
        {"specularFactor", Value(p, "specular_intensity")},
        {"specularColorFactor", Arr(Colour(p, "specular_color"))}};
  }
  json images = json::array(), textures = json::array();
  auto add = [&](const MapRef* map) {
    images.push_back({{"uri", Relative(map->path, path)}});
    textures.push_back({{"source", int(images.size()) - 1}});
    return json{{"index", int(textures.size()) - 1}};
  };
  if (const MapRef* map = FindMap(c, "base_color"))
    m["pbrMetallicRoughness"]["baseColorTexture"] = add(map);
  if (const MapRef* map = FindMap(c, "normal")) m["normalTexture"] = add(map);
  if (const MapRef* map = FindMap(c, "sheen_color"))
    m["extensions"]["KHR_materials_sheen"]["sheenColorTexture"] = add(map);
  json samplers = json::array();
  if (c.physical_aniso && c.weave) {
    // One period of the weave per texture, tiled uv_repeats times per uv unit: sampler REPEAT
    // (10497) with trilinear minification (9987 LINEAR_MIPMAP_LINEAR) and LINEAR (9729)
    // magnification; KHR_texture_transform scale (R, R) on each texture reference.
    const WeaveTextures& w = *c.weave;
    samplers.push_back({{"magFilter", 9729}, {"minFilter", 9987}, {"wrapS", 10497}, {"wrapT", 10497}});
    auto add_weave = [&](const std::string& png) {
      images.push_back({{"uri", Relative(png, path)}, {"mimeType", "image/png"}});
      textures.push_back({{"source", int(images.size()) - 1}, {"sampler", 0}});
      return json{{"index", int(textures.size()) - 1},
                  {"texCoord", 0},
                  {"extensions",
                   {{"KHR_texture_transform", {{"scale", {w.uv_repeats, w.uv_repeats}}}}}}};
    };
    if (FindMap(c, "base_color"))
      throw ConvertError(path + ": baseColorTexture: the preset has both a carried colour map "
                                "and weave maps; only one base colour texture can be written");
    m["pbrMetallicRoughness"]["baseColorFactor"] = {w.base_factor[0], w.base_factor[1],
                                                    w.base_factor[2], 1.0};
    m["pbrMetallicRoughness"]["baseColorTexture"] = add_weave(c.base_color_png);
    m["extensions"]["KHR_materials_anisotropy"]["anisotropyTexture"] = add_weave(c.anisotropy_png);
    j["extensionsUsed"].push_back("KHR_texture_transform");
    m["extras"]["clothfit_weave_textures"] = WeaveTexturesJson(w, "glTF");
  }
  m["extras"]["clothfit"] = c.provenance;
  j["materials"] = json::array({m});
  if (!images.empty()) {
    j["images"] = images;
    j["textures"] = textures;
  }
  if (!samplers.empty()) j["samplers"] = samplers;
  io::WriteTextAtomic(path, j.dump(2) + "\n");
}

void WriteFilamentMat(const std::string& path, const Converted& c) {
  const render::MaterialPreset& p = c.cloth;
  const MapRef* base_map = FindMap(c, "base_color");
  const MapRef* normal_map = FindMap(c, "normal");
  const Rgb<double> base = Factor(Colour(p, "base_color"), base_map);
  const Rgb<double> sheen = EffectiveSheen(p);
  std::string name = c.name;  // a string literal in the .mat: no quotes, backslashes, newlines
  for (char& ch : name)
    if (ch == '"' || ch == '\\' || ch == '\n') ch = '_';
  std::ostringstream s;
  s << "// " << name << ": written by clothfit convert. Filament cloth shading model\n"
    << "// (current shader tree). baseColor, sheenColor, subsurfaceColor are linear sRGB;\n"
    << "// roughness is perceptual (Filament squares it). sheenColor is always written\n"
    << "// explicitly (no reliance on Filament's sqrt(baseColor) / white default).\n";
  if (base_map)
    s << "// baseColorMap: " << Relative(base_map->path, path)
      << " (sRGB: load it as an SRGB8_A8 texture so sampling decodes to linear)\n";
  if (normal_map)
    s << "// normalMap: " << Relative(normal_map->path, path) << " (linear RGB8 texture)\n";
  std::vector<std::string> props = {"    name : \"" + name + "\"", "    shadingModel : cloth"};
  if (base_map || normal_map) {
    std::string params = "    parameters : [\n";
    if (base_map) params += "        { type : sampler2d, name : baseColorMap }";
    if (base_map && normal_map) params += ",\n";
    if (normal_map) params += "        { type : sampler2d, name : normalMap }";
    props.push_back(params + "\n    ]");
    props.push_back("    requires : [ uv0 ]");
  }
  s << "material {\n";
  for (size_t i = 0; i < props.size(); ++i) s << props[i] << (i + 1 < props.size() ? ",\n" : "\n");
  s << "}\n\nfragment {\n    void material(inout MaterialInputs material) {\n";
  if (normal_map)
    s << "        material.normal = texture(materialParams_normalMap, getUV0()).xyz * 2.0 - 1.0;\n";
  s << "        prepareMaterial(material);\n";
  s << "        material.baseColor = vec4(" << Num(base[0]) << ", " << Num(base[1]) << ", "
    << Num(base[2]) << ", 1.0)";
  if (base_map) s << " * texture(materialParams_baseColorMap, getUV0())";
  s << ";\n";
  s << "        material.roughness = " << Num(p.values[6]) << ";\n";
  s << "        material.sheenColor = vec3(" << Num(sheen[0]) << ", " << Num(sheen[1]) << ", "
    << Num(sheen[2]) << ");\n";
  if (p.cloth.subsurface) {
    const Rgb<double> sub = Colour(p, "subsurface_color");
    s << "        material.subsurfaceColor = vec3(" << Num(sub[0]) << ", " << Num(sub[1]) << ", "
      << Num(sub[2]) << ");\n";
  }
  s << "    }\n}\n";
  io::WriteTextAtomic(path, s.str());
}

void WritePngFile(const std::string& path, int width, int height, int channels,
                  const std::vector<unsigned char>& pixels, bool srgb) {
  std::string png;
  try {
    png = io::EncodePng(width, height, channels, pixels, srgb);
  } catch (const std::exception& e) {
    throw ConvertError(path + ": " + e.what());
  }
  io::WriteTextAtomic(path, png);
}

std::vector<std::string> WritePresetWithMaps(const std::string& path, const SourceMaterial& m,
                                             const json& provenance) {
  if (!m.analytic) throw ConvertError(path + ": not a preset source");
  render::MaterialPreset p = *m.analytic;
  std::vector<std::string> written;
  auto copy = [&](const std::string& from, const std::string& suffix) {
    std::string stem = path;
    const std::string ext = ".preset.json";
    if (stem.size() > ext.size() && stem.compare(stem.size() - ext.size(), ext.size(), ext) == 0)
      stem.resize(stem.size() - ext.size());
    const std::string to = stem + suffix;
    std::string bytes;
    try {
      bytes = limits::ReadFileBounded(from, limits::kMaxImageFileBytes, "weave map");
    } catch (const limits::InputError& e) {
      throw ConvertError(e.what());
    }
    io::WriteTextAtomic(to, bytes);
    written.push_back(to);
    return to;
  };
  if (!m.weave_maps_file.empty()) {
    json& f = p.extra["weave_maps"];
    const std::string exr = copy(m.weave_maps_file, ".weave.exr");
    f["file"] = fs::absolute(exr).lexically_normal().string();
    f["uri"] = Relative(exr, path);
    if (!m.glint_file.empty()) {
      const std::string g = copy(m.glint_file, ".glint.exr");
      f["glint_file"] = fs::absolute(g).lexically_normal().string();
      f["glint_uri"] = Relative(g, path);
    }
    f["paths"] =
        "\"uri\"/\"glint_uri\": relative to this preset's directory, read first by every reader "
        "(survive moving the directory); \"file\"/\"glint_file\": absolute, read only without a "
        "\"uri\"";
  }
  p.extra["convert"] = provenance;
  render::WritePreset(path, p);
  written.insert(written.begin(), path);
  return written;
}

render::MaterialPreset ReadThreejsPhysical(const std::string& path) {
  const json j = ReadJson(path);
  if (j.value("type", "") != "MeshPhysicalMaterial") Fail(path, "type", "not MeshPhysicalMaterial");
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kPhysicalSheen);
  const Rgb<double> c = FromHex(j.value("color", json()), path, "color");
  const Rgb<double> s = FromHex(j.value("sheenColor", json()), path, "sheenColor");
  const double sheen = CheckedNumber(j.value("sheen", json(1.0)), path, "sheen", 0, 1);
  for (int k = 0; k < 3; ++k) {
    p.values[size_t(k)] = c[k];
    p.values[size_t(5 + k)] = s[k] * sheen;
  }
  p.values[3] = CheckedNumber(j.value("roughness", json()), path, "roughness", 0, 1);
  p.values[4] = CheckedNumber(j.value("metalness", json()), path, "metalness", 0, 1);
  p.values[8] = CheckedNumber(j.value("sheenRoughness", json()), path, "sheenRoughness", 0, 1);
  if (!j.contains("anisotropy") && !j.contains("specularIntensity")) return p;
  // With anisotropy or specular: the physical-aniso model (same first 9 parameters).
  render::MaterialPreset a = render::DefaultPreset(ModelKind::kPhysicalAniso);
  std::copy(p.values.begin(), p.values.begin() + 9, a.values.begin());
  a.values[size_t(a.Offset("anisotropy_strength"))] =
      CheckedNumber(j.value("anisotropy", json(0.0)), path, "anisotropy", 0, 1);
  a.values[size_t(a.Offset("anisotropy_rotation"))] = CheckedNumber(
      j.value("anisotropyRotation", json(0.0)), path, "anisotropyRotation", -kPi, kPi);
  a.values[size_t(a.Offset("specular_intensity"))] =
      CheckedNumber(j.value("specularIntensity", json(1.0)), path, "specularIntensity", 0, 1);
  const Rgb<double> sc = FromHex(j.value("specularColor", json(0xffffff)), path, "specularColor");
  const int o = a.Offset("specular_color");
  for (int k = 0; k < 3; ++k) a.values[size_t(o + k)] = sc[k];
  return a;
}

render::MaterialPreset ReadThreejsCloth(const std::string& path) {
  const json j = ReadJson(path);
  if (j.value("type", "") != "MeshClothMaterial") Fail(path, "type", "not MeshClothMaterial");
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kCloth);
  p.cloth.variant = cloth::Variant::kSeedThreejs;  // the seed's material, explicit sheen
  const Rgb<double> c = FromHex(j.value("color", json()), path, "color");
  const Rgb<double> s = FromHex(j.value("sheen", json()), path, "sheen");
  for (int k = 0; k < 3; ++k) {
    p.values[size_t(k)] = c[k];
    p.values[size_t(3 + k)] = s[k];
  }
  p.values[6] = CheckedNumber(j.value("roughness", json()), path, "roughness", 0, 1);
  if (j.value("subsurface", false)) {
    p.cloth.subsurface = true;
    const Rgb<double> u = FromHex(j.value("subsurfaceColor", json()), path, "subsurfaceColor");
    for (int k = 0; k < 3; ++k) p.values[size_t(7 + k)] = u[k];
  }
  return p;
}

render::MaterialPreset ReadFilamentMat(const std::string& path) {
  std::ifstream in(path);
  if (!in) Fail(path, "file", "cannot open");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  if (text.find("shadingModel : cloth") == std::string::npos)
    Fail(path, "shadingModel", "not cloth");
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kCloth);
  const std::string num = R"(([-+0-9.eE]+))";
  auto vec = [&](const std::string& field, int n, int offset) {
    std::string pat = "material\\." + field + " = vec" + std::to_string(n == 1 ? 0 : n) + "\\(";
    if (n == 1) pat = "material\\." + field + " = ";
    for (int k = 0; k < n; ++k) pat += num + (k + 1 < n ? ", " : "");
    std::smatch m;
    if (!std::regex_search(text, m, std::regex(pat))) return false;
    for (int k = 0; k < n; ++k) p.values[size_t(offset + k)] = std::stod(m[size_t(k + 1)].str());
    return true;
  };
  if (!vec("baseColor", 4, 0)) Fail(path, "material.baseColor", "not found");
  if (!vec("roughness", 1, 6)) Fail(path, "material.roughness", "not found");
  if (!vec("sheenColor", 3, 3)) Fail(path, "material.sheenColor", "not found");
  if (vec("subsurfaceColor", 3, 7)) p.cloth.subsurface = true;
  return p;
}

}  // namespace clothfit::fit
