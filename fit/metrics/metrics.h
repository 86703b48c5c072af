// fit/metrics/metrics.h: image error metrics between a reference and a test image, each with a
// per-pixel error map. Our own implementations from the papers (no third-party code):
//
//   RMSE / PSNR      on linear values or on display values (see "Display values")
//   SSIM             Wang, Bovik, Sheikh & Simoncelli 2004, "Image quality assessment: from
//                    error visibility to structural similarity", IEEE TIP 13(4)
//   FLIP (LDR)       Andersson, Nilsson, Akenine-Moller, Oskarsson, Astrom & Fairchild 2020,
//                    "FLIP: A Difference Evaluator for Alternating Images", Proc. ACM CGIT 3(2)
//   HDR-FLIP         Andersson, Nilsson, Shirley & Akenine-Moller 2021, "Visualizing Errors in
//                    Rendered High Dynamic Range Images", Eurographics short papers
//   CIEDE2000        Sharma, Wu & Dalal 2005, "The CIEDE2000 color-difference formula:
//                    implementation notes, supplementary test data, and mathematical
//                    observations", Color Res. Appl. 30(1) (the formula as their eqs. 1-23)
//
// Conventions shared by every metric (docs/metrics.md is the long form):
//
// * Images are 3-channel RGB (RgbImage), row-major, top row first. Linear images are linear
//   sRGB / Rec.709 radiance (the references and renders). "Display" images are what the preview
//   shows: render::ToDisplay(c, tone_mapping, exposure), i.e. three.js tone mapping, clamp,
//   sRGB encoding (IEC 61966-2-1), values in [0, 1].
// * The first argument is the reference, the second the test image. Sizes must match
//   (std::invalid_argument naming both sizes otherwise).
// * Mask: optional, same size; a pixel counts when mask > 0.5. Error maps are always full size
//   (masked-out pixels get their value computed as usual), only the pooled numbers use the mask.
// * Non-finite input: a pixel with a NaN or +-Inf channel in either image is excluded from every
//   pooled number, reported in PixelCounts, and its map value is 0. Inside filters (SSIM, FLIP)
//   such pixels are replaced by 0 (FLIP; see Flip) or dropped from the window (SSIM), so no NaN
//   reaches any result. If no pixel counts, the functions throw std::invalid_argument (there is
//   no meaningful mean of nothing, and NaN is never returned).
// * Colour space chain for Lab (CIEDE2000, FLIP): linear sRGB -> XYZ with the IEC 61966-2-1
//   matrix (4-digit values) -> CIELAB with the white point M (1, 1, 1) = (0.9505, 1, 1.089)
//   (D65 as that matrix encodes it, so linear white is exactly L* = 100, a* = b* = 0).
#pragma once

#include <array>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "render/scene/image_io.h"
#include "render/scene/tonemap.h"

namespace clothfit::metrics {

// A 3-channel float image, interleaved RGB.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<float> rgb;  // size 3 * width * height

  RgbImage() = default;
  RgbImage(int w, int h, float fill = 0.0f)
      : width(w), height(h), rgb(size_t(3) * size_t(w) * size_t(h), fill) {}
  size_t pixel_count() const { return size_t(width) * size_t(height); }
};

// A single-channel float image (error map or mask).
struct Map {
  int width = 0, height = 0;
  std::vector<float> values;  // size width * height

  Map() = default;
  Map(int w, int h, float fill = 0.0f) : width(w), height(h), values(size_t(w) * size_t(h), fill) {}
};

// RGB from an io::Image: channels named R, G, B (any order, extra channels such as A are
// ignored); otherwise a single channel is replicated to grey; otherwise the first three
// channels. Throws std::invalid_argument naming `what` (e.g. the file) for 2 channels or none.
RgbImage ToRgb(const io::Image& image, const std::string& what);
// A mask from an io::Image: the channel named "Y", else "R", else the first channel.
Map ToMask(const io::Image& image, const std::string& what);
// Display values: render::ToDisplay per pixel (tone mapping, clamp to [0, 1], sRGB encoding).
// A pixel with a non-finite channel becomes NaN in all three, so the metrics still exclude it.
RgbImage ToDisplay(const RgbImage& linear, render::ToneMapping op, double exposure);
// A single-channel map as an io::Image (channel "Y") for io::WriteExr.
io::Image MapToImage(const Map& map);

// How many pixels entered the pooled numbers, and why others did not.
struct PixelCounts {
  long long counted = 0;         // inside the mask and finite in both images
  long long masked_out = 0;      // mask <= 0.5
  long long nonfinite_ref = 0;   // pixels with a NaN/Inf channel in the reference (anywhere)
  long long nonfinite_test = 0;  // ... in the test image
};

// A pooled number and its per-pixel map.
struct MetricResult {
  double value = 0.0;
  Map map;
  PixelCounts counts;
};

