// brdf/microcylinder.h: the fibre scattering of Sadeghi et al.'s microcylinder cloth model
// (Sadeghi, Bisker, De Deken, Jensen, "A Practical Microcylinder Appearance Model for Cloth
// Rendering", ACM TOG 32(2), 2013; formulas as render/reference/sadeghi.h states them), one
// implementation for both users (session 19):
//   - the reference renderer's SadeghiBsdf (render/reference/sadeghi.cpp), per tangent;
//   - woven's far-field yarn lobe of kind "sadeghi-microcylinder" (brdf/yarn_lobe.h): a
//     Sadeghi fabric is not spatially varying, so its far field IS the BSDF, and a shader can
//     evaluate it in closed form (web/clothfit.js does).
//
// Local frame: x = +u (thread 1, the warp), y = +v (thread 2, the weft), z = n. Directions unit,
// wo to the viewer, wi to the light. Angles of the fabric description in DEGREES.
//
// Per tangent k (thread j, offset theta_k): t_k = cos(theta_k) d_j + sin(theta_k) n,
// n_k = -sin(theta_k) d_j + cos(theta_k) n, b_k = t_k x n_k, weight w_k = a_j / N_j.
//   Scatter() returns, for one tangent seen from wo (wo.n_k > 0),
//     surface = w_k P_k(wo) M cos(theta_i) f_r,s / cos^2(theta_d)
//     volume  = w_k P_k(wo) M cos(theta_i) f_r,v / (A cos^2(theta_d))     (per unit albedo A)
//   and the fabric's BSDF is f(wo, wi) = sum_k (surface_k + A_j volume_k) / (Q(wo) wi.z),
//   Q(wo) = sum_k w_k P_k(wo) + (1 - a_1 - a_2) wo.z.
// The arithmetic is the reference renderer's, operation for operation: when it moved here
// (session 19) a fingerprint of SadeghiBsdf::Eval over the six presets x 20,000 direction pairs
// was the same bits before and after (532a89bdf1ef3fde); tests/test_s19_microcylinder.cpp
// checks that EvalSplit recombined is SadeghiBsdf::Eval.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "brdf/math.h"

