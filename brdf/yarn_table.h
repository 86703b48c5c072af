// brdf/yarn_table.h: a tabulated yarn lobe (session 11; docs/fitting.md "The far-field yarn
// lobe"): the warp and weft yarn specular of a fabric as a 4D table over (wo, wi), with, per wo,
// the lobe's image-based-light summary (albedo, mean direction, equivalent GGX roughness) for a
// split-sum read of a prefiltered environment. The values are data (baked from the fabric's
// woven BSDF by fit/yarn_farfield.h), not fitted: a renderer scales them by the fitted colours.
//
// Frame: local directions x = t (+u, warp), y = b (+v, weft), z = n (brdf/woven.h's frame).
// Grid: theta = acos(z) in [0, pi/2], n_theta bins of equal angle; phi = atan2(y, x) in
// [0, 2 pi), n_phi bins; values at bin centres, interpolated linearly in (theta, phi) of wo and
// of wi (periodic in phi, clamped in theta), i.e. 16 taps.
//   lobe[(((k * nt + to) * np + po) * nt + ti) * np + pi]   k = 0 warp, 1 weft; BRDF (1/sr),
//                                                           no cosine, no ks
//   ibl[((k * nt + to) * np + po) * 5 + c]                  c: albedo A = int T cos dw_i,
//                                                           mean direction (x, y, z) of T cos,
//                                                           roughness r (perceptual; GGX
//                                                           alpha = r^2) whose prefiltered lobe
//                                                           has the same mean cosine
// The IBL read of lobe k is A_k(wo) L_pref(dir_k(wo), r_k(wo)) (Karis 2013's split sum with the
// lobe's own albedo, direction and width in place of the DFG term, the reflection vector and
// the material roughness).
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "brdf/math.h"

namespace clothfit::yarn_table {

struct IblLobe {
  double albedo = 0.0;
  Vec3<double> dir{0.0, 0.0, 1.0};  // local, unit
  double roughness = 1.0;
};

// One read of the prefiltered environment for the yarn lobes: weight[k] of lobe k (warp,
// weft) times L_pref(dir, roughness); dir local.
struct IblTap {
  double weight[2] = {0.0, 0.0};
  Vec3<double> dir{0.0, 0.0, 1.0};
  double roughness = 1.0;
};

struct Table {
  int n_theta = 0, n_phi = 0;
  std::vector<float> lobe;  // 2 n_theta^2 n_phi^2
  std::vector<float> ibl;   // 2 n_theta n_phi 5

  bool Valid() const {
    return n_theta > 1 && n_phi > 2 &&
           lobe.size() == size_t(2) * size_t(n_theta * n_phi) * size_t(n_theta * n_phi) &&
           ibl.size() == size_t(2) * size_t(n_theta * n_phi) * 5;
  }
  // Bin centre direction of (theta bin, phi bin).
  Vec3<double> Direction(int it, int ip) const {
    const double th = (it + 0.5) * (0.5 * kPi) / n_theta, ph = (ip + 0.5) * (2.0 * kPi) / n_phi;
    return {std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)};
  }

  // Two-tap linear weights of a direction along theta (clamped) and phi (periodic).
  struct Taps {
    int t0, t1, p0, p1;
    double ft, fp;
  };
  Taps Locate(const Vec3<double>& d) const {
    const double th = std::acos(std::clamp(d.z, -1.0, 1.0));
    double ph = std::atan2(d.y, d.x);
    if (ph < 0.0) ph += 2.0 * kPi;
    Taps t;
    const double u = std::clamp(th / (0.5 * kPi) * n_theta - 0.5, 0.0, double(n_theta - 1));
    t.t0 = std::min(int(u), n_theta - 2);
    t.ft = u - t.t0;
    t.t1 = t.t0 + 1;
    double v = ph / (2.0 * kPi) * n_phi - 0.5;
    if (v < 0.0) v += n_phi;
    t.p0 = std::min(int(v), n_phi - 1);
    t.fp = v - t.p0;
    t.p1 = (t.p0 + 1) % n_phi;
    return t;
  }

