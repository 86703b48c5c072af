#include "brdf/lut.h"

#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>

#include "brdf/terms.h"

namespace clothfit::lut {
namespace {

// View direction in the shading frame (n = +z), in the xz plane.
Vec3<double> ViewDir(double NoV) { return {std::sqrt(std::max(0.0, 1.0 - NoV * NoV)), 0.0, NoV}; }

Vec3<double> HalfFromAngles(double cos_h, double phi) {
  const double sin_h = std::sqrt(std::max(0.0, 1.0 - cos_h * cos_h));
  return {sin_h * std::cos(phi), sin_h * std::sin(phi), cos_h};
}

// Sum over S x S strata of g(h) with h drawn from a half-vector density, where
// `cos_theta_h(u)` inverts the radial CDF. Returns the mean of `term` over the strata.
template <typename CosThetaFn, typename TermFn>
double StratifiedMean(int S, CosThetaFn cos_theta_h, TermFn term) {
  double sum = 0.0;
  for (int a = 0; a < S; ++a) {
    const double u1 = (a + 0.5) / S;
    const double cos_h = cos_theta_h(u1);
    for (int b = 0; b < S; ++b) {
      const double phi = 2.0 * kPi * (b + 0.5) / S;
      sum += term(HalfFromAngles(cos_h, phi));
    }
  }
  return sum / (double(S) * S);
}

// Reflect v about h; returns l and v.h.
inline Vec3<double> Reflect(const Vec3<double>& v, const Vec3<double>& h, double& VoH) {
  VoH = Dot(v, h);
  return h * (2.0 * VoH) - v;
}

double CharlieCosThetaH(double u, double alpha) {
  // sin(theta_h) = u^(alpha / (2 alpha + 1))  (Estevez & Kulla 2017, importance sampling)
  const double sin_h = std::pow(u, alpha / (2.0 * alpha + 1.0));
  return std::sqrt(std::max(0.0, 1.0 - sin_h * sin_h));
}

template <typename VisFn>
double IntegrateCharlie(double NoV, double alpha, int S, VisFn vis) {
  const Vec3<double> v = ViewDir(NoV);
  return StratifiedMean(
      S, [alpha](double u) { return CharlieCosThetaH(u, alpha); },
      [&](const Vec3<double>& h) {
        double VoH;
        const Vec3<double> l = Reflect(v, h, VoH);
        const double NoL = l.z;
        const double NoH = h.z;
        if (NoL <= 0.0 || VoH <= 0.0 || NoH <= 0.0) return 0.0;
        return vis(NoL) * NoL * 4.0 * VoH / NoH;
      });
}

}  // namespace

void IntegrateGgx(double NoV, double r, int S, double& A, double& B) {
  const double alpha = std::max(r * r, kMinAlpha);
  const double a2 = alpha * alpha;
  const Vec3<double> v = ViewDir(NoV);
  double sa = 0.0, sb = 0.0;
  for (int a = 0; a < S; ++a) {
    const double u1 = (a + 0.5) / S;
    // GGX D cos sampling (Walter et al. 2007): cos^2 = (1 - u) / (1 + (a2 - 1) u)
    const double cos_h = std::sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1));
    for (int b = 0; b < S; ++b) {
      const Vec3<double> h = HalfFromAngles(cos_h, 2.0 * kPi * (b + 0.5) / S);
      double VoH;
      const Vec3<double> l = Reflect(v, h, VoH);
      const double NoL = l.z;
      if (NoL <= 0.0 || VoH <= 0.0) continue;
      const double w = V_SmithGGXCorrelated(alpha, NoV, NoL) * NoL * 4.0 * VoH / h.z;
      const double Fc = Pow5(1.0 - VoH);
      sa += (1.0 - Fc) * w;
      sb += Fc * w;
    }
  }
  A = sa / (double(S) * S);
  B = sb / (double(S) * S);
}

double IntegrateClothDg(double NoV, double r, int S) {
  const double alpha = std::max(r * r, kMinAlpha);
  return IntegrateCharlie(NoV, alpha, S, [NoV](double NoL) { return V_Neubelt(NoV, NoL); });
}

double IntegrateSheenAlbedo(double NoV, double r, int S) {
  const double alpha = std::max(r * r, kMinAlpha);
  return IntegrateCharlie(NoV, alpha, S,
                          [NoV, alpha](double NoL) { return V_Charlie(NoV, NoL, alpha); });
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
      IntegrateGgx(NoV, r, s.samples_per_axis, A, B);
      t.at(i, j, 0) = float(A);
      t.at(i, j, 1) = float(B);
      t.at(i, j, 2) = float(IntegrateClothDg(NoV, r, s.samples_per_axis));
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
      t.at(i, j, 0) =
          float(IntegrateSheenAlbedo(Table2D::Centre(i, s.size), r, s.samples_per_axis));
    }
  });
  return t;
}

const Table2D& DefaultDfg() {
  static const Table2D table = ComputeDfg(Settings{128, 64});
  return table;
}

const Table2D& DefaultSheenAlbedo() {
  static const Table2D table = ComputeSheenAlbedo(Settings{32, 64});
  return table;
}

}  // namespace clothfit::lut
