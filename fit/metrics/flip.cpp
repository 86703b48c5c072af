// fit/metrics/flip.cpp: FLIP (LDR) and HDR-FLIP
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
namespace {

using namespace internal;

// ---- FLIP ---------------------------------------------------------------------------------

// The paper's CSF parameters (Andersson et al. 2020, section 4.1 / Table 1).
struct CsfTerm {
  double a, b;
};
constexpr CsfTerm kCsfY = {1.0, 0.0047};
constexpr CsfTerm kCsfCx = {1.0, 0.0053};
constexpr CsfTerm kCsfCz1 = {34.1, 0.04};
constexpr CsfTerm kCsfCz2 = {13.5, 0.025};
constexpr double kCsfBMax = 0.04;

constexpr double kQc = 0.7, kPc = 0.4, kPt = 0.95, kQf = 0.5;
constexpr double kFeatureWidthDeg = 0.082;

struct CsfKernel {
  // A sum of separable terms: sum_t weight_t (k_t(x) k_t(y)), each k_t normalised to sum 1,
  // the weights summing to 1.
  std::vector<std::pair<double, std::vector<double>>> terms;
};

CsfKernel MakeCsfKernel(std::initializer_list<CsfTerm> terms, double ppd) {
  const int r = int(std::ceil(3.0 * std::sqrt(kCsfBMax / (2.0 * kPi * kPi)) * ppd));
  CsfKernel out;
  double total = 0.0;
  for (const CsfTerm& t : terms) {
    // s(x) = a sqrt(pi/b) exp(-pi^2 (x^2 + y^2) / b), x = pixel offset / ppd degrees; the 2D
    // term is amp * g(x) g(y) with g(x) = exp(-pi^2 x^2 / b).
    std::vector<double> g(size_t(2 * r + 1));
    double sum = 0.0;
    for (int i = -r; i <= r; ++i) {
      const double x = double(i) / ppd;
      g[size_t(i + r)] = std::exp(-kPi * kPi * x * x / t.b);
      sum += g[size_t(i + r)];
    }
    for (double& v : g) v /= sum;
    const double weight = t.a * std::sqrt(kPi / t.b) * sum * sum;  // 2D sum of the term
    total += weight;
    out.terms.emplace_back(weight, std::move(g));
  }
  for (auto& t : out.terms) t.first /= total;
  return out;
}

Plane ApplyCsf(const Plane& in, int w, int h, const CsfKernel& k) {
  Plane out(in.size(), 0.0);
  for (const auto& [weight, g] : k.terms) {
    const Plane f = Filter2(in, w, h, g, g, Border::kClamp);
    for (size_t i = 0; i < out.size(); ++i) out[i] += weight * f[i];
  }
  return out;
}

struct FlipKernels {
  CsfKernel y, cx, cz;
  flip_detail::FeatureKernels features;
};

FlipKernels MakeFlipKernels(double ppd) {
  if (!(ppd > 0.0) || !std::isfinite(ppd))
    throw std::invalid_argument("FLIP: pixels per degree must be finite and > 0, got " +
                                std::to_string(ppd));
  return {MakeCsfKernel({kCsfY}, ppd), MakeCsfKernel({kCsfCx}, ppd),
          MakeCsfKernel({kCsfCz1, kCsfCz2}, ppd), flip_detail::MakeFeatureKernels(ppd)};
}

// One image through the colour pipeline (steps 1-4) and the feature detector (step 6).
struct FlipPrepared {
  std::vector<Lab> lab;  // Hunt-adjusted CIELAB of the filtered image
  Plane edge, point;     // feature magnitudes
};

FlipPrepared PrepareFlip(const RgbImage& lin, const FlipKernels& k) {
  const int w = lin.width, h = lin.height;
  const size_t n = lin.pixel_count();
  Plane yy(n), cx(n), cz(n), yn(n);
  for (size_t i = 0; i < n; ++i) {
    double c[3];
    for (int j = 0; j < 3; ++j) c[j] = std::clamp(double(lin.rgb[3 * i + size_t(j)]), 0.0, 1.0);
    double xyz[3];
    for (int r = 0; r < 3; ++r)
      xyz[r] = kRgbToXyz[r][0] * c[0] + kRgbToXyz[r][1] * c[1] + kRgbToXyz[r][2] * c[2];
    const double ny = xyz[1] / kWhite[1];
    yy[i] = 116.0 * ny - 16.0;
    cx[i] = 500.0 * (xyz[0] / kWhite[0] - ny);
    cz[i] = 200.0 * (ny - xyz[2] / kWhite[2]);
    yn[i] = ny;  // = (Y' + 16) / 116
  }
  const Plane fy = ApplyCsf(yy, w, h, k.y), fcx = ApplyCsf(cx, w, h, k.cx),
              fcz = ApplyCsf(cz, w, h, k.cz);
  FlipPrepared p;
  p.lab.resize(n);
  const Mat3& inv = XyzToRgb();
  for (size_t i = 0; i < n; ++i) {
    const double ny = (fy[i] + 16.0) / 116.0;
    const double xyz[3] = {kWhite[0] * (fcx[i] / 500.0 + ny), kWhite[1] * ny,
                           kWhite[2] * (ny - fcz[i] / 200.0)};
    double rgb[3];
    for (int r = 0; r < 3; ++r) {
      const auto& row = inv[size_t(r)];
      rgb[r] = std::clamp(row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2], 0.0, 1.0);
    }
    p.lab[i] = flip_detail::HuntLab(rgb[0], rgb[1], rgb[2]);
  }
  const auto& fk = k.features;
  const Plane hg = FilterRows(yn, w, h, fk.gauss, Border::kClamp);
  const Plane he = FilterRows(yn, w, h, fk.edge, Border::kClamp);
  const Plane hp = FilterRows(yn, w, h, fk.point, Border::kClamp);
  const Plane ex = FilterCols(he, w, h, fk.gauss, Border::kClamp);
  const Plane px = FilterCols(hp, w, h, fk.gauss, Border::kClamp);
  const Plane ey = FilterCols(hg, w, h, fk.edge, Border::kClamp);
  const Plane py = FilterCols(hg, w, h, fk.point, Border::kClamp);
  p.edge.resize(n);
  p.point.resize(n);
  for (size_t i = 0; i < n; ++i) {
    p.edge[i] = std::hypot(ex[i], ey[i]);
    p.point[i] = std::hypot(px[i], py[i]);
  }
  return p;
}

