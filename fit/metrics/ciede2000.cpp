// fit/metrics/ciede2000.cpp: CIEDE2000
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

// ---- public: CIEDE2000 ------------------------------------------------------------------------

Lab LinearSrgbToLab(double r, double g, double b) {
  double xyz[3];
  for (int i = 0; i < 3; ++i)
    xyz[i] = kRgbToXyz[i][0] * r + kRgbToXyz[i][1] * g + kRgbToXyz[i][2] * b;
  return XyzToLab(xyz[0], xyz[1], xyz[2]);
}

// Sharma, Wu & Dalal 2005, eqs. (1)-(23); angles in degrees as in the paper.
double Ciede2000(const Lab& p, const Lab& q) {
  constexpr double kDeg = kPi / 180.0;
  const double pow25_7 = 6103515625.0;  // 25^7
  // (2)-(4): C*ab, its mean, G.
  const double c1 = std::hypot(p.a, p.b), c2 = std::hypot(q.a, q.b);
  const double cbar = 0.5 * (c1 + c2);
  const double cbar7 = std::pow(cbar, 7.0);
  const double g = 0.5 * (1.0 - std::sqrt(cbar7 / (cbar7 + pow25_7)));
  // (5)-(7): a', C', h' (h' = 0 when a' = b = 0).
  const double a1 = (1.0 + g) * p.a, a2 = (1.0 + g) * q.a;
  const double cp1 = std::hypot(a1, p.b), cp2 = std::hypot(a2, q.b);
  auto hue = [&](double a, double b) {
    if (a == 0.0 && b == 0.0) return 0.0;
    double h = std::atan2(b, a) / kDeg;
    return h < 0.0 ? h + 360.0 : h;
  };
  const double h1 = hue(a1, p.b), h2 = hue(a2, q.b);
  // (8)-(11): differences.
  const double dl = q.L - p.L, dc = cp2 - cp1;
  double dh = 0.0;
  if (cp1 * cp2 != 0.0) {
    dh = h2 - h1;
    if (dh > 180.0)
      dh -= 360.0;
    else if (dh < -180.0)
      dh += 360.0;
  }
  const double dH = 2.0 * std::sqrt(cp1 * cp2) * std::sin(0.5 * dh * kDeg);
  // (12)-(14): means.
  const double lbar = 0.5 * (p.L + q.L), cpbar = 0.5 * (cp1 + cp2);
  double hbar = h1 + h2;
  if (cp1 * cp2 != 0.0) {
    if (std::abs(h1 - h2) <= 180.0)
      hbar = 0.5 * (h1 + h2);
    else if (h1 + h2 < 360.0)
      hbar = 0.5 * (h1 + h2 + 360.0);
    else
      hbar = 0.5 * (h1 + h2 - 360.0);
  }
  // (15)-(22): weighting functions.
  const double t = 1.0 - 0.17 * std::cos((hbar - 30.0) * kDeg) +
                   0.24 * std::cos(2.0 * hbar * kDeg) + 0.32 * std::cos((3.0 * hbar + 6.0) * kDeg) -
                   0.20 * std::cos((4.0 * hbar - 63.0) * kDeg);
  const double dtheta = 30.0 * std::exp(-((hbar - 275.0) / 25.0) * ((hbar - 275.0) / 25.0));
  const double cpbar7 = std::pow(cpbar, 7.0);
  const double rc = 2.0 * std::sqrt(cpbar7 / (cpbar7 + pow25_7));
  const double l50 = (lbar - 50.0) * (lbar - 50.0);
  const double sl = 1.0 + 0.015 * l50 / std::sqrt(20.0 + l50);
  const double sc = 1.0 + 0.045 * cpbar;
  const double sh = 1.0 + 0.015 * cpbar * t;
  const double rt = -std::sin(2.0 * dtheta * kDeg) * rc;
  // (23), k_L = k_C = k_H = 1.
  const double tl = dl / sl, tc = dc / sc, th = dH / sh;
  return std::sqrt(std::max(0.0, tl * tl + tc * tc + th * th + rt * tc * th));
}

Ciede2000Result Ciede2000(const RgbImage& ref, const RgbImage& test, const Map* mask) {
  const Coverage cov = Cover(ref, test, mask, "CIEDE2000");
  Ciede2000Result res;
  res.counts = cov.counts;
  res.map = Map(ref.width, ref.height);
  std::vector<double> pooled;
  pooled.reserve(size_t(cov.counts.counted));
  for (size_t i = 0; i < ref.pixel_count(); ++i) {
    if (!cov.finite[i]) continue;
    const float* a = &ref.rgb[3 * i];
    const float* b = &test.rgb[3 * i];
    const double de =
        Ciede2000(LinearSrgbToLab(double(a[0]), double(a[1]), double(a[2])),
                  LinearSrgbToLab(double(b[0]), double(b[1]), double(b[2])));
    res.map.values[i] = float(de);
    if (cov.counted[i]) pooled.push_back(de);
  }
  res.value = std::accumulate(pooled.begin(), pooled.end(), 0.0) / double(pooled.size());
  std::sort(pooled.begin(), pooled.end());
  const double pos = 0.95 * double(pooled.size() - 1);
  const size_t lo = size_t(pos);
  const size_t hi = std::min(lo + 1, pooled.size() - 1);
  res.p95 = pooled[lo] + (pos - double(lo)) * (pooled[hi] - pooled[lo]);
  return res;
}

}  // namespace clothfit::metrics