// ---- RMSE and PSNR -----------------------------------------------------------------------
// RMSE = sqrt(mean over counted pixels and the 3 channels of (ref - test)^2).
// Map: per-pixel root mean square over the 3 channels, sqrt(sum_c (ref_c - test_c)^2 / 3).
MetricResult Rmse(const RgbImage& ref, const RgbImage& test, const Map* mask = nullptr);
// PSNR = 20 log10(peak / RMSE) dB with an explicit peak (> 0; display values: 1; linear
// values: whatever the caller declares as the peak, never derived from the data). Identical
// images give +infinity (never NaN). Map: the same per-pixel RMS map as Rmse.
MetricResult Psnr(const RgbImage& ref, const RgbImage& test, double peak,
                  const Map* mask = nullptr);

// ---- SSIM (Wang et al. 2004) -----------------------------------------------------------------
// Per channel on display values, then the three SSIM maps are averaged (a per-pixel mean of
// SSIM_R, SSIM_G, SSIM_B; not on luma). Local statistics use an 11 x 11 Gaussian window,
// sigma 1.5, normalised to sum 1, as population (weighted, no Bessel correction) moments:
//   mu_x = w*x, sigma_x^2 = w*(x^2) - mu_x^2, sigma_xy = w*(x y) - mu_x mu_y,
//   SSIM = (2 mu_x mu_y + C1)(2 sigma_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(sigma_x^2 +
//          sigma_y^2 + C2)),  C1 = (K1 L)^2, C2 = (K2 L)^2, K1 = 0.01, K2 = 0.03,
// with L = data_range given explicitly (1 for display values).
// Borders: the window is truncated at the image edge and renormalised (pixels outside the
// image, and pixels with non-finite values, have weight 0), so the map is defined everywhere.
// The pooled mean, as in Wang's reference code ("valid" filtering), uses only counted pixels
// whose full 11 x 11 window lies inside the image; when the image is smaller than 11 pixels
// in a direction no pixel qualifies, and the mean then uses every counted pixel with the
// truncated windows (used_border_pixels = true).
struct SsimOptions {
  double data_range = 1.0;  // L
  double k1 = 0.01, k2 = 0.03;
  double sigma = 1.5;
  int taps = 11;
};
struct SsimResult : MetricResult {
  bool used_border_pixels = false;
};
SsimResult Ssim(const RgbImage& ref_display, const RgbImage& test_display,
                const SsimOptions& options = {}, const Map* mask = nullptr);

// ---- FLIP (Andersson et al. 2020) ------------------------------------------------------------
// LDR-FLIP of sRGB-encoded display images (values in [0, 1]; clamped on input). Per pixel:
//  1. sRGB -> linear -> XYZ -> YCxCz: Y' = 116 Y/Yn - 16, Cx = 500 (X/Xn - Y/Yn),
//     Cz = 200 (Y/Yn - Z/Zn) (white as above).
//  2. CSF filtering per channel, the paper's spatial filters (x in degrees, pixel pitch
//     1/ppd):  s(x) = sum_i a_i sqrt(pi/b_i) exp(-pi^2 |x|^2 / b_i) with
//     Y': a1 = 1, b1 = 0.0047;  Cx: a1 = 1, b1 = 0.0053;
//     Cz: a1 = 34.1, b1 = 0.04, a2 = 13.5, b2 = 0.025.
//     One radius for all: r = ceil(3 sqrt(b_max / (2 pi^2)) ppd) pixels, b_max = 0.04 (3
//     standard deviations of the widest Gaussian). Each 2D kernel is normalised to sum 1, so
//     flat regions pass unchanged. Each Gaussian term is separable and is applied as a
//     horizontal then a vertical 1D pass; edges clamp to the nearest pixel (replication).
//  3. Back to linear RGB, clamp to [0, 1] (the sRGB gamut), -> XYZ -> CIELAB.
//  4. Hunt adjustment: a* <- 0.01 L* a*, b* <- 0.01 L* b*.
//  5. Colour error: HyAB distance |dL| + sqrt(da^2 + db^2), raised to q_c = 0.7, remapped
//     with cmax = HyAB(Hunt(Lab(green)), Hunt(Lab(blue)))^0.7, p_c = 0.4, p_t = 0.95:
//       e_c = (p_t / (p_c cmax)) d                                 if d < p_c cmax
//       e_c = p_t + (d - p_c cmax) / (cmax - p_c cmax) (1 - p_t)   otherwise,
//     then min(e_c, 1) (a no-op in theory: green-blue is the largest distance).
//  6. Features on the unfiltered normalised luminance Y/Yn = (Y' + 16) / 116, Gaussian
//     sigma = 0.5 * 0.082 * ppd pixels, radius ceil(3 sigma): edges with the first derivative
//     of the Gaussian (positive weights normalised to sum 1), points with the second
//     derivative (positive weights to sum 1, negative to sum -1), each in x and y (the other
//     axis smoothed with the normalised Gaussian), magnitudes |(f_x, f_y)|. Then
//       e_f = (max(| |edge_r| - |edge_t| |, | |point_r| - |point_t| |) / sqrt(2))^q_f, q_f = 0.5.
//  7. FLIP = e_c^(1 - e_f), in [0, 1]; exactly 0 where e_c = 0 (the paper's formula would
//     give 0^0 = 1 only in the degenerate case e_f = 1).
// Pooled value: the arithmetic mean over counted pixels. Non-finite pixels are replaced by 0
// before filtering.
struct FlipOptions {
  double ppd = 67.0;  // pixels per degree; 67.02 for 0.7 m, 3840 px across 0.7 m (the paper's)
};
MetricResult Flip(const RgbImage& ref_srgb, const RgbImage& test_srgb,
                  const FlipOptions& options = {}, const Map* mask = nullptr);
