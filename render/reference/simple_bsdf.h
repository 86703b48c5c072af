// render/reference/simple_bsdf.h: simple, independently reproducible materials for the fabric
// slot, so that a scene card renders the same in clothfit and in another renderer (Blender
// Cycles, scripts/cycles-reference) and the two can be compared on an identical material.
//
// Each model is chosen to be EXACTLY what one Cycles 3.4 shader node computes (the Cycles
// conventions are cited per class), so that a disagreement is a renderer bug, not a model gap:
//
//   lambert        Cycles "Diffuse BSDF" (roughness 0):      f = albedo / pi
//   ggx_conductor  Cycles "Glossy BSDF", distribution GGX:   f = colour D G / (4 cos_o cos_i)
//                  with alpha = roughness^2 (the node's perceptual roughness squared), no
//                  Fresnel term (F = colour at every angle), separable Smith shadowing.
//
// Both are reflection only, like every clothfit BSDF (two-sidedness: the integrator flips the
// frame to the viewer's side; Cycles does the same for a closed or a back-facing surface).
#pragma once

#include "render/reference/bsdf.h"

namespace clothfit::render {

// GGX (Trowbridge-Reitz) microfacet distribution, isotropic, alpha = roughness^2.
//   D(h)  = alpha^2 / (pi (cos^2 h (alpha^2 - 1) + 1)^2)        (Walter et al. 2007, eq. 33)
//   G1(v) = 2 / (1 + sqrt(1 + alpha^2 tan^2 v))                 (Walter et al. 2007, eq. 34)
//   G     = G1(wo) G1(wi)   (separable: what Cycles 3.4's bsdf_microfacet_ggx_eval_reflect uses)
// Sampling: visible normals (Heitz 2018, "Sampling the GGX Distribution of Visible Normals",
// JCGT 7(4)), pdf(wi) = G1(wo) D(h) / (4 cos_o).
struct Ggx {
  double alpha = 0.25;
  double D(double cos_h) const;
  double G1(double cos_v) const;
  Vec3d SampleVisibleNormal(const Vec3d& wo, const Point2d& u) const;
};

// Cycles "Glossy BSDF" (GGX): a conductor whose reflectance is `colour` at every angle.
class GgxConductorBsdf final : public Bsdf {
 public:
  // roughness: the node's input in [0, 1]; alpha = roughness^2, clamped to >= 1e-4.
  GgxConductorBsdf(const Rgbd& colour, double roughness);
  Rgbd Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const override;
  double Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const override;
  bool Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
              BsdfSample* out) const override;
  std::string Name() const override { return "ggx_conductor"; }
  double alpha() const { return ggx_.alpha; }

 private:
  Rgbd colour_;
  Ggx ggx_;
};

}  // namespace clothfit::render
