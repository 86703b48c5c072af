// Image metrics (fit/metrics/metrics.h): identities, published CIEDE2000 data, hand-derived FLIP/SSIM/
// PSNR values, FLIP properties, the HDR-FLIP exposure-range rule, masks, non-finite input and
// bad input.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "fit/metrics/metrics.h"
#include "render/scene/image_io.h"

namespace clothfit::metrics {
namespace {
namespace fs = std::filesystem;

RgbImage Uniform(int w, int h, float r, float g, float b) {
  RgbImage img(w, h);
  for (size_t i = 0; i < img.pixel_count(); ++i) {
    img.rgb[3 * i] = r;
    img.rgb[3 * i + 1] = g;
    img.rgb[3 * i + 2] = b;
  }
  return img;
}

// A deterministic texture with values in [lo, hi]: smooth blobs plus a checker and a stripe,
// so that both the colour and the feature terms of FLIP see structure.
RgbImage Texture(int w, int h, float lo, float hi, unsigned seed = 1) {
  RgbImage img(w, h);
  unsigned s = seed * 2654435761u + 12345u;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) {
        s = s * 1664525u + 1013904223u;
        const double noise = double(s >> 8) / double(1u << 24);
        const double smooth = 0.5 + 0.5 * std::sin(0.37 * x + 1.3 * c) * std::cos(0.23 * y);
        const double checker = ((x / 3 + y / 3) % 2) ? 0.3 : 0.0;
        const double v = std::clamp(0.5 * smooth + 0.25 * noise + checker, 0.0, 1.0);
        img.rgb[3 * (size_t(y) * size_t(w) + size_t(x)) + size_t(c)] =
            float(double(lo) + double(hi - lo) * v);
      }
  return img;
}

RgbImage AddOffset(const RgbImage& img, float d) {
  RgbImage out = img;
  for (float& v : out.rgb) v += d;
  return out;
}

fs::path TempDir() {
  fs::path d = fs::temp_directory_path() / ("clothfit_test_metrics_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

void WriteRgbExr(const std::string& path, const RgbImage& img) {
  io::Image out;
  out.width = img.width;
  out.height = img.height;
  out.channel_names = {"R", "G", "B"};
  out.pixels = img.rgb;
  io::WriteExr(path, out);
}

// ---- CIEDE2000 ----------------------------------------------------------------------------

struct SharmaPair {
  Lab lab1, lab2;
  double de;
};

std::vector<SharmaPair> LoadSharmaPairs() {
  const fs::path path = fs::path(__FILE__).parent_path() / "data" / "ciede2000_sharma.csv";
  std::ifstream f(path);
  EXPECT_TRUE(f.good()) << path;
  std::vector<SharmaPair> pairs;
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 'L') continue;  // comments, header
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream in(line);
    SharmaPair p;
    in >> p.lab1.L >> p.lab1.a >> p.lab1.b >> p.lab2.L >> p.lab2.a >> p.lab2.b >> p.de;
    EXPECT_FALSE(in.fail()) << line;
    pairs.push_back(p);
  }
  return pairs;
}

TEST(MetricsCiede2000, SharmaWuDalalPublishedPairsToRtol1e4) {
  const std::vector<SharmaPair> pairs = LoadSharmaPairs();
  ASSERT_EQ(pairs.size(), 34u);
  EXPECT_DOUBLE_EQ(pairs[0].lab1.a, 2.6772);  // the first pair, as published
  EXPECT_DOUBLE_EQ(pairs[0].lab2.b, -82.7485);
  EXPECT_DOUBLE_EQ(pairs[0].de, 2.0425);
  for (size_t i = 0; i < pairs.size(); ++i) {
    const SharmaPair& p = pairs[i];
    EXPECT_NEAR(Ciede2000(p.lab1, p.lab2), p.de, 1e-4 * p.de) << "pair " << i + 1;
    EXPECT_NEAR(Ciede2000(p.lab2, p.lab1), p.de, 1e-4 * p.de) << "pair " << i + 1 << " swapped";
  }
}

TEST(MetricsCiede2000, IdentityAndLabOfLinearColours) {
  const Lab c{52.0, 10.0, -30.0};
  EXPECT_EQ(Ciede2000(c, c), 0.0);
  // Linear white is the white point: L* = 100, a* = b* = 0 exactly (up to rounding).
  const Lab white = LinearSrgbToLab(1, 1, 1);
  EXPECT_NEAR(white.L, 100.0, 1e-12);
  EXPECT_NEAR(white.a, 0.0, 1e-12);
  EXPECT_NEAR(white.b, 0.0, 1e-12);
  // 18% grey: Y/Yn = 0.18 -> L* = 116 * 0.18^(1/3) - 16 = 49.49611.
  EXPECT_NEAR(LinearSrgbToLab(0.18, 0.18, 0.18).L, 116.0 * std::cbrt(0.18) - 16.0, 1e-12);
  // Black; and the linear segment below (6/29)^3: f(t) = t / (3 (6/29)^2) + 4/29, so
  // L* = 116 f(Y) - 16 = 116 Y 841 / 108 = 903.30 Y.
  EXPECT_NEAR(LinearSrgbToLab(0, 0, 0).L, 0.0, 1e-12);
  EXPECT_NEAR(LinearSrgbToLab(0.001, 0.001, 0.001).L, 0.001 * 116.0 / (3.0 * 36.0 / 841.0), 1e-9);
  // Red (1, 0, 0): XYZ / white = (0.4124 / 0.9505, 0.2126, 0.0193 / 1.089) = (0.433877,
  // 0.2126, 0.017723), all above (6/29)^3, cube roots (0.757046, 0.596835, 0.260721) ->
  // L* = 116 * 0.596835 - 16 = 53.2329, a* = 500 (0.757046 - 0.596835) = 80.1053,
  // b* = 200 (0.596835 - 0.260721) = 67.2228 (the commonly quoted 53.24, 80.09, 67.20 use
  // the unrounded matrix).
  const Lab red = LinearSrgbToLab(1, 0, 0);
  EXPECT_NEAR(red.L, 53.2329, 1e-3);
  EXPECT_NEAR(red.a, 80.1053, 1e-3);
  EXPECT_NEAR(red.b, 67.2228, 1e-3);
}

TEST(MetricsCiede2000, ImageMeanAndP95OverCountedPixels) {
  // 20 pixels, test = ref with a growing grey step; the per-pixel values come from the scalar
  // formula, pooled by hand: mean, and p95 at position 0.95 * 19 = 18.05 of the sorted values.
  RgbImage ref = Uniform(5, 4, 0.2f, 0.2f, 0.2f), test = ref;
  std::vector<double> de;
  for (size_t i = 0; i < 20; ++i) {
    const float v = 0.2f + 0.01f * float(i);
    test.rgb[3 * i] = test.rgb[3 * i + 1] = test.rgb[3 * i + 2] = v;
    de.push_back(Ciede2000(LinearSrgbToLab(double(0.2f), double(0.2f), double(0.2f)),
                           LinearSrgbToLab(double(v), double(v), double(v))));
  }
  const Ciede2000Result r = Ciede2000(ref, test);
  double mean = 0;
  for (double d : de) mean += d / 20.0;
  std::sort(de.begin(), de.end());
  EXPECT_NEAR(r.value, mean, 1e-9);
  EXPECT_NEAR(r.p95, de[18] + 0.05 * (de[19] - de[18]), 1e-9);
  EXPECT_EQ(r.counts.counted, 20);
  EXPECT_NEAR(r.map.values[7],
              Ciede2000(LinearSrgbToLab(0.2, 0.2, 0.2),
                        LinearSrgbToLab(double(0.27f), double(0.27f), double(0.27f))),
              1e-5);
}

// ---- identities -----------------------------------------------------------------------------

TEST(MetricsIdentity, EveryMetricOfAnImageWithItself) {
  const RgbImage x = Texture(24, 20, 0.0f, 3.0f);  // HDR values
  CompareOptions o;
  const CompareResult r = Compare(x, x, o);
  EXPECT_EQ(r.rmse_linear, 0.0);
  EXPECT_EQ(r.rmse_display, 0.0);
  EXPECT_TRUE(std::isinf(r.psnr_linear) && r.psnr_linear > 0) << r.psnr_linear;  // not NaN
  EXPECT_TRUE(std::isinf(r.psnr_display) && r.psnr_display > 0) << r.psnr_display;
  EXPECT_NEAR(r.ssim, 1.0, 1e-12);
  EXPECT_EQ(r.flip, 0.0);
  EXPECT_EQ(r.hdr_flip, 0.0);
  EXPECT_EQ(r.ciede2000_mean, 0.0);
  EXPECT_EQ(r.ciede2000_p95, 0.0);
  EXPECT_EQ(r.ciede2000_display_mean, 0.0);
  for (const auto& m : r.maps) {
    ASSERT_EQ(m.map.values.size(), x.pixel_count()) << m.name;
    if (m.name == "ssim") {
      for (float v : m.map.values) EXPECT_NEAR(v, 1.0f, 1e-6f);
    } else if (m.name != "hdr_flip_exposure") {
      for (float v : m.map.values) EXPECT_EQ(v, 0.0f) << m.name;
    }
  }
  // LDR FLIP and SSIM directly, on display-like values.
  const RgbImage d = Texture(16, 16, 0.0f, 1.0f, 7);
  EXPECT_EQ(Flip(d, d).value, 0.0);
  EXPECT_NEAR(Ssim(d, d).value, 1.0, 1e-12);
}

// ---- RMSE / PSNR ------------------------------------------------------------------------------

TEST(MetricsPsnr, UniformDifferenceKnownValues) {
  const RgbImage a = Uniform(6, 5, 0.3f, 0.3f, 0.3f);
  const RgbImage b = Uniform(6, 5, 0.4f, 0.4f, 0.4f);
  // RMSE = |0.4 - 0.3| = 0.1; PSNR = 20 log10(peak / 0.1) = 20 dB (peak 1), 26.0206 (peak 2).
  EXPECT_NEAR(Rmse(a, b).value, 0.1, 1e-7);
  EXPECT_NEAR(Psnr(a, b, 1.0).value, 20.0, 1e-5);
  EXPECT_NEAR(Psnr(a, b, 2.0).value, 20.0 * std::log10(20.0), 1e-5);
  EXPECT_NEAR(Rmse(a, b).map.values[3], 0.1f, 1e-7f);
  EXPECT_THROW(Psnr(a, b, 0.0), std::invalid_argument);
  EXPECT_THROW(Psnr(a, b, std::numeric_limits<double>::infinity()), std::invalid_argument);
}

// ---- SSIM -------------------------------------------------------------------------------------

TEST(MetricsSsim, ConstantImagesHandDerivedValue) {
  // Constant images: every window has sigma_x = sigma_y = sigma_xy = 0, so
  // SSIM = (2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1) * (0 + C2) / (0 + C2), C1 = (0.01 L)^2.
  // With x = 0.4, y = 0.6, L = 1: (0.48 + 1e-4) / (0.52 + 1e-4) = 0.923091...
  const double expect = (2 * 0.4 * 0.6 + 1e-4) / (0.4 * 0.4 + 0.6 * 0.6 + 1e-4);
  for (int size : {8, 16}) {  // 8 < 11: no full window fits, the truncated windows are used
    const RgbImage a = Uniform(size, size, 0.4f, 0.4f, 0.4f);
    const RgbImage b = Uniform(size, size, 0.6f, 0.6f, 0.6f);
    const SsimResult r = Ssim(a, b);
    EXPECT_NEAR(r.value, expect, 1e-6) << size;
    EXPECT_EQ(r.used_border_pixels, size < 11);
    for (float v : r.map.values) EXPECT_NEAR(v, expect, 1e-6);
  }
  // An explicit data range changes C1, C2: L = 2 -> C1 = 4e-4.
  SsimOptions o;
  o.data_range = 2.0;
  EXPECT_NEAR(Ssim(Uniform(16, 16, 0.4f, 0.4f, 0.4f), Uniform(16, 16, 0.6f, 0.6f, 0.6f), o).value,
              (0.48 + 4e-4) / (0.52 + 4e-4), 1e-6);
}

TEST(MetricsSsim, SymmetricAndBelowOneForDifferentImages) {
  const RgbImage a = Texture(32, 24, 0.0f, 1.0f, 3), b = Texture(32, 24, 0.0f, 1.0f, 4);
  const double ab = Ssim(a, b).value, ba = Ssim(b, a).value;
  EXPECT_NEAR(ab, ba, 1e-12);
  EXPECT_LT(ab, 0.99);
  EXPECT_GT(ab, -1.0);
}

// ---- FLIP -------------------------------------------------------------------------------------

// Hand derivation for uniform images (every pixel the same colour):
//  * CSF filtering: each 2D kernel sums to 1 and borders replicate, so a constant image passes
//    unchanged; the clamp to [0, 1] is a no-op for in-gamut colours.
//  * Features: the edge kernel is antisymmetric and the point kernel's positive and negative
//    weights sum to +1 and -1, so both respond 0 on a constant image: e_f = 0 and
//    FLIP = e_c^(1 - 0) = e_c.
//  * Lab with the IEC 61966-2-1 matrix and white XYZ(1,1,1) = (0.9505, 1, 1.089):
//      green (0,1,0): XYZ = (0.3576, 0.7152, 0.1192) -> L* = 87.7370, a* = -86.1884,
//                     b* = 83.1861; Hunt (x 0.877370): a = -75.6192, b = 72.9851
//      blue  (0,0,1): XYZ = (0.1805, 0.0722, 0.9505) -> L* = 32.3026, a* = 79.1936,
//                     b* = -107.8537; Hunt (x 0.323026): a = 25.5816, b = -34.8395
//      HyAB = |87.7370 - 32.3026| + sqrt(101.2008^2 + 107.8246^2) = 55.4344 + 147.8775
//           = 203.3119;  cmax = 203.3119^0.7 = 41.27755;  p_c cmax = 16.51102.
//  * green vs blue: d = cmax -> e_c = 0.95 + (cmax - 0.4 cmax) / (0.6 cmax) * 0.05 = 1.
//  * black vs white: L* 0 vs 100, a* = b* = 0 -> HyAB = 100, d = 100^0.7 = 25.11886 >= 16.51102
//      -> e_c = 0.95 + (25.11886 - 16.51102) / (41.27755 - 16.51102) * 0.05 = 0.967378.
//  * sRGB grey 0.5 vs 0.6: linear ((v + 0.055)/1.055)^2.4 = 0.214041, 0.318547; L* = 116
//      Y^(1/3) - 16 = 53.38896, 63.22259; HyAB = 9.833630; d = 9.833630^0.7 = 4.953358 < 16.51102
//      -> e_c = 0.95 / 16.51102 * 4.953358 = 0.285003.
TEST(MetricsFlip, HandDerivedValuesForUniformImages) {
  EXPECT_NEAR(flip_detail::MaxColourError(), 41.27755, 1e-4);
  struct Case {
    float a[3], b[3];
    double expect;
  };
  const Case cases[] = {
      {{0, 1, 0}, {0, 0, 1}, 1.0},
      {{0, 0, 0}, {1, 1, 1}, 0.967378},
      {{0.5f, 0.5f, 0.5f}, {0.6f, 0.6f, 0.6f}, 0.285003},
      {{0.3f, 0.7f, 0.2f}, {0.3f, 0.7f, 0.2f}, 0.0},
  };
  for (const Case& c : cases) {
    const RgbImage a = Uniform(4, 3, c.a[0], c.a[1], c.a[2]);
    const RgbImage b = Uniform(4, 3, c.b[0], c.b[1], c.b[2]);
    const MetricResult r = Flip(a, b);
    EXPECT_NEAR(r.value, c.expect, 2e-6) << c.a[0] << "," << c.a[1] << " vs " << c.b[0];
    for (float v : r.map.values) EXPECT_NEAR(v, c.expect, 2e-6);
  }
}

// Hand derivation for a vertical step edge, luminance 0 for columns x <= c and 1 for x > c
// (black | white, so Y/Yn is exactly 0 or 1), at PPD 67 (sigma = 0.5 * 0.082 * 67 = 2.747 px,
// radius 9). Every row is the same, so the y-derivatives vanish and the vertical smoothing
// (Gaussian, sum 1) leaves a column unchanged. The x responses are correlations
// sum_j k(j) I(x + j):
//  * edge at x = c: sum_{j >= 1} e(j) = the whole negative lobe of the antisymmetric kernel
//    = -1, so |edge| = 1; at x = c + 1: sum_{j >= 0} e(j) = -1 as well (e(0) = 0).
//  * point at x = c: sum_{j >= 1} s(j). The kernel is symmetric with sum(s) = 1 - 1 = 0, so
//    s(0) + 2 sum_{j >= 1} s(j) = 0 and the response is -s(0) / 2; at x = c + 1 it is
//    s(0) + (-s(0) / 2) = s(0) / 2: |point| = |s(0)| / 2 on both sides.
//  * more than a radius from the step both responses are 0.
TEST(MetricsFlip, StepEdgeFeatureResponsesHandDerived) {
  const int w = 40, h = 6, c = 19;
  RgbImage step(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = c + 1; x < w; ++x)
      for (int k = 0; k < 3; ++k) step.rgb[3 * (size_t(y) * w + size_t(x)) + size_t(k)] = 1.0f;
  const flip_detail::FeatureKernels k = flip_detail::MakeFeatureKernels(67.0);
  ASSERT_EQ(k.radius, 9);
  const double s0 = k.point[size_t(k.radius)];
  EXPECT_LT(s0, 0.0);
  const flip_detail::FeatureMaps f = flip_detail::FeatureMagnitudes(step, 67.0);
  for (int y = 0; y < h; ++y) {
    for (int x : {c, c + 1}) {
      const size_t i = size_t(y) * w + size_t(x);
      EXPECT_NEAR(f.edge.values[i], 1.0, 1e-6) << x;
      EXPECT_NEAR(f.point.values[i], std::abs(s0) / 2.0, 1e-6) << x;
    }
    for (int x : {0, c - k.radius, c + 1 + k.radius, w - 1}) {
      const size_t i = size_t(y) * w + size_t(x);
      EXPECT_NEAR(f.edge.values[i], 0.0, 1e-6) << x;
      EXPECT_NEAR(f.point.values[i], 0.0, 1e-6) << x;
    }
  }
}

TEST(MetricsFlip, MonotoneInAGrowingUniformOffset) {
  const RgbImage ref = Texture(32, 32, 0.05f, 0.5f, 11);
  double previous = 0.0;
  for (float d : {0.005f, 0.01f, 0.02f, 0.05f, 0.1f, 0.2f, 0.3f, 0.45f}) {
    const double f = Flip(ref, AddOffset(ref, d)).value;
    EXPECT_GT(f, previous) << "offset " << d;
    EXPECT_LE(f, 1.0);
    previous = f;
  }
}

TEST(MetricsFlip, SymmetricColourErrorAndUnitRange) {
  const float colours[][3] = {
      {0.9f, 0.1f, 0.1f}, {0.1f, 0.8f, 0.3f}, {0.2f, 0.2f, 0.9f}, {0.5f, 0.5f, 0.5f}, {1, 1, 0}};
  for (const auto& a : colours)
    for (const auto& b : colours) {
      const RgbImage ia = Uniform(5, 5, a[0], a[1], a[2]), ib = Uniform(5, 5, b[0], b[1], b[2]);
      EXPECT_NEAR(Flip(ia, ib).value, Flip(ib, ia).value, 1e-7);
    }
  const RgbImage x = Texture(24, 24, 0.0f, 1.0f, 5), y = Texture(24, 24, 0.0f, 1.0f, 6);
  const MetricResult xy = Flip(x, y), yx = Flip(y, x);
  EXPECT_NEAR(xy.value, yx.value, 1e-7);
  for (size_t i = 0; i < xy.map.values.size(); ++i) {
    EXPECT_NEAR(xy.map.values[i], yx.map.values[i], 1e-6);
    EXPECT_GE(xy.map.values[i], 0.0f);
    EXPECT_LE(xy.map.values[i], 1.0f);
  }
}

TEST(MetricsFlip, PixelsPerDegreeOfThePaperSetup) {
  // 0.7 m from a 0.7 m wide, 3840 px monitor: 3840 * pi / 180 = 67.0206.
  EXPECT_NEAR(PixelsPerDegree(0.7, 0.7, 3840), 67.0206, 1e-4);
  EXPECT_THROW(Flip(Uniform(4, 4, 0, 0, 0), Uniform(4, 4, 1, 1, 1), FlipOptions{0.0}),
               std::invalid_argument);
}

// ---- HDR-FLIP ---------------------------------------------------------------------------------

TEST(MetricsHdrFlip, AutomaticRangeIsThePaperFormula) {
  // t(x) = 0.85: (0.9036 - 0.85 * 0.8748) x^2 + (0.018 - 0.85 * 0.354) x - 0.85 * 0.14 = 0
  //   0.16002 x^2 - 0.2829 x - 0.119 = 0 -> x_max = (0.2829 + sqrt(0.2829^2 + 4 * 0.16002 *
  //   0.119)) / (2 * 0.16002) = 2.118872.
  // A uniform reference of luminance Y: start = stop = log2(2.118872 / Y).
  EXPECT_NEAR(HdrFlipToneMap(2.118872), 0.85, 1e-6);
  const ExposureRange r = AutomaticExposureRange(Uniform(4, 4, 0.5f, 0.5f, 0.5f));
  EXPECT_NEAR(r.start, std::log2(2.118872 / 0.5), 1e-5);
  EXPECT_NEAR(r.stop, std::log2(2.118872 / 0.5), 1e-5);
  // Max luminance 6 and median 0.5 (4 bright pixels out of 16): a span of log2(12) = 3.585
  // stops, so N = max(2, ceil(3.585)) = 4 exposures.
  RgbImage img = Uniform(4, 4, 0.5f, 0.5f, 0.5f);
  for (size_t i = 0; i < 4; ++i) img.rgb[3 * i] = img.rgb[3 * i + 1] = img.rgb[3 * i + 2] = 6.0f;
  const ExposureRange r2 = AutomaticExposureRange(img);
  EXPECT_NEAR(r2.start, std::log2(2.118872 / 6.0), 1e-5);
  EXPECT_NEAR(r2.stop, std::log2(2.118872 / 0.5), 1e-5);
  const HdrFlipResult h = HdrFlip(img, AddOffset(img, 0.1f));
  EXPECT_TRUE(h.automatic_range);
  EXPECT_EQ(h.exposures, 4);
  EXPECT_NEAR(h.range.start, r2.start, 1e-12);
  // Even count: the median is the mean of the two middle values (numpy's 50th percentile, as
  // in the FLIP reference implementation): 8 pixels at 0.25 and 8 at 1 give a median of 0.625.
  RgbImage half = Uniform(4, 4, 1.0f, 1.0f, 1.0f);
  for (size_t i = 0; i < 8; ++i) half.rgb[3 * i] = half.rgb[3 * i + 1] = half.rgb[3 * i + 2] = 0.25f;
  EXPECT_NEAR(AutomaticExposureRange(half).stop, std::log2(2.118872 / 0.625), 1e-5);
}

TEST(MetricsHdrFlip, NegativeRadianceIsClippedBeforeToneMapping) {
  // The rational fit alone would give t(-10) = (90.36 - 0.18) / (87.48 - 3.54 + 0.14) = 1.07,
  // i.e. white; the reference implementation clips inputs to 0 first.
  EXPECT_EQ(HdrFlipToneMap(-10.0), 0.0);
  EXPECT_EQ(HdrFlipToneMap(-1e-3), 0.0);
  EXPECT_EQ(HdrFlipToneMap(0.0), 0.0);
}

TEST(MetricsHdrFlip, ZeroMedianReferenceUsesTheExplicitRangeAndStaysFinite) {
  // A black background covering 75% of the reference: median luminance 0, so the automatic
  // stop exposure log2(x_max / 0) is infinite.
  RgbImage ref(16, 16);
  for (int y = 4; y < 8; ++y)
    for (int x = 0; x < 16; ++x)
      for (int c = 0; c < 3; ++c) ref.rgb[3 * (size_t(y) * 16 + size_t(x)) + size_t(c)] = 4.0f;
  const RgbImage test = AddOffset(ref, 0.05f);
  const ExposureRange automatic = AutomaticExposureRange(ref);
  EXPECT_TRUE(std::isfinite(automatic.start));
  EXPECT_TRUE(std::isinf(automatic.stop));
  EXPECT_THROW(HdrFlip(ref, test), std::invalid_argument);  // never a silent NaN

  HdrFlipOptions o;
  o.range = ExposureRange{-3.0, 2.0};
  const HdrFlipResult r = HdrFlip(ref, test, o);
  EXPECT_FALSE(r.automatic_range);
  EXPECT_EQ(r.range.start, -3.0);  // the caller's range, untouched
  EXPECT_EQ(r.range.stop, 2.0);
  EXPECT_EQ(r.exposures, 5);
  EXPECT_TRUE(std::isfinite(r.value));
  EXPECT_GT(r.value, 0.0);
  EXPECT_LE(r.value, 1.0);
  for (float v : r.map.values) ASSERT_TRUE(std::isfinite(v) && v >= 0.0f && v <= 1.0f);
  for (float e : r.exposure_map.values) EXPECT_TRUE(e >= -3.0f && e <= 2.0f);
  // The same range for a second test image against the same reference.
  const HdrFlipResult r2 = HdrFlip(ref, AddOffset(ref, 0.2f), o);
  EXPECT_EQ(r2.range.start, -3.0);
  EXPECT_GT(r2.value, r.value);

  CompareOptions co;
  co.hdr_range = o.range;
  const CompareResult cr = Compare(ref, test, co);
  EXPECT_EQ(cr.hdr_flip, r.value);
  EXPECT_FALSE(cr.hdr_range_automatic);
}

TEST(MetricsHdrFlip, ExplicitRangeIsUsedEvenWhenAutomaticWouldWork) {
  const RgbImage ref = Texture(16, 16, 0.1f, 4.0f, 2);
  HdrFlipOptions o;
  o.range = ExposureRange{0.0, 0.0};  // N = 2 exposures, both at 0 stops
  const HdrFlipResult r = HdrFlip(ref, AddOffset(ref, 0.3f), o);
  EXPECT_EQ(r.range.start, 0.0);
  EXPECT_EQ(r.range.stop, 0.0);
  EXPECT_EQ(r.exposures, 2);
  // At exposure 0 HDR-FLIP is LDR-FLIP of the tone-mapped linear images.
  RgbImage tr = ref, tt = AddOffset(ref, 0.3f);
  for (float& v : tr.rgb) v = float(HdrFlipToneMap(double(v)));
  for (float& v : tt.rgb) v = float(HdrFlipToneMap(double(v)));
  const Map ldr = flip_detail::FlipMapLinear(tr, tt, 67.0);
  for (size_t i = 0; i < ldr.values.size(); ++i) EXPECT_FLOAT_EQ(r.map.values[i], ldr.values[i]);
  EXPECT_EQ(HdrFlip(ref, ref, o).value, 0.0);
  o.range = ExposureRange{1.0, -1.0};
  EXPECT_THROW(HdrFlip(ref, ref, o), std::invalid_argument);
  o.range = ExposureRange{0.0, std::numeric_limits<double>::infinity()};
  EXPECT_THROW(HdrFlip(ref, ref, o), std::invalid_argument);
}

// ---- masks and non-finite input ----------------------------------------------------------------

TEST(MetricsMask, PixelsOutsideTheMaskDoNotCountButMapsStayFullSize) {
  const RgbImage ref = Texture(16, 16, 0.1f, 0.9f, 8);
  RgbImage test = ref;
  Map mask(16, 16, 1.0f);
  for (int y = 0; y < 16; ++y)
    for (int x = 12; x < 16; ++x) {
      mask.values[size_t(y) * 16 + size_t(x)] = 0.25f;  // <= 0.5: out
      test.rgb[3 * (size_t(y) * 16 + size_t(x))] += 0.5f;
    }
  const MetricResult p = Psnr(ref, test, 1.0, &mask);
  EXPECT_TRUE(std::isinf(p.value));
  EXPECT_EQ(p.counts.counted, 16 * 12);
  EXPECT_EQ(p.counts.masked_out, 16 * 4);
  EXPECT_GT(p.map.values[15], 0.0f);  // the map still shows the masked-out difference
  EXPECT_EQ(Ciede2000(ref, test, &mask).value, 0.0);
  EXPECT_GT(Ciede2000(ref, test).value, 0.0);
  const Map wrong_size(8, 8, 1.0f);
  EXPECT_THROW(Rmse(ref, test, &wrong_size), std::invalid_argument);
  const Map none(16, 16, 0.0f);
  EXPECT_THROW(Rmse(ref, test, &none), std::invalid_argument);
}

TEST(MetricsNonFinite, ReportedExcludedAndNeverPropagated) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const RgbImage ref0 = Texture(20, 20, 0.0f, 2.0f, 9);
  RgbImage ref = ref0, test = AddOffset(ref0, 0.05f);
  ref.rgb[3 * 5 + 1] = nan;
  ref.rgb[3 * 50] = inf;
  test.rgb[3 * 77 + 2] = -inf;
  test.rgb[3 * 5] = nan;  // the same pixel as a reference NaN
  const CompareResult r = Compare(ref, test);
  EXPECT_EQ(r.counts.nonfinite_ref, 2);
  EXPECT_EQ(r.counts.nonfinite_test, 2);
  EXPECT_EQ(r.counts.counted, 400 - 3);
  for (double v : {r.rmse_linear, r.psnr_linear, r.rmse_display, r.psnr_display, r.ssim, r.flip,
                   r.hdr_flip, r.ciede2000_mean, r.ciede2000_p95, r.ciede2000_display_mean})
    EXPECT_TRUE(std::isfinite(v)) << v;
  for (const auto& m : r.maps) {
    for (float v : m.map.values) ASSERT_TRUE(std::isfinite(v)) << m.name;
    if (m.name == "hdr_flip_exposure") continue;
    for (size_t i : {size_t(5), size_t(50), size_t(77)}) {
      EXPECT_EQ(m.map.values[i], 0.0f) << m.name;
    }
  }
  // Pooled per-pixel metrics equal those with the bad pixels masked out of clean images.
  Map mask(20, 20, 1.0f);
  mask.values[5] = mask.values[50] = mask.values[77] = 0.0f;
  const RgbImage test0 = AddOffset(ref0, 0.05f);
  EXPECT_NEAR(r.rmse_linear, Rmse(ref0, test0, &mask).value, 1e-12);
  EXPECT_NEAR(r.ciede2000_mean, Ciede2000(ref0, test0, &mask).value, 1e-12);
  // Nothing finite left: an error, not NaN.
  EXPECT_THROW(Rmse(Uniform(2, 2, nan, 0, 0), Uniform(2, 2, 0, 0, 0)), std::invalid_argument);
}

