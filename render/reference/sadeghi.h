// render/reference/sadeghi.h: the Sadeghi et al. microcylinder cloth BSDF for the reference tracer.
//
// Sadeghi, Bisker, De Deken, Jensen, "A Practical Microcylinder Appearance Model for Cloth
// Rendering", ACM TOG 32(2), 2013. The fabric is two threads (one per weave direction); each
// thread's tangent distribution is a list of tangent offsets. Every tangent is a fibre
// (microcylinder) that reflects at its surface and scatters in its volume. Not spatially
// varying (the uv is ignored). Formulas as implemented (docs/woven-cloth.md section 2):
//
//   orientation  thread 1 runs along the shading x axis (+u, warp), thread 2 along y (+v,
//                weft); offset theta_k tilts the tangent out of the cloth plane toward n:
//                t = cos(theta_k) d + sin(theta_k) n, thread surface normal
//                n_k = -sin(theta_k) d + cos(theta_k) n, b = t x n_k.
//   fibre angles theta_{i,o} = asin(w.t) (longitudinal, from the normal plane of t);
//                phi_{i,o} = atan2(w.b, w.n_k); phi_d = phi_i - phi_o wrapped to [-pi, pi];
//                theta_h = (theta_i + theta_o)/2, theta_d = (theta_i - theta_o)/2.
//   surface      f_r,s = F_r(eta, cos(theta_d) cos(phi_d/2)) cos(phi_d/2) g(gamma_s, theta_h)
//   volume       f_r,v = F_t F_t' ((1 - k_d) g(gamma_v, theta_h) + k_d) / (cos theta_i +
//                cos theta_o) A, with F_t = F_t' = 1 - F_r at the same angle (symmetric).
//   fibre        f_s = (f_r,s + f_r,v) / cos^2(theta_d); g = unit-area Gaussian of std gamma.
//   masking      M = (1 - u(phi_d)) M_i M_o + u(phi_d) min(M_i, M_o), M = max(0, cos phi),
//                u(phi_d) = exp(-phi_d^2 / (2 sigma^2)), sigma = 20 deg.
//   projection   P_k(wo) = max(0, wo.n_k): the tangent's visible projected area toward wo.
//   fabric       f(wo, wi) = sum_j (a_j/N_j) sum_k P_k(wo) f_s M cos(theta_i) / (Q(wo) wi.z),
//                Q(wo) = sum_j (a_j/N_j) sum_k P_k(wo) + (1 - a_1 - a_2) wo.z: the visible-
//                area-weighted average of the fibre radiances (the gaps are black); dividing
//                by wi.z converts the fibre irradiance cos(theta_i) M_i = max(0, wi.n_k) to the
//                surface convention. Q depends on wo only, so f is NOT reciprocal where the
//                tangents tilt (documented and tested); for untilted threads it is.
//
// Sampling: one-sample MIS over the mixture: cosine (probability 0.3) and a lobe strategy:
// tangent k with probability proportional to (a_j/N_j) P_k(wo) m_k (m_k: fraction of its
// volume-width cone above the surface, woven_sampling.h ConeMass), then wi near its specular
// cone (render/reference/woven_sampling.h) with the surface width (logistic scale 2 gamma_s sqrt(3)/pi)
// or the volume width (2 gamma_v sqrt(3)/pi), each with probability 1/2.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "brdf/microcylinder.h"
#include "render/reference/bsdf.h"
#include "render/reference/woven_sampling.h"

namespace clothfit::render {

struct SadeghiThread {
  double eta = 1.46;            // fibre index of refraction
  Rgbd albedo;                  // A (coloured volume albedo, scale already applied)
  double kd = 0.3;              // isotropic fraction of the volume term
  double gamma_s = 12.0;        // surface Gaussian width, degrees
  double gamma_v = 24.0;        // volume Gaussian width, degrees
  double a = 0.33;              // area coverage
  std::vector<double> offsets;  // tangent offsets, degrees
};

struct SadeghiFabric {
  std::string name;
  SadeghiThread thread[2];
};

// A thread's optical constants and offsets as brdf/microcylinder.h takes them (its colour is
// the caller's: volume_scale, 1 by default, only weighs woven's lobe). The one conversion used
// by SadeghiBsdf, woven's microcylinder lobe (fit/yarn_farfield.h) and the tests.
microcylinder::Thread MicrocylinderThread(const SadeghiThread& t, double volume_scale = 1.0);

// The six published fabrics (Sadeghi et al. 2013, table 2): linen_plain,
// silk_crepe_de_chine, polyester_satin_charmeuse, polyester_satin_charmeuse_back, silk_shot,
// velvet.
const std::vector<SadeghiFabric>& SadeghiPresets();
// Throws std::invalid_argument listing the valid names.
const SadeghiFabric& SadeghiPreset(const std::string& name);

class SadeghiBsdf final : public Bsdf {
 public:
  static constexpr double kMaskingSigmaDeg = 20.0;
  static constexpr double kCosineProbability = 0.3;

  // Throws std::invalid_argument on out-of-range parameters (eta > 1, a_j >= 0,
  // a_1 + a_2 <= 1, widths > 0, offsets in [-90, 90], at least one offset per thread).
  explicit SadeghiBsdf(SadeghiFabric fabric);

  Rgbd Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const override;
  double Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const override;
  bool Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
              BsdfSample* out) const override;
  std::string Name() const override { return "sadeghi:" + fabric_.name; }

  const SadeghiFabric& fabric() const { return fabric_; }

 private:
  static constexpr size_t kMaxTangents = 128;  // 2 threads x 64 offsets
  using Probabilities = std::array<double, kMaxTangents>;
  // Everything that depends on wo only, per tangent: Eval's outgoing fibre angles and the
  // sampling strategy's selection probabilities and cones. A path vertex calls Eval and Pdf
  // for every light and environment sample and Sample once, all with the same wo, so this is
  // kept in a one-entry thread-local memo keyed by the BSDF instance and the bits of wo (a
  // pure function of its key: the results are exactly those of recomputing it).
  struct WoTangent {
    microcylinder::Outgoing angles;  // Eval's outgoing fibre angles (brdf/microcylinder.h)
    woven::Cone cone_s, cone_v;  // the lobe strategy's cones (surface, volume width)
  };
  struct WoState {
    double q = 0.0;     // Q(wo)
    bool lobe = false;  // some tangent selectable
    double c = 1.0;     // probability of cosine sampling
    Probabilities prob{};
    std::array<WoTangent, kMaxTangents> tg;
  };
  struct Memo;
  const WoState& StateFor(const Vec3d& wo) const;
  void ComputeState(const Vec3d& wo, WoState* s) const;
  double MixturePdf(const WoState& s, const Vec3d& wi) const;

  SadeghiFabric fabric_;
  std::vector<microcylinder::Tangent> tangents_;  // brdf/microcylinder.h
  microcylinder::Thread optics_[2];  // the threads' constants (MicrocylinderThread)
  double scale_s_[2] = {0, 0}, scale_v_[2] = {0, 0};
  uint64_t instance_id_ = 0;
};

// Unpolarised Fresnel reflectance of a dielectric (eta = n_fibre / n_air) at incidence cosine
// cos_i in [0, 1].
double FresnelDielectric(double cos_i, double eta);

}  // namespace clothfit::render