// Pixels per degree of visual angle for a monitor `width_m` wide with `width_px` pixels seen
// from `distance_m`: distance * (width_px / width_m) * pi / 180.
double PixelsPerDegree(double distance_m, double width_m, double width_px);

// ---- HDR-FLIP (Andersson et al. 2021) --------------------------------------------------------
// Exposure compensation values (stops) [start, stop].
struct ExposureRange {
  double start = 0.0, stop = 0.0;
};
// HDR-FLIP on linear images: N = max(2, ceil(stop - start)) exposures
// c_i = start + i (stop - start) / (N - 1); at each, both images are scaled by 2^c_i, tone
// mapped per channel with the paper's ACES fit (Narkowicz's curve with the 0.6 input scale)
//   t(x) = clamp((k0 x^2 + k1 x + k2) / (k3 x^2 + k4 x + k5), 0, 1), x = max(radiance, 0),
//   k = (0.6^2 2.51, 0.6 0.03, 0, 0.6^2 2.43, 0.6 0.59, 0.14),
// and compared with LDR-FLIP (steps 1-7 above, starting from these linear values); the map is
// the per-pixel maximum over exposures, the pooled value its mean over counted pixels.
//
// The range: when `range` is given it is used as is, always (it must be finite with
// start <= stop); give the same range for every test image compared with one reference, so
// their numbers are comparable. Only without it is AutomaticExposureRange(reference) used, and
// HdrFlip throws std::invalid_argument when that range is not finite (e.g. a reference whose
// median luminance is 0, such as a render on a black background).
struct HdrFlipOptions {
  double ppd = 67.0;
  std::optional<ExposureRange> range;
};
struct HdrFlipResult : MetricResult {
  ExposureRange range;           // the range used
  bool automatic_range = false;  // true when it came from AutomaticExposureRange
  int exposures = 0;             // N
  Map exposure_map;              // per pixel, the exposure (stops) that gave the maximum
};
HdrFlipResult HdrFlip(const RgbImage& ref_linear, const RgbImage& test_linear,
                      const HdrFlipOptions& options = {}, const Map* mask = nullptr);
// The paper's automatic range from the reference's luminance Y (Rec.709 weights) over counted
// pixels: x_max solves t(x_max) = 0.85;  start = log2(x_max / max Y),  stop = log2(x_max /
// median Y) (median: the mean of the two middle elements for an even count, as numpy's 50th
// percentile in the FLIP reference implementation). A median of 0 gives
// stop = +infinity and a maximum of 0 gives start = +infinity: the result is then not finite
// and must not be used (the caller checks std::isfinite on both ends).
ExposureRange AutomaticExposureRange(const RgbImage& ref_linear, const Map* mask = nullptr);
// The HDR-FLIP tone mapper t(x) above (exposed for tests).
double HdrFlipToneMap(double x);

// ---- CIEDE2000 (Sharma, Wu & Dalal 2005) --------------------------------------------------
struct Lab {
  double L = 0.0, a = 0.0, b = 0.0;
};
// Linear sRGB -> XYZ (IEC 61966-2-1) -> CIELAB with the white above. Works for values outside
// [0, 1] (HDR radiance gives L* > 100; the linear segment of f handles negative values).
Lab LinearSrgbToLab(double r, double g, double b);
// CIEDE2000 with k_L = k_C = k_H = 1; symmetric in its arguments, 0 for identical colours.
double Ciede2000(const Lab& lab1, const Lab& lab2);
// Per-pixel CIEDE2000 of the Lab colours of the given (linear sRGB) images; value = mean,
// p95 = 95th percentile over counted pixels (linear interpolation between closest ranks:
// position 0.95 (n - 1) in the sorted values, i.e. Hyndman & Fan type 7).
struct Ciede2000Result : MetricResult {
  double p95 = 0.0;
};
Ciede2000Result Ciede2000(const RgbImage& ref_linear, const RgbImage& test_linear,
                          const Map* mask = nullptr);

