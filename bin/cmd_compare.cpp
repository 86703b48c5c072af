// clothfit compare: every image metric (fit/metrics/metrics.h) between a reference and a test image.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "fit/metrics/metrics.h"
#include "render/scene/image_io.h"
#include "render/scene/tonemap.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {

void AddCompareCommand(CLI::App& app, const Globals& g, int& exit_code);

namespace {

// How each map is shown in its PNG: value v -> colour map position (v - lo) / (hi - lo).
struct PngScale {
  double lo, hi;
};
PngScale ScaleFor(const std::string& name, const metrics::CompareResult& r) {
  if (name == "ssim") return {1.0, 0.0};  // dissimilarity 1 - SSIM
  if (name == "flip" || name == "hdr_flip") return {0.0, 1.0};
  if (name.rfind("ciede2000", 0) == 0) return {0.0, 10.0};  // Delta E 10 = top of the map
  if (name == "rmse_display") return {0.0, 0.25};
  if (name == "hdr_flip_exposure") return {r.hdr_range.start, r.hdr_range.stop};
  return {0.0, 0.25};  // rmse_linear, in units of the linear values
}

std::string Num(double v, int digits = 6) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

nlohmann::json JsonNum(double v) {
  // JSON has no infinity: PSNR of identical images is written as the string "inf".
  if (std::isfinite(v)) return v;
  return v > 0 ? "inf" : "-inf";
}

// Why HDR-FLIP is missing, with what to do about it (text, JSON and the stderr warning).
std::string HdrFlipUnavailable(const metrics::CompareResult& r) {
  return r.hdr_flip_unavailable + "; give --hdr-range cstart,cstop (stops; the same range for "
         "every test image of this reference; docs/metrics.md)";
}

std::string Table(const metrics::CompareResult& r, const metrics::CompareOptions& o) {
  std::ostringstream s;
  s << "size " << r.width << "x" << r.height << ", pixels counted " << r.counts.counted
    << " (masked out " << r.counts.masked_out << ", non-finite: reference "
    << r.counts.nonfinite_ref << ", test " << r.counts.nonfinite_test << ")\n";
  s << "display: " << render::ToneMappingName(o.tone_mapping) << ", exposure " << Num(o.exposure)
    << ", sRGB\n";
  auto row = [&](const char* name, const std::string& value, const std::string& note) {
    char buf[128];  // the note is appended whole (it may be long)
    std::snprintf(buf, sizeof buf, "  %-22s %14s  ", name, value.c_str());
    s << buf << note << "\n";
  };
  row("rmse_linear", Num(r.rmse_linear), "");
  row("psnr_linear [dB]", Num(r.psnr_linear), "peak " + Num(o.linear_peak));
  row("rmse_display", Num(r.rmse_display), "");
  row("psnr_display [dB]", Num(r.psnr_display), "peak 1");
  row("ssim", Num(r.ssim),
      r.ssim_used_border_pixels ? "image < 11 px: border windows pooled"
                                : "11x11 Gaussian, sigma 1.5, L = 1");
  row("flip", Num(r.flip), "LDR-FLIP of display, ppd " + Num(o.ppd));
  if (r.hdr_flip_unavailable.empty())
    row("hdr_flip", Num(r.hdr_flip),
        std::string(r.hdr_range_automatic ? "automatic" : "explicit") + " range [" +
            Num(r.hdr_range.start) + ", " + Num(r.hdr_range.stop) + "], " +
            std::to_string(r.hdr_exposures) + " exposures");
  else
    row("hdr_flip", "unavailable", HdrFlipUnavailable(r));
  row("ciede2000_mean", Num(r.ciede2000_mean), "Lab of linear values");
  row("ciede2000_p95", Num(r.ciede2000_p95), "");
  row("ciede2000_display_mean", Num(r.ciede2000_display_mean), "Lab of displayed colour");
  row("ciede2000_display_p95", Num(r.ciede2000_display_p95), "");
  return s.str();
}

nlohmann::json Json(const metrics::CompareResult& r, const metrics::CompareOptions& o,
                    const std::string& a, const std::string& b, const std::string& mask) {
  nlohmann::json j;
  j["reference"] = a;
  j["test"] = b;
  j["mask"] = mask.empty() ? nlohmann::json(nullptr) : nlohmann::json(mask);
  j["width"] = r.width;
  j["height"] = r.height;
  j["pixels"] = {{"counted", r.counts.counted},
                 {"masked_out", r.counts.masked_out},
                 {"nonfinite_reference", r.counts.nonfinite_ref},
                 {"nonfinite_test", r.counts.nonfinite_test}};
  j["display"] = {{"tone_mapping", std::string(render::ToneMappingName(o.tone_mapping))},
                  {"exposure", o.exposure}};
  j["rmse_linear"] = JsonNum(r.rmse_linear);
  j["psnr_linear"] = JsonNum(r.psnr_linear);
  j["psnr_linear_peak"] = o.linear_peak;
  j["rmse_display"] = JsonNum(r.rmse_display);
  j["psnr_display"] = JsonNum(r.psnr_display);
  j["ssim"] = JsonNum(r.ssim);
  j["ssim_used_border_pixels"] = r.ssim_used_border_pixels;
  j["flip"] = JsonNum(r.flip);
  j["ppd"] = o.ppd;
  // HDR-FLIP unavailable: hdr_flip and hdr_flip_range are null and hdr_flip_unavailable
  // says why (null when it was computed).
  const bool hdr = r.hdr_flip_unavailable.empty();
  j["hdr_flip"] = hdr ? JsonNum(r.hdr_flip) : nlohmann::json(nullptr);
  j["hdr_flip_range"] = hdr ? nlohmann::json{{"start", r.hdr_range.start},
                                             {"stop", r.hdr_range.stop},
                                             {"automatic", r.hdr_range_automatic},
                                             {"exposures", r.hdr_exposures}}
                            : nlohmann::json(nullptr);
  j["hdr_flip_unavailable"] = hdr ? nlohmann::json(nullptr) : nlohmann::json(HdrFlipUnavailable(r));
  j["ciede2000_mean"] = JsonNum(r.ciede2000_mean);
  j["ciede2000_p95"] = JsonNum(r.ciede2000_p95);
  j["ciede2000_display_mean"] = JsonNum(r.ciede2000_display_mean);
  j["ciede2000_display_p95"] = JsonNum(r.ciede2000_display_p95);
  return j;
}

// "cstart,cstop" -> range; throws naming the flag.
metrics::ExposureRange ParseRange(const std::string& text) {
  const size_t comma = text.find(',');
  auto fail = [&]() -> metrics::ExposureRange {
    throw std::invalid_argument(
        "--hdr-range: expected \"cstart,cstop\" (two finite numbers, "
        "cstart <= cstop), got \"" +
        text + "\"");
  };
  if (comma == std::string::npos) return fail();
  try {
    size_t n1 = 0, n2 = 0;
    const std::string s1 = text.substr(0, comma), s2 = text.substr(comma + 1);
    metrics::ExposureRange r{std::stod(s1, &n1), std::stod(s2, &n2)};
    if (n1 != s1.size() || n2 != s2.size() || !std::isfinite(r.start) || !std::isfinite(r.stop) ||
        r.start > r.stop)
      return fail();
    return r;
  } catch (const std::logic_error&) {  // stod: invalid_argument / out_of_range
    return fail();
  }
}

void WriteMaps(const std::string& dir, const metrics::CompareResult& r) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw io::IoError(dir + ": cannot create the maps directory: " + ec.message());
  for (const auto& m : r.maps) {
    const std::string base = (fs::path(dir) / m.name).string();
    io::Image img = metrics::MapToImage(m.map);
    img.metadata["clothfit:map"] = m.name;
    io::WriteExr(base + ".exr", img);
    const PngScale sc = ScaleFor(m.name, r);
    std::vector<float> rgb(3 * m.map.values.size());
    for (size_t i = 0; i < m.map.values.size(); ++i) {
      const double span = sc.hi - sc.lo;
      const double t = span != 0.0 ? (double(m.map.values[i]) - sc.lo) / span : 0.0;
      const std::array<float, 3> c = metrics::ErrorMapColour(t);
      for (size_t k = 0; k < 3; ++k) rgb[3 * i + k] = c[k];
    }
    io::WritePng8(base + ".png", m.map.width, m.map.height, rgb);
  }
}

}  // namespace

void AddCompareCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    std::string reference, test, mask, maps_dir, tone_mapping = "ACESFilmic", hdr_range;
    double exposure = 1.0, ppd = 67.0, peak = 1.0;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "compare",
      "every image metric between a reference (A) and a test image (B) of the same size: RMSE "
      "and PSNR (linear and display), SSIM, FLIP, HDR-FLIP, CIEDE2000 (docs/metrics.md)");
  cmd->add_option("reference", args->reference, "reference image A (linear EXR)")->required();
  cmd->add_option("test", args->test, "test image B (linear EXR), same size as A")->required();
  cmd->add_option("--mask", args->mask,
                  "mask image of the same size; pixels with mask > 0.5 count (channel Y, else "
                  "R, else the first)");
  cmd->add_flag("--json", args->json, "print the results as JSON on stdout instead of a table");
  cmd->add_option("--maps", args->maps_dir,
                  "write every per-pixel error map to this directory as EXR and colour-mapped "
                  "PNG");
  cmd->add_option("--tone-mapping", args->tone_mapping,
                  "display transform for the display metrics (Linear|Reinhard|Cineon|"
                  "ACESFilmic|AgX|Neutral)");
  cmd->add_option("--exposure", args->exposure, "display exposure multiplier (> 0)")
      ->check(PositiveFinite());
  cmd->add_option("--hdr-range", args->hdr_range,
                  "HDR-FLIP exposure range \"cstart,cstop\" in stops; use the same range for "
                  "every test image of one reference (required when the reference's median "
                  "luminance is 0); automatic from the reference when absent");
  cmd->add_option("--ppd", args->ppd, "FLIP pixels per degree (67: 0.7 m, 3840 px over 0.7 m)")
      ->check(PositiveFinite());
  cmd->add_option("--peak", args->peak, "peak value for the linear PSNR (display PSNR uses 1)")
      ->check(PositiveFinite());
  cmd->callback([args, &g, &exit_code]() {
    try {
      metrics::CompareOptions o;
      try {
        o.tone_mapping = render::ParseToneMapping(args->tone_mapping);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(std::string("--tone-mapping: ") + e.what());
      }
      o.exposure = args->exposure;
      o.ppd = args->ppd;
      o.linear_peak = args->peak;
      if (!args->hdr_range.empty()) o.hdr_range = ParseRange(args->hdr_range);
      const metrics::CompareResult r =
          metrics::CompareFiles(args->reference, args->test, args->mask, o);
      if (!args->maps_dir.empty()) {
        WriteMaps(args->maps_dir, r);
        if (!g.quiet)
          std::fprintf(stderr, "clothfit compare: wrote %zu maps to %s\n", r.maps.size(),
                       args->maps_dir.c_str());
      }
      // HDR-FLIP unavailable: the other metrics are printed and the exit status stays 0
      // (docs/metrics.md); a warning on stderr says so in both output forms.
      if (!r.hdr_flip_unavailable.empty())
        std::fprintf(stderr, "clothfit compare: warning: HDR-FLIP unavailable: %s\n",
                     HdrFlipUnavailable(r).c_str());
      if (args->json) {
        std::printf("%s\n", limits::DumpJson(Json(r, o, args->reference, args->test, args->mask)).c_str());
      } else {
        std::printf("%s", Table(r, o).c_str());
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit compare: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
