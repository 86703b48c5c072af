// render/reference/irawan.h: the Irawan-Marschner woven-cloth BSDF for the reference path tracer.
//
// Irawan & Marschner, "Specular Reflection from Woven Cloth", ACM TOG 31(1), 2012, and
// Irawan, "The Appearance of Woven Cloth", PhD thesis, Cornell 2008. A spatially varying,
// anisotropic BRDF: the surface is tiled by a weave pattern (render/reference/weave_pattern.h); each
// point lies on one yarn segment (warp or weft); the specular term is the reflection of the
// fibres of the curved yarn whose highlight falls within a band around the point; a Lambert
// term kd/pi is added. Formulas as implemented (docs/woven-cloth.md section 1 has the
// derivations; all angles in radians, directions in the yarn frame defined below):
//
//   frames      draft (X right, Y up) = shading frame rotated +90 deg about n: the draft's
//               Y axis (warp) is the shading x axis (+u, warp), X is -v.
//               X = -v * repeat_v * W, Y = u * repeat_u * H (cells). Yarn frame: warp
//               (x, y, z)_yarn = (-d.y, d.x, d.z); weft rotated a further 90 deg:
//               (-d.x, -d.y, d.z). The yarn runs along its yarn-frame y axis.
//   position    (across, along) = (pX, pY) for warp, (-pY, pX) for weft, p = point - centre
//               (cells); u = along / (l/2) * umax, v = across * pi / w.
//   filament    u_h = atan(h_y / h_z), valid |u_h| < umax; n = (sin v, sin u_h cos v,
//   (psi = 0)   cos u_h cos v), t = (0, cos u_h, -sin u_h); G = a (R(u_h) + a cos v) /
//               (|wi + wo| |(t x h)_x|), a = w/2; smoothing A *= 1 - smoothstep((|u_h| -
//               (1-ss) umax) / (ss umax)); domain factor pi l; band |along - y_h| < l hWidth/2,
//               y_h = clamp(u_h / umax * l/2, +-(l - l hWidth)/2) (band kept inside the
//               segment), value / (l hWidth).
//   staple      D = (h_y cos u - h_z sin u) / (sqrt(h_x^2 + (h_y sin u + h_z cos u)^2) tan psi),
//   (psi != 0)  valid |D| < 1; v_h = atan2(-h_y sin u - h_z cos u, h_x) + acos(D) wrapped to
//               (-pi, pi], valid |v_h| < pi/2; n at (u, v_h); G = a (R(u) + a cos v_h) /
//               (|wi + wo| (n.h) |sin psi|); domain factor 2 w umax; band |across - x_h| <
//               w hWidth/2, x_h = clamp(v_h w / pi, +-(w - w hWidth)/2), value / (w hWidth).
//   common      fc = alpha + vonMises(-wi.wo, beta), vonMises(x, b) = exp(b x)/(2 pi I0(|b|));
//               A = (1/4pi) c1 c2 / (c1 + c2), c = max(0, n.w); spine radius of curvature R
//               from rhat = 1 + kappa (1 + 1/tan umax) (circle, ellipse, parabola, hyperbola);
//               area factor (warpArea + weftArea) / warpArea (warp) or / weftArea (weft).
//   f           = ks * I * spec * specNorm + kd / pi (no cosine; bsdf.h), I = fineness
//               variation min(-log xi, 10); specNorm = 1 / (pi * E[spec]) with E over 10 000
//               deterministic draws of (position, cosine-distributed wi, wo), so with ks = 1 the
//               tile-averaged bi-hemispherical specular albedo is 1: ks is a relative albedo.
//
// Sampling (woven_sampling.h): one-sample MIS (balance heuristic = the mixture pdf) of
// cosine sampling (probability c) and a lobe strategy: one of K = 8 fibre tangents of the
// highlight band at this point (uniform over the band of u_h for filament yarns, of v_h for
// staple yarns, midpoints), then wi near its specular cone. Pdf() is that exact mixture.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "brdf/yarn_lobe.h"
#include "render/reference/bsdf.h"
#include "render/reference/weave_pattern.h"
#include "render/reference/woven_sampling.h"

namespace clothfit::render {

// Where a surface point falls in the weave.
struct IrawanPoint {
  int yarn = 0;         // index into pattern.yarns
  double across = 0.0;  // yarn-frame position relative to the segment centre, cells
  double along = 0.0;
  double u = 0.0, v = 0.0;          // along-yarn inclination angle, across-yarn angle (radians)
  double umax = 0.0;                // radians, after the umax noise
  double intensity = 1.0;           // fineness intensity variation
  double sin_u = 0.0, cos_u = 1.0;  // sin(u), cos(u)
  double spine_radius = 0.0;        // SpineRadius(|u|, umax, ...) (staple yarns only)
};

class IrawanBsdf final : public Bsdf {
 public:
  static constexpr int kTangents = 8;  // tangents of the discretised highlight band

