// fit/metrics.cpp: image error metrics (fit/metrics.h documents every formula and choice).
#include "fit/metrics.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

namespace clothfit::metrics {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInf = std::numeric_limits<double>::infinity();

// ---- colour spaces ----------------------------------------------------------------------------

// Linear sRGB -> XYZ, IEC 61966-2-1 (4-digit values). Row sums = the white point.
constexpr double kRgbToXyz[3][3] = {
    {0.4124, 0.3576, 0.1805}, {0.2126, 0.7152, 0.0722}, {0.0193, 0.1192, 0.9505}};
constexpr double kWhite[3] = {0.4124 + 0.3576 + 0.1805, 0.2126 + 0.7152 + 0.0722,
                              0.0193 + 0.1192 + 0.9505};

using Mat3 = std::array<std::array<double, 3>, 3>;

// The exact inverse of kRgbToXyz (adjugate / determinant), computed once.
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

struct Coverage {
  std::vector<unsigned char> counted;  // per pixel
  std::vector<unsigned char> finite;   // per pixel: both images finite
  PixelCounts counts;
};

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

using Plane = std::vector<double>;

enum class Border { kClamp, kZero };

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
    const Rgb<double> d = render::ToDisplay(Rgb<double>(p[0], p[1], p[2]), op, exposure);
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
        Ciede2000(LinearSrgbToLab(a[0], a[1], a[2]), LinearSrgbToLab(b[0], b[1], b[2]));
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
  HdrFlipResult hf = HdrFlip(ref, test, HdrFlipOptions{o.ppd, o.hdr_range}, mask);
  res.hdr_flip = hf.value;
  res.hdr_range = hf.range;
  res.hdr_range_automatic = hf.automatic_range;
  res.hdr_exposures = hf.exposures;
  Ciede2000Result de = Ciede2000(ref, test, mask);
  res.ciede2000_mean = de.value;
  res.ciede2000_p95 = de.p95;
  // The displayed colour as linear light: sRGB-decode the display values.
  RgbImage ref_dl = ref_d, test_dl = test_d;
  for (float& v : ref_dl.rgb) v = std::isfinite(v) ? float(flip_detail::SrgbToLinear(v)) : v;
  for (float& v : test_dl.rgb) v = std::isfinite(v) ? float(flip_detail::SrgbToLinear(v)) : v;
  Ciede2000Result ded = Ciede2000(ref_dl, test_dl, mask);
  res.ciede2000_display_mean = ded.value;
  res.ciede2000_display_p95 = ded.p95;

  res.maps.push_back({"rmse_linear", std::move(rl.map)});
  res.maps.push_back({"rmse_display", std::move(rd.map)});
  res.maps.push_back({"ssim", std::move(s.map)});
  res.maps.push_back({"flip", std::move(f.map)});
  res.maps.push_back({"hdr_flip", std::move(hf.map)});
  res.maps.push_back({"hdr_flip_exposure", std::move(hf.exposure_map)});
  res.maps.push_back({"ciede2000", std::move(de.map)});
  res.maps.push_back({"ciede2000_display", std::move(ded.map)});
  return res;
}

CompareResult CompareFiles(const std::string& reference_path, const std::string& test_path,
                           const std::string& mask_path, const CompareOptions& options) {
  const RgbImage ref = ToRgb(io::ReadImage(reference_path), reference_path);
  const RgbImage test = ToRgb(io::ReadImage(test_path), test_path);
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
