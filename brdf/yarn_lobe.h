// brdf/yarn_lobe.h: the far-field yarn lobe of a woven fabric (session 12): the Irawan-Marschner
// yarn specular (Irawan & Marschner 2012, "Specular reflection from woven cloth", ACM TOG 31(1);
// Irawan's thesis, Cornell 2008, ch. 4) averaged over the weave period, in the closed form a
// real-time shader evaluates: a preset's "woven": {"yarn_lobe": {...}} (docs/preset-format.md
// "The far-field yarn lobe"), drawn by the C++ preview (render/preview) and by web/clothfit.js
// MeshWovenMaterial alike. docs/fitting.md "The far-field yarn lobe" has the measurements.
//
// This header also holds the per-point Irawan specular (SegmentSpecular) that the reference
// renderer's IrawanBsdf (render/reference/irawan.h) evaluates: one implementation for both.
//
// Local frame: x = t (+u, warp), y = b (+v, weft), z = n (brdf/woven.h's frame). Directions
// unit, wo to the viewer, wi to the light. Lengths (width, length, across, along) in weave
// cells; angles (psi, umax) in DEGREES in FarField::Group (the fabric files' unit), radians in
// the per-point structs.
//
//   T_k(wo, wi) = scale sum_{g: type k} share_g area_factor_g
//                 (1/N) sum_j SegmentSpecular(g, node j, wo, wi, band extent of g)
//
// Per group of identical yarn segments g (share = its fraction of the tile's cells; across,
// along = half extents of its cells), N midpoints s_j = -1 + (2j + 1)/N of the coordinate the
// highlight does not select (staple, psi != 0: along, u = clamp(s_j along / (l/2) umax, +-umax);
// filament, psi = 0: across, v = clamp(s_j across pi / w, +-pi/2)); the highlight band's
// indicator is replaced by its overlap with the cells (the band average). scale = the fabric's
// specular normalisation x the fineness intensity's mean (1 - e^-10 when fineness > 0). The
// pattern's umax noise is not modelled (nominal umax). T has no cosine and no ks.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "brdf/math.h"
#include "brdf/microcylinder.h"
#include "brdf/yarn_table.h"

