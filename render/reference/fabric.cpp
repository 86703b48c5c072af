// render/reference/fabric.cpp: the fabric JSON loader (schema in fabric.h and docs/woven-cloth.md).
#include "render/reference/fabric.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "render/reference/irawan.h"
#include "render/reference/sadeghi.h"
#include "render/reference/simple_bsdf.h"
#include "render/reference/weave_pattern.h"
#include "render/scene/input_limits.h"

namespace clothfit::render {
namespace {

[[noreturn]] void Fail(const std::string& path, const std::string& message) {
  throw FabricError(path + ": " + message);
}

std::string LineColumn(const std::string& text, size_t byte) {
  size_t line = 1, col = 1;
  for (size_t i = 0; i < text.size() && i + 1 < byte; ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(col);
}

std::string GetString(const nlohmann::json& j, const char* field, const std::string& path) {
  if (!j.contains(field)) Fail(path, std::string("missing field '") + field + "'");
  const auto& v = j.at(field);
  if (!v.is_string()) Fail(path, std::string("field '") + field + "' must be a string");
  const std::string s = v.get<std::string>();
  if (s.empty() || s.size() > 256) {
    Fail(path, std::string("field '") + field + "' must be a non-empty string (<= 256 chars)");
  }
  return s;
}

// An RGB triple of finite numbers in [0, 1] (reflectances).
Rgbd GetRgb01(const nlohmann::json& j, const char* field, const std::string& path) {
  if (!j.contains(field)) Fail(path, std::string("missing field '") + field + "'");
  const auto& v = j.at(field);
  if (!v.is_array() || v.size() != 3) {
    Fail(path, std::string("field '") + field + "' must be an array of 3 numbers");
  }
  double c[3];
  for (size_t i = 0; i < 3; ++i) {
    if (!v[i].is_number()) Fail(path, std::string("field '") + field + "' must hold numbers");
    c[i] = v[i].get<double>();
    if (!std::isfinite(c[i]) || c[i] < 0.0 || c[i] > 1.0) {
      Fail(path, std::string("field '") + field + "' must be in [0, 1], got " + v.dump());
    }
  }
  return Rgbd(c[0], c[1], c[2]);
}

}  // namespace

Fabric ParseFabric(const std::string& text, const std::string& path) {
  nlohmann::json j;
  try {
    limits::CheckJsonDepth(text, path);  // before the DOM: nlohmann copies and dumps recurse
    j = nlohmann::json::parse(text);
  } catch (const limits::InputError& e) {
    throw FabricError(e.what());
  } catch (const nlohmann::json::parse_error& e) {
    Fail(path, "JSON syntax error at " + LineColumn(text, e.byte) + ": " +
                   limits::EscapeForMessage(e.what(), 400));
  } catch (const nlohmann::json::out_of_range& e) {  // 406: a number beyond double (1e400)
    Fail(path, "malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  }
  if (!j.is_object()) Fail(path, "top level must be a JSON object");
  static const std::set<std::string> known = {"format", "version",    "name",       "model",
                                              "preset", "weave_file", "uv_repeats", "albedo",
                                              "colour", "roughness"};
  for (const auto& item : j.items()) {
    if (!known.count(item.key())) {
      Fail(path, "unknown field '" + limits::EscapeForMessage(item.key(), 80) +
                     "' (valid: format, version, name, model, preset, weave_file, uv_repeats, "
                     "albedo, colour, roughness)");
    }
  }
  if (GetString(j, "format", path) != "clothfit-fabric") {
    Fail(path, "field 'format' must be \"clothfit-fabric\"");
  }
  if (!j.contains("version")) Fail(path, "missing field 'version'");
  if (!j.at("version").is_number_integer() || j.at("version").get<long>() != 1) {
    Fail(path, "field 'version' must be 1");
  }
  Fabric f;
  f.name = GetString(j, "name", path);
  // The name goes to terminals (summary lines, progress bars), EXR metadata and reports: no
  // control bytes (session 28: an ESC sequence in it reached the terminal unescaped).
  for (const char ch : f.name) {
    const auto byte = static_cast<unsigned char>(ch);
    if (byte < 0x20 || byte == 0x7f)
      Fail(path, "field 'name' must be printable text without control characters, got \"" +
                     limits::EscapeForMessage(f.name, 80) + "\"");
  }
  f.model = GetString(j, "model", path);
  // Simple materials (simple_bsdf.h): no weave, no preset; for comparisons with other renderers.
  if (f.model == "lambert" || f.model == "ggx_conductor") {
    for (const char* woven : {"preset", "weave_file", "uv_repeats"}) {
      if (j.contains(woven)) Fail(path, std::string("field '") + woven + "' applies to woven models only");
    }
    const char* other = f.model == "lambert" ? "colour" : "albedo";
    if (j.contains(other)) Fail(path, std::string("field '") + other + "' does not apply to model '" + f.model + "'");
    if (f.model == "lambert") {
      if (j.contains("roughness")) Fail(path, "field 'roughness' does not apply to model 'lambert'");
      f.bsdf = std::make_unique<LambertBsdf>(GetRgb01(j, "albedo", path));
    } else {
      if (!j.contains("roughness") || !j.at("roughness").is_number()) {
        Fail(path, "field 'roughness' must be a number in [0, 1]");
      }
      const double r = j.at("roughness").get<double>();
      if (!std::isfinite(r) || r < 0.0 || r > 1.0) {
        Fail(path, "field 'roughness' must be in [0, 1], got " + j.at("roughness").dump());
      }
      f.bsdf = std::make_unique<GgxConductorBsdf>(GetRgb01(j, "colour", path), r);
    }
    return f;
  }
  for (const char* simple : {"albedo", "colour", "roughness"}) {
    if (j.contains(simple)) {
      Fail(path, std::string("unknown field '") + simple + "' for model '" + f.model +
                     "' (it applies to models lambert/ggx_conductor only)");
    }
  }
  f.preset = GetString(j, "preset", path);
  // The preset names a file under ../weaves/ (or a built-in table): a plain name, so that it
  // cannot walk out of the fabric library ("../../x").
  if (f.preset == "." || f.preset == ".." ||
      f.preset.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                 "0123456789_.-") != std::string::npos)
    Fail(path, "field 'preset' must be a plain name of letters, digits, '_', '.' and '-', got \"" +
                   limits::EscapeForMessage(f.preset, 80) + "\"");
  if (!j.contains("uv_repeats")) Fail(path, "missing field 'uv_repeats'");
  if (!j.at("uv_repeats").is_number()) Fail(path, "field 'uv_repeats' must be a number");
  f.uv_repeats = j.at("uv_repeats").get<double>();
  if (!std::isfinite(f.uv_repeats) || !(f.uv_repeats > 0.0) || f.uv_repeats > 10000.0) {
    Fail(path, "field 'uv_repeats' must be in (0, 10000], got " + j.at("uv_repeats").dump());
  }
  f.weave_period_uv = 1.0 / f.uv_repeats;
  if (f.model == "irawan") {
    std::filesystem::path weave;
    if (j.contains("weave_file")) {
      weave = GetString(j, "weave_file", path);
    } else {
      weave = std::filesystem::path("..") / "weaves" / (f.preset + ".weave");
    }
    if (weave.is_relative()) weave = std::filesystem::path(path).parent_path() / weave;
    f.weave_path = weave.lexically_normal().string();
    try {
      WeavePattern pattern = LoadWeave(f.weave_path);
      f.bsdf = std::make_unique<IrawanBsdf>(std::move(pattern), f.uv_repeats, f.uv_repeats);
    } catch (const WeavePatternError& e) {
      // A fabric copied out of datasets/fabrics/ loses its ../weaves/ neighbour: say where the
      // file was looked for and how to point at it.
      const std::string hint =
          j.contains("weave_file")
              ? " ('weave_file' is relative to the fabric file's directory)"
              : " ('preset' \"" + f.preset + "\" names ../weaves/" + f.preset +
                    ".weave next to the fabric file's directory; copy that file along, or give "
                    "'weave_file' with its path)";
      Fail(path, std::string("field 'preset'/'weave_file': ") + e.what() +
                     (std::filesystem::exists(weave) ? std::string() : hint));
    }
  } else if (f.model == "sadeghi") {
    if (j.contains("weave_file")) Fail(path, "field 'weave_file' applies to model 'irawan' only");
    try {
      f.bsdf = std::make_unique<SadeghiBsdf>(SadeghiPreset(f.preset));
    } catch (const std::invalid_argument& e) {
      Fail(path, std::string("field 'preset': ") + e.what());
    }
  } else {
    Fail(path, "field 'model' must be \"irawan\", \"sadeghi\", \"lambert\" or \"ggx_conductor\", got \"" +
                   limits::EscapeForMessage(f.model, 80) + "\"");
  }
  return f;
}

Fabric LoadFabric(const std::string& path) {
  std::string text;
  try {  // size checked on the descriptor before reading (/dev/zero is refused, not read)
    text = limits::ReadFileBounded(path, limits::kMaxSmallTextBytes, "fabric file");
  } catch (const limits::InputError& e) {
    throw FabricError(e.what());
  }
  return ParseFabric(text, path);
}

}  // namespace clothfit::render
