// fit/metrics/metrics_common.cpp: colour spaces, coverage and separable filtering shared by the metric families; image conversions; the error-map colour ramp
// (fit/metrics/metrics.h documents every formula and choice).
#include "fit/metrics/metrics.h"
#include "fit/metrics/metrics_internal.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace clothfit::metrics {
namespace internal {

const Mat3& XyzToRgb() {
  static const Mat3 inv = [] {
    const auto& m = kRgbToXyz;
    Mat3 r{};
    r[0][0] = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    r[0][1] = m[0][2] * m[2][1] - m[0][1] * m[2][2];
    r[0][2] = m[0][1] * m[1][2] - m[0][2] * m[1][1];
    r[1][0] = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    r[1][1] = m[0][0] * m[2][2] - m[0][2] * m[2][0];
    r[1][2] = m[0][2] * m[1][0] - m[0][0] * m[1][2];
    r[2][0] = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    r[2][1] = m[0][1] * m[2][0] - m[0][0] * m[2][1];
    r[2][2] = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    const double det = m[0][0] * r[0][0] + m[0][1] * r[1][0] + m[0][2] * r[2][0];
    for (auto& row : r)
      for (double& v : row) v /= det;
    return r;
  }();
  return inv;
}

// CIELAB f(t): cube root above (6/29)^3, the linear segment below (also for t < 0).
double LabF(double t) {
  constexpr double d = 6.0 / 29.0;
  return t > d * d * d ? std::cbrt(t) : t / (3.0 * d * d) + 4.0 / 29.0;
}

Lab XyzToLab(double x, double y, double z) {
  const double fx = LabF(x / kWhite[0]), fy = LabF(y / kWhite[1]), fz = LabF(z / kWhite[2]);
  return {116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)};
}

double Luminance(const float* p) {
  return kRgbToXyz[1][0] * double(p[0]) + kRgbToXyz[1][1] * double(p[1]) +
         kRgbToXyz[1][2] * double(p[2]);
}

bool Finite3(const float* p) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

// ---- coverage ---------------------------------------------------------------------------------

std::string SizeText(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

void CheckSameSize(const RgbImage& ref, const RgbImage& test, const Map* mask,
                   const std::string& metric) {
  if (ref.width <= 0 || ref.height <= 0)
    throw std::invalid_argument(metric + ": empty reference image");
  if (ref.rgb.size() != 3 * ref.pixel_count() || test.rgb.size() != 3 * test.pixel_count())
    throw std::invalid_argument(metric + ": image buffer size does not match its dimensions");
  if (ref.width != test.width || ref.height != test.height)
    throw std::invalid_argument(metric + ": size mismatch: reference is " +
                                SizeText(ref.width, ref.height) + ", test is " +
                                SizeText(test.width, test.height));
  if (mask && (mask->width != ref.width || mask->height != ref.height ||
               mask->values.size() != ref.pixel_count()))
    throw std::invalid_argument(metric + ": size mismatch: mask is " +
                                SizeText(mask->width, mask->height) + ", images are " +
                                SizeText(ref.width, ref.height));
}

Coverage Cover(const RgbImage& ref, const RgbImage& test, const Map* mask,
               const std::string& metric) {
  CheckSameSize(ref, test, mask, metric);
  const size_t n = ref.pixel_count();
  Coverage c;
  c.counted.assign(n, 0);
  c.finite.assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    const bool fr = Finite3(&ref.rgb[3 * i]), ft = Finite3(&test.rgb[3 * i]);
    c.counts.nonfinite_ref += fr ? 0 : 1;
    c.counts.nonfinite_test += ft ? 0 : 1;
    c.finite[i] = (fr && ft) ? 1 : 0;
    const bool in_mask = !mask || mask->values[i] > 0.5f;  // NaN mask values: out
    c.counts.masked_out += in_mask ? 0 : 1;
    c.counted[i] = (in_mask && fr && ft) ? 1 : 0;
    c.counts.counted += c.counted[i];
  }
  if (c.counts.counted == 0)
    throw std::invalid_argument(
        metric +
        ": no pixel to pool (the mask selects none, or every selected pixel has a "
        "non-finite value in the reference or the test image)");
  return c;
}

// A copy with every channel of non-finite pixels set to 0 (for filtering).
RgbImage Sanitized(const RgbImage& img, const Coverage& cov) {
  RgbImage out = img;
  for (size_t i = 0; i < out.pixel_count(); ++i)
    if (!cov.finite[i]) out.rgb[3 * i] = out.rgb[3 * i + 1] = out.rgb[3 * i + 2] = 0.0f;
  return out;
}

double MeanOver(const Map& map, const Coverage& cov) {
  double sum = 0.0;
  for (size_t i = 0; i < map.values.size(); ++i)
    if (cov.counted[i]) sum += double(map.values[i]);
  return sum / double(cov.counts.counted);
}

void ZeroNonFinite(Map& map, const Coverage& cov) {
  for (size_t i = 0; i < map.values.size(); ++i)
    if (!cov.finite[i]) map.values[i] = 0.0f;
}

// ---- separable filtering ------------------------------------------------------------------
// Plane: a double image, row-major. Kernels are correlations: out(x) = sum_k k[k] in(x + k - r).

Plane FilterRows(const Plane& in, int w, int h, const std::vector<double>& k, Border border) {
  Plane out(in.size(), 0.0);
  const int r = int(k.size() / 2);
  tbb::parallel_for(0, h, [&](int y) {
    const double* row = &in[size_t(y) * size_t(w)];
    double* o = &out[size_t(y) * size_t(w)];
    for (int x = 0; x < w; ++x) {
      double s = 0.0;
      for (int j = -r; j <= r; ++j) {
        int xx = x + j;
        if (xx < 0 || xx >= w) {
          if (border == Border::kZero) continue;
          xx = std::clamp(xx, 0, w - 1);
        }
        s += k[size_t(j + r)] * row[xx];
      }
      o[x] = s;
    }
  });
  return out;
}

