// render/reference/woven_sampling.h: the lobe-aware sampling strategy shared by the woven-cloth BSDFs.
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

#include "render/reference/bsdf.h"

namespace clothfit::render::woven {

// Logistic distribution truncated to [lo, hi]. Tail-safe: when the whole interval lies above
// mu it works with the survival function S(z) = 1/(1 + e^z) (accurate where the CDF rounds
// to 1), otherwise with the CDF F(z) = 1/(1 + e^-z) (accurate where it is tiny).
struct TruncatedLogistic {
  double mu = 0.0, s = 1.0, lo = -0.5 * kPi, hi = 0.5 * kPi;

  static double F(double z) { return 1.0 / (1.0 + std::exp(-z)); }
  static double S(double z) { return 1.0 / (1.0 + std::exp(z)); }
  bool UpperTail() const { return lo > mu; }
  double Mass() const {
    if (!(hi > lo)) return 0.0;
    const double zl = (lo - mu) / s, zh = (hi - mu) / s;
    return UpperTail() ? S(zl) - S(zh) : F(zh) - F(zl);
  }
  double Pdf(double x) const {
    if (x < lo || x > hi) return 0.0;
    const double e = std::exp(-std::abs(x - mu) / s);
    const double mass = Mass();
    return mass > 0.0 ? e / (s * (1.0 + e) * (1.0 + e) * mass) : 0.0;
  }
  double Sample(double u) const {
    const double zl = (lo - mu) / s, zh = (hi - mu) / s;
    double z;
    if (UpperTail()) {  // S decreases from S(zl) to S(zh)
      const double c = std::clamp(S(zl) - u * (S(zl) - S(zh)), 1e-300, 1.0 - 1e-16);
      z = std::log1p(-c) - std::log(c);
    } else {
      const double c = std::clamp(F(zl) + u * (F(zh) - F(zl)), 1e-300, 1.0 - 1e-16);
      z = std::log(c) - std::log1p(-c);
    }
    return std::clamp(mu + s * z, lo, hi);
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
// ct = sqrt(1 - t.z^2) (precomputed by the caller).
inline double PhiMax(double sin_theta, double cos_theta, const Vec3d& t, double ct) {
  const double a = cos_theta * ct;
  const double b = sin_theta * t.z;  // wi.z = b + a cos(phi)
  if (a <= 1e-12) return b > 0.0 ? kPi : 0.0;
  const double kappa = -b / a;
  if (kappa >= 1.0) return 0.0;
  if (kappa <= -1.0) return kPi;
  return std::acos(kappa);
}
inline double PhiMax(double sin_theta, double cos_theta, const Vec3d& t) {
  return PhiMax(sin_theta, cos_theta, t, std::sqrt(std::max(0.0, 1.0 - t.z * t.z)));
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

// One tangent's cone for a given wo, with the per-(wo, t) constants computed once.
struct Cone {
  Vec3d t;
  TruncatedLogistic theta;
  double mass = 0.0;  // theta.Mass()
  // Constants of ConePdf: 1 / s, 1 / (s mass), sqrt(1 - t.z^2).
  double inv_s = 0.0, inv_s_mass = 0.0, t_perp = 0.0;
};

inline Cone MakeCone(const Vec3d& wo, const Vec3d& t, double scale) {
  Cone c;
  c.t = t;
  c.theta = ConeTheta(wo, t, scale);
  c.mass = c.theta.Mass();
  c.inv_s = 1.0 / scale;
  c.inv_s_mass = c.mass > 0.0 ? 1.0 / (scale * c.mass) : 0.0;
  c.t_perp = std::sqrt(std::max(0.0, 1.0 - t.z * t.z));
  return c;
}

// Draws wi near the cone; returns false if no direction above the surface was produced.
inline bool SampleCone(const Cone& c, const Point2d& u, Vec3d* wi) {
  if (!(c.mass > 0.0)) return false;
  const double theta = c.theta.Sample(u.x);
  const double st = std::sin(theta), ct = std::cos(theta);
  const double phi_max = PhiMax(st, ct, c.t);
  if (!(phi_max > 0.0)) return false;
  const double phi = (2.0 * u.y - 1.0) * phi_max;
  Vec3d b1, b2;
  ConeBasis(c.t, &b1, &b2);
  *wi = c.t * st + (b1 * std::cos(phi) + b2 * std::sin(phi)) * ct;
  return wi->z > 0.0;
}

// Solid-angle density of SampleCone at wi.
inline double ConePdf(const Cone& c, const Vec3d& wi) {
  if (!(wi.z > 0.0) || !(c.mass > 0.0)) return 0.0;
  const double st = std::clamp(Dot(wi, c.t), -1.0, 1.0);
  const double ct = std::sqrt(std::max(0.0, 1.0 - st * st));
  if (ct < 1e-12) return 0.0;
  const double x = std::asin(st);
  if (x < c.theta.lo || x > c.theta.hi) return 0.0;
  const double phi_max = PhiMax(st, ct, c.t, c.t_perp);
  if (!(phi_max > 0.0)) return 0.0;
  // p_theta = e / (s (1 + e)^2 mass) (TruncatedLogistic::Pdf), over 2 phi_max cos(theta).
  const double e = std::exp(-std::abs(x - c.theta.mu) * c.inv_s);
  const double e1 = 1.0 + e;
  return e * c.inv_s_mass / (e1 * e1 * (2.0 * phi_max * ct));
}

// Convenience forms for one-off use.
inline bool SampleCone(const Vec3d& wo, const Vec3d& t, double scale, const Point2d& u, Vec3d* wi) {
  return SampleCone(MakeCone(wo, t, scale), u, wi);
}
inline double ConePdf(const Vec3d& wo, const Vec3d& t, double scale, const Vec3d& wi) {
  return ConePdf(MakeCone(wo, t, scale), wi);
}

}  // namespace clothfit::render::woven
