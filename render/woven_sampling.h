// render/woven_sampling.h: the lobe-aware sampling strategy shared by the woven-cloth BSDFs.
//
// Both fabric models reflect light specularly off fibres: a fibre with unit tangent t
// reflects wo into the cone wi.t = -wo.t (the half vector is normal to t). The strategy here
// draws wi near that cone for ONE given tangent (the models choose the tangent from a
// discrete distribution that depends only on wo and the surface point, so the mixture pdf is
// an exact finite sum):
//
//   theta_i = asin(wi.t) ~ logistic(mu = -asin(wo.t), scale s), truncated to [-pi/2, pi/2];
//   phi     = azimuth of wi about t, measured from b1 = normalize(n - (n.t) t),
//             uniform on [-phi_max(theta_i), phi_max(theta_i)], the exact set of azimuths with
//             wi.z > 0 (no sample is wasted below the surface);
//   pdf(wi | t) = p_logistic(theta_i) / (2 phi_max(theta_i) cos(theta_i))   [solid angle:
//             d omega = cos(theta_i) d theta_i d phi].
// A logistic (closed-form CDF and inverse) replaces a Gaussian: same role, heavier tails.
// phi_max = acos(kappa), kappa = -sin(theta_i) t.z / (cos(theta_i) sqrt(1 - t.z^2)), clamped.
// The cone at theta_i reaches above the surface iff cos(theta_i - beta) > 0, beta = asin(t.z),
// so the logistic is truncated to [max(-pi/2, beta - pi/2), min(pi/2, beta + pi/2)]: no draw
// is wasted on a cone that lies wholly below the surface. ConeMass() is the fraction of the
// untruncated (on [-pi/2, pi/2]) logistic inside that range; the models use it to down-weight
// tangents whose specular cone is mostly below the surface.
#pragma once

#include <algorithm>
#include <cmath>

#include "render/bsdf.h"

namespace clothfit::render::woven {

// Logistic distribution truncated to [lo, hi].
struct TruncatedLogistic {
  double mu = 0.0, s = 1.0, lo = -0.5 * kPi, hi = 0.5 * kPi;

  static double Cdf(double x, double mu, double s) { return 1.0 / (1.0 + std::exp(-(x - mu) / s)); }
  double Mass() const { return Cdf(hi, mu, s) - Cdf(lo, mu, s); }
  double Pdf(double x) const {
    if (x < lo || x > hi) return 0.0;
    const double e = std::exp(-std::abs(x - mu) / s);
    const double mass = Mass();
    return mass > 0.0 ? e / (s * (1.0 + e) * (1.0 + e) * mass) : 0.0;
  }
  double Sample(double u) const {
    const double c0 = Cdf(lo, mu, s), c1 = Cdf(hi, mu, s);
    const double c = std::clamp(c0 + u * (c1 - c0), 1e-300, 1.0 - 1e-16);
    return std::clamp(mu + s * std::log(c / (1.0 - c)), lo, hi);
  }
};

// The logistic of tangent t for wo, truncated to the longitudinal angles whose cone reaches
// above the surface.
inline TruncatedLogistic ConeTheta(const Vec3d& wo, const Vec3d& t, double scale) {
  TruncatedLogistic lg;
  lg.mu = -std::asin(std::clamp(Dot(wo, t), -1.0, 1.0));
  lg.s = scale;
  const double beta = std::asin(std::clamp(t.z, -1.0, 1.0));
  lg.lo = std::max(-0.5 * kPi, beta - 0.5 * kPi);
  lg.hi = std::min(0.5 * kPi, beta + 0.5 * kPi);
  return lg;
}

// Fraction of the logistic on [-pi/2, pi/2] that lies in ConeTheta's range.
inline double ConeMass(const Vec3d& wo, const Vec3d& t, double scale) {
  const TruncatedLogistic lg = ConeTheta(wo, t, scale);
  TruncatedLogistic full = lg;
  full.lo = -0.5 * kPi;
  full.hi = 0.5 * kPi;
  const double m = full.Mass();
  return m > 0.0 ? lg.Mass() / m : 0.0;
}

// Half-range of the azimuth about t for which wi.z > 0, at longitudinal angle theta.
inline double PhiMax(double sin_theta, double cos_theta, const Vec3d& t) {
  const double ct = std::sqrt(std::max(0.0, 1.0 - t.z * t.z));
  const double a = cos_theta * ct;
  const double b = sin_theta * t.z;  // wi.z = b + a cos(phi)
  if (a <= 1e-12) return b > 0.0 ? kPi : 0.0;
  const double kappa = -b / a;
  if (kappa >= 1.0) return 0.0;
  if (kappa <= -1.0) return kPi;
  return std::acos(kappa);
}

// Orthonormal b1, b2 about t with b1 the normal's direction projected off t (b2.z = 0).
inline void ConeBasis(const Vec3d& t, Vec3d* b1, Vec3d* b2) {
  Vec3d p(-t.z * t.x, -t.z * t.y, 1.0 - t.z * t.z);  // n - (n.t) t
  if (Dot(p, p) < 1e-20) {                           // t along n: any perpendicular works
    p = Vec3d(1.0, 0.0, 0.0) - t * t.x;
  }
  *b1 = Normalize(p);
  *b2 = Cross(t, *b1);
}

// Draws wi near the specular cone of tangent t for wo; returns false if the cone has no
// direction above the surface at the drawn theta.
inline bool SampleCone(const Vec3d& wo, const Vec3d& t, double scale, const Point2d& u, Vec3d* wi) {
  const TruncatedLogistic lg = ConeTheta(wo, t, scale);
  if (!(lg.Mass() > 0.0)) return false;
  const double theta = lg.Sample(u.x);
  const double st = std::sin(theta), ct = std::cos(theta);
  const double phi_max = PhiMax(st, ct, t);
  if (!(phi_max > 0.0)) return false;
  const double phi = (2.0 * u.y - 1.0) * phi_max;
  Vec3d b1, b2;
  ConeBasis(t, &b1, &b2);
  *wi = t * st + (b1 * std::cos(phi) + b2 * std::sin(phi)) * ct;
  return wi->z > 0.0;
}

// Solid-angle density of SampleCone at wi.
inline double ConePdf(const Vec3d& wo, const Vec3d& t, double scale, const Vec3d& wi) {
  if (!(wi.z > 0.0)) return 0.0;
  const double st = std::clamp(Dot(wi, t), -1.0, 1.0);
  const double ct = std::sqrt(std::max(0.0, 1.0 - st * st));
  if (ct < 1e-12) return 0.0;
  const double phi_max = PhiMax(st, ct, t);
  if (!(phi_max > 0.0)) return 0.0;
  return ConeTheta(wo, t, scale).Pdf(std::asin(st)) / (2.0 * phi_max * ct);
}

}  // namespace clothfit::render::woven
