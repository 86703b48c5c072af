// render/preview/prefilter.h: prefiltered radiance mip chains for split-sum specular IBL, as the
// engines build them, sampled with the engines' roughness-to-LOD mappings and trilinear
// filtering.
//
// Level k of a chain of `levels` is an equirect image (map space, same orientation as the
// Environment it was built from) of width base_width / 2^k and half that height, holding the
// environment prefiltered for roughness r_k:
//   kGgx     (Filament, three.js): split-sum prefilter with n = v = R (Karis 2013),
//              P(R) = sum L(l_i) NoL_i / sum NoL_i,  h_i ~ D_GGX(alpha = r^2) NoH,
//              l_i = reflect(-R, h_i). LOD mapping (Filament):
//              lod = lodsForRoughnessOne r (2 - r), lodsForRoughnessOne = levels - 1, so
//              level k holds r_k = 1 - sqrt(1 - k / (levels - 1)).
//   kCharlie (glTF sample viewer, KHR_materials_sheen): the same estimator with
//              h_i ~ D_Charlie(alpha = r^2) NoH (Estevez & Kulla 2017); LOD mapping
//              lod = r (levels - 1), so r_k = k / (levels - 1).
// Level 0 (r = 0) is the plain environment, box-filtered (solid-angle weighted) to the base
// width. Samples are taken with filtered importance sampling (Colbert & Krivanek 2007, GPU
// Gems 3 ch. 20): each sample reads a box-filtered pyramid of the plain environment at
// lod_s = 1/2 log2(Omega_s / Omega_p) + 1, Omega_s = 1 / (N pdf(l)) the sample's solid angle,
// Omega_p the base texel's solid angle at the equator, so a few hundred samples give a
// noise-free result.
//
// Sample() does what a GPU does with a trilinear sampler on such a chain: bilinear within a
// level (wrap in u, clamp in v, texel centres at (i + 1/2) / W), linear between the two
// nearest levels, lod clamped to [0, levels - 1].
#pragma once

#include <functional>
#include <vector>

#include "brdf/math.h"
#include "render/scene/environment.h"

namespace clothfit::render {

class PrefilteredEnvironment {
 public:
  enum class Kernel { kGgx, kCharlie };

  // One equirect image, RGB float, top row first (the Environment's layout).
  struct Level {
    int width = 0, height = 0;
    double roughness = 0.0;  // perceptual r this level was prefiltered for
    std::vector<float> rgb;
    // Radiance at the poles: the mean of the top (bottom) row, whose texels all touch the pole.
    Rgb<double> pole_top, pole_bottom;
    // Bilinear lookup at a MAP-space unit direction: wrap in u; in v, between the centre of
    // the first (last) row and the pole it blends linearly towards pole_top (pole_bottom), so
    // the lookup is continuous through the pole (a clamp in v would return the top row at the
    // lookup's own azimuth: two values half a turn apart on either side of the pole).
    Rgb<double> Bilinear(const Vec3<double>& map_dir) const;
    // Sets pole_top and pole_bottom from rgb (call after writing rgb).
    void SetPoles();
  };

  // Called after each finished level with (levels done, levels total).
  using Progress = std::function<void(int, int)>;

  // Builds the chain. Throws std::invalid_argument (naming the parameter) unless levels >= 1,
  // base_width is a power of two in [8, 8192], base_width / 2^(levels - 1) >= 4, and
  // samples in [1, 65536]. Parallel over rows (TBB). The environment's intensity is baked in;
  // its rotation_y is kept and applied in Sample.
  static PrefilteredEnvironment Build(const Environment& env, Kernel kernel, int levels,
                                      int base_width, int samples, const Progress& progress = {});

  // The engine's LOD for perceptual roughness r (clamped to [0, 1]).
  double LodForRoughness(double r) const;
  // Trilinear lookup of radiance arriving from WORLD direction dir (unit) at the given lod.
  Rgb<double> Sample(const Vec3<double>& dir, double lod) const;

  Kernel kernel() const { return kernel_; }
  int levels() const { return static_cast<int>(levels_.size()); }
  const Level& level(int k) const { return levels_[static_cast<size_t>(k)]; }
  double rotation_y() const { return rotation_y_; }

  // Roughness held by level k of a chain with `levels` levels (the LOD mapping inverted).
  static double RoughnessForLevel(Kernel kernel, int k, int levels);

 private:
  Kernel kernel_ = Kernel::kGgx;
  std::vector<Level> levels_;
  double rotation_y_ = 0.0, cos_rot_ = 1.0, sin_rot_ = 0.0;
};

}  // namespace clothfit::render