Map FlipMapLinearWith(const RgbImage& ref, const RgbImage& test, const FlipKernels& k) {
  const FlipPrepared r = PrepareFlip(ref, k), t = PrepareFlip(test, k);
  Map map(ref.width, ref.height);
  for (size_t i = 0; i < map.values.size(); ++i) {
    const double d = std::pow(flip_detail::HyAB(r.lab[i], t.lab[i]), kQc);
    const double ec = std::min(1.0, flip_detail::RemapColourError(d));
    const double df = std::max(std::abs(r.edge[i] - t.edge[i]), std::abs(r.point[i] - t.point[i]));
    const double ef = std::pow(std::min(1.0, df / std::sqrt(2.0)), kQf);
    map.values[i] = ec > 0.0 ? float(std::pow(ec, 1.0 - ef)) : 0.0f;
  }
  return map;
}

// ---- HDR-FLIP -----------------------------------------------------------------------------

// ACES fit with the 0.6 input scale (HDR-FLIP paper; Narkowicz 2015 curve).
constexpr double kTm[6] = {0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14};
constexpr double kTmTarget = 0.85;

}  // namespace

using namespace internal;

// ---- public: FLIP -----------------------------------------------------------------------------

namespace flip_detail {

double SrgbToLinear(double v) {
  v = std::clamp(v, 0.0, 1.0);
  return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4);
}

Lab HuntLab(double r, double g, double b) {
  Lab l = LinearSrgbToLab(r, g, b);
  l.a *= 0.01 * l.L;
  l.b *= 0.01 * l.L;
  return l;
}

double HyAB(const Lab& x, const Lab& y) {
  return std::abs(x.L - y.L) + std::hypot(x.a - y.a, x.b - y.b);
}

double MaxColourError() {
  static const double cmax = std::pow(HyAB(HuntLab(0, 1, 0), HuntLab(0, 0, 1)), kQc);
  return cmax;
}

