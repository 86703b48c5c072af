#include "fit/metrics/report.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include "fit/metrics/reference_halves.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
#include "render/scene/material.h"

namespace clothfit::report {
namespace fs = std::filesystem;

namespace {

// ---- small helpers -------------------------------------------------------------------------

std::string Fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

// Canonical column order of the models in a report.
int ModelRank(const std::string& model) {
  if (model == "cloth") return 0;
  if (model == "physical-sheen") return 1;
  if (model == "standard") return 2;
  if (model == "gltf-sheen") return 3;
  if (model == "woven") return 4;
  if (model == "physical-aniso") return 5;
  return 6;
}

std::string ModelTitle(const std::string& model) {
  if (model == "cloth") return "cloth (Filament)";
  if (model == "physical-sheen") return "MeshPhysicalMaterial (sheen)";
  if (model == "standard") return "MeshStandardMaterial";
  if (model == "gltf-sheen") return "glTF KHR_materials_sheen";
  if (model == "woven") return "woven (clothfit, web/)";
  if (model == "physical-aniso") return "MeshPhysicalMaterial (sheen + anisotropy, weave maps)";
  return model;
}

// The title of one fitted model: ModelTitle, plus the yarn lobe a woven preset carries
// ("woven": {"yarn_lobe"}, session 12), so the page says which woven it shows.
std::string ModelTitle(const ModelSpec& m) {
  std::string t = ModelTitle(m.model);
  const nlohmann::json* w = m.preset.is_object() && m.preset.contains("woven") ? &m.preset.at("woven") : nullptr;
  if (m.model == "woven" && w && w->is_object() && w->contains("yarn_lobe")) {
    const nlohmann::json& y = w->at("yarn_lobe");
    const bool micro = y.is_object() && y.contains("model") && y.at("model") == "sadeghi-microcylinder";
    t += micro ? ", microcylinder fibre lobe" : ", far-field yarn lobe";
  }
  else if (m.model == "woven")
    t += ", GGX yarn lobes";
  return t;
}

// Resolves a path written in a preset: absolute as is, relative to the preset's directory.
std::string Resolve(const std::string& path, const std::string& preset_path) {
  const fs::path p(path);
  if (p.is_absolute()) return path;
  return (fs::path(preset_path).parent_path() / p).lexically_normal().string();
}

const nlohmann::json& Field(const nlohmann::json& j, const std::string& key,
                            const std::string& where) {
  if (!j.is_object() || !j.contains(key))
    throw ReportError(where + ": missing field \"" + key + "\"");
  return j.at(key);
}

std::string StringField(const nlohmann::json& j, const std::string& key, const std::string& where,
                        const std::string& hint = "") {
  if (!j.is_object() || !j.contains(key))
    throw ReportError(where + ": missing field \"" + key + "\"" + hint);
  const nlohmann::json& v = j.at(key);
  if (!v.is_string()) throw ReportError(where + ": field \"" + key + "\" must be a string");
  return v.get<std::string>();
}

// Reads an image and converts it to RGB; every error names the file.
struct LoadedImage {
  metrics::RgbImage rgb;
  std::optional<metrics::Map> coverage;  // "fabric", else "A"
  metrics::ReferenceHalves halves;       // references only (want_coverage)
};

LoadedImage Load(const std::string& path, bool want_coverage) {
  io::Image img;
  try {
    img = io::ReadImage(path);
  } catch (const std::exception& e) {
    throw ReportError(e.what());
  }
  LoadedImage out;
  try {
    out.rgb = metrics::ToRgb(img, path);
  } catch (const std::exception& e) {
    throw ReportError(e.what());
  }
  if (want_coverage) {
    try {
      out.halves = metrics::ExtractHalves(img, path);
    } catch (const std::exception& e) {
      throw ReportError(e.what());
    }
    for (const char* name : {"fabric", "A"}) {
      const auto it = std::find(img.channel_names.begin(), img.channel_names.end(), name);
      if (it == img.channel_names.end()) continue;
      const size_t c = size_t(it - img.channel_names.begin());
      const size_t nc = size_t(img.channels());
      metrics::Map m(img.width, img.height);
      for (size_t i = 0; i < m.values.size(); ++i) {
        const float v = img.pixels[i * nc + c];
        m.values[i] = std::isfinite(v) ? v : 0.0f;  // non-finite coverage: not fabric
      }
      out.coverage = std::move(m);
      break;
    }
  }
  return out;
}

long long CountNonFinite(const metrics::RgbImage& img) {
  long long n = 0;
  for (size_t i = 0; i < img.pixel_count(); ++i)
    if (!std::isfinite(img.rgb[3 * i]) || !std::isfinite(img.rgb[3 * i + 1]) ||
        !std::isfinite(img.rgb[3 * i + 2]))
      ++n;
  return n;
}

// The display picture of a linear image (scene card transform); non-finite pixels magenta.
std::string DisplayPng(const metrics::RgbImage& linear, render::ToneMapping op, double exposure,
                       const std::string& what) {
  std::vector<float> rgb(linear.rgb.size());
  for (size_t i = 0; i < linear.pixel_count(); ++i) {
    const float* p = &linear.rgb[3 * i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      rgb[3 * i] = 1.0f;
      rgb[3 * i + 1] = 0.0f;
      rgb[3 * i + 2] = 1.0f;
      continue;
    }
    const Rgb<double> d =
        render::ToDisplay(Rgb<double>(double(p[0]), double(p[1]), double(p[2])), op, exposure);
    for (int k = 0; k < 3; ++k) rgb[3 * i + size_t(k)] = float(d[k]);
  }
  return Base64(io::EncodePng8(linear.width, linear.height, rgb, what));
}

// Outside the mask (not fabric: not in the pooled numbers) the colours are dimmed to 35 %.
constexpr float kOutsideDim = 0.35f;

std::string MapPng(const metrics::Map& map, const metrics::Map* mask, const std::string& what) {
  std::vector<float> rgb(3 * map.values.size());
  for (size_t i = 0; i < map.values.size(); ++i) {
    const std::array<float, 3> c = metrics::ErrorMapColour(double(map.values[i]));
    const float dim = (mask && !(mask->values[i] > 0.5f)) ? kOutsideDim : 1.0f;
    for (size_t k = 0; k < 3; ++k) rgb[3 * i + k] = c[k] * dim;
  }
  return Base64(io::EncodePng8(map.width, map.height, rgb, what));
}

// The scalar metrics a report carries, in report order: JSON keys and CSV columns. Each is
// copied from the metrics::CompareResult member of the same name; a PSNR may be +inf
// (identical images), every other value must be finite.
struct MetricField {
  const char* name;
  double Numbers::*numbers;
  double metrics::CompareResult::*result;
  bool psnr;
};
constexpr MetricField kMetricFields[] = {
    {"rmse_linear", &Numbers::rmse_linear, &metrics::CompareResult::rmse_linear, false},
    {"psnr_linear", &Numbers::psnr_linear, &metrics::CompareResult::psnr_linear, true},
    {"rmse_display", &Numbers::rmse_display, &metrics::CompareResult::rmse_display, false},
    {"psnr_display", &Numbers::psnr_display, &metrics::CompareResult::psnr_display, true},
    {"ssim", &Numbers::ssim, &metrics::CompareResult::ssim, false},
    {"flip", &Numbers::flip, &metrics::CompareResult::flip, false},
    {"hdr_flip", &Numbers::hdr_flip, &metrics::CompareResult::hdr_flip, false},
    {"ciede2000_mean", &Numbers::ciede2000_mean, &metrics::CompareResult::ciede2000_mean, false},
    {"ciede2000_p95", &Numbers::ciede2000_p95, &metrics::CompareResult::ciede2000_p95, false},
    {"ciede2000_display_mean", &Numbers::ciede2000_display_mean,
     &metrics::CompareResult::ciede2000_display_mean, false},
    {"ciede2000_display_p95", &Numbers::ciede2000_display_p95,
     &metrics::CompareResult::ciede2000_display_p95, false},
};

bool NumbersFinite(const Numbers& n) {
  for (const MetricField& f : kMetricFields) {
    const double v = n.*f.numbers;
    if (f.psnr ? (std::isnan(v) || (std::isinf(v) && v < 0)) : !std::isfinite(v)) return false;
  }
  return true;
}

struct Comparison {
  Numbers numbers;
  std::string flip_png;
};

Comparison Compare(const metrics::RgbImage& ref, const metrics::RgbImage& test,
                   const metrics::Map* mask, const SceneSpec& scene,
                   const metrics::ExposureRange& range, const ReportOptions& options,
                   const std::string& test_path) {
  Comparison out;
  metrics::CompareOptions o;
  o.tone_mapping = scene.tone_mapping;
  o.exposure = scene.exposure;
  o.ppd = options.ppd;
  o.hdr_range = range;
  const long long bad_ref = CountNonFinite(ref), bad_test = CountNonFinite(test);
  metrics::CompareResult r;
  try {
    r = metrics::Compare(ref, test, o, mask);
  } catch (const std::invalid_argument& e) {
    out.numbers.ok = false;
    out.numbers.why = (bad_ref || bad_test) ? "NaN/Inf in input" : std::string(e.what());
    out.numbers.counts.nonfinite_ref = bad_ref;
    out.numbers.counts.nonfinite_test = bad_test;
    metrics::Map blank(ref.width, ref.height);
    out.flip_png = MapPng(blank, mask, test_path);
    return out;
  }
  Numbers& n = out.numbers;
  for (const MetricField& f : kMetricFields) n.*f.numbers = r.*f.result;
  n.counts = r.counts;
  n.ok = NumbersFinite(n);
  if (!n.ok) n.why = "non-finite result";
  for (const auto& m : r.maps)
    if (m.name == "flip") out.flip_png = MapPng(m.map, mask, test_path);
  return out;
}

// ---- formatting --------------------------------------------------------------------------

std::string Na(const Numbers& n) { return "n/a (" + n.why + ")"; }

struct Column {
  const char* key;          // JSON / CSV name
  const char* title;        // HTML header
  const char* short_title;  // terminal header
  const char* help;         // tooltip
  int decimals;
  double Numbers::*field;
  bool psnr;
};

// The columns of every table, in order (HTML, terminal; JSON and CSV add the linear-Lab
// Delta E and the pixel counts).
const std::array<Column, 8>& Columns() {
  static const std::array<Column, 8> kColumns = {{
      {"rmse_display", "RMSE", "RMSE", "display values (tone mapped, sRGB), lower is better", 4,
       &Numbers::rmse_display, false},
      {"psnr_display", "PSNR dB", "PSNR", "display values, peak 1, higher is better", 2,
       &Numbers::psnr_display, true},
      {"ssim", "SSIM", "SSIM", "display values, 11x11 Gaussian, higher is better", 4,
       &Numbers::ssim, false},
      {"flip", "FLIP", "FLIP", "LDR-FLIP of the display values, PPD 67, lower is better", 4,
       &Numbers::flip, false},
      {"hdr_flip", "HDR-FLIP", "HDRFLIP", "HDR-FLIP of linear values, shared exposure range", 4,
       &Numbers::hdr_flip, false},
      {"ciede2000_display_mean", "&Delta;E00 mean", "dE mean",
       "CIEDE2000 of the displayed colour, mean", 2, &Numbers::ciede2000_display_mean, false},
      {"ciede2000_display_p95", "&Delta;E00 p95", "dE p95",
       "CIEDE2000 of the displayed colour, 95th percentile", 2, &Numbers::ciede2000_display_p95,
       false},
      {"rmse_linear", "RMSE lin", "RMSElin", "linear radiance", 4, &Numbers::rmse_linear, false},
  }};
  return kColumns;
}

std::string Cell(const Numbers& n, const Column& c) {
  if (!n.ok) return Na(n);
  return FormatNumber(n.*(c.field), c.decimals, c.psnr);
}

// Sort key for the index table: numbers as is, n/a last (empty), inf as a large number.
std::string SortKey(const Numbers& n, const Column& c) {
  if (!n.ok) return "";
  const double v = n.*(c.field);
  if (std::isinf(v)) return v > 0 ? "1e308" : "-1e308";
  return Fmt("%.9g", v);
}

nlohmann::json JsonNumber(double v) {
  if (std::isfinite(v)) return v;
  if (std::isinf(v) && v > 0) return "inf";  // PSNR of identical images (as clothfit compare)
  return nullptr;
}

nlohmann::json NumbersJson(const Numbers& n) {
  nlohmann::json j;
  j["ok"] = n.ok;
  if (!n.ok) j["why"] = n.why;
  for (const MetricField& f : kMetricFields)
    j[f.name] = n.ok ? JsonNumber(n.*f.numbers) : nlohmann::json(nullptr);
  j["pixels"] = {{"counted", n.counts.counted},
                 {"nonfinite_reference", n.counts.nonfinite_ref},
                 {"nonfinite_test", n.counts.nonfinite_test}};
  return j;
}

// A value from the preset's "fit" object for the solver table.
std::string FitValue(const nlohmann::json& fit, const std::string& key, int decimals) {
  if (!fit.is_object() || !fit.contains(key)) return "n/a (missing)";
  const nlohmann::json& v = fit.at(key);
  if (v.is_number()) return FormatNumber(v.get<double>(), decimals);
  if (v.is_null()) return "n/a (not finite in input)";
  if (v.is_string()) return EscapeHtml(v.get<std::string>());
  return EscapeHtml(v.dump());
}

std::string NonFiniteNote(const metrics::PixelCounts& c, const std::string& test_name) {
  if (c.nonfinite_ref == 0 && c.nonfinite_test == 0) return "";
  std::string s = "NaN/Inf pixels excluded:";
  if (c.nonfinite_ref) s += " reference " + std::to_string(c.nonfinite_ref);
  if (c.nonfinite_test) s += " " + test_name + " " + std::to_string(c.nonfinite_test);
  return s;
}

const char* kCss = R"CSS(
body{font:14px/1.4 system-ui,-apple-system,"Segoe UI",sans-serif;margin:24px auto;max-width:1200px;
color:#1d2127;background:#fafafa;padding:0 16px}
h1{font-size:24px;margin:0 0 4px}h2{font-size:19px;margin:28px 0 8px;border-bottom:1px solid #ccd;
padding-bottom:4px}h3{font-size:16px;margin:20px 0 6px}
.meta{color:#556;font-size:13px;margin:2px 0}
table{border-collapse:collapse;margin:6px 0 12px;font-size:13px;background:#fff}
th,td{border:1px solid #d5d8de;padding:3px 8px;text-align:right;white-space:nowrap}
th{background:#eef0f4;font-weight:600}td.l,th.l{text-align:left}
tr.floor td{color:#556;font-style:italic;background:#f4f4f7}
td.na{color:#a33}
.grid{display:grid;grid-template-columns:repeat(var(--cols),minmax(0,1fr));gap:8px;
max-width:calc(var(--cols)*264px)}
figure{margin:0;background:#fff;border:1px solid #d5d8de;padding:4px}
figure img{display:block;width:100%;height:auto;max-width:256px;margin:0 auto}
figcaption{font-size:12px;color:#333;margin-top:3px;text-align:center;overflow-wrap:anywhere}
.bar{display:inline-block;width:200px;height:12px;vertical-align:middle;border:1px solid #999;
background:linear-gradient(to right,#000,#1a1a99,#bf268c,#ff8c0d,#ffffd9)}
.sw{display:inline-block;width:28px;height:16px;border:1px solid #777;vertical-align:middle;
margin-right:6px}
.cards{display:flex;flex-wrap:wrap;gap:12px}
.card{background:#fff;border:1px solid #d5d8de;max-width:520px;padding:8px 12px}
code{font-size:12px;overflow-wrap:anywhere}pre{font-size:12px;white-space:pre-wrap;max-width:1100px}
th.s{cursor:pointer}th.s:after{content:" \2195";color:#889}
)CSS";

std::string Header(const std::string& title) {
  return "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>" +
         EscapeHtml(title) + "</title>\n<style>" + kCss + "</style></head><body>\n";
}

std::string Img(const std::string& b64, const std::string& alt) {
  return "<img alt=\"" + EscapeHtml(alt) + "\" src=\"data:image/png;base64," + b64 + "\">";
}

// One metrics table: rows of (label, numbers, is noise floor, name of the test image). The
// note column (excluded NaN/Inf pixels) appears only when some row has a note.
struct MetricsRowSpec {
  std::string label;
  const Numbers* numbers;
  bool floor;
  std::string test_name;
};

std::string MetricsTable(const std::vector<MetricsRowSpec>& rows) {
  bool notes = false;
  for (const MetricsRowSpec& r : rows)
    notes = notes || !NonFiniteNote(r.numbers->counts, r.test_name).empty();
  std::string s = "<table><tr><th class=\"l\">model</th>";
  for (const Column& c : Columns())
    s += std::string("<th title=\"") + c.help + "\">" + c.title + "</th>";
  s += notes ? "<th class=\"l\">note</th></tr>\n" : "</tr>\n";
  for (const MetricsRowSpec& r : rows) {
    const Numbers& n = *r.numbers;
    s += r.floor ? "<tr class=\"floor\">" : "<tr>";
    s += "<td class=\"l\">" + EscapeHtml(r.label) + "</td>";
    for (const Column& c : Columns())
      s += std::string(n.ok ? "<td>" : "<td class=\"na\">") + EscapeHtml(Cell(n, c)) + "</td>";
    if (notes) s += "<td class=\"l\">" + EscapeHtml(NonFiniteNote(n.counts, r.test_name)) + "</td>";
    s += "</tr>\n";
  }
  return s + "</table>\n";
}

// Parameter value cell (+ swatch for colours).
std::string ParameterCells(const std::string& name, const nlohmann::json& v) {
  auto num = [](const nlohmann::json& x) -> std::optional<double> {
    if (x.is_number()) {
      const double d = x.get<double>();
      if (std::isfinite(d)) return d;
    }
    return std::nullopt;
  };
  if (v.is_array()) {
    std::string text = "(";
    std::array<double, 3> c{};
    bool finite = true;
    for (size_t i = 0; i < v.size(); ++i) {
      const auto d = num(v[i]);
      text += (i ? ", " : "") + (d ? FormatNumber(*d, 4) : std::string("n/a"));
      if (!d) finite = false;
      if (i < 3 && d) c[i] = *d;
    }
    text += ")";
    std::string swatch;
    if (v.size() == 3 && name.find("color") != std::string::npos) {
      if (finite) {
        const std::string hex = SrgbHex(c[0], c[1], c[2]);
        swatch =
            "<span class=\"sw\" style=\"background:" + hex + "\"></span><code>" + hex + "</code>";
      } else {
        swatch = "n/a (not finite in input)";
      }
    }
    if (!finite) text += " n/a (not finite in input)";
    return "<td class=\"l\"><code>" + EscapeHtml(text) + "</code></td><td class=\"l\">" + swatch +
           "</td>";
  }
  const auto d = num(v);
  return "<td class=\"l\"><code>" +
         (d ? FormatNumber(*d, 4) : std::string("n/a (not finite in input)")) +
         "</code></td><td></td>";
}

}  // namespace

// ---- public helpers ------------------------------------------------------------------------

std::string Base64(const std::string& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (unsigned(static_cast<unsigned char>(bytes[i])) << 16) |
                       (unsigned(static_cast<unsigned char>(bytes[i + 1])) << 8) |
                       unsigned(static_cast<unsigned char>(bytes[i + 2]));
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  const size_t rest = bytes.size() - i;
  if (rest > 0) {
    unsigned v = unsigned(static_cast<unsigned char>(bytes[i])) << 16;
    if (rest == 2) v |= unsigned(static_cast<unsigned char>(bytes[i + 1])) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string Base64(const std::vector<unsigned char>& bytes) {
  return Base64(std::string(bytes.begin(), bytes.end()));
}

std::string FormatNumber(double v, int decimals, bool allow_infinity) {
  if (std::isnan(v)) return "n/a (not finite in input)";
  if (std::isinf(v)) {
    if (!allow_infinity) return "n/a (not finite in input)";
    return v > 0 ? "inf" : "-inf";
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return buf;
}

std::string EscapeHtml(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string SrgbHex(double r, double g, double b) {
  if (!std::isfinite(r) || !std::isfinite(g) || !std::isfinite(b)) return "";
  char buf[8];
  const auto enc = [](double x) { return int(std::lround(255.0 * render::SrgbEncode(x))); };
  std::snprintf(buf, sizeof buf, "#%02x%02x%02x", enc(r), enc(g), enc(b));
  return buf;
}

std::string PageName(const std::string& fabric_name) {
  std::string s;
  for (char c : fabric_name)
    s += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_') ? c : '_';
  if (s.empty() || s == "index") s = "fabric-" + s;  // never the index page itself
  return s + ".html";
}

// ---- inputs --------------------------------------------------------------------------------

namespace {

// ---- inputs: the pieces of FabricsFromPresets ----

nlohmann::json ReadPresetJson(const std::string& path) {
  if (!fs::exists(path)) throw ReportError(path + ": no such file");
  nlohmann::json j;
  try {  // bounded read and the nesting limit before the DOM (the preset is copied)
    const std::string text = limits::ReadFileBounded(path, limits::kMaxJsonFileBytes, "fit preset");
    limits::CheckJsonDepth(text, path);
    j = nlohmann::json::parse(text);
  } catch (const limits::InputError& e) {
    throw ReportError(e.what());
  } catch (const nlohmann::json::exception& e) {
    throw ReportError(path + ": malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  }
  return j;
}

// fit.scenes[i] of the preset at `path` (`where` names the entry): the scene, and the path of
// the model's preview of it (appended to `previews`).
SceneSpec ParseFitScene(const nlohmann::json& s, const std::string& where, const std::string& path,
                        std::vector<std::string>& previews) {
  SceneSpec sp;
  sp.scene_path = StringField(s, "scene", where);
  sp.name = fs::path(sp.scene_path).stem().string();
  sp.reference = Resolve(StringField(s, "reference", where), path);
  if (s.contains("reference2") && s.at("reference2").is_string())
    sp.reference2 = Resolve(s.at("reference2").get<std::string>(), path);
  const std::string op =
      StringField(s, "tone_mapping", where, " (re-run clothfit fit with --images)");
  try {
    sp.tone_mapping = render::ParseToneMapping(op);
  } catch (const std::invalid_argument& e) {
    throw ReportError(where + ": " + e.what());
  }
  const nlohmann::json& ex = Field(s, "exposure", where);
  if (!ex.is_number() || !std::isfinite(ex.get<double>()) || !(ex.get<double>() > 0))
    throw ReportError(where + ": exposure must be a finite number > 0");
  sp.exposure = ex.get<double>();
  previews.push_back(Resolve(
      StringField(s, "preview", where, " (re-run clothfit fit with --images DIR)"), path));
  return sp;
}

// The name of a fit made from the user's own references (no provenance.fabric): the leading
// words their file stems share, words split at '_', '-' and '.' (glos_sphere_s1.exr and
// glos_swatch_s1.exr -> "glos"); the first reference's stem when they share none. Presets
// fitted to the same references then share a page whatever their own file names (before
// session 27 the name was the preset's file stem, so DIR/woven.json and DIR/standard.json made
// two one-model pages).
std::string NameOfReferences(const std::vector<SceneSpec>& scenes) {
  const auto words = [](const std::string& stem) {
    std::vector<std::string> w(1);
    for (char c : stem) {
      if (c == '_' || c == '-' || c == '.') w.emplace_back();
      else w.back() += c;
    }
    return w;
  };
  const std::string first = fs::path(scenes.at(0).reference).stem().string();
  std::vector<std::string> common = words(first);
  for (const SceneSpec& s : scenes) {
    const std::vector<std::string> w = words(fs::path(s.reference).stem().string());
    size_t k = 0;
    while (k < common.size() && k < w.size() && common[k] == w[k]) ++k;
    common.resize(k);
  }
  std::string name;
  for (const std::string& w : common) {
    if (w.empty()) break;
    name += (name.empty() ? "" : "_") + w;
  }
  return name.empty() ? (first.empty() ? std::string("references") : first) : name;
}

// One fit preset: the model it holds, the scenes it was fitted on and the fabric it belongs to.
struct FitPreset {
  ModelSpec model;
  std::vector<SceneSpec> scenes;
  std::string fabric_name, fabric_path;
};

FitPreset ReadFitPreset(const std::string& path) {
  const nlohmann::json j = ReadPresetJson(path);
  FitPreset p;
  ModelSpec& m = p.model;
  m.preset_path = path;
  m.preset = j;
  m.model = StringField(j, "model", path);
  const nlohmann::json& fit =
      j.is_object() && j.contains("fit")
          ? j.at("fit")
          : throw ReportError(path + ": missing field \"fit\" (not written by clothfit fit?)");
  const nlohmann::json& scenes = Field(fit, "scenes", path + ": fit");
  if (!scenes.is_array() || scenes.empty())
    throw ReportError(path + ": fit.scenes must be a non-empty array");
  for (size_t i = 0; i < scenes.size(); ++i) {
    const std::string where = path + ": fit.scenes[" + std::to_string(i) + "]";
    p.scenes.push_back(ParseFitScene(scenes[i], where, path, m.previews));
  }
  if (j.contains("provenance") && j.at("provenance").is_object() &&
      j.at("provenance").contains("fabric") && j.at("provenance").at("fabric").is_string()) {
    p.fabric_path = j.at("provenance").at("fabric").get<std::string>();
    p.fabric_name = fs::path(p.fabric_path).stem().string();
  } else {
    p.fabric_name = NameOfReferences(p.scenes);
  }
  return p;
}

// Adds a preset to its fabric (a new one when first seen). Throws when the fabric's scenes
// differ from its first preset's or the fabric already has this model.
void AddToFabric(std::vector<FabricSpec>& fabrics,
                 std::map<std::string, std::string>& first_preset_of, FitPreset&& p) {
  const std::string& path = p.model.preset_path;
  const std::string& fabric_name = p.fabric_name;
  const std::vector<SceneSpec>& specs = p.scenes;
  const auto same_scenes = [&](const FabricSpec& f) {
    bool same = f.scenes.size() == specs.size();
    for (size_t i = 0; same && i < specs.size(); ++i)
      same = f.scenes[i].name == specs[i].name && f.scenes[i].reference == specs[i].reference;
    return same;
  };
  if (p.fabric_path.empty()) {
    // Named from its references: another set of references that happens to give the same
    // name is another fabric ("glos", "glos-2"), not an error.
    std::string name = fabric_name;
    for (int k = 2;; ++k) {
      const auto f = std::find_if(fabrics.begin(), fabrics.end(),
                                  [&](const FabricSpec& fs_) { return fs_.name == name; });
      if (f == fabrics.end() || (f->fabric_path.empty() && same_scenes(*f))) break;
      name = fabric_name + "-" + std::to_string(k);
    }
    p.fabric_name = name;
  }
  auto it = std::find_if(fabrics.begin(), fabrics.end(),
                         [&](const FabricSpec& fs_) { return fs_.name == fabric_name; });
  if (it == fabrics.end()) {
    FabricSpec fsp;
    fsp.name = fabric_name;
    fsp.fabric_path = p.fabric_path;
    fsp.scenes = specs;
    fabrics.push_back(fsp);
    first_preset_of[fabric_name] = path;
    it = fabrics.end() - 1;
  } else {
    if (!same_scenes(*it))
      throw ReportError(path + ": its scenes or references differ from " +
                        first_preset_of[fabric_name] + " (same fabric \"" + fabric_name + "\")");
    for (const ModelSpec& other : it->models)
      if (other.model == p.model.model)
        throw ReportError(path + ": model \"" + p.model.model + "\" of fabric \"" + fabric_name +
                          "\" given twice (also " + other.preset_path + ")");
  }
  it->models.push_back(std::move(p.model));
}

}  // namespace

std::vector<FabricSpec> FabricsFromPresets(const std::vector<std::string>& preset_paths) {
  if (preset_paths.empty()) throw ReportError("report: no fit presets given");
  std::vector<FabricSpec> fabrics;
  std::map<std::string, std::string> first_preset_of;  // fabric -> preset path (for errors)
  // Fabrics first, then fits to the user's own references: a fabric keeps its name and a fit
  // whose references' stems spell it becomes "NAME-2", whatever the argument order (session 28:
  // before, the fabric given after such a fit was refused as "the same fabric"). The pages then
  // keep the order of each group's first preset on the command line.
  std::vector<FitPreset> read;
  for (const std::string& path : preset_paths) read.push_back(ReadFitPreset(path));
  std::map<std::string, size_t> position;  // preset path -> index on the command line
  for (size_t i = 0; i < preset_paths.size(); ++i) position.emplace(preset_paths[i], i);
  std::vector<bool> own_refs;  // read before any preset is moved from
  for (const FitPreset& p : read) own_refs.push_back(p.fabric_path.empty());
  for (const bool own : {false, true})
    for (size_t i = 0; i < read.size(); ++i)
      if (own_refs[i] == own) AddToFabric(fabrics, first_preset_of, std::move(read[i]));
  const auto first = [&](const FabricSpec& f) {
    size_t m = preset_paths.size();
    for (const ModelSpec& x : f.models) m = std::min(m, position.at(x.preset_path));
    return m;
  };
  std::stable_sort(fabrics.begin(), fabrics.end(),
                   [&](const FabricSpec& a, const FabricSpec& b) { return first(a) < first(b); });
  for (FabricSpec& f : fabrics)
    std::stable_sort(f.models.begin(), f.models.end(), [](const ModelSpec& a, const ModelSpec& b) {
      return ModelRank(a.model) < ModelRank(b.model);
    });
  return fabrics;
}

// ---- numbers -------------------------------------------------------------------------------

Numbers MeanOver(const std::vector<const Numbers*>& per_scene,
                 const std::vector<std::string>& scene_names) {
  Numbers m;
  if (per_scene.empty()) {
    m.why = "no scenes";
    return m;
  }
  for (size_t i = 0; i < per_scene.size(); ++i) {
    if (!per_scene[i]->ok) {
      m.why = (i < scene_names.size() ? scene_names[i] : "a scene") + ": " + per_scene[i]->why;
      return m;
    }
  }
  const double n = double(per_scene.size());
  for (const MetricField& f : kMetricFields) {
    double s = 0.0;
    for (const Numbers* x : per_scene) s += x->*f.numbers;  // +inf PSNR stays +inf
    m.*f.numbers = s / n;
  }
  for (const Numbers* x : per_scene) {
    m.counts.counted += x->counts.counted;
    m.counts.masked_out += x->counts.masked_out;
    m.counts.nonfinite_ref += x->counts.nonfinite_ref;
    m.counts.nonfinite_test += x->counts.nonfinite_test;
  }
  m.ok = NumbersFinite(m);
  if (!m.ok) m.why = "non-finite mean";
  return m;
}

WeaveMapPictures WeaveMapThumbnails(const io::Image& img, const std::string& file, int periods) {
  WeaveMapPictures out;
  out.file = file;
  out.size = img.width;
  auto channel = [&](const std::string& name) {
    const auto it = std::find(img.channel_names.begin(), img.channel_names.end(), name);
    return it == img.channel_names.end() ? -1 : int(it - img.channel_names.begin());
  };
  const int n = std::min(img.width, 128), m = std::min(img.height, 128);
  if (n <= 0 || m <= 0 || periods < 1) {
    out.note = "empty map";
    return out;
  }
  const size_t nc = size_t(img.channels());
  auto texel = [&](int x, int y) {  // period texel of thumbnail pixel (x, y), nearest
    const int sx = (x % n) * img.width / n, sy = (y % m) * img.height / m;
    return &img.pixels[(size_t(sy) * size_t(img.width) + size_t(sx)) * nc];
  };
  // One picture from 1 (grey) or 3 (colour) channels. Grey (a lobe weight): value / max, so
  // black = 0 and white = the period's maximum. Colour (kd ratio): 0.5 + 0.5 (value - 1) / s,
  // s = max |value - 1| over the period and channels, so mid-grey = the tile mean.
  auto picture = [&](const std::string& title, const std::vector<int>& chans, int band) {
    WeaveMapPictures::Picture p;
    p.band = band;
    p.title = title;
    p.min = std::numeric_limits<double>::infinity();
    p.max = -p.min;
    const bool colour = chans.size() == 3;
    for (int y = 0; y < m; ++y)
      for (int x = 0; x < n; ++x)
        for (int c : chans) {
          const float v = texel(x, y)[c];
          if (!std::isfinite(v)) continue;
          p.min = std::min(p.min, double(v));
          p.max = std::max(p.max, double(v));
        }
    if (!(p.min <= p.max)) p.min = p.max = 0.0;  // no finite texel
    const double spread = std::max(std::abs(p.max - 1.0), std::abs(p.min - 1.0));
    p.scale = colour ? spread : p.max;
    const int W = n * periods, H = m * periods;
    std::vector<float> rgb(size_t(W) * size_t(H) * 3);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (size_t k = 0; k < 3; ++k) {
          const double v = double(texel(x, y)[chans[colour ? k : 0]]);
          double d = 0.0;
          if (std::isfinite(v))
            d = colour ? (p.scale > 0.0 ? 0.5 + 0.5 * (v - 1.0) / p.scale : 0.5)
                       : (p.scale > 0.0 ? v / p.scale : 0.0);
          rgb[(size_t(y) * size_t(W) + size_t(x)) * 3 + k] = float(std::clamp(d, 0.0, 1.0));
        }
    p.png = Base64(io::EncodePng8(W, H, rgb, file));
    out.pictures.push_back(std::move(p));
  };
  std::vector<std::string> missing;
  // One set of maps: the main ones (prefix "", band -1) or view band k ("view{k}.", band k).
  auto maps = [&](const std::string& prefix, int band) {
    for (const char* name : {"warp", "weft"}) {
      const int c = channel(prefix + name);
      if (c < 0)
        missing.push_back(prefix + name);
      else
        picture(std::string(name) + " weight", {c}, band);
    }
    const int kr = channel(prefix + "kd.R"), kg = channel(prefix + "kd.G"),
              kb = channel(prefix + "kd.B");
    if (kr < 0 || kg < 0 || kb < 0)
      missing.push_back(prefix + "kd.R/G/B");
    else
      picture("diffuse (kd) ratio, colour", {kr, kg, kb}, band);
  };
  maps("", -1);
  for (int k = 0; k < 8; ++k) {
    const std::string prefix = "view" + std::to_string(k) + ".";
    bool any = false;
    for (const std::string& c : img.channel_names) any = any || c.rfind(prefix, 0) == 0;
    if (!any) break;
    maps(prefix, k);
    out.view_bands = k + 1;
  }
  if (!missing.empty()) {
    out.note = "no channel";
    for (const std::string& c : missing) out.note += " " + c;
  }
  return out;
}

std::string NoiseFloorLabel(const std::string& source) {
  if (source == kSecondReference) return "noise floor (second seed)";
  if (source == kReferenceHalves) return "noise floor (two half-sample images of the reference)";
  if (source == "mixed") return "noise floor (mixed: second seed / half-sample images)";
  return "noise floor";
}

FabricReport BuildFabricReport(const FabricSpec& spec, const ReportOptions& options) {
  FabricReport rep;
  rep.spec = spec;
  rep.scenes.resize(spec.scenes.size());
  for (const ModelSpec& m : spec.models)
    if (m.previews.size() != spec.scenes.size())
      throw ReportError(m.preset_path + ": " + std::to_string(m.previews.size()) +
                        " previews for " + std::to_string(spec.scenes.size()) + " scenes");
  for (size_t si = 0; si < spec.scenes.size(); ++si) {
    const SceneSpec& sc = spec.scenes[si];
    SceneResult& out = rep.scenes[si];
    out.spec = sc;
    const LoadedImage ref = Load(sc.reference, true);
    out.width = ref.rgb.width;
    out.height = ref.rgb.height;
    const metrics::Map* mask = ref.coverage ? &*ref.coverage : nullptr;
    out.mask_from_coverage = mask != nullptr;
    out.fabric_pixels = 0;
    for (size_t i = 0; i < ref.rgb.pixel_count(); ++i)
      if (!mask || mask->values[i] > 0.5f) ++out.fabric_pixels;
    // One HDR-FLIP range per reference, shared by every comparison with it.
    const metrics::ExposureRange automatic = metrics::AutomaticExposureRange(ref.rgb, mask);
    out.hdr_range_automatic = std::isfinite(automatic.start) && std::isfinite(automatic.stop) &&
                              automatic.start <= automatic.stop;
    out.hdr_range = out.hdr_range_automatic ? automatic : kFallbackHdrRange;
    out.reference_png = DisplayPng(ref.rgb, sc.tone_mapping, sc.exposure, sc.reference);

    // The test images: the second reference (noise floor) and each model's preview.
    std::vector<std::string> paths;
    if (!sc.reference2.empty()) paths.push_back(sc.reference2);
    for (const ModelSpec& m : spec.models) paths.push_back(m.previews[si]);
    std::vector<LoadedImage> tests(paths.size());
    for (size_t k = 0; k < paths.size(); ++k) {
      tests[k] = Load(paths[k], false);
      if (tests[k].rgb.width != ref.rgb.width || tests[k].rgb.height != ref.rgb.height)
        throw ReportError(paths[k] + ": size " + std::to_string(tests[k].rgb.width) + "x" +
                          std::to_string(tests[k].rgb.height) + " differs from the reference " +
                          sc.reference + " (" + std::to_string(ref.rgb.width) + "x" +
                          std::to_string(ref.rgb.height) + ")");
    }
    // No second reference but half channels: the noise floor compares the two halves (one
    // more comparison, after the models; same mask and HDR-FLIP range).
    const bool use_halves = sc.reference2.empty() && ref.halves.present;
    const size_t comparisons = paths.size() + (use_halves ? 1 : 0);
    std::vector<Comparison> results(comparisons);
    std::vector<std::string> pictures(paths.size());
    tbb::parallel_for(size_t(0), comparisons, [&](size_t k) {
      if (k == paths.size()) {
        results[k] = Compare(ref.halves.a, ref.halves.b, mask, sc, out.hdr_range, options,
                             sc.reference + " (halves)");
        return;
      }
      results[k] = Compare(ref.rgb, tests[k].rgb, mask, sc, out.hdr_range, options, paths[k]);
      pictures[k] = DisplayPng(tests[k].rgb, sc.tone_mapping, sc.exposure, paths[k]);
    });
    size_t k = 0;
    if (!sc.reference2.empty()) {
      out.noise_floor = results[0].numbers;
      out.noise_flip_png = results[0].flip_png;
      out.noise_floor_source = kSecondReference;
      k = 1;
    } else if (use_halves) {
      out.noise_floor = results[paths.size()].numbers;
      out.noise_flip_png = results[paths.size()].flip_png;
      out.noise_floor_source = kReferenceHalves;
    }
    for (size_t mi = 0; mi < spec.models.size(); ++mi, ++k) {
      ModelSceneResult r;
      r.numbers = results[k].numbers;
      r.flip_png = results[k].flip_png;
      r.preview_png = pictures[k];
      out.models.push_back(std::move(r));
    }
  }
  std::vector<std::string> names;
  for (const SceneSpec& s : spec.scenes) names.push_back(s.name);
  for (size_t mi = 0; mi < spec.models.size(); ++mi) {
    std::vector<const Numbers*> per;
    for (const SceneResult& s : rep.scenes) per.push_back(&s.models[mi].numbers);
    rep.model_means.push_back(MeanOver(per, names));
  }
  bool all_floor = !rep.scenes.empty();
  std::vector<const Numbers*> floors;
  for (const SceneResult& s : rep.scenes) {
    if (!s.noise_floor) {
      all_floor = false;
    } else {
      floors.push_back(&*s.noise_floor);
      if (rep.noise_floor_source.empty())
        rep.noise_floor_source = s.noise_floor_source;
      else if (rep.noise_floor_source != s.noise_floor_source)
        rep.noise_floor_source = "mixed";
    }
  }
  if (all_floor) rep.noise_floor_mean = MeanOver(floors, names);
  // Weave maps (issue 12, item 5): thumbnails of each preset's maps. An unreadable map is a
  // note on the page (the metrics do not depend on it), not a failed report.
  for (const ModelSpec& m : spec.models) {
    std::optional<WeaveMapPictures> w;
    const nlohmann::json& wm = m.preset.contains("weave_maps") ? m.preset.at("weave_maps")
                                                                : nlohmann::json();
    if (wm.is_object()) {
      w = WeaveMapPictures{};
      // "uri" first (relative to the preset, render::ResolvePresetRelativeUri), "file" only
      // without one, as every reader does (docs/preset-format.md "Weave maps: `uri` and `file`").
      const bool has_uri = wm.contains("uri");
      if (has_uri ? !wm.at("uri").is_string()
                  : (!wm.contains("file") || !wm.at("file").is_string())) {
        w->note = limits::EscapeForMessage(m.preset_path, 400) +
                  (has_uri ? ": weave_maps.uri not a string"
                           : ": weave_maps.file missing or not a string");
      } else {
        std::string file;
        try {
          file = has_uri ? render::ResolvePresetRelativeUri(m.preset_path, "weave_maps.uri",
                                                            wm.at("uri").get<std::string>())
                         : Resolve(wm.at("file").get<std::string>(), m.preset_path);
          *w = WeaveMapThumbnails(io::ReadImage(file), file);
        } catch (const std::exception& e) {
          w->file = file;
          w->note = e.what();
        }
      }
      if (wm.contains("colour_space") && wm.at("colour_space").is_string())
        w->colour_space = wm.at("colour_space").get<std::string>();
      if (wm.contains("uv_repeats") && wm.at("uv_repeats").is_number())
        w->uv_repeats = wm.at("uv_repeats").get<double>();
      // The bands are drawn by woven only, and only when the preset names their cosines
      // (render/preview/weave_maps.h LoadPresetWeaveMaps, which also checks them against the
      // file; the report does not link the preview). Kept only when all are in (0, 1].
      if (m.model == "woven" && wm.contains("view_cosines") && wm.at("view_cosines").is_array() &&
          wm.at("view_cosines").size() <= 8) {
        for (const nlohmann::json& c : wm.at("view_cosines"))
          if (c.is_number() && c.get<double>() > 0.0 && c.get<double>() <= 1.0)
            w->view_cosines.push_back(c.get<double>());
        if (w->view_cosines.size() != wm.at("view_cosines").size()) w->view_cosines.clear();
      }
    }
    rep.weave_maps.push_back(std::move(w));
  }
  return rep;
}

// ---- pages ---------------------------------------------------------------------------------

namespace {

// A badge for a fit that did not converge or stopped at a degenerate bound (the preset's
// fit.status, written by `clothfit fit`; older presets: fit.termination != CONVERGENCE).
std::string ConvergenceBadge(const nlohmann::json& fit) {
  std::string status;
  if (fit.contains("status") && fit.at("status").is_string()) {
    status = fit.at("status").get<std::string>();
  } else if (fit.contains("termination") && fit.at("termination").is_string() &&
             fit.at("termination").get<std::string>() != "CONVERGENCE") {
    status = "not converged";
  }
  if (status.empty() || status == "ok") return "";
  std::string title = status;
  if (fit.contains("at_bound") && fit.at("at_bound").is_array())
    for (const auto& b : fit.at("at_bound"))
      if (b.is_object() && b.value("flagged", false) && b.contains("name") && b.at("name").is_string())
        title += "; " + b.at("name").get<std::string>() + " at a bound";
  return " <span class=\"badge\" style=\"background:#c62828;color:#fff;border-radius:3px;"
         "padding:0 4px;font-size:80%\" title=\"" + EscapeHtml(title) + "\">" +
         EscapeHtml(status) + "</span>";
}

// ---- the pieces of a fabric page (FabricHtml), in page order ----

void FabricPageIntro(std::ostream& h, const FabricSpec& spec) {
  h << Header(spec.name + " - clothfit report");
  h << "<p class=\"meta\"><a href=\"index.html\">&larr; all fabrics</a></p>\n";
  h << "<h1>" << EscapeHtml(spec.name) << "</h1>\n";
  if (!spec.fabric_path.empty())
    h << "<p class=\"meta\">fabric definition <code>" << EscapeHtml(spec.fabric_path)
      << "</code></p>\n";
  h << "<p class=\"meta\">Images are tone mapped with each scene card's operator and exposure "
       "(three.js r187 display transform, sRGB). Metrics compare each fitted preview with the "
       "path-traced reference over the fabric pixels only; the noise floor compares the "
       "reference with a second reference rendered with another seed or, without one, the "
       "reference's two half-sample images (each with half the samples: a conservative floor, "
       "its RMSE about &radic;2 &times; the two-seed one). No fit can be expected to beat it. "
       "Lower is better except PSNR and SSIM. See docs/report.md.</p>\n";
}

// Summary: means over scenes.
void FabricPageSummary(std::ostream& h, const FabricReport& rep) {
  const FabricSpec& spec = rep.spec;
  std::vector<MetricsRowSpec> rows;
  if (rep.noise_floor_mean)
    rows.push_back({NoiseFloorLabel(rep.noise_floor_source), &*rep.noise_floor_mean, true,
                    rep.noise_floor_source == kReferenceHalves ? "second half" : "second reference"});
  for (size_t mi = 0; mi < spec.models.size(); ++mi)
    rows.push_back({ModelTitle(spec.models[mi]), &rep.model_means[mi], false, "preview"});
  h << "<h2>Metrics, mean over " << spec.scenes.size() << " scenes</h2>\n" << MetricsTable(rows);
}

// One scene's heading and the line describing its display transform, mask and FLIP range.
void SceneHeading(std::ostream& h, const SceneResult& s) {
  const SceneSpec& sc = s.spec;
  h << "<h2 id=\"scene-" << EscapeHtml(sc.name) << "\">Scene: " << EscapeHtml(sc.name)
    << "</h2>\n<p class=\"meta\"><code>" << EscapeHtml(sc.scene_path) << "</code>; " << s.width
    << "&times;" << s.height << " px; display " << render::ToneMappingName(sc.tone_mapping)
    << ", exposure " << FormatNumber(sc.exposure, 2) << "; " << s.fabric_pixels
    << (s.mask_from_coverage ? " fabric pixels (reference coverage)"
                             : " pixels (no coverage channel: all)")
    << "; HDR-FLIP range [" << FormatNumber(s.hdr_range.start, 2) << ", "
    << FormatNumber(s.hdr_range.stop, 2) << "] stops ("
    << (s.hdr_range_automatic ? "automatic from the reference"
                              : "fallback: automatic range not finite")
    << ")</p>\n";
}

// One scene's picture grid: reference and previews on the first row, FLIP maps on the second.
void ScenePictures(std::ostream& h, const FabricSpec& spec, const SceneResult& s) {
  const SceneSpec& sc = s.spec;
  const size_t cols = 1 + spec.models.size();
  h << "<div class=\"grid\" style=\"--cols:" << cols << "\">\n";
  h << "<figure>" << Img(s.reference_png, "reference " + sc.name)
    << "<figcaption>reference<br><code>" << EscapeHtml(fs::path(sc.reference).filename().string())
    << "</code></figcaption></figure>\n";
  for (size_t mi = 0; mi < spec.models.size(); ++mi) {
    const Numbers& n = s.models[mi].numbers;
    h << "<figure>"
      << Img(s.models[mi].preview_png, spec.models[mi].model + " preview " + sc.name)
      << "<figcaption>" << EscapeHtml(ModelTitle(spec.models[mi])) << " preview<br>RMSE "
      << EscapeHtml(Cell(n, Columns()[0])) << "</figcaption></figure>\n";
  }
  if (s.noise_floor)
    h << "<figure>" << Img(s.noise_flip_png, "FLIP noise floor " + sc.name)
      << "<figcaption>FLIP: "
      << (s.noise_floor_source == kReferenceHalves ? "first vs second half-sample image"
                                                   : "reference vs second seed")
      << "<br>mean "
      << EscapeHtml(Cell(*s.noise_floor, Columns()[3])) << "</figcaption></figure>\n";
  else
    h << "<figure><figcaption>no second reference or half channels: no noise floor"
         "</figcaption></figure>\n";
  for (size_t mi = 0; mi < spec.models.size(); ++mi) {
    const Numbers& n = s.models[mi].numbers;
    h << "<figure>" << Img(s.models[mi].flip_png, spec.models[mi].model + " FLIP " + sc.name)
      << "<figcaption>FLIP: " << EscapeHtml(ModelTitle(spec.models[mi])) << "<br>mean "
      << EscapeHtml(Cell(n, Columns()[3])) << "</figcaption></figure>\n";
  }
  h << "</div>\n<p class=\"meta\">FLIP error maps (LDR-FLIP of the display images): 0 "
       "<span class=\"bar\"></span> 1"
    << (s.mask_from_coverage ? "; outside the fabric (not in the numbers) dimmed to 35 %" : "")
    << "</p>\n";
}

// Per scene: pictures and a table.
void FabricPageScene(std::ostream& h, const FabricSpec& spec, const SceneResult& s) {
  SceneHeading(h, s);
  ScenePictures(h, spec, s);
  std::vector<MetricsRowSpec> rows;
  if (s.noise_floor)
    rows.push_back({NoiseFloorLabel(s.noise_floor_source), &*s.noise_floor, true,
                    s.noise_floor_source == kReferenceHalves ? "second half" : "second reference"});
  for (size_t mi = 0; mi < spec.models.size(); ++mi)
    rows.push_back({ModelTitle(spec.models[mi]), &s.models[mi].numbers, false, "preview"});
  h << MetricsTable(rows);
}

// Fitted parameters: one card per model.
void FabricPageParameters(std::ostream& h, const FabricSpec& spec,
                          const std::string& report_dir);
void ViewerLinks(std::ostream& h, const FabricSpec& spec, const ModelSpec& m,
                 const std::string& report_dir);

void FabricPageParameters(std::ostream& h, const FabricSpec& spec,
                          const std::string& report_dir) {
  h << "<h2>Fitted parameters</h2>\n<p class=\"meta\">Parameter values are <b>linear</b> sRGB "
       "(Rec.709 primaries) as the engines take them (a three.js <code>Color</code> after "
       "<code>convertSRGBToLinear</code>, a Filament <code>baseColor</code>); swatches show the "
       "colour <b>sRGB-encoded</b> for the screen (hex = what a colour picker shows). Roughness "
       "is perceptual <i>r</i> (the models use &alpha; = r&sup2;). docs/preset-format.md.</p>\n"
       "<div class=\"cards\">\n";
  for (const ModelSpec& m : spec.models) {
    h << "<div class=\"card\"><h3>" << EscapeHtml(ModelTitle(m.model)) << "</h3>\n";
    if (m.preset.contains("engine") && m.preset.at("engine").is_string())
      h << "<p class=\"meta\">" << EscapeHtml(m.preset.at("engine").get<std::string>()) << "</p>";
    if (m.preset.contains("cloth") && m.preset.at("cloth").is_object())
      h << "<p class=\"meta\">cloth options <code>" << EscapeHtml(m.preset.at("cloth").dump())
        << "</code></p>";
    h << "<p class=\"meta\">preset <code>" << EscapeHtml(m.preset_path) << "</code></p>\n";
    ViewerLinks(h, spec, m, report_dir);
    h << "<table><tr><th class=\"l\">parameter</th><th class=\"l\">value (linear)</th>"
         "<th class=\"l\">swatch (sRGB-encoded)</th></tr>\n";
    if (m.preset.contains("parameters") && m.preset.at("parameters").is_object()) {
      for (const auto& [name, v] : m.preset.at("parameters").items())
        h << "<tr><td class=\"l\">" << EscapeHtml(name) << "</td>" << ParameterCells(name, v)
          << "</tr>\n";
    } else {
      h << "<tr><td class=\"l na\" colspan=\"3\">n/a (no parameters in the preset)</td></tr>";
    }
    h << "</table></div>\n";
  }
  h << "</div>\n";
}

// The fit's noise floor cell: the mean of fit.scenes[].noise_floor.
std::string FitNoiseFloorText(const nlohmann::json& fit) {
  std::string floor = "n/a (no second reference)";
  if (fit.contains("scenes") && fit.at("scenes").is_array()) {
    double sum = 0.0;
    int n = 0;
    bool bad = false;
    for (const auto& s : fit.at("scenes"))
      if (s.is_object() && s.contains("noise_floor")) {
        if (!s.at("noise_floor").is_number())
          bad = true;
        else {
          sum += s.at("noise_floor").get<double>();
          ++n;
        }
      }
    if (bad)
      floor = "n/a (not finite in input)";
    else if (n)
      floor = FormatNumber(sum / n, 4);
  }
  return floor;
}

// Solver summary: one row per model, then each model's Ceres report.
void FabricPageSolver(std::ostream& h, const FabricSpec& spec) {
  h << "<h2>Solver</h2>\n<p class=\"meta\">Ceres Levenberg-Marquardt with bounds, multi-start; "
       "cost and RMSE in the fit space over block means (docs/fitting.md); fit noise floor = "
       "RMSE between the two references / &radic;2 over the same blocks.</p>\n"
       "<table><tr><th class=\"l\">model</th><th>iterations</th><th>starts</th>"
       "<th>initial cost</th><th>final cost</th><th>fit s</th><th>setup s</th>"
       "<th class=\"l\">termination</th><th class=\"l\">space</th><th class=\"l\">loss</th>"
       "<th>block px</th><th>fit RMSE</th><th>fit noise floor</th>"
       "<th class=\"l\">environment sun</th></tr>\n";
  for (const ModelSpec& m : spec.models) {
    const nlohmann::json fit = m.preset.value("fit", nlohmann::json::object());
    const std::string floor = FitNoiseFloorText(fit);
    h << "<tr><td class=\"l\">" << EscapeHtml(ModelTitle(m.model)) << "</td><td>"
      << FitValue(fit, "iterations", 0) << "</td><td>" << FitValue(fit, "starts", 0) << "</td><td>"
      << FitValue(fit, "initial_cost", 4) << "</td><td>" << FitValue(fit, "final_cost", 4)
      << "</td><td>" << FitValue(fit, "seconds", 2) << "</td><td>"
      << FitValue(fit, "setup_seconds", 2) << "</td><td class=\"l\">"
      << FitValue(fit, "termination", 0) << ConvergenceBadge(fit) << "</td><td class=\"l\">"
      << FitValue(fit, "space", 0)
      << "</td><td class=\"l\">" << FitValue(fit, "loss", 0) << "</td><td>"
      << FitValue(fit, "block_pixels", 0) << "</td><td>" << FitValue(fit, "rmse", 4) << "</td><td>"
      << floor << "</td><td class=\"l\">"
      // s21: the sun mode the fit's previews used (docs/sun.md): "card" = each card's
      // environment.sun, else auto; "panels" = softboxes as lights too
      << (fit.contains("env_sun") ? FitValue(fit, "env_sun", 0) : std::string("not recorded"))
      << "</td></tr>\n";
  }
  h << "</table>\n";
  for (const ModelSpec& m : spec.models) {
    const nlohmann::json fit = m.preset.value("fit", nlohmann::json::object());
    if (fit.contains("solver") && fit.at("solver").is_string())
      h << "<details><summary>" << EscapeHtml(ModelTitle(m.model))
        << ": Ceres report</summary><pre>" << EscapeHtml(fit.at("solver").get<std::string>())
        << "</pre></details>\n";
  }
}

}  // namespace

namespace {

// The directory holding web/viewer.html: the first ancestor of `start` (inclusive) that has it.
fs::path FindRepoRoot(fs::path start) {
  std::error_code ec;
  start = fs::absolute(start, ec).lexically_normal();
  for (fs::path d = start; !d.empty(); d = d.parent_path()) {
    if (fs::is_regular_file(d / "web" / "viewer.html", ec)) return d;
    if (d == d.parent_path()) break;
  }
  return {};
}

// Percent-encoding of a query value (RFC 3986 unreserved characters and '/' kept).
std::string UrlEncode(const std::string& s) {
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (const unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~' || c == '/') {
      out += char(c);
    } else {
      out += '%';
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

// A path as one POSIX shell word: kept as is when it holds only safe characters, else in single
// quotes (a ' inside as '\'').
std::string ShellQuote(const std::string& s) {
  const bool safe = !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '/' || c == '.' || c == '_' || c == '-' || c == '+';
  });
  if (safe) return s;
  std::string out = "'";
  for (const char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// "open in the three.js viewer" links, one per scene, for one fitted preset.
void ViewerLinks(std::ostream& h, const FabricSpec& spec, const ModelSpec& m,
                 const std::string& report_dir) {
  if (report_dir.empty()) return;
  std::string links;
  for (const SceneSpec& sc : spec.scenes) {
    const std::string href = ViewerLink(report_dir, sc.scene_path, m.preset_path);
    if (href.empty()) continue;
    links += std::string(links.empty() ? "" : " &middot; ") + "<a class=\"viewer\" href=\"" +
             EscapeHtml(href) + "\">" + EscapeHtml(sc.name) + "</a>";
  }
  if (links.empty()) return;
  std::vector<std::string> scene_paths;
  for (const SceneSpec& sc : spec.scenes) scene_paths.push_back(sc.scene_path);
  std::string roots;
  for (const std::string& d : ViewerRoots(report_dir, m.preset_path, scene_paths))
    roots += " --root " + EscapeHtml(ShellQuote(d));
  h << "<p class=\"meta\">three.js viewer: in the repository run <code>node web/serve.mjs"
    << roots << "</code>, then open " << links << "</p>\n";
}

}  // namespace

namespace {
fs::path ViewerRepoRoot(const std::string& report_dir) {
  std::error_code ec;
  fs::path root = FindRepoRoot(report_dir);
  if (root.empty()) root = FindRepoRoot(fs::current_path(ec));
  if (root.empty()) {
    // the running binary: build/bin/clothfit inside the checkout
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec && !exe.empty()) root = FindRepoRoot(exe.parent_path());
  }
  return root;
}

// The scene card's file, or empty when it cannot be found.
fs::path ResolveCard(const fs::path& root, const std::string& scene_path,
                     const std::string& preset_path) {
  std::error_code ec;
  fs::path card = scene_path;
  if (!card.is_relative()) return fs::is_regular_file(card, ec) ? card : fs::path();
  const fs::path candidates[] = {root / card, fs::absolute(card, ec),
                                 fs::path(preset_path).parent_path() / card};
  for (const fs::path& c : candidates)
    if (fs::is_regular_file(c, ec)) return fs::absolute(c, ec).lexically_normal();
  return {};
}

bool InsideDir(const fs::path& file, const fs::path& dir) {
  const fs::path rel = file.lexically_relative(dir);
  return !rel.empty() && *rel.begin() != "..";
}

// The URL path serve.mjs answers for `file` (see ViewerLink), each path segment percent-encoded
// (a '#', '?', '%' or ',' in a file name must reach the server as part of the name; ViewerLink
// then encodes the whole path once more as a query value).
std::string ServedPath(const fs::path& root, const fs::path& file) {
  std::error_code ec;
  const fs::path abs = fs::absolute(file, ec).lexically_normal();
  const bool inside = InsideDir(abs, root);
  const fs::path rel = inside ? abs.lexically_relative(root) : abs.relative_path();
  std::string out = inside ? "" : "/fs";
  for (const fs::path& seg : rel) {
    std::string e;
    for (const char c : seg.string()) e += c == '/' ? std::string("%2F") : UrlEncode(std::string(1, c));
    out += "/" + e;
  }
  return out;
}
}  // namespace

std::string ViewerLink(const std::string& report_dir, const std::string& scene_path,
                       const std::string& preset_path) {
  const fs::path root = ViewerRepoRoot(report_dir);
  if (root.empty()) return "";
  std::string href = std::string(kViewerOrigin) + "/web/viewer.html?preset=" +
                     UrlEncode(ServedPath(root, preset_path));
  const fs::path card = ResolveCard(root, scene_path, preset_path);
  if (!card.empty()) href += "&card=" + UrlEncode(ServedPath(root, card));
  return href;
}

std::vector<std::string> ViewerRoots(const std::string& report_dir, const std::string& preset_path,
                                     const std::vector<std::string>& scene_paths) {
  const fs::path root = ViewerRepoRoot(report_dir);
  std::vector<std::string> dirs;
  if (root.empty()) return dirs;
  std::error_code ec;
  std::vector<fs::path> files = {preset_path};
  // A JSON file's string field, "" when the file, the field or its type is not there (the
  // page's hint only; the fit and the viewer report real errors).
  const auto field = [](const fs::path& file, std::initializer_list<const char*> keys) {
    try {
      const nlohmann::json j = ReadPresetJson(file.string());  // bounded, depth-checked
      const nlohmann::json* v = &j;
      for (const char* k : keys) {
        if (!v->is_object() || !v->contains(k)) return std::string();
        v = &v->at(k);
      }
      return v->is_string() ? v->get<std::string>() : std::string();
    } catch (const std::exception&) {
      return std::string();
    }
  };
  // Session 28: the files the viewer fetches through the preset and the cards too, where they
  // sit in other directories: a weave map named relative to the preset (web/clothfit.js
  // weaveMapUrl; an absolute name is looked up next to the preset), a card's glTF and an
  // environment given as a path (environmentUrl; a name is served from the data cache).
  const auto relative_to = [&](const fs::path& base, const std::string& rel) {
    if (rel.empty() || fs::path(rel).is_absolute()) return;
    files.push_back(base.parent_path() / rel);
  };
  for (const char* key : {"file", "uri"})
    relative_to(preset_path, field(preset_path, {"weave_maps", key}));
  for (const std::string& sc : scene_paths) {
    const fs::path card = ResolveCard(root, sc, preset_path);
    if (card.empty()) continue;
    files.push_back(card);
    relative_to(card, field(card, {"gltf"}));
    const std::string env = field(card, {"environment", "path"});
    if (env.find('/') != std::string::npos || fs::path(env).has_extension()) relative_to(card, env);
  }
  for (const fs::path& f : files) {
    const fs::path abs = fs::absolute(f, ec).lexically_normal();
    if (InsideDir(abs, root)) continue;
    const std::string d = abs.parent_path().generic_string();
    if (std::find(dirs.begin(), dirs.end(), d) == dirs.end()) dirs.push_back(d);
  }
  return dirs;
}

namespace {

// The weave maps of the presets that have them (issue 12, item 5).
void FabricPageWeaveMaps(std::ostream& h, const FabricReport& rep) {
  bool any = false;
  for (const auto& w : rep.weave_maps) any = any || w.has_value();
  if (!any) return;
  h << "<h2>Weave maps</h2>\n<p class=\"meta\">The per-texel maps the preview samples "
       "(fit/weave_maps.h): one weave period per map, shown tiled 2 &times; 2 periods (nearest "
       "texel, at most 128 texels per period). <b>Encoding</b>: every channel is a linear ratio "
       "to its tile mean (mean 1); warp and weft weight the yarn lobes, kd scales the diffuse "
       "colour per channel (linear sRGB). <b>Display</b> (8-bit values, no sRGB encoding): a weight "
       "as value / max, black = 0 and white = the period's maximum; the kd ratio as "
       "0.5 + 0.5 (value &minus; 1) / s per channel, s = the largest |value &minus; 1| in the "
       "period, so mid-grey is the tile mean. Ranges are over one period.</p>\n";
  for (size_t mi = 0; mi < rep.weave_maps.size() && mi < rep.spec.models.size(); ++mi) {
    if (!rep.weave_maps[mi]) continue;
    const WeaveMapPictures& w = *rep.weave_maps[mi];
    const std::string& model = rep.spec.models[mi].model;
    h << "<h3>" << EscapeHtml(ModelTitle(model)) << " <span class=\"meta\">(model <code>"
      << EscapeHtml(model) << "</code>)</span></h3>\n<p class=\"meta\">maps <code>"
      << EscapeHtml(w.file) << "</code>";
    if (w.size > 0) h << "; " << w.size << "&times;" << w.size << " texels per period";
    if (w.uv_repeats > 0) h << "; " << FormatNumber(w.uv_repeats, 2) << " periods per UV unit";
    if (!w.colour_space.empty()) h << "; preset: &ldquo;" << EscapeHtml(w.colour_space) << "&rdquo;";
    h << "</p>\n";
    if (!w.note.empty()) h << "<p class=\"meta na\">n/a (" << EscapeHtml(w.note) << ")</p>\n";
    if (w.pictures.empty()) continue;
    // One grid per set: the main maps, then each view band under its own line.
    const bool drawn = int(w.view_cosines.size()) == w.view_bands;
    for (int band = -1; band < w.view_bands; ++band) {
      size_t count = 0;
      for (const WeaveMapPictures::Picture& p : w.pictures) count += p.band == band;
      if (count == 0) continue;
      if (band == 0)
        h << "<p class=\"meta\"><b>View bands</b> (docs/preview.md \"View-dependent weave "
             "maps\"): the same maps fitted at one view cosine each. "
          << (drawn ? "woven's preview blends them per pixel in place of the main maps above, "
                      "linearly in NoV between the bands' cosines and clamped to the end bands "
                      "outside them (physical-aniso draws the main maps only)."
                    : model != "woven"
                          ? "Only woven draws view bands, so the preview does not draw them."
                          : "The preset names no matching weave_maps.view_cosines, so the "
                            "preview does not draw them.")
          << "</p>\n";
      if (band >= 0)
        h << "<p class=\"meta\">view band " << band
          << (drawn ? " at NoV = " + FormatNumber(w.view_cosines[size_t(band)], 3) : std::string())
          << "</p>\n";
      h << "<div class=\"grid\" style=\"--cols:" << count << "\">\n";
      for (const WeaveMapPictures::Picture& p : w.pictures) {
        if (p.band != band) continue;
        const std::string name =
            band < 0 ? p.title : "view band " + std::to_string(band) + " " + p.title;
        h << "<figure><img style=\"image-rendering:pixelated;width:192px\" alt=\""
          << EscapeHtml(model + " " + name) << "\" src=\"data:image/png;base64," << p.png
          << "\"><figcaption>" << EscapeHtml(p.title) << "<br>range [" << FormatNumber(p.min, 2)
          << ", " << FormatNumber(p.max, 2) << "] &times; tile mean"
          << (p.title.find("colour") != std::string::npos
                  ? "<br>mid-grey = 1, s = " + FormatNumber(p.scale, 3)
                  : "<br>white = " + FormatNumber(p.scale, 2))
          << "</figcaption></figure>\n";
      }
      h << "</div>\n";
    }
  }
}

}  // namespace

std::string FabricHtml(const FabricReport& rep, const std::string& report_dir) {
  const FabricSpec& spec = rep.spec;
  std::ostringstream h;
  FabricPageIntro(h, spec);
  FabricPageSummary(h, rep);
  for (const SceneResult& s : rep.scenes) FabricPageScene(h, spec, s);
  FabricPageParameters(h, spec, report_dir);
  FabricPageWeaveMaps(h, rep);
  FabricPageSolver(h, spec);
  h << "</body></html>\n";
  return h.str();
}

namespace {

// "Which model": per fabric, the model with the lowest fit error (fit.rmse, the block display
// RMSE the fit minimises, the README's headline figure) and the one with the lowest per-pixel
// FLIP, said in words for a reader who does not know the metrics (session 27: the index gave
// only the table, and on twill its columns disagree); then what the badges mean.
void IndexWhichModel(std::ostream& h, const std::vector<FabricReport>& reports) {
  h << "<h2>Which model</h2>\n<ul>\n";
  bool any_badge = false;
  for (const FabricReport& r : reports) {
    int best_fit = -1, best_flip = -1;
    double fit_min = 0, flip_min = 0;
    for (size_t mi = 0; mi < r.spec.models.size(); ++mi) {
      const nlohmann::json fit = r.spec.models[mi].preset.value("fit", nlohmann::json::object());
      any_badge = any_badge || !ConvergenceBadge(fit).empty();
      if (fit.contains("rmse") && fit.at("rmse").is_number()) {
        const double v = fit.at("rmse").get<double>();
        if (std::isfinite(v) && (best_fit < 0 || v < fit_min)) {
          best_fit = int(mi);
          fit_min = v;
        }
      }
      const Numbers& n = r.model_means[mi];
      if (n.ok && std::isfinite(n.flip) && (best_flip < 0 || n.flip < flip_min)) {
        best_flip = int(mi);
        flip_min = n.flip;
      }
    }
    if (best_fit < 0 && best_flip < 0) continue;
    const auto title = [&](int mi) { return EscapeHtml(ModelTitle(r.spec.models[size_t(mi)].model)); };
    h << "<li><a href=\"" << EscapeHtml(PageName(r.spec.name)) << "\">" << EscapeHtml(r.spec.name)
      << "</a>: ";
    if (best_fit >= 0)
      h << "<b>" << title(best_fit) << "</b> has the lowest fit error (block RMSE "
        << FormatNumber(fit_min, 4) << ", the error over 16-pixel blocks the fit minimises)";
    if (best_flip >= 0) {
      if (best_flip == best_fit)
        h << " and the lowest per-pixel FLIP (" << FormatNumber(flip_min, 3) << ")";
      else
        h << (best_fit >= 0 ? "; " : "") << "<b>" << title(best_flip)
          << "</b> has the lowest per-pixel FLIP (" << FormatNumber(flip_min, 3)
          << "): the metrics disagree, compare the images on the fabric's page";
    }
    h << ".</li>\n";
  }
  h << "</ul>\n<p class=\"meta\">Lower is better in every column but PSNR and SSIM. FLIP (0 to "
       "1) is the perceived difference per pixel; CIEDE2000 &Delta;E is the colour difference "
       "(1 is about the smallest a viewer notices). A preset that only a path tracer could match "
       "still differs: compare with the noise-floor row.";
  if (any_badge)
    h << " A red badge next to a model flags its fit: <i>not converged</i> (the solver stopped "
         "at its iteration limit) or <i>at bound</i> (a parameter stopped at the end of its "
         "range, named when you hover the badge); the preset is usable but worth a look.";
  h << "</p>\n";
}

}  // namespace

std::string IndexHtml(const std::vector<FabricReport>& reports) {
  std::ostringstream h;
  h << Header("clothfit report");
  h << "<h1>clothfit report</h1>\n<p class=\"meta\">One row per fabric and model: metrics of "
       "the fitted real-time preview against the path-traced reference, mean over the scenes, "
       "fabric pixels only. The noise-floor rows compare two references with different seeds or, "
       "without a second seed, the reference's two half-sample images (a conservative floor). "
       "Click a column header to sort. Same numbers: <a href=\"report.json\">report.json</a>, "
       "<a href=\"report.csv\">report.csv</a>; definitions in docs/report.md.</p>\n";
  h << "<table id=\"summary\"><thead><tr><th class=\"l s\" data-t=\"s\">fabric</th>"
       "<th class=\"l s\" data-t=\"s\">model</th>";
  for (const Column& c : Columns())
    h << "<th class=\"s\" title=\"" << c.help << "\">" << c.title << "</th>";
  h << "<th class=\"s\">fit s</th></tr></thead><tbody>\n";
  auto row = [&](const FabricReport& r, const std::string& model, const Numbers& n, bool floor,
                 const std::string& seconds, const std::string& seconds_key,
                 const std::string& badge = "") {
    h << (floor ? "<tr class=\"floor\">" : "<tr>") << "<td class=\"l\" data-v=\""
      << EscapeHtml(r.spec.name) << "\"><a href=\"" << EscapeHtml(PageName(r.spec.name)) << "\">"
      << EscapeHtml(r.spec.name) << "</a></td><td class=\"l\" data-v=\"" << EscapeHtml(model)
      << "\">" << EscapeHtml(model) << badge << "</td>";
    for (const Column& c : Columns())
      h << (n.ok ? "<td" : "<td class=\"na\"") << " data-v=\"" << SortKey(n, c) << "\">"
        << EscapeHtml(Cell(n, c)) << "</td>";
    h << "<td data-v=\"" << seconds_key << "\">" << seconds << "</td></tr>\n";
  };
  for (const FabricReport& r : reports) {
    if (r.noise_floor_mean)
      row(r, NoiseFloorLabel(r.noise_floor_source), *r.noise_floor_mean, true, "", "");
    for (size_t mi = 0; mi < r.spec.models.size(); ++mi) {
      const nlohmann::json fit = r.spec.models[mi].preset.value("fit", nlohmann::json::object());
      std::string sec = "n/a (missing)", key;
      if (fit.contains("seconds") && fit.at("seconds").is_number()) {
        sec = FormatNumber(fit.at("seconds").get<double>(), 2);
        key = Fmt("%.9g", fit.at("seconds").get<double>());
      }
      row(r, ModelTitle(r.spec.models[mi].model), r.model_means[mi], false, sec, key,
          ConvergenceBadge(fit));
    }
  }
  h << "</tbody></table>\n";
  IndexWhichModel(h, reports);
  h << "<h2>Fabrics</h2>\n<ul>\n";
  for (const FabricReport& r : reports)
    h << "<li><a href=\"" << EscapeHtml(PageName(r.spec.name)) << "\">" << EscapeHtml(r.spec.name)
      << "</a> (" << r.spec.models.size() << " models, " << r.spec.scenes.size()
      << " scenes)</li>\n";
  h << "</ul>\n";
  // Sort: numeric when both keys parse, text otherwise; empty keys (n/a) always last.
  h << R"JS(<script>
(function(){var t=document.getElementById('summary');var hs=t.tHead.rows[0].cells;
for(var i=0;i<hs.length;i++)(function(i){var asc=true;hs[i].onclick=function(){
var b=t.tBodies[0],rs=Array.prototype.slice.call(b.rows);
rs.sort(function(x,y){var a=x.cells[i].getAttribute('data-v'),c=y.cells[i].getAttribute('data-v');
if(a===''&&c==='')return 0;if(a==='')return 1;if(c==='')return -1;
var p=parseFloat(a),q=parseFloat(c),r=(!isNaN(p)&&!isNaN(q))?p-q:a.localeCompare(c);
return asc?r:-r;});rs.forEach(function(r){b.appendChild(r);});asc=!asc;};})(i);})();
</script>
)JS";
  h << "</body></html>\n";
  return h.str();
}

nlohmann::json ReportJson(const std::vector<FabricReport>& reports) {
  nlohmann::json j;
  j["schema"] = "clothfit.report";
  j["version"] = 1;
  j["region"] = "fabric pixels of the reference (coverage > 0.5)";
  nlohmann::json fabrics = nlohmann::json::array();
  for (const FabricReport& r : reports) {
    nlohmann::json f;
    f["name"] = r.spec.name;
    f["fabric"] = r.spec.fabric_path;
    f["page"] = PageName(r.spec.name);
    nlohmann::json models = nlohmann::json::array();
    for (size_t mi = 0; mi < r.spec.models.size(); ++mi) {
      const ModelSpec& m = r.spec.models[mi];
      nlohmann::json mj;
      mj["model"] = m.model;
      mj["preset"] = m.preset_path;
      mj["parameters"] = m.preset.value("parameters", nlohmann::json(nullptr));
      const nlohmann::json fit = m.preset.value("fit", nlohmann::json::object());
      nlohmann::json solver;
      for (const char* k : {"iterations", "starts", "initial_cost", "final_cost", "seconds",
                            "setup_seconds", "termination", "space", "loss", "rmse"})
        solver[k] = fit.contains(k) ? fit.at(k) : nlohmann::json(nullptr);
      mj["solver"] = solver;
      mj["mean"] = NumbersJson(r.model_means[mi]);
      models.push_back(mj);
    }
    f["models"] = models;
    f["noise_floor_mean"] =
        r.noise_floor_mean ? NumbersJson(*r.noise_floor_mean) : nlohmann::json(nullptr);
    f["noise_floor_source"] = r.noise_floor_mean ? nlohmann::json(r.noise_floor_source)
                                                 : nlohmann::json(nullptr);
    nlohmann::json scenes = nlohmann::json::array();
    for (const SceneResult& s : r.scenes) {
      nlohmann::json sj;
      sj["name"] = s.spec.name;
      sj["scene"] = s.spec.scene_path;
      sj["reference"] = s.spec.reference;
      sj["reference2"] =
          s.spec.reference2.empty() ? nlohmann::json(nullptr) : nlohmann::json(s.spec.reference2);
      sj["tone_mapping"] = std::string(render::ToneMappingName(s.spec.tone_mapping));
      sj["exposure"] = s.spec.exposure;
      sj["width"] = s.width;
      sj["height"] = s.height;
      sj["fabric_pixels"] = s.fabric_pixels;
      sj["hdr_flip_range"] = {{"start", s.hdr_range.start},
                              {"stop", s.hdr_range.stop},
                              {"automatic", s.hdr_range_automatic}};
      sj["noise_floor"] = s.noise_floor ? NumbersJson(*s.noise_floor) : nlohmann::json(nullptr);
      sj["noise_floor_source"] =
          s.noise_floor ? nlohmann::json(s.noise_floor_source) : nlohmann::json(nullptr);
      nlohmann::json ms = nlohmann::json::object();
      for (size_t mi = 0; mi < r.spec.models.size(); ++mi)
        ms[r.spec.models[mi].model] = NumbersJson(s.models[mi].numbers);
      sj["models"] = ms;
      scenes.push_back(sj);
    }
    f["scenes"] = scenes;
    fabrics.push_back(f);
  }
  j["fabrics"] = fabrics;
  return j;
}

std::string ReportCsv(const std::vector<FabricReport>& reports) {
  std::ostringstream s;
  s << "fabric,model,scene";
  for (const MetricField& f : kMetricFields) s << "," << f.name;
  s << ",pixels_counted,nonfinite_reference,nonfinite_test,status\n";
  auto num = [](double v) -> std::string {
    if (std::isfinite(v)) return Fmt("%.9g", v);
    return (std::isinf(v) && v > 0) ? "inf" : "";
  };
  auto csv_text = [](const std::string& t) {
    std::string q = "\"";
    for (char c : t) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
  };
  auto row = [&](const std::string& fabric, const std::string& model, const std::string& scene,
                 const Numbers& n) {
    s << csv_text(fabric) << "," << csv_text(model) << "," << csv_text(scene);
    for (const MetricField& f : kMetricFields) s << "," << (n.ok ? num(n.*f.numbers) : std::string());
    s << "," << n.counts.counted << "," << n.counts.nonfinite_ref << "," << n.counts.nonfinite_test
      << "," << csv_text(n.ok ? "ok" : "n/a: " + n.why) << "\n";
  };
  for (const FabricReport& r : reports) {
    for (const SceneResult& sc : r.scenes) {
      if (sc.noise_floor)
        row(r.spec.name,
            sc.noise_floor_source == kReferenceHalves ? "noise-floor-halves" : "noise-floor",
            sc.spec.name, *sc.noise_floor);
      for (size_t mi = 0; mi < r.spec.models.size(); ++mi)
        row(r.spec.name, r.spec.models[mi].model, sc.spec.name, sc.models[mi].numbers);
    }
    if (r.noise_floor_mean)
      row(r.spec.name,
          r.noise_floor_source == kReferenceHalves ? "noise-floor-halves"
          : r.noise_floor_source == "mixed"        ? "noise-floor-mixed"
                                                   : "noise-floor",
          "mean", *r.noise_floor_mean);
    for (size_t mi = 0; mi < r.spec.models.size(); ++mi)
      row(r.spec.name, r.spec.models[mi].model, "mean", r.model_means[mi]);
  }
  return s.str();
}

std::string TerminalTable(const std::vector<FabricReport>& reports) {
  std::ostringstream s;
  char buf[256];
  // Column widths from the names shown (at least the headers' old 10 / 15, at most 60: longer
  // names widen the table instead of pushing the numbers out of their columns).
  int fw = 10, mw = 15;
  for (const FabricReport& r : reports) {
    fw = std::max(fw, int(std::min<size_t>(r.spec.name.size(), 60)));
    for (const ModelSpec& m : r.spec.models) mw = std::max(mw, int(std::min<size_t>(m.model.size(), 60)));
  }
  std::snprintf(buf, sizeof buf, "%-*s %-*s", fw, "fabric", mw, "model");
  s << buf;
  for (const Column& c : Columns()) {
    std::snprintf(buf, sizeof buf, " %8s", c.short_title);
    s << buf;
  }
  s << "\n";
  auto row = [&](const std::string& fabric, const std::string& model, const Numbers& n) {
    std::snprintf(buf, sizeof buf, "%-*s %-*s", fw, fabric.c_str(), mw, model.c_str());
    s << buf;
    if (!n.ok) {
      s << " " << Na(n) << "\n";
      return;
    }
    for (const Column& c : Columns()) {
      std::snprintf(buf, sizeof buf, " %8s",
                    FormatNumber(n.*(c.field), c.decimals, c.psnr).c_str());
      s << buf;
    }
    s << "\n";
  };
  for (const FabricReport& r : reports) {
    if (r.noise_floor_mean)
      row(r.spec.name, r.noise_floor_source == kReferenceHalves ? "noise (halves)" : "noise floor",
          *r.noise_floor_mean);
    for (size_t mi = 0; mi < r.spec.models.size(); ++mi)
      row(r.spec.name, r.spec.models[mi].model, r.model_means[mi]);
  }
  s << "(mean over scenes, fabric pixels; display values except RMSElin and HDRFLIP; dE = "
       "CIEDE2000 of the displayed colour)\n";
  for (const FabricReport& r : reports)
    if (r.noise_floor_mean && r.noise_floor_source != kSecondReference) {
      s << "(noise (halves): the reference's two half-sample images compared; conservative, "
           "RMSE about sqrt(2) x a second seed's)\n";
      break;
    }
  return s.str();
}

std::string WriteReport(const std::vector<FabricReport>& reports, const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw ReportError(dir + ": cannot create the report directory: " + ec.message());
  for (const FabricReport& r : reports)
    io::WriteTextAtomic((fs::path(dir) / PageName(r.spec.name)).string(), FabricHtml(r, dir));
  io::WriteTextAtomic((fs::path(dir) / "report.json").string(), ReportJson(reports).dump(2) + "\n");
  io::WriteTextAtomic((fs::path(dir) / "report.csv").string(), ReportCsv(reports));
  const std::string index = (fs::path(dir) / "index.html").string();
  io::WriteTextAtomic(index, IndexHtml(reports));
  return index;
}

}  // namespace clothfit::report
