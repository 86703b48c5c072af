// render/preview/sh.h: order-2 spherical-harmonics irradiance, as Filament and three.js light diffuse
// IBL: 9 RGB coefficients projected from the environment map, convolved with the clamped
// cosine (Ramamoorthi & Hanrahan 2001, "An Efficient Representation for Irradiance
// Environment Maps").
//
// Basis: the real spherical harmonics Y_lm, l <= 2, orthonormal on the sphere
// (int Y_lm Y_l'm' dw = delta), evaluated on the WORLD direction (x, y, z) (+Y up) with the
// polynomials and ordering of Ramamoorthi & Hanrahan (also three.js's SphericalHarmonics3):
//   k  (l, m)   Y_k(x, y, z)
//   0  (0,  0)  0.282095                        = 1 / (2 sqrt(pi))
//   1  (1, -1)  0.488603 y                      = sqrt(3 / (4 pi)) y
//   2  (1,  0)  0.488603 z
//   3  (1,  1)  0.488603 x
//   4  (2, -2)  1.092548 x y                    = sqrt(15 / (4 pi)) x y
//   5  (2, -1)  1.092548 y z
//   6  (2,  0)  0.315392 (3 z^2 - 1)            = sqrt(5 / (16 pi)) (3 z^2 - 1)
//   7  (2,  1)  1.092548 x z
//   8  (2,  2)  0.546274 (x^2 - y^2)            = sqrt(15 / (16 pi)) (x^2 - y^2)
// (full-precision constants below, not the 6-digit values). Coefficients are the plain
// projections L_k = int L(w) Y_k(w) dw of the radiance (no pre-scaling: Filament's cmgen bakes
// the A_l / pi factors and its own basis constants into the coefficients; we do not).
//
// Irradiance: E(n) = sum_l A_l sum_m L_lm Y_lm(n) with the clamped-cosine kernel's zonal
// coefficients A_0 = pi, A_1 = 2 pi / 3, A_2 = pi / 4 (Ramamoorthi & Hanrahan eq. 8).
// IrradianceOverPi returns E_d = E / pi, the Lambert-convolved radiance of
// brdf/params.h (IblWeights::diffuse multiplies it directly).
#pragma once

#include <array>

#include "brdf/math.h"
#include "render/scene/environment.h"

namespace clothfit::render {

inline constexpr int kShCoefficients = 9;

// The normalisation constants of the basis above (exact values to double precision).
inline constexpr double kShY00 = 0.28209479177387814;  // 1 / (2 sqrt(pi))
inline constexpr double kShY1 = 0.4886025119029199;    // sqrt(3 / (4 pi))
inline constexpr double kShY2a = 1.0925484305920792;   // sqrt(15 / (4 pi)): xy, yz, xz
inline constexpr double kShY20 = 0.31539156525252005;  // sqrt(5 / (16 pi)): 3 z^2 - 1
inline constexpr double kShY22 = 0.5462742152960396;   // sqrt(15 / (16 pi)): x^2 - y^2

struct Sh9 {
  std::array<Rgb<double>, kShCoefficients> c{};  // L_k, ordered as in the table above
};

// The nine basis functions at a unit direction d (world frame).
template <typename T>
inline std::array<T, kShCoefficients> ShBasis(const Vec3<T>& d) {
  const T x = d.x, y = d.y, z = d.z;
  return {Const<T>(kShY00),
          Const<T>(kShY1) * y,
          Const<T>(kShY1) * z,
          Const<T>(kShY1) * x,
          Const<T>(kShY2a) * x * y,
          Const<T>(kShY2a) * y * z,
          Const<T>(kShY20) * (Const<T>(3.0) * z * z - Const<T>(1.0)),
          Const<T>(kShY2a) * x * z,
          Const<T>(kShY22) * (x * x - y * y)};
}

// Projects the environment onto the basis, in world space (the card's rotation_y and
// intensity applied). The radiance is taken as piecewise constant over each texel's (u, v)
// cell (a box reconstruction of the map), and each basis polynomial is integrated over each
// cell in closed form: the projection is exact for that reconstruction, with no quadrature
// error (a constant map gives L_0 = sqrt(4 pi) L and L_k = 0 otherwise, to rounding).
// The moments are computed in map space and rotated into world space by R_y(rotation_y).
Sh9 ProjectEnvironment(const Environment& env);

// Rotates coefficients by R_y(angle) about +Y (right-handed, +X towards -Z): the result
// describes the rotated radiance L'(w) = L(R_y(-angle) w).
Sh9 RotateY(const Sh9& sh, double angle);

// E_d(n) = (1/pi) int L(l) max(n.l, 0) dl in its order-2 approximation, for a unit normal n
// (not normalised here). Templated so ceres::Jet normals flow through.
// clamp_negative: the order-2 series can dip below 0 behind a strong light; Filament clamps
// (its shader's irradianceSH returns max(E, 0)), three.js r187 does not (shGetIrradianceAt
// has no clamp). Default: clamp, as Filament. The clamp is a Max, so the derivative is 0
// where it acts.
template <typename T>
inline Rgb<T> IrradianceOverPi(const Sh9& sh, const Vec3<T>& n, bool clamp_negative = true) {
  // A_l / pi: 1, 2/3, 1/4.
  static constexpr std::array<double, kShCoefficients> kBand = {
      1.0, 2.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0, 0.25, 0.25, 0.25, 0.25, 0.25};
  const std::array<T, kShCoefficients> y = ShBasis(n);
  Rgb<T> e = Rgb<T>::Splat(Const<T>(0.0));
  for (size_t k = 0; k < kShCoefficients; ++k) {
    const T w = Const<T>(kBand[k]) * y[k];
    e += CastRgb<T>(sh.c[k]) * w;
  }
  if (clamp_negative) {
    const T zero = Const<T>(0.0);
    e = Rgb<T>(Max(e.r, zero), Max(e.g, zero), Max(e.b, zero));
  }
  return e;
}

}  // namespace clothfit::render