// ---- bad input ----------------------------------------------------------------------------------

TEST(MetricsBadInput, SizeMismatchMissingFileAndCorruptExrNameTheFile) {
  const fs::path dir = TempDir();
  const std::string a = (dir / "a.exr").string(), b = (dir / "b.exr").string(),
                    small = (dir / "small.exr").string(), junk = (dir / "junk.exr").string();
  WriteRgbExr(a, Texture(8, 6, 0.0f, 1.0f, 1));
  WriteRgbExr(b, Texture(8, 6, 0.0f, 1.0f, 2));
  WriteRgbExr(small, Texture(4, 4, 0.0f, 1.0f, 3));
  {
    std::ofstream f(junk, std::ios::binary);
    f << "v/1\x01 this is not an EXR file";
  }
  auto message = [](auto&& fn) -> std::string {
    try {
      fn();
    } catch (const std::exception& e) {
      return e.what();
    }
    return "(no error)";
  };
  const std::string mismatch = message([&] { CompareFiles(a, small, ""); });
  EXPECT_NE(mismatch.find(a), std::string::npos) << mismatch;
  EXPECT_NE(mismatch.find(small), std::string::npos) << mismatch;
  EXPECT_NE(mismatch.find("8x6"), std::string::npos) << mismatch;
  EXPECT_THROW(CompareFiles(a, small, ""), std::invalid_argument);

  const std::string missing = (dir / "missing.exr").string();
  EXPECT_THROW(CompareFiles(missing, b, ""), io::IoError);
  EXPECT_NE(message([&] { CompareFiles(a, missing, ""); }).find(missing), std::string::npos);
  EXPECT_THROW(CompareFiles(a, junk, ""), io::IoError);
  EXPECT_NE(message([&] { CompareFiles(junk, b, ""); }).find(junk), std::string::npos);
  const std::string mask_msg = message([&] { CompareFiles(a, b, small); });
  EXPECT_NE(mask_msg.find(small), std::string::npos) << mask_msg;

  const CompareResult ok = CompareFiles(a, b, "");
  EXPECT_EQ(ok.width, 8);
  EXPECT_GT(ok.flip, 0.0);
  // In memory: a size mismatch names both sizes.
  const std::string mem = message([&] { Compare(Uniform(3, 2, 0, 0, 0), Uniform(2, 3, 0, 0, 0)); });
  EXPECT_NE(mem.find("3x2"), std::string::npos) << mem;
  EXPECT_NE(mem.find("2x3"), std::string::npos) << mem;
  fs::remove_all(dir);
}

