#include "fit/reference.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fit/image_fit.h"
#include "fit/metrics/reference_halves.h"
#include "render/scene/image_io.h"

namespace clothfit::fit {
namespace {

int Channel(const io::Image& img, const std::string& name) {
  for (int c = 0; c < img.channels(); ++c)
    if (img.channel_names[size_t(c)] == name) return c;
  return -1;
}

// Relative standard error of every pixel when the file has no stderr.*: sigma = k_c x, with
// k_c from the image (Immerkaer). Kept >= 0.
void FillEstimatedNoise(Reference* r) {
  for (int c = 0; c < 3; ++c) {
    const double k = EstimateRelativeNoise(*r, c);
    for (size_t p = 0; p < r->weight.size(); ++p)
      r->std_error[p * 3 + size_t(c)] = float(k * std::max(0.0, double(r->rgb[p * 3 + size_t(c)])));
  }
}

}  // namespace

AlphaMode ParseAlphaMode(const std::string& s) {
  if (s == "auto") return AlphaMode::kAuto;
  if (s == "premultiplied") return AlphaMode::kPremultiplied;
  if (s == "straight") return AlphaMode::kStraight;
  throw std::invalid_argument("--alpha: unknown '" + s + "' (valid: auto, premultiplied, straight)");
}

NoiseMode ParseNoiseMode(const std::string& s) {
  if (s == "auto") return NoiseMode::kAuto;
  if (s == "image") return NoiseMode::kImage;
  if (s == "none") return NoiseMode::kNone;
  throw std::invalid_argument("--noise: unknown '" + s + "' (valid: auto, image, none)");
}

void RequireLinearImage(const io::Image& image, const std::string& path) {
  if (image.float_source) return;
  throw FitError(path + ": a reference must be linear radiance (float or half EXR, or Radiance "
                 "HDR); this is a " + image.source_format + " " + image.file_format +
                 " with display-encoded (sRGB) values, which the fit would take for radiance: "
                 "give the renderer's linear EXR or HDR, not a tone-mapped image "
                 "(docs/references.md)");
}

Reference ReadReference(const std::string& path, const ReferenceOptions& o) {
  const io::Image img = io::ReadImage(path);
  RequireLinearImage(img, path);
  Reference r;
  r.path = path;
  r.width = img.width;
  r.height = img.height;
  const int ch[3] = {Channel(img, "R"), Channel(img, "G"), Channel(img, "B")};
  if (ch[0] < 0 || ch[1] < 0 || ch[2] < 0) throw FitError(path + ": reference needs channels R, G, B");
  const int se[3] = {Channel(img, "stderr.R"), Channel(img, "stderr.G"), Channel(img, "stderr.B")};
  const bool has_stderr = se[0] >= 0 && se[1] >= 0 && se[2] >= 0;
  // Coverage channel and layout.
  int cov = -1;
  bool clothfit_layout = false;
  if (o.coverage_channel == "none") {
    cov = -1;
  } else if (!o.coverage_channel.empty()) {
    cov = Channel(img, o.coverage_channel);
    if (cov < 0) throw FitError(path + ": no channel '" + o.coverage_channel + "' (--coverage-channel)");
    clothfit_layout = o.coverage_channel == "fabric";
  } else {
    cov = Channel(img, "fabric");
    clothfit_layout = cov >= 0;
    if (cov < 0) cov = Channel(img, "A");
  }
  bool premultiplied = false;
  if (cov >= 0 && !clothfit_layout)
    premultiplied = o.alpha != AlphaMode::kStraight;  // auto: OpenEXR's rule
  if (clothfit_layout && o.alpha == AlphaMode::kPremultiplied) premultiplied = true;
  r.layout = cov < 0            ? "no coverage"
             : clothfit_layout && !premultiplied ? "clothfit (fabric channel)"
             : premultiplied   ? "premultiplied alpha (" + img.channel_names[size_t(cov)] + ")"
                               : "straight alpha (" + img.channel_names[size_t(cov)] + ")";

  const size_t np = size_t(img.width) * size_t(img.height);
  const size_t nc = size_t(img.channels());
  r.rgb.resize(np * 3);
  r.std_error.assign(np * 3, 0.f);
  r.fabric.assign(np, 1.f);
  r.weight.assign(np, 1.f);
  size_t bad = 0, first = 0;
  for (size_t p = 0; p < np; ++p) {
    const float* px = &img.pixels[p * nc];
    float a = 1.f;
    if (cov >= 0) a = std::isfinite(px[cov]) ? std::clamp(px[cov], 0.f, 1.f) : 0.f;
    r.fabric[p] = a;
    r.weight[p] = clothfit_layout && !premultiplied ? (a >= 0.999f ? 1.f : 0.f) : a;
    // Premultiplied: radiance of the covered part; below 1e-4 coverage the division only
    // amplifies noise and the pixel's weight is ~0 anyway.
    const float inv = premultiplied ? (a > 1e-4f ? 1.f / a : 0.f) : 1.f;
    for (size_t c = 0; c < 3; ++c) {
      const float v = px[ch[c]];
      if (!std::isfinite(v) && bad++ == 0) first = p;
      r.rgb[p * 3 + c] = v * inv;
      if (has_stderr) r.std_error[p * 3 + c] = std::isfinite(px[se[c]]) ? px[se[c]] * inv : 0.f;
    }
  }
  if (bad > 0) {
    throw FitError(path + ": " + std::to_string(bad) + " non-finite R/G/B values (first at pixel x=" +
                   std::to_string(first % size_t(img.width)) + ", y=" +
                   std::to_string(first / size_t(img.width)) + "); refusing to fit to them");
  }
  // Half-sample images (the noise floor without a second seed): same coverage handling as R/G/B.
  metrics::ReferenceHalves halves;
  try {
    halves = metrics::ExtractHalves(img, path);
  } catch (const std::invalid_argument& e) {
    throw FitError(e.what());
  }
  if (halves.present) {
    r.half_batches = halves.half_batches;
    r.batches = halves.batches;
    r.half_a.resize(np * 3);
    r.half_b.resize(np * 3);
    for (size_t p = 0; p < np; ++p) {
      const float a = cov >= 0 ? r.fabric[p] : 1.f;
      const float inv = premultiplied ? (a > 1e-4f ? 1.f / a : 0.f) : 1.f;
      for (size_t c = 0; c < 3; ++c) {
        const float va = halves.a.rgb[p * 3 + c], vb = halves.b.rgb[p * 3 + c];
        r.half_a[p * 3 + c] = std::isfinite(va) ? va * inv : 0.f;
        r.half_b[p * 3 + c] = std::isfinite(vb) ? vb * inv : 0.f;
      }
    }
  }
  if (has_stderr && o.noise != NoiseMode::kImage && o.noise != NoiseMode::kNone) {
    r.noise = "stderr channels";
  } else if (o.noise == NoiseMode::kNone) {
    std::fill(r.std_error.begin(), r.std_error.end(), 0.f);
    r.noise = "none (--noise none)";
  } else {
    FillEstimatedNoise(&r);
    r.noise = "estimated from the image (Immerkaer 1996)";
  }
  return r;
}

bool HasHalfChannels(const std::string& path) {
  const io::Image img = io::ReadImage(path);
  return Channel(img, "half.R") >= 0 && Channel(img, "half.G") >= 0 && Channel(img, "half.B") >= 0;
}

double EstimateRelativeNoise(const Reference& ref, int c) {
  const int W = ref.width, H = ref.height;
  double sum = 0.0, mean = 0.0;
  size_t n = 0;
  static const int kMask[3][3] = {{1, -2, 1}, {-2, 4, -2}, {1, -2, 1}};
  for (int y = 1; y + 1 < H; ++y) {
    for (int x = 1; x + 1 < W; ++x) {
      double response = 0.0;
      bool covered = true;
      for (int dy = -1; dy <= 1 && covered; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const size_t p = size_t(y + dy) * size_t(W) + size_t(x + dx);
          if (ref.weight[p] <= 0.5f) {
            covered = false;
            break;
          }
          response += kMask[dy + 1][dx + 1] * double(ref.rgb[p * 3 + size_t(c)]);
        }
      if (!covered) continue;
      sum += std::abs(response);
      mean += double(ref.rgb[(size_t(y) * size_t(W) + size_t(x)) * 3 + size_t(c)]);
      ++n;
    }
  }
  if (n == 0 || mean <= 0.0) return 0.0;
  const double sigma = std::sqrt(kPi / 2.0) / 6.0 * sum / double(n);
  return sigma / (mean / double(n));
}

WeavePeriod ParseWeavePeriod(const std::string& s) {
  static const std::pair<const char*, double> kUnits[] = {
      {"uv", 1.0}, {"mm", 1e-3}, {"cm", 1e-2}, {"m", 1.0}};
  std::string number = s;
  WeavePeriod p;
  double scale = 1.0;
  for (const auto& [suffix, factor] : kUnits) {
    const std::string u(suffix);
    if (s.size() > u.size() && s.compare(s.size() - u.size(), u.size(), u) == 0) {
      number = s.substr(0, s.size() - u.size());
      scale = factor;
      p.uv = u == "uv";
      break;
    }
  }
  size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(number, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != number.size() || !(v > 0.0) || !std::isfinite(v))
    throw std::invalid_argument("--weave-period: '" + s +
                                "' is not a positive length (e.g. 0.002, 2mm, 0.2cm) or UV period "
                                "(e.g. 0.05uv)");
  p.value = v * scale;
  return p;
}

double WeavePeriodUv(const WeavePeriod& p, const render::Scene& scene, const std::string& card) {
  if (p.uv) return p.value;
  if (!(scene.card.uv_metres_per_unit > 0.0))
    throw std::invalid_argument("--weave-period: " + card +
                                " has no uv_metres_per_unit, so a length cannot become a UV "
                                "period; give the period in UV units (e.g. 0.05uv)");
  return p.value / scene.card.uv_metres_per_unit;
}

}  // namespace clothfit::fit
