// The real-time woven model (brdf/woven.h): an independent vector transcription of its lobes,
// reductions, reciprocity, energy against the phase table, the phase table against the DFG LUT,
// conventions (twist, warp/weft), and Jet derivatives against Ridders finite differences.
#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

#include "brdf/lut.h"
#include "brdf/models.h"
#include "brdf/woven.h"

namespace clothfit {
namespace {

using V3 = Vec3<double>;

V3 Dir(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

woven::Params<double> SomeParams() {
  woven::Params<double> p;
  p.base_color = {0.45, 0.40, 0.30};
  p.specular_color = {0.55, 0.50, 0.45};
  p.roughness = 0.6;
  p.anisotropy = 0.75;
  p.twist = -9.0;
  p.warp_share = 0.55;
  p.specular_f0 = 0.07;
  p.forward_scattering = 1.7;
  p.sheen_color = {0.0, 0.0, 0.0};
  p.sheen_roughness = 0.6;
  p.diffuse_roughness = 0.4;  // the rough diffuse On in every test that does not reset it
  return p;
}

Rgb<double> Direct(const woven::Params<double>& p, const V3& v, const V3& l,
                   const woven::Options& o = {}) {
  return woven::EvalDirect(p, o, CosinesFromDirections(v, l), TangentCosinesFromDirections(v, l),
                           woven::WeaveSample<double>{}, lut::DefaultDfg(),
                           lut::DefaultWovenPhase());
}

// int Direct(p, v, l).r dl over the upper hemisphere (cosine included in Direct): midpoint
// rule in (cos theta, phi), n x n cells.
double HemisphereIntegralR(const woven::Params<double>& p, const V3& v, int n) {
  double sum = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double mu = (i + 0.5) / n, phi = 2 * kPi * (j + 0.5) / n;
      const double st = std::sqrt(1 - mu * mu);
      sum += Direct(p, v, V3(st * std::cos(phi), st * std::sin(phi), mu)).r;
    }
  return sum * 2 * kPi / (double(n) * n);
}

// Literal transcription: anisotropic GGX with the textbook form
// D = 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) and Heitz's anisotropic Smith
// Lambda(w) = (-1 + sqrt(1 + (ax^2 wx^2 + ay^2 wy^2) / wz^2)) / 2, G2 = 1 / (1 + L(v) + L(l)).
double LiteralLobe(double ax, double ay, const V3& X, const V3& Y, const V3& v, const V3& l) {
  const V3 h = Normalize(v + l);
  const double hx = Dot(h, X), hy = Dot(h, Y), hz = h.z;
  const double D = 1.0 / (kPi * ax * ay * std::pow(hx * hx / (ax * ax) + hy * hy / (ay * ay) + hz * hz, 2));
  auto lambda = [&](const V3& w) {
    const double a2 = ax * ax * Dot(w, X) * Dot(w, X) + ay * ay * Dot(w, Y) * Dot(w, Y);
    return 0.5 * (-1.0 + std::sqrt(1.0 + a2 / (w.z * w.z)));
  };
  const double G = 1.0 / (1.0 + lambda(v) + lambda(l));
  return D * G / (4.0 * v.z * l.z);
}

TEST(WovenModel, YarnLobesMatchALiteralAnisotropicGgxTranscription) {
  woven::Params<double> p = SomeParams();
  p.base_color = {0, 0, 0};
  p.specular_color = {1, 1, 1};
  p.specular_f0 = 1.0;  // Fp = 1
  const double r = p.roughness, s = p.anisotropy;
  const double aa = r * r, ac = aa + (1 - aa) * s * s;
  const double rho = p.twist * kPi / 180.0;
  const V3 aw(std::cos(rho), std::sin(rho), 0), cw(-std::sin(rho), std::cos(rho), 0);
  for (double tv : {0.2, 0.9, 1.35})
    for (double tl : {0.1, 0.7, 1.3})
      for (double phi : {0.3, 1.9, 3.0, 4.4}) {
        const V3 v = Dir(tv, 0.4), l = Dir(tl, 0.4 + phi);
        // warp lobe: across c_w with alpha_c, along a_w with alpha_a; weft: axes swapped
        const double want = p.warp_share * LiteralLobe(ac, aa, cw, aw, v, l) +
                            (1 - p.warp_share) * LiteralLobe(ac, aa, aw, cw, v, l);
        const Rgb<double> got = Direct(p, v, l);
        EXPECT_NEAR(got.r / l.z, want, 1e-9 * std::max(1.0, want)) << tv << " " << tl << " " << phi;
      }
}

TEST(WovenModel, ZeroSpecularIsLambertPlusScaledSheen) {
  woven::Params<double> p = SomeParams();
  p.diffuse_roughness = 0.0;  // Lambert (the default)
  p.specular_color = {0, 0, 0};
  p.sheen_color = {0.3, 0.2, 0.1};
  const V3 v = Dir(0.7, 0), l = Dir(0.4, 2.0);
  const Cosines<double> c = CosinesFromDirections(v, l);
  const Table2D& dfg = lut::DefaultDfg();
  const double rs = p.sheen_roughness;
  const double S = std::min(1 - 0.3 * dfg.Sample(c.NoV, rs, 2), 1 - 0.3 * dfg.Sample(c.NoL, rs, 2));
  const double dv = D_Charlie(rs * rs, c.NoH) * V_Neubelt(c.NoV, c.NoL);
  const Rgb<double> got = Direct(p, v, l);
  for (int ch = 0; ch < 3; ++ch)
    EXPECT_NEAR(got[ch], (p.sheen_color[ch] * dv + S * p.base_color[ch] / kPi) * c.NoL, 1e-12);
  // and without sheen it is exactly Lambert
  p.sheen_color = {0, 0, 0};
  EXPECT_NEAR(Direct(p, v, l).g, p.base_color.g / kPi * c.NoL, 1e-15);
}

// On (Fujii's improved Oren-Nayar, session 18), literally: f_d = base/pi A (1 + sigma s/t).
TEST(WovenModel, RoughDiffuseIsFujiiOrenNayar) {
  woven::Params<double> p = SomeParams();
  p.specular_color = {0, 0, 0};
  p.diffuse_roughness = 0.8;
  const double A = 1.0 / (1.0 + (0.5 - 2.0 / (3.0 * kPi)) * 0.8);
  for (double tv : {0.2, 0.9, 1.4})
    for (double tl : {0.1, 0.7, 1.3})
      for (double phi : {0.0, 1.0, 2.0, kPi}) {
        const V3 v = Dir(tv, 0.0), l = Dir(tl, phi);
        const double s = Dot(l, v) - l.z * v.z;
        const double t = s > 0 ? std::max(l.z, v.z) : 1.0;
        const double want = p.base_color.g / kPi * A * (1.0 + 0.8 * s / t) * l.z;
        EXPECT_NEAR(Direct(p, v, l).g, want, 1e-12 * want + 1e-15) << tv << " " << tl << " " << phi;
      }
  // forward (light behind, grazing) darker than Lambert, retro-reflection brighter
  const V3 v = Dir(1.2, 0.0);
  const double lambert = p.base_color.g / kPi * v.z;
  EXPECT_LT(Direct(p, v, Dir(1.2, kPi)).g, 0.5 * lambert);
  EXPECT_GT(Direct(p, v, v).g, 1.5 * lambert);
  // sigma = 0 is Lambert to the bit
  p.diffuse_roughness = 0.0;
  EXPECT_EQ(Direct(p, v, Dir(1.2, kPi)).g, p.base_color.g * Fd_Lambert<double>() * v.z);
}

// The IBL diffuse weight Eo(NoV) (closed-form G) equals the hemispherical integral of the
// direct diffuse (midpoint rule in (cos theta, phi)), for several sigma and views.
TEST(WovenModel, RoughDiffuseIblAlbedoMatchesBruteForceIntegral) {
  woven::Params<double> p = SomeParams();
  p.specular_color = {0, 0, 0};
  p.sheen_color = {0, 0, 0};
  p.base_color = {1, 1, 1};
  for (double sigma : {0.0, 0.3, 1.0})
    for (double nov : {0.05, 0.3, 0.7, 0.99}) {
      p.diffuse_roughness = sigma;
      const double sum = HemisphereIntegralR(p, V3(std::sqrt(1 - nov * nov), 0, nov), 400);
      const woven::WovenIblWeights<double> w = woven::EvalIbl(
          p, {}, nov, woven::WeaveSample<double>{}, lut::DefaultDfg(), lut::DefaultWovenPhase());
      EXPECT_NEAR(w.diffuse.r, sum, 2e-4) << "sigma " << sigma << " NoV " << nov;
    }
  EXPECT_EQ(woven::OnAlbedoG(1.0), 0.0);
  EXPECT_NEAR(woven::OnAlbedoG(0.0), (kPi / 2 - 2.0 / 3.0) / kPi, 1e-15);
}

TEST(WovenModel, IsReciprocal) {
  woven::Params<double> p = SomeParams();
  p.sheen_color = {0.2, 0.3, 0.1};
  for (double tv : {0.3, 1.1})
    for (double tl : {0.5, 1.4})
      for (double phi : {0.2, 2.5}) {
        const V3 v = Dir(tv, 0.1), l = Dir(tl, 0.1 + phi);
        const Rgb<double> a = Direct(p, v, l), b = Direct(p, l, v);
        EXPECT_NEAR(a.g / l.z, b.g / v.z, 1e-9 * a.g / l.z);
      }
}

TEST(WovenModel, TwistOf90DegreesSwapsWarpAndWeft) {
  woven::Params<double> p = SomeParams(), q = SomeParams();
  p.twist = 0;
  q.twist = 90;
  q.warp_share = 1 - p.warp_share;
  const V3 v = Dir(0.9, 0.3), l = Dir(1.2, 2.9);
  EXPECT_NEAR(Direct(p, v, l).r, Direct(q, v, l).r, 1e-12);
}

TEST(WovenModel, WarpLobeHighlightIsElongatedAcrossTheWarp) {
  // A cylinder along +u (warp) reflects into a cone around its axis: the microfacet normals
  // spread across the fibre (alpha_c > alpha_a). At normal view, tilting h by the same angle
  // across the fibre (towards +v) loses less than tilting it along (towards +u); LoH and NoL
  // are the same for both, so only D and the shadowing differ.
  woven::Params<double> p = SomeParams();
  p.twist = 0;
  p.warp_share = 1;
  p.base_color = {0, 0, 0};
  p.roughness = 0.3;
  p.anisotropy = 0.9;
  const V3 v(0, 0, 1);
  const double d = 0.2;
  auto reflect = [&](const V3& h) { return h * (2 * Dot(v, h)) - v; };
  const V3 along = reflect(V3(std::sin(d), 0, std::cos(d)));
  const V3 across = reflect(V3(0, std::sin(d), std::cos(d)));
  EXPECT_GT(Direct(p, v, across).r, 5 * Direct(p, v, along).r);
}

TEST(WovenModel, PhaseTableAtBetaZeroIsTheDfgAlbedo) {
  const Table2D& ph = lut::DefaultWovenPhase();
  const Table2D& dfg = lut::DefaultDfg();
  ASSERT_EQ(ph.channels, 9);
  for (double nov : {0.1, 0.3, 0.6, 0.95})
    for (double r : {0.2, 0.5, 0.8})
      EXPECT_NEAR(ph.Sample(nov, r, 0), dfg.Sample(nov, r, 0) + dfg.Sample(nov, r, 1), 2e-3)
          << nov << " " << r;
}

TEST(WovenModel, IblYarnAlbedoMatchesBruteForceIntegralOfTheDirectLobe) {
  // Isotropic lobe (anisotropy 0) at a texel-centre roughness and a beta node: the split-sum
  // yarn weight must equal int f_y cos dl (midpoint rule in (cos theta, phi)).
  woven::Params<double> p = SomeParams();
  p.base_color = {0, 0, 0};
  p.specular_color = {1, 1, 1};
  p.anisotropy = 0;
  p.roughness = 0.578125;  // texel centre (18 + 0.5)/32 of the 32-texel phase table
  p.forward_scattering = 2.0;
  p.specular_f0 = 0.1;
  for (double nov : {0.171875, 0.515625, 0.890625}) {
    const double sum = HemisphereIntegralR(p, V3(std::sqrt(1 - nov * nov), 0, nov), 600);
    const woven::WovenIblWeights<double> w = woven::EvalIbl(
        p, {}, nov, woven::WeaveSample<double>{}, lut::DefaultDfg(), lut::DefaultWovenPhase());
    EXPECT_NEAR(w.warp.r + w.weft.r, sum, 0.01 * sum + 2e-3) << "NoV " << nov;
  }
}

TEST(WovenModel, AlbedoScaledLayeringDarkensOnlyTheDiffuse) {
  woven::Params<double> p = SomeParams();
  woven::Options o;
  o.yarn_layer = woven::YarnLayer::kAlbedoScaled;
  const V3 v = Dir(1.2, 0), l = Dir(0.5, 1.0);
  const Rgb<double> add = Direct(p, v, l), scaled = Direct(p, v, l, o);
  EXPECT_LT(scaled.r, add.r);
  p.base_color = {0, 0, 0};
  EXPECT_NEAR(Direct(p, v, l).r, Direct(p, v, l, o).r, 1e-15);
}

TEST(WovenModel, EdgeCosinesGiveFiniteJets) {
  using J = ceres::Jet<double, woven::kParameterCount>;
  std::array<J, woven::kParameterCount> x;
  const std::array<double, woven::kParameterCount> v{0.5, 0.4, 0.3, 0.6, 0.5, 0.4, 0.045, 1.0,
                                                     90.0, 1.0, 0.0, 8.0, 0.3, 0.2, 0.1, 1.0,
                                                     1.0};
  for (int k = 0; k < woven::kParameterCount; ++k) x[size_t(k)] = J(v[size_t(k)], k);
  for (double a : {0.0, 1e-8, 1.0, -0.3})
    for (double t : {0.0, 1.0, -1.0}) {
      const Cosines<J> c{J(a), J(a), J(a), J(a)};
      const TangentCosines<J> tc{J(t), J(0.0), J(t), J(0.0), J(t), J(0.0)};
      Rgb<J> d, i;
      EvaluateFlat<J>(ModelId::kWoven, x.data(), c, d, i, &tc);
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_TRUE(ceres::isfinite(d[ch])) << a << " " << t;
        EXPECT_TRUE(ceres::isfinite(i[ch])) << a << " " << t;
      }
    }
}

struct WovenFunctor {
  Cosines<double> c;
  TangentCosines<double> t;
  template <typename T>
  bool operator()(const T* x, T* out) const {
    const Cosines<T> ct{T(c.NoV), T(c.NoL), T(c.NoH), T(c.LoH)};
    const TangentCosines<T> tt{T(t.ToV), T(t.BoV), T(t.ToL), T(t.BoL), T(t.ToH), T(t.BoH)};
    Rgb<T> d, i;
    EvaluateFlat<T>(ModelId::kWoven, x, ct, d, i, &tt);
    for (int k = 0; k < 3; ++k) {
      out[k] = d[k];
      out[3 + k] = i[k];
    }
    return true;
  }
};

void CheckDerivatives(std::array<double, woven::kParameterCount> x, const V3& v, const V3& l) {
  auto* f = new WovenFunctor{CosinesFromDirections(v, l), TangentCosinesFromDirections(v, l)};
  ceres::AutoDiffCostFunction<WovenFunctor, 6, woven::kParameterCount> cost(f);
  ceres::NumericDiffOptions nd;
  nd.ridders_relative_initial_step_size = 1e-5;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(&cost, no_manifolds, nd);
  ceres::GradientChecker::ProbeResults res;
  std::vector<const double*> blocks{x.data()};
  checker.Probe(blocks.data(), 1e-5, &res);
  ASSERT_TRUE(res.return_value);
  const auto& jet = res.jacobians[0];
  const auto& num = res.numeric_jacobians[0];
  for (int row = 0; row < jet.rows(); ++row)
    for (int col = 0; col < jet.cols(); ++col) {
      const double a = jet(row, col), b = num(row, col);
      EXPECT_LE(std::abs(a - b), 1e-5 * std::max(std::abs(a), std::abs(b)) + 1e-9)
          << "d(out " << row << ")/d(x" << col << "): jet " << a << " vs Ridders " << b;
    }
}

TEST(WovenModel, JetDerivativesMatchFiniteDifferences) {
  // Roughnesses between texel centres; beta between nodes; distinct colour channels.
  const std::array<double, woven::kParameterCount> interior{
      0.45, 0.40, 0.30, 0.55, 0.50, 0.45, 0.5546875, 0.7, -9.0, 0.55, 0.07, 1.7,
      0.20, 0.15, 0.10, 0.6171875, 0.35};
  const std::array<double, woven::kParameterCount> near_bounds{
      0.99, 0.02, 0.5, 0.98, 0.01, 0.3, 0.0461, 0.999, 89.0, 0.999, 0.995, 7.9,
      0.01, 0.02, 0.03, 0.0461, 0.99};
  for (const auto& x : {interior, near_bounds}) {
    CheckDerivatives(x, Dir(0.3, 0.2), Dir(0.8, 2.6));
    CheckDerivatives(x, Dir(1.3, 0.0), Dir(1.2, 3.0));  // backlit, near-mirror forward
    CheckDerivatives(x, Dir(0.9, 1.0), Dir(1.0, 1.9));
  }
}

}  // namespace
}  // namespace clothfit
