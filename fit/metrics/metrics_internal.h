// fit/metrics/metrics_internal.h: helpers shared by the metric families (one per .cpp file):
// colour spaces, coverage (which pixels a metric pools), separable filtering. Not part of the
// public API (fit/metrics/metrics.h); defined in fit/metrics/metrics_common.cpp.
#pragma once

#include <array>
#include <limits>
#include <string>
#include <vector>

#include "fit/metrics/metrics.h"

namespace clothfit::metrics::internal {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kInf = std::numeric_limits<double>::infinity();

// ---- colour spaces ----------------------------------------------------------------------------

// Linear sRGB -> XYZ, IEC 61966-2-1 (4-digit values). Row sums = the white point.
inline constexpr double kRgbToXyz[3][3] = {
    {0.4124, 0.3576, 0.1805}, {0.2126, 0.7152, 0.0722}, {0.0193, 0.1192, 0.9505}};
inline constexpr double kWhite[3] = {0.4124 + 0.3576 + 0.1805, 0.2126 + 0.7152 + 0.0722,
                                     0.0193 + 0.1192 + 0.9505};

using Mat3 = std::array<std::array<double, 3>, 3>;

// The exact inverse of kRgbToXyz (adjugate / determinant), computed once.
const Mat3& XyzToRgb();
// CIELAB f(t): cube root above (6/29)^3, the linear segment below (also for t < 0).
double LabF(double t);
Lab XyzToLab(double x, double y, double z);
// CIE Y of a linear sRGB pixel.
double Luminance(const float* p);
bool Finite3(const float* p);

// ---- coverage ---------------------------------------------------------------------------------

std::string SizeText(int w, int h);

struct Coverage {
  std::vector<unsigned char> counted;  // per pixel
  std::vector<unsigned char> finite;   // per pixel: both images finite
  PixelCounts counts;
};

// Throws std::invalid_argument naming `metric` when the sizes of ref, test and mask differ.
void CheckSameSize(const RgbImage& ref, const RgbImage& test, const Map* mask,
                   const std::string& metric);
// The pixels a metric pools: inside the mask and finite in both images. Throws when none.
Coverage Cover(const RgbImage& ref, const RgbImage& test, const Map* mask,
               const std::string& metric);
// A copy with every channel of non-finite pixels set to 0 (for filtering).
RgbImage Sanitized(const RgbImage& img, const Coverage& cov);
double MeanOver(const Map& map, const Coverage& cov);
void ZeroNonFinite(Map& map, const Coverage& cov);

// ---- separable filtering ------------------------------------------------------------------
// Plane: a double image, row-major. Kernels are correlations: out(x) = sum_k k[k] in(x + k - r).

using Plane = std::vector<double>;

enum class Border { kClamp, kZero };

Plane FilterRows(const Plane& in, int w, int h, const std::vector<double>& k, Border border);
Plane FilterCols(const Plane& in, int w, int h, const std::vector<double>& k, Border border);
Plane Filter2(const Plane& in, int w, int h, const std::vector<double>& kx,
              const std::vector<double>& ky, Border border);
// exp(-x^2 / (2 sigma^2)) sampled at integer offsets -r..r, normalised to sum 1.
std::vector<double> GaussianKernel(double sigma, int r);

}  // namespace clothfit::metrics::internal
