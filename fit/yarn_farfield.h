// fit/yarn_farfield.h: the far-field (weave-period averaged) yarn specular of a fabric's
// Irawan-Marschner BSDF, as a yarn lobe for the preview (render/preview/preview.h
// PreviewOptions::yarn_lobe). A measurement (docs/fitting.md, "The far-field yarn lobe
// (session 11)"): how far the woven preview gets when its yarn lobe has the reference's own
// shape instead of the anisotropic GGX x phase Fresnel fit of it.
//
//   T_k(wo, wi) = E_x[ 1{yarn at x is of type k} SpecularIntegrand(x, wo, wi) I(x) specNorm ]
//
// k = warp or weft; x uniform over the weave tiles (render/reference/irawan.h: the specular
// term of Eval without the yarn's ks, fineness intensity I and umax noise included); local
// directions x = t (+u, warp), y = b (+v, weft), z = n. The reference BSDF averaged over a
// tile is then sum_k ks_k T_k(wo, wi) + mean(kd) / pi: a block of pixels that spans whole
// weave periods sees this average (fit/image_fit.h blocks).
// The expectation is a Monte Carlo estimate with `positions` stratified points (jittered on a
// sqrt x sqrt grid over one tile, each shifted by its own whole random tile) whose random numbers
// are a hash of (wo, wi): deterministic, thread-safe, unbiased; its noise averages out over a
// block's pixels and an exact IBL's directions.
#pragma once

#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "brdf/math.h"
#include "brdf/yarn_lobe.h"
#include "brdf/yarn_table.h"

namespace clothfit::render {
class IrawanBsdf;
struct MaterialPreset;
}

namespace clothfit::fit {

class YarnFarField {
 public:
  // Throws std::invalid_argument when the fabric file is not an Irawan fabric (the message
  // names the file) or positions is not a square in [1, 4096].
  YarnFarField(const std::string& fabric_path, int positions = 16);
  ~YarnFarField();
  YarnFarField(const YarnFarField&) = delete;
  YarnFarField& operator=(const YarnFarField&) = delete;

