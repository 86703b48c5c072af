// tests/quadrature.h: brute-force hemisphere quadrature over the light direction, written
// independently of brdf/lut.cpp's importance sampler (midpoint rule in (cos theta, phi)).
#pragma once

#include <cmath>
#include <functional>

#include "brdf/math.h"
#include "brdf/params.h"

namespace clothfit::testing {

// int_{H^2} f(cosines(v, l)) NoL dl with v at NoV in the xz plane; f gets raw cosines.
// n_mu x n_phi midpoint cells in (mu = cos theta_l, phi); phi symmetric, so [0, pi] doubled.
inline double HemisphereIntegral(double NoV, const std::function<double(const Cosines<double>&)>& f,
                                 int n_mu = 1024, int n_phi = 512) {
  const Vec3<double> v(std::sqrt(1.0 - NoV * NoV), 0.0, NoV);
  double sum = 0.0;
  for (int a = 0; a < n_mu; ++a) {
    const double mu = (a + 0.5) / n_mu;
    const double s = std::sqrt(1.0 - mu * mu);
    for (int b = 0; b < n_phi; ++b) {
      const double phi = kPi * (b + 0.5) / n_phi;
      const Vec3<double> l(s * std::cos(phi), s * std::sin(phi), mu);
      sum += f(CosinesFromDirections(v, l)) * mu;
    }
  }
  return sum * (1.0 / n_mu) * (kPi / n_phi) * 2.0;
}

// int_0^{pi/2} D(cos theta) cos theta sin theta dtheta * 2 pi, midpoint in theta.
inline double NormalisationIntegral(const std::function<double(double)>& D, int n = 200000) {
  double sum = 0.0;
  const double dt = 0.5 * kPi / n;
  for (int i = 0; i < n; ++i) {
    const double t = (i + 0.5) * dt;
    sum += D(std::cos(t)) * std::cos(t) * std::sin(t);
  }
  return sum * dt * 2.0 * kPi;
}

}  // namespace clothfit::testing