TEST(MetricsCompare, ChannelLayoutsAndDisplayTransform) {
  io::Image grey;
  grey.width = 2;
  grey.height = 1;
  grey.channel_names = {"Y"};
  grey.pixels = {0.25f, 0.5f};
  const RgbImage g = ToRgb(grey, "grey.exr");
  EXPECT_EQ(g.rgb, (std::vector<float>{0.25f, 0.25f, 0.25f, 0.5f, 0.5f, 0.5f}));
  io::Image bgra = grey;
  bgra.channel_names = {"B", "G", "R", "A"};
  bgra.pixels = {3, 2, 1, 9, 6, 5, 4, 9};
  EXPECT_EQ(ToRgb(bgra, "x").rgb, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  io::Image two = grey;
  two.channel_names = {"U", "V"};
  two.pixels = {0, 0, 0, 0};
  try {
    ToRgb(two, "uv.exr");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("uv.exr"), std::string::npos);
  }
  // Display values are render::ToDisplay: ACES at exposure 1 of linear 0.18 grey.
  const RgbImage d =
      ToDisplay(Uniform(1, 1, 0.18f, 0.18f, 0.18f), render::ToneMapping::kAcesFilmic, 1.0);
  const Rgb<double> expect =
      render::ToDisplay(Rgb<double>(double(0.18f), double(0.18f), double(0.18f)),
                        render::ToneMapping::kAcesFilmic, 1.0);
  EXPECT_NEAR(d.rgb[0], expect.r, 1e-6);
}

}  // namespace
}  // namespace clothfit::metrics