  // T_warp, T_weft at (wo, wi); 0 unless both are above the surface.
  void Eval(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) const {
    out[0] = out[1] = 0.0;
    if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
    const Taps a = Locate(wo), b = Locate(wi);
    const int to[2] = {a.t0, a.t1}, po[2] = {a.p0, a.p1}, ti[2] = {b.t0, b.t1}, pi[2] = {b.p0, b.p1};
    const double wto[2] = {1.0 - a.ft, a.ft}, wpo[2] = {1.0 - a.fp, a.fp};
    const double wti[2] = {1.0 - b.ft, b.ft}, wpi[2] = {1.0 - b.fp, b.fp};
    const size_t D = size_t(n_theta) * size_t(n_phi);
    for (int k = 0; k < 2; ++k) {
      double s = 0.0;
      for (int i0 = 0; i0 < 2; ++i0)
        for (int i1 = 0; i1 < 2; ++i1) {
          const size_t o = (size_t(k) * D + size_t(to[i0]) * size_t(n_phi) + size_t(po[i1])) * D;
          const double wo_w = wto[i0] * wpo[i1];
          for (int j0 = 0; j0 < 2; ++j0)
            for (int j1 = 0; j1 < 2; ++j1)
              s += wo_w * wti[j0] * wpi[j1] *
                   double(lobe[o + size_t(ti[j0]) * size_t(n_phi) + size_t(pi[j1])]);
        }
      out[k] = s;
    }
  }

  // The environment integral of both lobes at wo as one read per wi bin (a filtered
  // quadrature: weight_k = T_k(wo, bin centre) cos(theta_i) dw_i, read at the bin centre with
  // the prefiltered roughness `row_roughness[theta bin]` whose lobe spans about the bin;
  // bins whose weight is below 1e-4 of the total are dropped). taps is cleared first; none
  // for wo below the surface or a row_roughness of the wrong size (BinRoughness()).
  void BinTaps(const Vec3<double>& wo, const std::vector<double>& row_roughness,
               std::vector<IblTap>* taps) const {
    taps->clear();
    if (!(wo.z > 0.0) || row_roughness.size() != size_t(n_theta)) return;
    const double dth = 0.5 * kPi / n_theta, dph = 2.0 * kPi / n_phi;
    double total = 0.0;
    for (int it = 0; it < n_theta; ++it)
      for (int ip = 0; ip < n_phi; ++ip) {
        const Vec3<double> wi = Direction(it, ip);
        double v[2];
        Eval(wo, wi, v);
        const double w = wi.z * std::sin((it + 0.5) * dth) * dth * dph;
        IblTap t;
        t.weight[0] = v[0] * w;
        t.weight[1] = v[1] * w;
        t.dir = wi;
        t.roughness = row_roughness[size_t(it)];
        total += t.weight[0] + t.weight[1];
        taps->push_back(t);
      }
    const double cut = 1e-4 * total;
    taps->erase(std::remove_if(taps->begin(), taps->end(),
                               [cut](const IblTap& t) { return t.weight[0] + t.weight[1] <= cut; }),
                taps->end());
  }
  // BinTaps' row roughness: a uniform cap of the bin's solid angle has mean cosine (1 + cos a)/2,
  // 2 pi (1 - cos a) = dw; the prefiltered lobe with that mean cosine (RoughnessForMeanCosine).
  std::vector<double> BinRoughness() const;

  // The IBL summary of both lobes at wo (interpolated; the direction renormalised).
  void Ibl(const Vec3<double>& wo_in, IblLobe out[2]) const {
    const Vec3<double> wo(wo_in.x, wo_in.y, std::max(wo_in.z, 1e-4));
    const Taps a = Locate(wo);
    const int to[2] = {a.t0, a.t1}, po[2] = {a.p0, a.p1};
    const double wto[2] = {1.0 - a.ft, a.ft}, wpo[2] = {1.0 - a.fp, a.fp};
    for (int k = 0; k < 2; ++k) {
      double v[5] = {0, 0, 0, 0, 0};
      for (int i0 = 0; i0 < 2; ++i0)
        for (int i1 = 0; i1 < 2; ++i1) {
          const float* e = &ibl[((size_t(k) * size_t(n_theta) + size_t(to[i0])) * size_t(n_phi) +
                                 size_t(po[i1])) * 5];
          for (int c = 0; c < 5; ++c) v[c] += wto[i0] * wpo[i1] * double(e[c]);
        }
      out[k].albedo = std::max(v[0], 0.0);
      const Vec3<double> d(v[1], v[2], v[3]);
      const double len = Length(d);
      out[k].dir = len > 1e-12 ? d * (1.0 / len) : Vec3<double>(0.0, 0.0, 1.0);
      out[k].roughness = std::clamp(v[4], 0.0, 1.0);
    }
  }
};

