// fit/metrics/ssim.cpp: SSIM
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

// ---- public: SSIM -----------------------------------------------------------------------------

SsimResult Ssim(const RgbImage& ref, const RgbImage& test, const SsimOptions& o, const Map* mask) {
  if (!(o.data_range > 0.0) || !std::isfinite(o.data_range))
    throw std::invalid_argument("SSIM: data_range must be finite and > 0");
  if (o.taps < 1 || o.taps % 2 == 0 || !(o.sigma > 0.0))
    throw std::invalid_argument("SSIM: taps must be odd and >= 1, sigma > 0");
  const Coverage cov = Cover(ref, test, mask, "SSIM");
  const int w = ref.width, h = ref.height, r = o.taps / 2;
  const size_t n = ref.pixel_count();
  const std::vector<double> g = GaussianKernel(o.sigma, r);
  const double c1 = (o.k1 * o.data_range) * (o.k1 * o.data_range);
  const double c2 = (o.k2 * o.data_range) * (o.k2 * o.data_range);

  // Weights: 1 for pixels finite in both images, 0 otherwise; zero outside the image.
  Plane wgt(n);
  for (size_t i = 0; i < n; ++i) wgt[i] = cov.finite[i] ? 1.0 : 0.0;
  const Plane sw = Filter2(wgt, w, h, g, g, Border::kZero);

  SsimResult res;
  res.counts = cov.counts;
  res.map = Map(w, h);
  Plane acc(n, 0.0);
  for (size_t c = 0; c < 3; ++c) {
    Plane x(n), y(n), xx(n), yy(n), xy(n);
    for (size_t i = 0; i < n; ++i) {
      x[i] = cov.finite[i] ? double(ref.rgb[3 * i + c]) : 0.0;
      y[i] = cov.finite[i] ? double(test.rgb[3 * i + c]) : 0.0;
      xx[i] = x[i] * x[i];
      yy[i] = y[i] * y[i];
      xy[i] = x[i] * y[i];
    }
    const Plane mx = Filter2(x, w, h, g, g, Border::kZero),
                my = Filter2(y, w, h, g, g, Border::kZero);
    const Plane mxx = Filter2(xx, w, h, g, g, Border::kZero),
                myy = Filter2(yy, w, h, g, g, Border::kZero),
                mxy = Filter2(xy, w, h, g, g, Border::kZero);
    for (size_t i = 0; i < n; ++i) {
      if (!cov.finite[i]) continue;  // sw[i] > 0 for finite pixels (own weight)
      const double ux = mx[i] / sw[i], uy = my[i] / sw[i];
      const double vx = mxx[i] / sw[i] - ux * ux, vy = myy[i] / sw[i] - uy * uy;
      const double cxy = mxy[i] / sw[i] - ux * uy;
      acc[i] +=
          ((2.0 * ux * uy + c1) * (2.0 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
    }
  }
  for (size_t i = 0; i < n; ++i) res.map.values[i] = cov.finite[i] ? float(acc[i] / 3.0) : 0.0f;

  // Pool: counted pixels whose full window lies inside the image ("valid"); else all counted.
  double sum = 0.0;
  long long count = 0;
  for (int yv = r; yv < h - r; ++yv)
    for (int xv = r; xv < w - r; ++xv) {
      const size_t i = size_t(yv) * size_t(w) + size_t(xv);
      if (cov.counted[i]) sum += acc[i] / 3.0, ++count;
    }
  if (count == 0) {
    res.used_border_pixels = true;
    for (size_t i = 0; i < n; ++i)
      if (cov.counted[i]) sum += acc[i] / 3.0, ++count;
  }
  res.value = sum / double(count);
  return res;
}

}  // namespace clothfit::metrics