// ---- Everything at once -------------------------------------------------------------------
struct CompareOptions {
  render::ToneMapping tone_mapping = render::ToneMapping::kAcesFilmic;  // display transform
  double exposure = 1.0;                                                // (scene card)
  double linear_peak = 1.0;  // PSNR peak of linear values (explicit; not derived from data)
  double ppd = 67.0;         // FLIP and HDR-FLIP
  std::optional<ExposureRange> hdr_range;  // HDR-FLIP range; automatic only when absent
};
struct CompareResult {
  int width = 0, height = 0;
  PixelCounts counts;
  double rmse_linear = 0, psnr_linear = 0;    // linear values, PSNR peak = linear_peak
  double rmse_display = 0, psnr_display = 0;  // display values, PSNR peak = 1
  double ssim = 0;                            // display values, L = 1
  bool ssim_used_border_pixels = false;
  double flip = 0;      // LDR-FLIP of the display images
  double hdr_flip = 0;  // HDR-FLIP of the linear images (NaN when unavailable, below)
  ExposureRange hdr_range;
  bool hdr_range_automatic = false;
  int hdr_exposures = 0;
  // Empty when HDR-FLIP was computed. Otherwise why not: without CompareOptions::hdr_range the
  // automatic range is not finite (the reference's median or maximum luminance over counted
  // pixels is 0, e.g. a transparent film or a black background); hdr_flip is then NaN,
  // hdr_range holds the non-finite automatic range, there are no hdr_flip maps, and every
  // other metric is computed as usual.
  std::string hdr_flip_unavailable;
  double ciede2000_mean = 0, ciede2000_p95 = 0;                  // Lab of the linear values
  double ciede2000_display_mean = 0, ciede2000_display_p95 = 0;  // Lab of the displayed colour
  struct NamedMap {
    std::string name;  // rmse_linear, rmse_display, ssim, flip, hdr_flip, ciede2000, ...
    Map map;
  };
  std::vector<NamedMap> maps;
};
// Every metric between a reference and a test image (linear). Display metrics use
// ToDisplay(tone_mapping, exposure). Non-finite pixels of the linear inputs are excluded from
// all metrics consistently (their map values are 0). HDR-FLIP without an explicit range whose
// automatic range is not finite does not throw (HdrFlip would): it is reported unavailable
// (CompareResult::hdr_flip_unavailable) and the other metrics are still computed.
CompareResult Compare(const RgbImage& ref_linear, const RgbImage& test_linear,
                      const CompareOptions& options = {}, const Map* mask = nullptr);
// Reads the images (and the mask when mask_path is not empty) and runs Compare. Errors name
// the file: io::IoError for a missing or unreadable file, std::invalid_argument for a size
// mismatch or an unusable channel layout.
CompareResult CompareFiles(const std::string& reference_path, const std::string& test_path,
                           const std::string& mask_path, const CompareOptions& options = {});

// The colour map of error-map pictures (clothfit compare --maps, reports): piecewise linear in
// display RGB through black -> deep blue -> magenta -> orange -> pale yellow over t in [0, 1]
// (clamped; non-finite t -> black). Returns display (sRGB-encoded) values in [0, 1].
std::array<float, 3> ErrorMapColour(double t);

// ---- Internals exposed for tests (FLIP building blocks) ---------------------------------------
namespace flip_detail {
// The sRGB decoding (IEC 61966-2-1 EOTF) of a value clamped to [0, 1].
double SrgbToLinear(double v);
// Hunt-adjusted CIELAB of a linear colour (step 4).
Lab HuntLab(double r, double g, double b);
double HyAB(const Lab& x, const Lab& y);
// cmax = HyAB(Hunt(green), Hunt(blue))^0.7.
double MaxColourError();
// Step 5 remapping of d = HyAB^0.7 (before the min(., 1)).
double RemapColourError(double d);
// 1D feature kernels for a given ppd: the normalised Gaussian, the edge (first derivative)
// and point (second derivative) kernels, index i <-> offset i - radius.
struct FeatureKernels {
  int radius = 0;
  std::vector<double> gauss, edge, point;
};
FeatureKernels MakeFeatureKernels(double ppd);
// Step 6 on one linear image (values clamped to [0, 1]): |edge| and |point| per pixel.
struct FeatureMaps {
  Map edge, point;
};
FeatureMaps FeatureMagnitudes(const RgbImage& linear, double ppd);
// The per-pixel LDR-FLIP map of two linear images with values in [0, 1] (steps 1-7 after the
// sRGB decoding), no pooling.
Map FlipMapLinear(const RgbImage& ref_linear, const RgbImage& test_linear, double ppd);
}  // namespace flip_detail

}  // namespace clothfit::metrics
