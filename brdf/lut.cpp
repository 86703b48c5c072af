#include "brdf/lut.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <type_traits>
#include <atomic>
#include <cmath>
#include <vector>

#include "brdf/terms.h"

namespace clothfit::lut {
namespace {

// Panel breakpoints in theta_h: uniform every pi/8, plus points clustered where the
// distribution varies on its own scale (GGX: tan(theta) = alpha s near the normal;
// Charlie: pi/2 - sqrt(alpha) s near the tangent plane).
std::vector<double> Breakpoints(double alpha, bool charlie) {
  std::vector<double> b;
  for (int k = 0; k <= 4; ++k) b.push_back(k * kPi / 8.0);
  for (double s : {0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 64.0}) {
    b.push_back(charlie ? 0.5 * kPi - std::sqrt(alpha) * s : std::atan(alpha * s));
  }
  std::vector<double> out;
  std::sort(b.begin(), b.end());
  for (double t : b) {
    if (t < 0.0 || t > 0.5 * kPi) continue;
    if (out.empty() || t - out.back() > 1e-9) out.push_back(t);
  }
  return out;
}

// int over the hemisphere of directions l of f(l) where f(l) = D(h) g(h, l) and the change
// of variables dl = 4 (v.h) dh is applied by the caller's g. Integrates in the half vector:
//   int_0^{pi/2} int_{valid phi} D(theta_h) g sin(theta_h) dphi dtheta_h,
// with Gauss-Legendre panels in theta_h and midpoints over the azimuth arc where
// n.l = 2 (v.h) cos(theta_h) - NoV > 0 (solved in closed form, so the integrand has no
// discontinuity in phi), using the mirror symmetry about the plane of n and v.
// `g` returns an std::array of integrands (several channels share one quadrature).
template <typename DFn, typename GFn,
          typename Acc = std::invoke_result_t<GFn, double, double, double>>
Acc HalfVectorIntegral(double NoV, double alpha, bool charlie, const Settings& s, DFn D, GFn g) {
  static thread_local GaussLegendre gl_cache(8);
  if (int(gl_cache.x.size()) != s.gauss_legendre_order)
    gl_cache = GaussLegendre(s.gauss_legendre_order);
  const GaussLegendre& gl = gl_cache;
  const double sin_v = std::sqrt(std::max(0.0, 1.0 - NoV * NoV));
  const Vec3<double> v(sin_v, 0.0, NoV);
  const std::vector<double> br = Breakpoints(alpha, charlie);
  Acc total{};
  for (size_t p = 0; p + 1 < br.size(); ++p) {
    const double t0 = br[p], t1 = br[p + 1];
    for (size_t k = 0; k < gl.x.size(); ++k) {
      const double th = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * gl.x[k];
      const double wt = 0.5 * (t1 - t0) * gl.w[k];
      const double ch = std::cos(th), sh = std::sin(th);
      // n.l > 0  <=>  cos(phi) > (NoV / (2 cos_h) - NoV cos_h) / (sin_v sin_h)
      const double num = NoV / (2.0 * ch) - NoV * ch;
      const double den = sin_v * sh;
      double phi_max;
      if (den < 1e-12) {
        phi_max = num < 0.0 ? kPi : 0.0;
      } else {
        const double c0 = num / den;
        phi_max = c0 <= -1.0 ? kPi : (c0 >= 1.0 ? 0.0 : std::acos(c0));
      }
      if (phi_max <= 0.0) continue;
      Acc acc{};
      // Midpoints phi_b = (b + 0.5) dphi by rotation recurrence (no sincos per sample).
      const double dphi = phi_max / s.azimuth_samples;
      const double cd = std::cos(dphi), sd = std::sin(dphi);
      double cphi = std::cos(0.5 * dphi), sphi = std::sin(0.5 * dphi);
      for (int b = 0; b < s.azimuth_samples; ++b) {
        const Vec3<double> h(sh * cphi, sh * sphi, ch);
        const double c_next = cphi * cd - sphi * sd;
        sphi = sphi * cd + cphi * sd;
        cphi = c_next;
        const double VoH = Dot(v, h);
        const double NoL = 2.0 * VoH * ch - NoV;
        if (NoL <= 0.0 || VoH <= 0.0) continue;
        const Acc x = g(NoL, VoH, ch);
        for (size_t m = 0; m < x.size(); ++m) acc[m] += x[m];
      }
      // 2 phi_max: both halves of the symmetric arc
      const double scale = wt * D(ch) * sh * 2.0 * phi_max / s.azimuth_samples;
      for (size_t m = 0; m < acc.size(); ++m) total[m] += scale * acc[m];
    }
  }
  return total;
}

}  // namespace

void IntegrateGgx(double NoV, double r, const Settings& s, double& A, double& B) {
  const double alpha = std::max(r * r, kMinAlpha);
  // f cos dl = D V F NoL 4 VoH dh; A and B share one quadrature.
  auto D = [alpha](double ch) { return D_GGX(alpha, ch); };
  const std::array<double, 2> ab =
      HalfVectorIntegral(NoV, alpha, false, s, D, [&](double NoL, double VoH, double) {
        const double w = V_SmithGGXCorrelated(alpha, NoV, NoL) * NoL * 4.0 * VoH;
        const double Fc = Pow5(1.0 - VoH);
        return std::array<double, 2>{w * (1.0 - Fc), w * Fc};
      });
  A = ab[0];
  B = ab[1];
}

double IntegrateClothDg(double NoV, double r, const Settings& s) {
  const double alpha = std::max(r * r, kMinAlpha);
  return HalfVectorIntegral(
      NoV, alpha, true, s, [alpha](double ch) { return D_Charlie(alpha, ch, false); },
      [&](double NoL, double VoH, double) {
        return std::array<double, 1>{V_Neubelt(NoV, NoL) * NoL * 4.0 * VoH};
      })[0];
}

double IntegrateSheenAlbedo(double NoV, double r, const Settings& s) {
  const double alpha = std::max(r * r, kMinAlpha);
  return HalfVectorIntegral(
      NoV, alpha, true, s, [alpha](double ch) { return D_Charlie(alpha, ch, false); },
      [&](double NoL, double VoH, double) {
        return std::array<double, 1>{V_Charlie(NoV, NoL, alpha) * NoL * 4.0 * VoH};
      })[0];
}

namespace {
template <typename RowFn>
void ParallelRows(int rows, const Progress& progress, RowFn fn) {
  std::atomic<int> done{0};
  tbb::parallel_for(0, rows, [&](int j) {
    fn(j);
    const int d = ++done;
    if (progress) progress(d, rows);
  });
}
}  // namespace

Table2D ComputeDfg(const Settings& s, const Progress& progress) {
  Table2D t(s.size, s.size, 3);
  t.u_axis = "NoV = (i + 0.5) / N";
  t.v_axis = "perceptual roughness r = (j + 0.5) / N; alpha = r^2";
  ParallelRows(s.size, progress, [&](int j) {
    const double r = Table2D::Centre(j, s.size);
    for (int i = 0; i < s.size; ++i) {
      const double NoV = Table2D::Centre(i, s.size);
      double A, B;
      IntegrateGgx(NoV, r, s, A, B);
      t.at(i, j, 0) = float(A);
      t.at(i, j, 1) = float(B);
      t.at(i, j, 2) = float(IntegrateClothDg(NoV, r, s));
    }
  });
  return t;
}

Table2D ComputeSheenAlbedo(const Settings& s, const Progress& progress) {
  Table2D t(s.size, s.size, 1);
  t.u_axis = "NoV = (i + 0.5) / N";
  t.v_axis = "sheen roughness r_s = (j + 0.5) / N; alpha = r_s^2";
  ParallelRows(s.size, progress, [&](int j) {
    const double r = Table2D::Centre(j, s.size);
    for (int i = 0; i < s.size; ++i) {
      t.at(i, j, 0) = float(IntegrateSheenAlbedo(Table2D::Centre(i, s.size), r, s));
    }
  });
  return t;
}

const Table2D& DefaultDfg() {
  static const Table2D table = ComputeDfg(Settings{128});
  return table;
}

const Table2D& DefaultSheenAlbedo() {
  static const Table2D table = ComputeSheenAlbedo(Settings{32});
  return table;
}

}  // namespace clothfit::lut
