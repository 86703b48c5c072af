// brdf/table.h: a 2-D table of float channels with GPU-style bilinear filtering that
// ceres::Jet can differentiate (the weights carry the derivative; the texel indices come
// from the scalar part).
//
// Conventions (also written into every EXR the toolkit writes, see docs/conventions.md):
//   - texel (i, j) holds the value at u = (i + 0.5) / width, v = (j + 0.5) / height;
//   - sampling uses clamp-to-edge, like a GL texture with CLAMP_TO_EDGE + LINEAR;
//   - storage is row-major, row j (v) after row j - 1, channels interleaved.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "brdf/math.h"

namespace clothfit {

struct Table2D {
  int width = 0;     // texels along u
  int height = 0;    // texels along v
  int channels = 0;  // interleaved
  std::vector<float> data;
  std::string u_axis;  // what u means, e.g. "NoV"
  std::string v_axis;  // what v means, e.g. "perceptual roughness r"

  Table2D() = default;
  Table2D(int w, int h, int c) : width(w), height(h), channels(c), data(size_t(w) * h * c, 0.f) {}

  float& at(int i, int j, int c) { return data[(size_t(j) * width + i) * channels + c]; }
  float at(int i, int j, int c) const { return data[(size_t(j) * width + i) * channels + c]; }

  // Coordinate of texel centre i along an axis of n texels.
  static double Centre(int i, int n) { return (i + 0.5) / n; }

  // Bilinear sample of channel c at (u, v) in [0, 1]^2 (clamped to edge).
  template <typename T>
  T Sample(const T& u, const T& v, int c) const {
    T fu, fv;
    int i0, j0;
    Locate(u, width, i0, fu);
    Locate(v, height, j0, fv);
    const int i1 = i0 + 1 < width ? i0 + 1 : i0;
    const int j1 = j0 + 1 < height ? j0 + 1 : j0;
    const T one = Const<T>(1.0);
    const T a = Const<T>(double(at(i0, j0, c))) * (one - fu) + Const<T>(double(at(i1, j0, c))) * fu;
    const T b = Const<T>(double(at(i0, j1, c))) * (one - fu) + Const<T>(double(at(i1, j1, c))) * fu;
    return a * (one - fv) + b * fv;
  }

 private:
  // Texel-space position x = u n - 0.5, clamped to [0, n - 1]; i0 = floor, f = fraction.
  // Outside the clamp the fraction is a constant, so the derivative is 0 there (as on a GPU).
  template <typename T>
  static void Locate(const T& u, int n, int& i0, T& f) {
    const T x = u * Const<T>(double(n)) - Const<T>(0.5);
    const double xs = ScalarPart(x);
    if (!(xs > 0.0)) {  // also catches NaN: clamp to the first texel
      i0 = 0;
      f = Const<T>(0.0);
      return;
    }
    if (xs >= double(n - 1)) {
      i0 = n - 1;
      f = Const<T>(0.0);
      return;
    }
    i0 = int(std::floor(xs));
    f = x - Const<T>(double(i0));
  }
};

}  // namespace clothfit