  // repeat_u, repeat_v: weave tiles per UV unit along u and v. Throws std::invalid_argument
  // on a non-positive repeat; the pattern is validated (WeavePatternError).
  IrawanBsdf(WeavePattern pattern, double repeat_u, double repeat_v);

  Rgbd Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const override;
  double Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const override;
  bool Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
              BsdfSample* out) const override;
  std::string Name() const override { return "irawan:" + pattern_.name; }

  const WeavePattern& pattern() const { return pattern_; }
  double specular_normalisation() const { return spec_norm_; }
  double repeat_u() const { return repeat_u_; }
  double repeat_v() const { return repeat_v_; }

  // The weave location of a surface uv (after the repeats).
  IrawanPoint Locate(const Point2d& uv) const;
  // Unnormalised specular integrand (ks = 1, no intensity variation) in the shading frame.
  double SpecularIntegrand(const IrawanPoint& p, const Vec3d& wo, const Vec3d& wi) const;
  // The same averaged over the highlight band's coordinate (across for staple yarns, along for
  // filament yarns) uniform in [-half_extent, half_extent] (the segment's cells, in cells): the
  // band test replaced by its mean, |band n [-e, e]| / 2e. The point's other coordinate (u for
  // staple, v for filament) is what is left to average over for the tile mean
  // (fit/yarn_farfield.h's quadrature). 0 for half_extent <= 0.
  double SpecularBandAverage(const IrawanPoint& p, const Vec3d& wo, const Vec3d& wi,
                             double half_extent) const;
  // Probability of choosing cosine sampling at this point.
  double CosineProbability(const IrawanPoint& p) const;

 private:
  IrawanPoint LocateDraft(double X, double Y) const;
  // band_extent > 0: SpecularBandAverage's half extent; 0: the band test (SpecularIntegrand).
  double Specular(const IrawanPoint& p, const Vec3d& wo, const Vec3d& wi, double band_extent) const;
  // Per-(uv, wo) state shared by Eval, Pdf and Sample at one shading point: the weave location
  // and the lobe strategy's cones. Kept in a one-entry thread-local memo keyed by this BSDF's
  // instance id, uv and wo (a path vertex calls Eval for each light, Eval/Pdf for the
  // environment and Sample with the same wo and uv): a pure function of its key, so the
  // results are exactly those of recomputing it.
  struct Local {
    IrawanPoint p;
    bool lobe = false;  // cones valid (band not empty)
    double c = 1.0;     // probability of cosine sampling
    woven::Cone cones[kTangents];
  };
  struct Memo;
  static Memo& ThreadMemo();
  const IrawanPoint& PointAt(const ShadingPoint& sp) const;
  const Local& LocalAt(const Vec3d& wo, const ShadingPoint& sp) const;
  double MixturePdf(const Local& l, const Vec3d& wi) const;
  // Per-yarn constants (parallel to pattern_.yarns).
  struct YarnConst {
    double psi = 0.0, sin_psi = 0.0, cos_psi = 1.0, tan_psi = 0.0;
    double area_factor = 1.0;  // (warpArea + weftArea) / (warpArea or weftArea)
  };
  std::vector<YarnConst> yarn_const_;
  uint64_t instance_id_ = 0;
  // Tangents (shading frame) and lobe scale of the highlight band; false if the band is empty.
  bool Tangents(const IrawanPoint& p, Vec3d* t, double* scale) const;
  // The kTangents cones of the lobe strategy for wo; false if the band is empty.
  bool Cones(const IrawanPoint& p, const Vec3d& wo, woven::Cone* cones) const;

  WeavePattern pattern_;
  double repeat_u_, repeat_v_;
  yarn_lobe::Phase phase_;               // the specular's pattern constants
  std::vector<yarn_lobe::Yarn> yarn_shape_;  // per yarn: the specular's constants
  double spec_norm_ = 0.0;
};

// Shading-frame direction to the yarn frame of a warp or weft segment, and back.
Vec3d ToYarnFrame(const Vec3d& d, YarnType type);
Vec3d FromYarnFrame(const Vec3d& d, YarnType type);

// The yarn geometry functions live with the specular in brdf/yarn_lobe.h (SpineRadius,
// FilamentRadius: the spine's radius of curvature; BesselI0).
using yarn_lobe::BesselI0;
using yarn_lobe::FilamentRadius;
using yarn_lobe::SpineRadius;

}  // namespace clothfit::render