// Mean cosine about its axis of the prefiltered GGX lobe at perceptual roughness r (alpha =
// r^2), the split-sum prefilter's assumption n = v = R: reflected directions l = 2 (n.h) h - n
// of h ~ D(h) (n.h), weighted by n.l (Karis 2013's prefilter weights). Deterministic quadrature
// over theta_h (the lobe is symmetric about n): mu = E[(n.l)^2] / E[n.l].
// The quadrature's nodes: cos and sin of theta_h = (i + 0.5) (pi/2) / N, computed once (the
// bisection below evaluates the quadrature ~40 times per call and a yarn lobe's summary bake
// calls it twice per wo bin; session 14 measured the trig at ~20 % of a woven fit's CPU time).
struct PrefilterNodes {
  static constexpr int N = 2048;
  double c[N], s[N];
  PrefilterNodes() {
    for (int i = 0; i < N; ++i) {
      const double th = (i + 0.5) * (0.5 * kPi) / N;
      c[i] = std::cos(th);
      s[i] = std::sin(th);
    }
  }
  static const PrefilterNodes& Get() {
    static const PrefilterNodes nodes;  // thread-safe initialisation
    return nodes;
  }
};

inline double PrefilteredMeanCosine(double r) {
  const double a = std::max(r * r, 1e-4), a2 = a * a;
  const PrefilterNodes& nodes = PrefilterNodes::Get();
  double num = 0.0, den = 0.0;
  for (int i = 0; i < PrefilterNodes::N; ++i) {
    const double c = nodes.c[i], s = nodes.s[i];
    const double q = c * c * (a2 - 1.0) + 1.0;
    const double D = a2 / (kPi * q * q);
    const double nl = 2.0 * c * c - 1.0;  // n.l for l = 2 (n.h) h - n
    if (nl <= 0.0) continue;
    const double w = D * c * s * nl;  // pdf(h) dtheta (the 2 pi in phi cancels) x weight n.l
    num += w * nl;
    den += w;
  }
  return den > 0.0 ? num / den : 1.0;
}

// The roughness whose prefiltered lobe has mean cosine mu (bisection on the monotone
// PrefilteredMeanCosine; mu at or above the r = 0.045 lobe's gives 0.045, below the r = 1
// lobe's gives 1).
inline double RoughnessForMeanCosine(double mu) {
  double lo = 0.045, hi = 1.0;
  static const double mu_lo = PrefilteredMeanCosine(0.045), mu_hi = PrefilteredMeanCosine(1.0);
  if (mu >= mu_lo) return lo;
  if (mu <= mu_hi) return hi;
  for (int it = 0; it < 40; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (PrefilteredMeanCosine(mid) > mu) lo = mid;
    else hi = mid;
  }
  return 0.5 * (lo + hi);
}

inline std::vector<double> Table::BinRoughness() const {
  std::vector<double> r(size_t(std::max(n_theta, 0)));
  const double dth = 0.5 * kPi / n_theta, dph = 2.0 * kPi / n_phi;
  for (int it = 0; it < n_theta; ++it) {
    const double dw = std::sin((it + 0.5) * dth) * dth * dph;
    const double cos_a = std::max(-1.0, 1.0 - dw / (2.0 * kPi));
    r[size_t(it)] = RoughnessForMeanCosine(0.5 * (1.0 + cos_a));
  }
  return r;
}

}  // namespace clothfit::yarn_table
