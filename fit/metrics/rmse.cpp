// fit/metrics/rmse.cpp: RMSE and PSNR
// (fit/metrics/metrics.h documents every formula and choice).
#include "fit/metrics/metrics.h"
#include "fit/metrics/metrics_internal.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace clothfit::metrics {
using namespace internal;

// ---- public: RMSE / PSNR ----------------------------------------------------------------------

MetricResult Rmse(const RgbImage& ref, const RgbImage& test, const Map* mask) {
  const Coverage cov = Cover(ref, test, mask, "RMSE");
  MetricResult res;
  res.counts = cov.counts;
  res.map = Map(ref.width, ref.height);
  double sum = 0.0;
  for (size_t i = 0; i < ref.pixel_count(); ++i) {
    if (!cov.finite[i]) continue;
    double se = 0.0;
    for (size_t c = 0; c < 3; ++c) {
      const double d = double(ref.rgb[3 * i + c]) - double(test.rgb[3 * i + c]);
      se += d * d;
    }
    res.map.values[i] = float(std::sqrt(se / 3.0));
    if (cov.counted[i]) sum += se;
  }
  res.value = std::sqrt(sum / (3.0 * double(cov.counts.counted)));
  return res;
}

MetricResult Psnr(const RgbImage& ref, const RgbImage& test, double peak, const Map* mask) {
  if (!(peak > 0.0) || !std::isfinite(peak))
    throw std::invalid_argument("PSNR: peak must be finite and > 0, got " + std::to_string(peak));
  MetricResult res = Rmse(ref, test, mask);
  res.value = res.value > 0.0 ? 20.0 * std::log10(peak / res.value) : kInf;
  return res;
}

}  // namespace clothfit::metrics