Plane FilterCols(const Plane& in, int w, int h, const std::vector<double>& k, Border border) {
  Plane out(in.size(), 0.0);
  const int r = int(k.size() / 2);
  tbb::parallel_for(0, h, [&](int y) {
    double* o = &out[size_t(y) * size_t(w)];
    for (int j = -r; j <= r; ++j) {
      int yy = y + j;
      if (yy < 0 || yy >= h) {
        if (border == Border::kZero) continue;
        yy = std::clamp(yy, 0, h - 1);
      }
      const double kj = k[size_t(j + r)];
      const double* row = &in[size_t(yy) * size_t(w)];
      for (int x = 0; x < w; ++x) o[x] += kj * row[x];
    }
  });
  return out;
}

Plane Filter2(const Plane& in, int w, int h, const std::vector<double>& kx,
              const std::vector<double>& ky, Border border) {
  return FilterCols(FilterRows(in, w, h, kx, border), w, h, ky, border);
}

// exp(-x^2 / (2 sigma^2)) sampled at integer offsets -r..r, normalised to sum 1.
std::vector<double> GaussianKernel(double sigma, int r) {
  std::vector<double> k(size_t(2 * r + 1));
  double sum = 0.0;
  for (int i = -r; i <= r; ++i) {
    k[size_t(i + r)] = std::exp(-double(i * i) / (2.0 * sigma * sigma));
    sum += k[size_t(i + r)];
  }
  for (double& v : k) v /= sum;
  return k;
}

}  // namespace internal

using namespace internal;

// ---- public: conversions --------------------------------------------------------------------

RgbImage ToRgb(const io::Image& image, const std::string& what) {
  const int nc = image.channels();
  const size_t n = size_t(image.width) * size_t(image.height);
  if (image.width <= 0 || image.height <= 0) throw std::invalid_argument(what + ": empty image");
  if (image.pixels.size() != n * size_t(nc))
    throw std::invalid_argument(what + ": pixel buffer does not match the image size");
  std::array<int, 3> idx = {-1, -1, -1};
  for (int c = 0; c < nc; ++c) {
    const std::string& name = image.channel_names[size_t(c)];
    if (name == "R") idx[0] = c;
    if (name == "G") idx[1] = c;
    if (name == "B") idx[2] = c;
  }
  if (idx[0] < 0 || idx[1] < 0 || idx[2] < 0) {
    if (nc == 1) {
      idx = {0, 0, 0};
    } else if (nc >= 3) {
      idx = {0, 1, 2};
    } else {
      throw std::invalid_argument(what + ": expected R, G, B channels (or 1 grey channel), got " +
                                  std::to_string(nc) + " channels");
    }
  }
  RgbImage out(image.width, image.height);
  for (size_t i = 0; i < n; ++i)
    for (size_t c = 0; c < 3; ++c)
      out.rgb[3 * i + c] = image.pixels[i * size_t(nc) + size_t(idx[c])];
  return out;
}

Map ToMask(const io::Image& image, const std::string& what) {
  const int nc = image.channels();
  const size_t n = size_t(image.width) * size_t(image.height);
  if (image.width <= 0 || image.height <= 0 || nc <= 0)
    throw std::invalid_argument(what + ": empty mask image");
  if (image.pixels.size() != n * size_t(nc))
    throw std::invalid_argument(what + ": pixel buffer does not match the image size");
  int ch = 0;
  bool found = false;
  for (const char* want : {"Y", "R"}) {
    for (int c = 0; c < nc && !found; ++c)
      if (image.channel_names[size_t(c)] == want) ch = c, found = true;
    if (found) break;
  }
  Map m(image.width, image.height);
  for (size_t i = 0; i < n; ++i) m.values[i] = image.pixels[i * size_t(nc) + size_t(ch)];
  return m;
}

RgbImage ToDisplay(const RgbImage& linear, render::ToneMapping op, double exposure) {
  RgbImage out(linear.width, linear.height);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (size_t i = 0; i < linear.pixel_count(); ++i) {
    const float* p = &linear.rgb[3 * i];
    float* o = &out.rgb[3 * i];
    if (!Finite3(p)) {  // stays non-finite, so the metrics exclude it
      o[0] = o[1] = o[2] = nan;
      continue;
    }
    const Rgb<double> d =
        render::ToDisplay(Rgb<double>(double(p[0]), double(p[1]), double(p[2])), op, exposure);
    for (int c = 0; c < 3; ++c) o[c] = float(d[c]);
  }
  return out;
}

io::Image MapToImage(const Map& map) {
  io::Image img;
  img.width = map.width;
  img.height = map.height;
  img.channel_names = {"Y"};
  img.pixels = map.values;
  return img;
}

std::array<float, 3> ErrorMapColour(double t) {
  static constexpr float kStops[5][3] = {{0.00f, 0.00f, 0.00f},
                                         {0.10f, 0.10f, 0.60f},
                                         {0.75f, 0.15f, 0.55f},
                                         {1.00f, 0.55f, 0.05f},
                                         {1.00f, 1.00f, 0.85f}};
  if (!std::isfinite(t)) t = 0.0;
  const double x = std::clamp(t, 0.0, 1.0) * 4.0;
  const int i = std::min(3, int(x));
  const float f = float(x - double(i));
  std::array<float, 3> c{};
  for (size_t k = 0; k < 3; ++k) c[k] = kStops[i][k] + f * (kStops[i + 1][k] - kStops[i][k]);
  return c;
}


}  // namespace clothfit::metrics
