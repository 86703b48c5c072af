// fit/metrics/compare.cpp: Compare: every metric of one image pair, from memory or files
// (fit/metrics/metrics.h documents every formula and choice).
#include "fit/metrics/metrics.h"
#include "fit/metrics/metrics_internal.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace clothfit::metrics {
using namespace internal;

namespace {
// Empty when the reference's automatic HDR-FLIP range is finite; otherwise why it is not, in
// words (the range goes to *range).
std::string UnusableAutomaticRange(const RgbImage& ref, const Map* mask, ExposureRange* range) {
  *range = AutomaticExposureRange(ref, mask);
  if (std::isfinite(range->start) && std::isfinite(range->stop)) return {};
  const char* what = std::isfinite(range->start) ? "median" : "maximum";
  return std::string("the automatic exposure range is not finite: the reference's ") + what +
         " luminance over the counted pixels is 0 (e.g. a transparent film or a black "
         "background)";
}
}  // namespace

// ---- public: Compare --------------------------------------------------------------------------

CompareResult Compare(const RgbImage& ref, const RgbImage& test, const CompareOptions& o,
                      const Map* mask) {
  if (!(o.exposure > 0.0) || !std::isfinite(o.exposure))
    throw std::invalid_argument("compare: exposure must be finite and > 0");
  const Coverage cov = Cover(ref, test, mask, "compare");
  CompareResult res;
  res.width = ref.width;
  res.height = ref.height;
  res.counts = cov.counts;

  const RgbImage ref_d = ToDisplay(ref, o.tone_mapping, o.exposure);
  const RgbImage test_d = ToDisplay(test, o.tone_mapping, o.exposure);

  MetricResult rl = Rmse(ref, test, mask);
  res.rmse_linear = rl.value;
  res.psnr_linear = Psnr(ref, test, o.linear_peak, mask).value;
  MetricResult rd = Rmse(ref_d, test_d, mask);
  res.rmse_display = rd.value;
  res.psnr_display = Psnr(ref_d, test_d, 1.0, mask).value;
  SsimResult s = Ssim(ref_d, test_d, SsimOptions{}, mask);
  res.ssim = s.value;
  res.ssim_used_border_pixels = s.used_border_pixels;
  MetricResult f = Flip(ref_d, test_d, FlipOptions{o.ppd}, mask);
  res.flip = f.value;
  // HDR-FLIP: an automatic range that is not finite makes it unavailable, not the comparison.
  HdrFlipResult hf;
  if (!o.hdr_range) res.hdr_flip_unavailable = UnusableAutomaticRange(ref, mask, &res.hdr_range);
  if (res.hdr_flip_unavailable.empty()) {
    hf = HdrFlip(ref, test, HdrFlipOptions{o.ppd, o.hdr_range}, mask);
    res.hdr_flip = hf.value;
    res.hdr_range = hf.range;
    res.hdr_exposures = hf.exposures;
  } else {
    res.hdr_flip = std::numeric_limits<double>::quiet_NaN();
  }
  res.hdr_range_automatic = !o.hdr_range;
  Ciede2000Result de = Ciede2000(ref, test, mask);
  res.ciede2000_mean = de.value;
  res.ciede2000_p95 = de.p95;
  // The displayed colour as linear light: sRGB-decode the display values.
  RgbImage ref_dl = ref_d, test_dl = test_d;
  for (float& v : ref_dl.rgb)
    v = std::isfinite(v) ? float(flip_detail::SrgbToLinear(double(v))) : v;
  for (float& v : test_dl.rgb)
    v = std::isfinite(v) ? float(flip_detail::SrgbToLinear(double(v))) : v;
  Ciede2000Result ded = Ciede2000(ref_dl, test_dl, mask);
  res.ciede2000_display_mean = ded.value;
  res.ciede2000_display_p95 = ded.p95;

  res.maps.push_back({"rmse_linear", std::move(rl.map)});
  res.maps.push_back({"rmse_display", std::move(rd.map)});
  res.maps.push_back({"ssim", std::move(s.map)});
  res.maps.push_back({"flip", std::move(f.map)});
  if (res.hdr_flip_unavailable.empty()) {
    res.maps.push_back({"hdr_flip", std::move(hf.map)});
    res.maps.push_back({"hdr_flip_exposure", std::move(hf.exposure_map)});
  }
  res.maps.push_back({"ciede2000", std::move(de.map)});
  res.maps.push_back({"ciede2000_display", std::move(ded.map)});
  return res;
}

namespace {
// The metrics compare linear radiance; an 8/16-bit image holds display-encoded values, and
// treating them as linear would silently give wrong numbers (docs/metrics.md).
io::Image ReadLinear(const std::string& path) {
  io::Image img = io::ReadImage(path);
  if (!img.float_source)
    throw std::invalid_argument(path + ": compare needs linear images (float or half EXR/HDR); "
                                "this is a " + img.source_format + " " + img.file_format +
                                " with display-encoded (sRGB) values");
  return img;
}
}  // namespace

CompareResult CompareFiles(const std::string& reference_path, const std::string& test_path,
                           const std::string& mask_path, const CompareOptions& options) {
  const RgbImage ref = ToRgb(ReadLinear(reference_path), reference_path);
  const RgbImage test = ToRgb(ReadLinear(test_path), test_path);
  if (ref.width != test.width || ref.height != test.height)
    throw std::invalid_argument("size mismatch: " + reference_path + " is " +
                                SizeText(ref.width, ref.height) + " but " + test_path + " is " +
                                SizeText(test.width, test.height));
  std::optional<Map> mask;
  if (!mask_path.empty()) {
    mask = ToMask(io::ReadImage(mask_path), mask_path);
    if (mask->width != ref.width || mask->height != ref.height)
      throw std::invalid_argument("size mismatch: mask " + mask_path + " is " +
                                  SizeText(mask->width, mask->height) + " but " + reference_path +
                                  " is " + SizeText(ref.width, ref.height));
  }
  return Compare(ref, test, options, mask ? &*mask : nullptr);
}

}  // namespace clothfit::metrics