  // out[0] warp, out[1] weft; zero unless wo.z > 0 and wi.z > 0.
  void Eval(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) const;
  // The same expectation by a deterministic quadrature, the form a shader can evaluate: per
  // group of identical yarns (type, psi, umax, kappa, width, length and the half extents of
  // their cells; weight = its share of the tile's cells), the band-averaged specular
  // (IrawanBsdf::SpecularBandAverage over the band coordinate's extent) at `nodes` midpoints
  // of the other coordinate's extent (staple: along, u = clamp(along / (l/2) umax); filament:
  // across, v = clamp(across pi / w)), as LocateDraft maps them, times E[I] = 1 - e^-10
  // (fineness > 0) and specNorm. The pattern's umax noise (period > 0) is not modelled: the
  // nominal umax is used. nodes in [1, 64] (std::invalid_argument otherwise).
  // Evaluated as yarn_lobe::Lobe(Description(nodes, 0)) (brdf/yarn_lobe.h), built per call:
  // for checks; a renderer builds the Lobe once. nodes in [1, 64].
  void EvalQuadrature(const Vec3<double>& wo, const Vec3<double>& wi, double out[2],
                      int nodes = 16) const;
  // The lobe's preset description (brdf/yarn_lobe.h FarField; a preset's "woven": {"yarn_lobe"}):
  // the groups above and the pattern's constants, scale = specNorm E[I]; table_theta > 0: with
  // its environment summary on a table_theta x 2 table_theta grid baked from the quadrature
  // (deterministic). Throws std::invalid_argument on nodes outside [1, 64].
  yarn_lobe::FarField Description(int nodes, int table_theta) const;
  // The warp's share of the tile-averaged yarn specular albedo (deterministic estimate over
  // cosine-distributed wo, wi), for the record: m = warp_share at which the preview's
  // 2 m T_w + 2 (1 - m) T_f weights the lobes as the reference with equal ks does is 0.5.
  double WarpAlbedoShare(int pairs = 4096) const;
  std::string Describe() const;  // the pattern and settings, for logs and fit records
  // The lobe tabulated (brdf/yarn_table.h): T_k at the bin centres of (wo, wi) from Eval, and
  // per wo bin the IBL summary integrated over the wi bins (midpoint rule, dw = sin theta
  // dtheta dphi): A = sum T cos dw, dir = normalize(sum T cos wi dw), r =
  // RoughnessForMeanCosine(|sum T cos wi dw| / A). Parallel; deterministic.
  // jitter > 0: each entry is the average over `jitter` (wo, wi) pairs drawn uniformly in
  // angle within the two bins (a box-filtered table) instead of the bin centres' values.
  // quadrature_nodes > 0: entries from EvalQuadrature (deterministic) instead of Eval.
  yarn_table::Table Bake(int n_theta = 16, int n_phi = 32, int jitter = 0,
                         int quadrature_nodes = 0) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct FitOptions;  // fit/image_fit.h

// How a fit's previews draw the yarn lobes when they are the fabric's far-field lobe (the
// `clothfit fit --yarn-lobe` modes; recorded as the preset's fit.yarn_lobe_settings so that
// `clothfit evaluate` draws the same):
//   farfield        the Monte Carlo lobe for every light sample (needs an exact IBL)
//   table           the baked table for the lights and its split sum for the environment
//   farfield-split  the Monte Carlo lobe for the lights, the table's split sum
//   quadrature      EvalQuadrature for the lights, the split sum of a table baked from it
struct YarnLobeSettings {
  std::string mode, fabric;
  int positions = 16, nodes = 16, table_theta = 16, table_jitter = 0;
  std::string ibl = "summary";  // the table's split sum: "summary" (one read per lobe) or "bins"
};
nlohmann::json ToJson(const YarnLobeSettings& s);
// Throws std::runtime_error naming `where` and the field on a missing or bad field.
YarnLobeSettings YarnLobeSettingsFromJson(const nlohmann::json& j, const std::string& where);
// Sets options' yarn_far_field, yarn_table, yarn_table_ibl_only and yarn_quadrature_nodes and
// locks the parameters the lobe ignores (roughness, anisotropy, twist, specular_f0,
// forward_scattering). Throws std::invalid_argument on a bad mode or fabric, or a bake of more
// than 2e10 lobe evaluations. Returns a log line (empty when no table is baked).
std::string ApplyYarnLobe(const YarnLobeSettings& s, FitOptions* options);
// The product form (session 12): the fabric's lobe as a preset description (YarnFarField::
// Description(s.nodes, s.table_theta)) in options->start.yarn_lobe, so every preview of the fit
// and the written preset draw it (render/preview/preview.h ApplyPresetYarnLobe); sets the start's
// woven "ibl" to "split" and locks the parameters the lobe ignores, as ApplyYarnLobe. Throws
// std::invalid_argument on a fabric without yarns, a bad node count or a start whose woven yarn
// layer is not additive. Returns a log line.
std::string ApplyPresetYarnLobe(const YarnLobeSettings& s, FitOptions* options);

// Session 19: the far-field lobe of a Sadeghi fabric (render/reference/sadeghi.h), i.e. its
// BSDF in closed form (brdf/yarn_lobe.h FarField::Kind::kMicrocylinder), with its environment
// summary (table_theta x 2 table_theta; the wi sums wi_sub times finer, at most the narrowest
// Gaussian width apart) and the threads' volume albedo. ApplyPresetYarnLobe takes this path for
// a "sadeghi" fabric: tint_warp = 1, tint_weft = albedo, start at MicrocylinderStart. Throws
// std::invalid_argument on a fabric that is not a sadeghi fabric or whose two threads differ in
// hue (the lobe carries one volume colour; threads of one hue and different strengths are
// carried by Thread::volume_scale).
struct MicrocylinderLobe {
  yarn_lobe::FarField lobe;
  Rgb<double> albedo;
  int wi_sub = 1;
};
MicrocylinderLobe MicrocylinderDescription(const std::string& fabric_path, int table_theta = 16);
// "" when fabric_path is a sadeghi fabric the lobe carries (threads of one hue), else why not
// (what MicrocylinderDescription would throw). Throws on a fabric file that does not load.
std::string MicrocylinderRefusal(const std::string& fabric_path);
// The woven values at which the microcylinder lobe is the reference BSDF: specular_color 1,
// warp_share 0.5, base_color and sheen_color 0.
void MicrocylinderStart(render::MaterialPreset* preset);

}  // namespace clothfit::fit
