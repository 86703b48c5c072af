// render/scene/environment.h: equirectangular environment maps (and a procedural sky), with
// luminance-CDF importance sampling for the path tracer and the lookups the preview needs.
//
// Orientation (three.js equirectUv, the toolkit's convention; docs/environments.md):
//   for a world direction d (unit, +Y up), after applying the card's rotation about +Y:
//     u = atan2(d.z, d.x) / (2 pi) + 0.5        (column, left to right)
//     v = asin(d.y) / pi + 0.5                  (v = 1 at the image's TOP row: the zenith)
//   pixel (i, j) (j = 0 the top row) covers u in [i/W, (i+1)/W), v in [1-(j+1)/H, 1-j/H).
// Rotation: the map is rotated by +rotation_y about +Y, i.e. a lookup in world direction d
// reads the map at R_y(-rotation_y) d.
// Radiance values are linear RGB times the card's intensity. Negative and non-finite texels
// (real maps have them: lossy DWAB compression) are clamped to 0 on load, counted, and
// reported once through the warning callback.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "brdf/math.h"

namespace clothfit::render {

struct EnvironmentStats {
  long long negative_texels = 0;   // any channel < 0, clamped to 0
  long long nonfinite_texels = 0;  // any channel NaN/Inf, set to 0
};

class Environment {
 public:
  // Loads an EXR or Radiance HDR (io::ReadImage). Throws io::IoError naming the file.
  static Environment Load(const std::string& path, double intensity, double rotation_y,
                          const std::function<void(const std::string&)>& warn = {});
  // A procedural sky (fallback when no map is installed): a smooth blue-to-white gradient
  // with a sun disc; same interface. Deterministic.
  static Environment ProceduralSky(double intensity, double rotation_y, int width = 512);
  // Uniform radiance everywhere (white furnace tests).
  static Environment Constant(const std::array<double, 3>& radiance, int width = 64);
  // A map from texels already in memory (RGB, top row first, width x height, finite, >= 0:
  // throws std::invalid_argument otherwise); `source` names it (caches key prefilters on it).
  // Used for the sun-free map of render/scene/sun.h and by tests.
  static Environment FromPixels(int width, int height, std::vector<float> rgb, double intensity,
                                double rotation_y, const std::string& source);

  // Radiance arriving FROM world direction d (unit). Bilinear in the map.
  Rgb<double> Eval(const Vec3<double>& d) const;
  // Draws a direction with pdf proportional to luminance x sin(theta) per texel (piecewise
  // constant in (u, v)); returns the world direction, its solid-angle pdf and radiance.
  // The luminance is that of the bilinear map averaged over the texel ([1 6 1]/8 filter), so
  // the pdf is positive wherever Eval is. pdf = 0 (only exactly at a pole) means "discard".
  // An all-black map samples the uniform sphere (pdf 1/(4 pi)). docs/environments.md §6.
  Vec3<double> Sample(double u1, double u2, double* pdf, Rgb<double>* radiance) const;
  // Solid-angle pdf of Sample for direction d (unit).
  double Pdf(const Vec3<double>& d) const;

  int width() const { return width_; }
  int height() const { return height_; }
  const std::vector<float>& pixels() const { return rgb_; }  // RGB, top row first
  double intensity() const { return intensity_; }
  double rotation_y() const { return rotation_y_; }
  const EnvironmentStats& stats() const { return stats_; }
  const std::string& source() const { return source_; }

  // Map-space direction <-> (u, v) per the convention above (no rotation applied).
  static void DirectionToUv(const Vec3<double>& d, double* u, double* v);
  static Vec3<double> UvToDirection(double u, double v);
  Vec3<double> WorldToMap(const Vec3<double>& d) const;  // R_y(-rotation_y) d
  Vec3<double> MapToWorld(const Vec3<double>& m) const;  // R_y(+rotation_y) m

 private:
  void BuildDistribution();
  void SetRotation(double rotation_y);                   // sets rotation_y_, cos_rot_, sin_rot_
  Rgb<double> Texel(int i, int j) const;                 // stored RGB (no intensity)
  double TexelDensity(int i, int j) const;               // p(u, v) inside texel (i, j)

  int width_ = 0, height_ = 0;
  std::vector<float> rgb_;
  double intensity_ = 1.0, rotation_y_ = 0.0;
  double cos_rot_ = 1.0, sin_rot_ = 0.0;  // of rotation_y_
  EnvironmentStats stats_;
  std::string source_;
  // Sampling: marginal CDF over rows, conditional CDF per row (width_ + 1 entries each).
  std::vector<double> marginal_cdf_, conditional_cdf_;
  // Guide tables (the cutpoint method, Chen & Asau 1974): guide[g] = FindInterval(cdf, g / G)
  // per CDF, so a lookup searches only between two guide entries. Same result as the full
  // binary search, a few cache lines instead of ~10 dependent misses per sample.
  std::vector<int> marginal_guide_, conditional_guide_;
  std::vector<double> row_weight_;
  double total_weight_ = 0.0;
};

}  // namespace clothfit::render