double RemapColourError(double d) {
  const double cmax = MaxColourError();
  return d < kPc * cmax ? (kPt / (kPc * cmax)) * d
                        : kPt + (d - kPc * cmax) / (cmax - kPc * cmax) * (1.0 - kPt);
}

FeatureKernels MakeFeatureKernels(double ppd) {
  const double sigma = 0.5 * kFeatureWidthDeg * ppd;
  FeatureKernels k;
  k.radius = int(std::ceil(3.0 * sigma));
  const int r = k.radius;
  k.gauss = GaussianKernel(sigma, r);
  k.edge.resize(k.gauss.size());
  k.point.resize(k.gauss.size());
  double edge_pos = 0.0, point_pos = 0.0, point_neg = 0.0;
  for (int i = -r; i <= r; ++i) {
    const double x = double(i);
    const double gi = std::exp(-x * x / (2.0 * sigma * sigma));
    const double e = -x * gi;                               // d/dx, up to a constant
    const double p = (x * x / (sigma * sigma) - 1.0) * gi;  // d2/dx2, up to a constant
    k.edge[size_t(i + r)] = e;
    k.point[size_t(i + r)] = p;
    if (e > 0) edge_pos += e;
    if (p > 0) point_pos += p;
    if (p < 0) point_neg -= p;
  }
  for (double& e : k.edge) e /= edge_pos;
  for (double& p : k.point) p /= (p > 0 ? point_pos : point_neg);
  return k;
}

FeatureMaps FeatureMagnitudes(const RgbImage& linear, double ppd) {
  if (linear.rgb.size() != 3 * linear.pixel_count())
    throw std::invalid_argument("FLIP: image buffer size does not match its dimensions");
  const FlipPrepared p = PrepareFlip(linear, MakeFlipKernels(ppd));
  FeatureMaps out{Map(linear.width, linear.height), Map(linear.width, linear.height)};
  for (size_t i = 0; i < p.edge.size(); ++i) {
    out.edge.values[i] = float(p.edge[i]);
    out.point.values[i] = float(p.point[i]);
  }
  return out;
}

Map FlipMapLinear(const RgbImage& ref, const RgbImage& test, double ppd) {
  CheckSameSize(ref, test, nullptr, "FLIP");
  return FlipMapLinearWith(ref, test, MakeFlipKernels(ppd));
}

}  // namespace flip_detail

double PixelsPerDegree(double distance_m, double width_m, double width_px) {
  return distance_m * (width_px / width_m) * kPi / 180.0;
}

MetricResult Flip(const RgbImage& ref_srgb, const RgbImage& test_srgb, const FlipOptions& o,
                  const Map* mask) {
  const Coverage cov = Cover(ref_srgb, test_srgb, mask, "FLIP");
  const FlipKernels k = MakeFlipKernels(o.ppd);
  RgbImage ref = Sanitized(ref_srgb, cov), test = Sanitized(test_srgb, cov);
  for (float& v : ref.rgb) v = float(flip_detail::SrgbToLinear(double(v)));
  for (float& v : test.rgb) v = float(flip_detail::SrgbToLinear(double(v)));
  MetricResult res;
  res.counts = cov.counts;
  res.map = FlipMapLinearWith(ref, test, k);
  ZeroNonFinite(res.map, cov);
  res.value = MeanOver(res.map, cov);
  return res;
}

// ---- public: HDR-FLIP -------------------------------------------------------------------------

double HdrFlipToneMap(double x) {
  // Negative radiance is clipped to 0 first, as the FLIP reference implementation does
  // (NVlabs/flip tone_map: max(img, 0)); without it the rational function maps large
  // negative values towards 1 (white): t(-10) = 1.07 before the clamp.
  x = std::max(x, 0.0);
  const double num = (kTm[0] * x + kTm[1]) * x + kTm[2];
  const double den = (kTm[3] * x + kTm[4]) * x + kTm[5];  // > 0 for all x (no real roots)
  return std::clamp(num / den, 0.0, 1.0);
}

