// render/reference/simple_bsdf.cpp: the GGX conductor of simple_bsdf.h (formulas cited there).
#include "render/reference/simple_bsdf.h"

#include <algorithm>
#include <cmath>

namespace clothfit::render {

double Ggx::D(double cos_h) const {
  if (cos_h <= 0.0) return 0.0;
  const double a2 = alpha * alpha;
  const double c2 = cos_h * cos_h;
  const double d = c2 * (a2 - 1.0) + 1.0;
  return a2 / (kPi * d * d);
}

double Ggx::G1(double cos_v) const {
  if (cos_v <= 0.0) return 0.0;
  const double c2 = cos_v * cos_v;
  const double tan2 = std::max(0.0, 1.0 - c2) / c2;
  return 2.0 / (1.0 + std::sqrt(1.0 + alpha * alpha * tan2));
}

// Heitz 2018, listing 1: stretch wo, sample the projected hemisphere, unstretch.
Vec3d Ggx::SampleVisibleNormal(const Vec3d& wo, const Point2d& u) const {
  const Vec3d vh = Normalize(Vec3d{alpha * wo.x, alpha * wo.y, wo.z});
  const double lensq = vh.x * vh.x + vh.y * vh.y;
  const Vec3d t1 = lensq > 0.0 ? Vec3d{-vh.y, vh.x, 0.0} * (1.0 / std::sqrt(lensq))
                               : Vec3d{1.0, 0.0, 0.0};
  const Vec3d t2 = Cross(vh, t1);
  const double r = std::sqrt(u.x);
  const double phi = 2.0 * kPi * u.y;
  const double p1 = r * std::cos(phi);
  double p2 = r * std::sin(phi);
  const double s = 0.5 * (1.0 + vh.z);
  p2 = (1.0 - s) * std::sqrt(std::max(0.0, 1.0 - p1 * p1)) + s * p2;
  const Vec3d nh =
      t1 * p1 + t2 * p2 + vh * std::sqrt(std::max(0.0, 1.0 - p1 * p1 - p2 * p2));
  return Normalize(Vec3d{alpha * nh.x, alpha * nh.y, std::max(1e-12, nh.z)});
}

GgxConductorBsdf::GgxConductorBsdf(const Rgbd& colour, double roughness) : colour_(colour) {
  const double r = std::clamp(roughness, 0.0, 1.0);
  ggx_.alpha = std::max(1e-4, r * r);
}

Rgbd GgxConductorBsdf::Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const {
  if (wo.z <= 0.0 || wi.z <= 0.0) return Rgbd(0, 0, 0);
  const Vec3d h = Normalize(wo + wi);
  const double v = ggx_.D(h.z) * ggx_.G1(wo.z) * ggx_.G1(wi.z) / (4.0 * wo.z * wi.z);
  return colour_ * v;
}

double GgxConductorBsdf::Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const {
  if (wo.z <= 0.0 || wi.z <= 0.0) return 0.0;
  const Vec3d h = Normalize(wo + wi);
  return ggx_.G1(wo.z) * ggx_.D(h.z) / (4.0 * wo.z);
}

bool GgxConductorBsdf::Sample(const Vec3d& wo, const Point2d& u, double, const ShadingPoint& sp,
                              BsdfSample* out) const {
  if (wo.z <= 0.0) return false;
  const Vec3d h = ggx_.SampleVisibleNormal(wo, u);
  const double oh = Dot(wo, h);
  if (oh <= 0.0) return false;
  out->wi = h * (2.0 * oh) - wo;
  if (out->wi.z <= 0.0) return false;
  out->pdf = Pdf(wo, out->wi, sp);
  out->f = Eval(wo, out->wi, sp);
  return out->pdf > 0.0;
}

}  // namespace clothfit::render
