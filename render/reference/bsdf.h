// render/reference/bsdf.h: the BSDF interface of the reference path tracer.
//
// Unlike brdf/ (real-time models, templated for Jets), these are physically based
// reflectance models evaluated in double by the path tracer; a virtual call per shading
// event is fine here. All directions are in the LOCAL shading frame:
//   z = shading normal n, x = surface tangent along +u (dP/du: the warp direction of a
//   fabric), y = n x t (along +v, the weft direction).
// Conventions:
//   - Eval returns f(wo, wi) WITHOUT the cosine factor; the integrator multiplies |cos wi|.
//   - wo points away from the surface toward the viewer, wi toward the light.
//   - Pdf is in solid angle over wi; Sample draws wi with that pdf and returns
//     f and pdf for it (f unweighted: the integrator computes f cos / pdf).
//   - Reflection only: wi.z <= 0 or wo.z <= 0 gives f = 0 and pdf = 0 (fabrics here are
//     opaque; two-sidedness is handled by the integrator flipping the frame to wo's side).
//   - Spatially varying models read the surface point's uv (in fabric units after the
//     fabric's uv scale) from ShadingPoint.
#pragma once

#include <memory>
#include <string>

#include "brdf/math.h"

namespace clothfit::render {

using Vec3d = Vec3<double>;
using Rgbd = Rgb<double>;

struct Point2d {
  double x = 0.0, y = 0.0;
};

// What a BSDF may know about where it is evaluated.
struct ShadingPoint {
  Point2d uv;  // surface uv (glTF TEXCOORD_0), NOT yet multiplied by the fabric's repeats
};

struct BsdfSample {
  Vec3d wi;
  Rgbd f;            // BSDF value for (wo, wi), no cosine
  double pdf = 0.0;  // solid-angle pdf of wi
};

class Bsdf {
 public:
  virtual ~Bsdf() = default;
  virtual Rgbd Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const = 0;
  virtual double Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const = 0;
  // u1, u2 in [0, 1)^2 plus a third uniform uc for choosing between strategies/lobes.
  // Returns false when no direction could be generated (the path ends).
  virtual bool Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
                      BsdfSample* out) const = 0;
  virtual std::string Name() const = 0;
};

// Cosine-weighted hemisphere sampling (Malley), pdf = cos(theta) / pi.
inline Vec3d SampleCosineHemisphere(const Point2d& u) {
  const double r = std::sqrt(u.x);
  const double phi = 2.0 * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0, 1.0 - u.x))};
}
inline double CosineHemispherePdf(double cos_theta) {
  return cos_theta > 0.0 ? cos_theta * kInvPi : 0.0;
}

// Lambertian reflector with albedo `albedo` (used by the analytic and furnace tests and for
// non-fabric materials of a scene).
class LambertBsdf final : public Bsdf {
 public:
  explicit LambertBsdf(const Rgbd& albedo) : albedo_(albedo) {}
  Rgbd Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const override {
    if (wo.z <= 0.0 || wi.z <= 0.0) return Rgbd(0, 0, 0);
    return albedo_ * kInvPi;
  }
  double Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const override {
    return wo.z > 0.0 ? CosineHemispherePdf(wi.z) : 0.0;
  }
  bool Sample(const Vec3d& wo, const Point2d& u, double, const ShadingPoint&,
              BsdfSample* out) const override {
    if (wo.z <= 0.0) return false;
    out->wi = SampleCosineHemisphere(u);
    out->pdf = CosineHemispherePdf(out->wi.z);
    out->f = albedo_ * kInvPi;
    return out->pdf > 0.0;
  }
  std::string Name() const override { return "lambert"; }

 private:
  Rgbd albedo_;
};

}  // namespace clothfit::render