namespace clothfit::yarn_lobe {

double SmoothStep01(double x);
// Seeliger's law (Irawan thesis 4.2): (1/4pi) c1 c2 / (c1 + c2), single-scattering albedo 1;
// 0 when either cosine is <= 0.
double Seeliger(double cos1, double cos2);
// Modified Bessel function of the first kind, order 0 (power series).
double BesselI0(double x);
// Radius of curvature of the yarn spine at inclination |u| (docs/woven-cloth.md 1.3).
double SpineRadius(double u_abs, double umax, double kappa, double width, double length);
// The radius the filament (psi = 0) specular reads at u_h with filament smoothing ss:
// SpineRadius(min(|u_h|, (1 - ss) umax), (1 - ss) umax, ...) (Mitsuba 0.5 irawan.cpp);
// ss = 0 gives SpineRadius(|u_h|, umax, ...).
double FilamentRadius(double u_h_abs, double umax, double ss, double kappa, double width,
                      double length);
// Shading frame -> yarn frame of a warp (x' = -y, y' = x) or weft (x' = -x, y' = -y) segment.
inline Vec3<double> ToYarnFrame(const Vec3<double>& d, bool warp) {
  return warp ? Vec3<double>(-d.y, d.x, d.z) : Vec3<double>(-d.x, -d.y, d.z);
}

// The pattern-wide constants of the specular.
struct Phase {
  double alpha = 0.0, beta = 0.0;  // phase: alpha + exp(beta * -wi.wo) von_mises_norm
  double von_mises_norm = 0.0;     // 1 / (2 pi I0(|beta|))
  double h_width = 0.5;            // the highlight band's width, a fraction of the segment
  double ss = 0.0;                 // filament smoothing, 0 <= ss < 1
};
// One yarn type's constants (angles in radians).
struct Yarn {
  bool warp = true;
  double psi = 0.0, sin_psi = 0.0, tan_psi = 0.0;
  double width = 1.0, length = 1.0, kappa = 0.0;
  double area_factor = 1.0;  // (warp area + weft area) / (this type's area)
};
// A yarn's constants from its description (psi in DEGREES, as the weave files write it).
Yarn MakeYarn(bool warp, double psi_deg, double width, double length, double kappa,
              double area_factor);
// A point on a segment (render/reference/irawan.h IrawanPoint's geometric part).
struct Point {
  double umax = 0.0;              // radians
  double across = 0.0, along = 0.0;  // from the segment centre, cells
  double u = 0.0, v = 0.0, sin_u = 0.0, cos_u = 1.0;
  double spine_radius = 0.0;      // SpineRadius(|u|, umax, ...) (staple yarns only)
};

// The Irawan specular f_s of the yarn at point p, without ks, intensity and specNorm; wo_s,
// wi_s in the shading frame; 0 unless both are above the surface. band_extent = 0: the
// highlight band's indicator at p; > 0: its mean over the band coordinate (staple: across,
// filament: along) uniform in [-band_extent, band_extent] (the band's overlap with the cells).
double SegmentSpecular(const Phase& ph, const Yarn& y, const Point& p, const Vec3<double>& wo_s,
                       const Vec3<double>& wi_s, double band_extent);

// The preset's description of the lobe ("woven": {"yarn_lobe"}; read and written by
// render/scene/material.cpp, made by fit/yarn_farfield.h from an Irawan fabric).
//
// Kind kMicrocylinder (session 19; preset "model": "sadeghi-microcylinder"): the far field of a
// Sadeghi fabric (render/reference/sadeghi.h), which does not vary over the cloth, so its far
// field is its BSDF: out[0] = the fibres' surface (Fresnel) reflection, white; out[1] = their
// volume scattering per unit albedo (brdf/microcylinder.h EvalSplit). With tint_warp = 1,
// tint_weft = the threads' albedo A, specular_color 1 and warp_share 0.5 woven's yarn term
// ks (tint_w 2 m out[0] + tint_f 2 (1 - m) out[1]) is the reference BSDF exactly; warp_share
// then weighs surface against volume. Only `threads` and `ibl` are used (groups, nodes and the
// Irawan constants are ignored).
struct FarField {
  enum class Kind { kIrawan, kMicrocylinder };
  Kind kind = Kind::kIrawan;
  microcylinder::Thread threads[2];  // kMicrocylinder
  struct Group {
    bool warp = true;
    double share = 0.0;  // fraction of the tile's cells
    double psi = 0.0, umax = 0.0;  // degrees
    double kappa = 0.0, width = 1.0, length = 1.0;
    double across = 0.5, along = 0.5;  // half extents of the group's cells
    double area_factor = 1.0;
  };
  static constexpr int kMaxGroups = 16, kMaxNodes = 64;  // silk charmeuse has 10 groups
  std::string fabric;  // where it was derived from (informative)
  int nodes = 16;
  double alpha = 0.0, beta = 0.0, h_width = 0.5, ss = 0.0, scale = 1.0;
  std::vector<Group> groups;
  // The environment summary (yarn_table.h Table::ibl; `lobe` left empty): per wo bin and lobe
  // the albedo, mean direction and equivalent roughness, baked from Eval (BakeIbl).
  yarn_table::Table ibl;
};

// Throws std::invalid_argument "<where>.<field>: <what>" (where names the object) on a value out of its documented
// range (kMicrocylinder: threads[j].eta in (1, 3), kd in [0, 1], gamma_s, gamma_v in (0, 90],
// a in [0, 1] with a_1 + a_2 <= 1, volume_scale in [0, 1], 1..64 offsets each in [-90, 90];
// then the ibl table as
// below); kIrawan: nodes in [1, 64], 1..16 groups, share in (0, 1], width, length, across, along > 0,
// umax in (0, 90) deg with width sin(umax) < length, |psi| < 90 deg, kappa >= -1, area_factor
// >= 1, 0 <= ss < 1, 0 < h_width <= 1, alpha, beta >= 0, scale >= 0, all finite; an ibl
// table with n_theta in [2, 64], n_phi in [3, 128], 2 n_theta n_phi 5 finite values (or none:
// n_theta = n_phi = 0 and no values, when `need_ibl` is false).
void Validate(const FarField& f, const std::string& where, bool need_ibl = true);

// The lobe, prepared for evaluation (per-group constants and per-node points).
class Lobe {
 public:
  explicit Lobe(const FarField& f);  // Validate(f, "yarn lobe", false) first
  // out[0] = T_warp, out[1] = T_weft (above).
  void Eval(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) const;
  const FarField& description() const { return f_; }

 private:
  FarField f_;
  Phase phase_;
  struct G {
    Yarn yarn;
    double weight = 0.0;  // scale share area_factor / nodes
    double band_extent = 0.0;
    std::vector<Point> nodes;
    std::vector<double> sin_v, cos_v;  // per node: sin and cos of its v (filament yarns)
  };
  // sum over g's nodes of SegmentSpecular (bit-identical), the node-independent work done once
  double GroupSum(const G& g, const Vec3<double>& wo, const Vec3<double>& wi) const;
  std::vector<G> groups_;
  std::vector<microcylinder::Tangent> tangents_;  // kMicrocylinder (duplicates merged)
  uint64_t id_ = 0;  // kMicrocylinder: keys Eval's per-thread cache of the wo-only work
};

// The table of a lobe `eval` (T_warp, T_weft at (wo, wi)) on an n_theta x n_phi grid over wo
// and wi (yarn_table.h Table): per wo bin the environment summary (midpoint rule over the wi
// bin centres, dw = sin theta dtheta dphi): A = sum T cos dw, dir = normalize(sum T cos wi dw),
// r = RoughnessForMeanCosine(|sum T cos wi dw| / A); with_lobe: also Table::lobe = T at the bin
// centres. eval must be thread-safe (parallel over wo); deterministic when eval is. Throws
// std::invalid_argument on a grid outside [2, 64] x [3, 128]. wi_sub > 1: the summary's wi
// sums run over a wi_sub times finer midpoint grid in theta and phi (wo stays at the bin
// centres), for lobes narrower than a bin; [1, 16], 1 when with_lobe.
yarn_table::Table Bake(const std::function<void(const Vec3<double>& wo, const Vec3<double>& wi,
                                                double out[2])>& eval,
                       int n_theta, int n_phi, bool with_lobe, int wi_sub = 1);

}  // namespace clothfit::yarn_lobe