namespace clothfit::microcylinder {

inline constexpr double kDegToRad = kPi / 180.0;
inline constexpr double kMaskingSigmaDeg = 20.0;  // Sadeghi et al. eq. 10's sigma
inline constexpr int kMaxOffsets = 64;            // per thread

// Unpolarised Fresnel reflectance of a dielectric (eta = n_fibre / n_air) at incidence cosine
// cos_i in [0, 1]; 1 under total internal reflection (eta < 1 only).
inline double FresnelDielectric(double cos_i, double eta) {
  const double ci = std::clamp(cos_i, 0.0, 1.0);
  const double sin_t2 = (1.0 - ci * ci) / (eta * eta);
  if (sin_t2 >= 1.0) return 1.0;
  const double ct = std::sqrt(1.0 - sin_t2);
  const double rs = (ci - eta * ct) / (ci + eta * ct);
  const double rp = (eta * ci - ct) / (eta * ci + ct);
  return 0.5 * (rs * rs + rp * rp);
}

// The unit-area Gaussian of standard deviation sigma (radians) at x.
inline double Gaussian(double sigma, double x) {
  return std::exp(-x * x / (2.0 * sigma * sigma)) / (sigma * std::sqrt(2.0 * kPi));
}

// a wrapped to [-pi, pi].
inline double WrapAngle(double a) {
  while (a > kPi) a -= 2.0 * kPi;
  while (a < -kPi) a += 2.0 * kPi;
  return a;
}

// A thread's optical constants (the colour, A, is kept by the caller).
struct Thread {
  double eta = 1.46;      // fibre index of refraction, in (1, 3)
  double kd = 0.3;        // isotropic fraction of the volume term, [0, 1]
  double gamma_s = 12.0;  // surface Gaussian width, degrees, (0, 90]
  double gamma_v = 24.0;  // volume Gaussian width, degrees, (0, 90]
  double a = 0.33;        // area coverage, [0, 1]; a_1 + a_2 <= 1
  std::vector<double> offsets;  // tangent offsets, degrees, [-90, 90], 1..64 of them
  // EvalSplit only (woven's lobe): this thread's albedo relative to the one colour the lobe
  // carries (woven's tint_weft), so threads of one hue and different strengths share it
  // (satin: 0.035 and 0.02 x the same colour). The reference renderer ignores it.
  double volume_scale = 1.0;
};

struct Tangent {
  Vec3<double> t, n, b;  // fibre tangent, thread surface normal, t x n (local frame)
  int thread = 0;
  double weight = 0.0;  // a_j / N_j
};

// The tangent of offset `offset_deg` on thread j (0: along x, 1: along y).
inline Tangent MakeTangent(int thread, double offset_deg, double weight) {
  const Vec3<double> d = thread == 0 ? Vec3<double>(1, 0, 0) : Vec3<double>(0, 1, 0);
  const Vec3<double> n(0, 0, 1);
  const double o = offset_deg * kDegToRad;
  Tangent tg;
  tg.t = d * std::cos(o) + n * std::sin(o);
  tg.n = d * -std::sin(o) + n * std::cos(o);
  tg.b = Cross(tg.t, tg.n);
  tg.thread = thread;
  tg.weight = weight;
  return tg;
}

// What one tangent's term needs from wo alone.
struct Outgoing {
  double proj = 0.0;                                     // max(0, wo.n_k) = P_k(wo)
  double sin_o = 0.0, theta_o = 0.0, cos_o = 1.0;        // theta_o = asin(wo.t)
  double phi_o = 0.0, cos_phi_o = 1.0, sin_phi_o = 0.0;  // phi_o = atan2(wo.b, wo.n_k)
};

// Fills w for tangent tg seen from wo; the angles only when proj > 0 (else they keep their
// defaults and the tangent contributes nothing).
inline void OutgoingAngles(const Tangent& tg, const Vec3<double>& wo, Outgoing* w) {
  w->proj = std::max(0.0, Dot(wo, tg.n));
  if (w->proj <= 0.0) return;
  w->sin_o = std::clamp(Dot(wo, tg.t), -1.0, 1.0);
  w->theta_o = std::asin(w->sin_o);
  w->cos_o = std::sqrt(std::max(0.0, 1.0 - w->sin_o * w->sin_o));  // = cos(asin(sin_o))
  const double x = Dot(wo, tg.n), y = Dot(wo, tg.b);
  w->phi_o = std::atan2(y, x);
  const double r = std::sqrt(x * x + y * y);
  // cos and sin of atan2(y, x); atan2(0, 0) = 0.
  w->cos_phi_o = r > 0.0 ? x / r : 1.0;
  w->sin_phi_o = r > 0.0 ? y / r : 0.0;
}

// One tangent's surface and volume terms (above) toward wi; false (and both 0) when the
// tangent does not scatter wo -> wi (not visible, or masked). The trigonometry of the angles
// is evaluated through identities (exact in real arithmetic):
//   cos(asin(s)) = sqrt(1 - s^2);  cos(atan2(y, x)) = x / sqrt(x^2 + y^2);
//   cos(theta_d) = sqrt((1 + cos(theta_i - theta_o)) / 2), theta_d in [-pi/2, pi/2];
//   cos(phi_d / 2) = sqrt((1 + cos(phi_i - phi_o)) / 2), phi_d in [-pi, pi] (wrapped; the
//   cosine of the difference does not depend on the wrap).
inline bool Scatter(const Tangent& tg, const Outgoing& w, const Thread& th, const Vec3<double>& wi,
                    double* surface, double* volume) {
  *surface = *volume = 0.0;
  if (w.proj <= 0.0) return false;
  const double sigma_m = kMaskingSigmaDeg * kDegToRad;
  const double x = Dot(wi, tg.n), y = Dot(wi, tg.b);
  const double r = std::sqrt(x * x + y * y);
  const double cos_phi_i = r > 0.0 ? x / r : 1.0;
  // Masking-shadowing (Sadeghi et al. eq. 10): correlated when phi_d is small. Both
  // terms vanish when either factor does (m_o > 0 here, since wo.n_k > 0).
  const double m_i = std::max(0.0, cos_phi_i), m_o = std::max(0.0, w.cos_phi_o);
  if (m_i <= 0.0 || m_o <= 0.0) return false;
  const double phi_d = WrapAngle(std::atan2(y, x) - w.phi_o);
  const double uu = std::exp(-phi_d * phi_d / (2.0 * sigma_m * sigma_m));
  const double mask = (1.0 - uu) * m_i * m_o + uu * std::min(m_i, m_o);
  if (mask <= 0.0) return false;
  const double sin_i = std::clamp(Dot(wi, tg.t), -1.0, 1.0);
  const double theta_i = std::asin(sin_i);
  const double cos_i = std::sqrt(std::max(0.0, 1.0 - sin_i * sin_i));
  const double theta_h = 0.5 * (theta_i + w.theta_o);
  const double cos_diff = cos_i * w.cos_o + sin_i * w.sin_o;  // cos(theta_i - theta_o)
  const double cos_d = std::sqrt(std::clamp(0.5 * (1.0 + cos_diff), 0.0, 1.0));
  const double sin_phi_i = r > 0.0 ? y / r : 0.0;
  const double cos_phi_diff = cos_phi_i * w.cos_phi_o + sin_phi_i * w.sin_phi_o;
  const double cos_half_phi = std::sqrt(std::clamp(0.5 * (1.0 + cos_phi_diff), 0.0, 1.0));
  const double fr = FresnelDielectric(cos_d * cos_half_phi, th.eta);
  const double ft = 1.0 - fr;
  // Surface reflection (eq. 4) and volume scattering (eq. 5).
  const double f_surface = fr * cos_half_phi * Gaussian(th.gamma_s * kDegToRad, theta_h);
  // Guard: cos_i + cos_o vanishes only when both directions run along the fibre; floored
  // at 1e-4 (changes nothing elsewhere).
  const double vol = ft * ft *
                     ((1.0 - th.kd) * Gaussian(th.gamma_v * kDegToRad, theta_h) + th.kd) /
                     std::max(cos_i + w.cos_o, 1e-4);
  // Guard: cos^2(theta_d) floored at 1e-4 (theta_d within 0.6 deg of 90 deg only).
  const double inv_cd2 = 1.0 / std::max(cos_d * cos_d, 1e-4);
  const double wt = tg.weight * w.proj * mask * cos_i * inv_cd2;
  *surface = wt * f_surface;
  *volume = wt * vol;
  return true;
}

// Every tangent of a two-thread fabric, thread 1's first (offsets in order).
inline std::vector<Tangent> MakeTangents(const Thread threads[2]) {
  std::vector<Tangent> out;
  for (int j = 0; j < 2; ++j)
    for (double off : threads[j].offsets)
      out.push_back(MakeTangent(j, off, threads[j].a / double(threads[j].offsets.size())));
  return out;
}

// Tangents of one thread with the same direction merged into one of the summed weight (satin's
// warp lists offsets twice): the same BSDF in real arithmetic, fewer terms (not the reference
// renderer's order of operations, so not its bits; woven's lobe uses it).
inline std::vector<Tangent> MergeDuplicates(const std::vector<Tangent>& in) {
  std::vector<Tangent> out;
  for (const Tangent& tg : in) {
    bool merged = false;
    for (Tangent& o : out)
      if (o.thread == tg.thread && o.t.x == tg.t.x && o.t.y == tg.t.y && o.t.z == tg.t.z) {
        o.weight += tg.weight;
        merged = true;
        break;
      }
    if (!merged) out.push_back(tg);
  }
  return out;
}

// What EvalSplit needs from wo alone: per tangent its Outgoing (w[k], tangents.size() of
// them), and Q(wo) (returned). Evaluating many wi for one wo (a table bake) prepares once.
inline double PrepareOutgoing(const std::vector<Tangent>& tangents, const Thread threads[2],
                              const Vec3<double>& wo, Outgoing* w) {
  double q = (1.0 - threads[0].a - threads[1].a) * wo.z;
  for (size_t k = 0; k < tangents.size(); ++k) {
    w[k] = Outgoing{};
    OutgoingAngles(tangents[k], wo, &w[k]);
    q += tangents[k].weight * w[k].proj;
  }
  return q;
}

// EvalSplit (below) from PrepareOutgoing's w and q for this wo: the same operations in the
// same order, so the same bits.
inline void EvalSplitPrepared(const std::vector<Tangent>& tangents, const Thread threads[2],
                              const Outgoing* w, double q, const Vec3<double>& wo,
                              const Vec3<double>& wi, double out[2]) {
  out[0] = out[1] = 0.0;
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
  double s_sum = 0.0, v_sum = 0.0;
  for (size_t k = 0; k < tangents.size(); ++k) {
    const Tangent& tg = tangents[k];
    double s = 0.0, v = 0.0;
    if (Scatter(tg, w[k], threads[tg.thread], wi, &s, &v)) {
      s_sum += s;
      v_sum += v * threads[tg.thread].volume_scale;
    }
  }
  if (!(q > 0.0)) return;
  const double k = 1.0 / (q * wi.z);
  out[0] = s_sum * k;
  out[1] = v_sum * k;
}

// The fabric's BSDF split by colour: out[0] = the surface (Fresnel) reflection, white; out[1]
// = the volume scattering per unit albedo, each thread's weighted by its volume_scale (the
// fabric's BSDF is out[0] + A out[1] when thread j has albedo volume_scale_j A). 0 unless
// wo.z > 0 and wi.z > 0. No cosine.
inline void EvalSplit(const std::vector<Tangent>& tangents, const Thread threads[2],
                      const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) {
  out[0] = out[1] = 0.0;
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
  // (one wo at a time: tests and references; a bake or the preview goes through yarn_lobe::Lobe,
  // which prepares wo once)
  std::vector<Outgoing> w(tangents.size());
  const double q = PrepareOutgoing(tangents, threads, wo, w.data());
  EvalSplitPrepared(tangents, threads, w.data(), q, wo, wi, out);
}

}  // namespace clothfit::microcylinder