ExposureRange AutomaticExposureRange(const RgbImage& ref, const Map* mask) {
  const Coverage cov = Cover(ref, ref, mask, "HDR-FLIP automatic exposure range");
  std::vector<double> lum;
  lum.reserve(size_t(cov.counts.counted));
  for (size_t i = 0; i < ref.pixel_count(); ++i)
    if (cov.counted[i]) lum.push_back(Luminance(&ref.rgb[3 * i]));
  // x_max: the positive root of t(x) = 0.85, i.e. of (k0 - t k3) x^2 + (k1 - t k4) x +
  // (k2 - t k5) = 0.
  const double a = kTm[0] - kTmTarget * kTm[3], b = kTm[1] - kTmTarget * kTm[4],
               c = kTm[2] - kTmTarget * kTm[5];
  const double x_max = (-b + std::sqrt(b * b - 4.0 * a * c)) / (2.0 * a);
  const double y_max = *std::max_element(lum.begin(), lum.end());
  // Median as the FLIP reference implementation takes it (numpy percentile 50): the middle
  // element, or the mean of the two middle elements for an even count.
  const auto mid = lum.begin() + std::ptrdiff_t((lum.size() - 1) / 2);
  std::nth_element(lum.begin(), mid, lum.end());
  double y_median = *mid;
  if (lum.size() % 2 == 0) y_median = 0.5 * (y_median + *std::min_element(mid + 1, lum.end()));
  ExposureRange range;
  range.start = y_max > 0.0 ? std::log2(x_max / y_max) : kInf;
  range.stop = y_median > 0.0 ? std::log2(x_max / y_median) : kInf;
  return range;
}

HdrFlipResult HdrFlip(const RgbImage& ref_linear, const RgbImage& test_linear,
                      const HdrFlipOptions& o, const Map* mask) {
  const Coverage cov = Cover(ref_linear, test_linear, mask, "HDR-FLIP");
  HdrFlipResult res;
  res.counts = cov.counts;
  if (o.range) {
    res.range = *o.range;
    if (!std::isfinite(res.range.start) || !std::isfinite(res.range.stop) ||
        res.range.start > res.range.stop)
      throw std::invalid_argument(
          "HDR-FLIP: exposure range must be finite with start <= stop, "
          "got [" +
          std::to_string(res.range.start) + ", " + std::to_string(res.range.stop) + "]");
  } else {
    res.range = AutomaticExposureRange(ref_linear, mask);
    res.automatic_range = true;
    if (!std::isfinite(res.range.start) || !std::isfinite(res.range.stop))
      throw std::invalid_argument(
          "HDR-FLIP: the automatic exposure range is not finite (the reference's median or "
          "maximum luminance is 0, e.g. a black background); give the range explicitly "
          "(cstart,cstop) and use the same range for every image compared with this reference");
  }
  const double span = res.range.stop - res.range.start;
  res.exposures = std::max(2, int(std::ceil(span)));
  const FlipKernels k = MakeFlipKernels(o.ppd);
  const RgbImage ref = Sanitized(ref_linear, cov), test = Sanitized(test_linear, cov);
  res.map = Map(ref.width, ref.height, 0.0f);
  res.exposure_map = Map(ref.width, ref.height, float(res.range.start));
  RgbImage ref_t(ref.width, ref.height), test_t(ref.width, ref.height);
  for (int e = 0; e < res.exposures; ++e) {
    const double c = res.range.start + double(e) * span / double(res.exposures - 1);
    const double scale = std::exp2(c);
    for (size_t i = 0; i < ref.rgb.size(); ++i) {
      ref_t.rgb[i] = float(HdrFlipToneMap(scale * double(ref.rgb[i])));
      test_t.rgb[i] = float(HdrFlipToneMap(scale * double(test.rgb[i])));
    }
    const Map m = FlipMapLinearWith(ref_t, test_t, k);
    for (size_t i = 0; i < m.values.size(); ++i) {
      if (e == 0 || m.values[i] > res.map.values[i]) {
        res.map.values[i] = m.values[i];
        res.exposure_map.values[i] = float(c);
      }
    }
  }
  ZeroNonFinite(res.map, cov);
  res.value = MeanOver(res.map, cov);
  return res;
}

}  // namespace clothfit::metrics
