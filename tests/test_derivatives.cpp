// Jet derivatives of every model and parameter against Ridders finite differences
// (ceres::GradientChecker), in the interior and near the bounds.
#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include <array>
#include <vector>

#include "brdf/models.h"

namespace clothfit {
namespace {

constexpr int kResiduals = 6;
constexpr double kRtol = 1e-5;
const std::vector<const ceres::Manifold*>* const kNoManifolds =
    nullptr;  // direct RGB + uniform-environment IBL RGB

template <int N>
struct ModelFunctor {
  ModelId model;
  Cosines<double> c;
  template <typename T>
  bool operator()(const T* x, T* out) const {
    const Cosines<T> ct{T(c.NoV), T(c.NoL), T(c.NoH), T(c.LoH)};
    Rgb<T> d, i;
    EvaluateFlat<T>(model, x, ct, d, i);
    for (int k = 0; k < 3; ++k) {
      out[k] = d[k];
      out[3 + k] = i[k];
    }
    return true;
  }
};

template <int N>
void Check(ModelId m, std::array<double, N> x, const Cosines<double>& c, double precision) {
  auto* functor = new ModelFunctor<N>{m, c};
  ceres::AutoDiffCostFunction<ModelFunctor<N>, kResiduals, N> cost(functor);
  ceres::NumericDiffOptions nd;
  // Ceres uses max(this, sqrt(eps)) as an absolute floor on the initial Ridders step, so it
  // must be small enough not to cross a roughness clamp or a LUT texel centre from the
  // probe points below (texels are 1/128 wide in r for the DFG, 1/32 for the sheen table).
  nd.ridders_relative_initial_step_size = 1e-5;
  ceres::GradientChecker checker(&cost, kNoManifolds, nd);
  ceres::GradientChecker::ProbeResults results;
  std::vector<const double*> blocks{x.data()};
  checker.Probe(blocks.data(), precision, &results);
  ASSERT_TRUE(results.return_value) << ModelName(m) << ": evaluation failed";
  // Compare the Jet Jacobian with Ridders' numeric one ourselves, with a relative tolerance
  // plus an absolute floor: derivatives below ~1e-9 are under the finite-difference noise
  // (residuals are O(1), steps 1e-5), where a purely relative test is meaningless.
  const auto& jet = results.jacobians[0];
  const auto& num = results.numeric_jacobians[0];
  for (int row = 0; row < jet.rows(); ++row) {
    for (int col = 0; col < jet.cols(); ++col) {
      const double a = jet(row, col), b = num(row, col);
      EXPECT_LE(std::abs(a - b), precision * std::max(std::abs(a), std::abs(b)) + 1e-9)
          << ModelName(m) << " d(residual " << row << ")/d(x" << col << "): jet " << a
          << " vs Ridders " << b << " at x" << col << " = " << x[size_t(col)] << ", NoV=" << c.NoV
          << " NoL=" << c.NoL;
    }
  }
}

Cosines<double> Config(double tv, double tl, double phi) {
  const Vec3<double> v(std::sin(tv), 0, std::cos(tv));
  const Vec3<double> l(std::sin(tl) * std::cos(phi), std::sin(tl) * std::sin(phi), std::cos(tl));
  return CosinesFromDirections(v, l);
}

const Cosines<double> kConfigs[] = {Config(0.3, 0.8, 2.4), Config(1.2, 0.5, 1.0),
                                    Config(0.9, 1.3, 3.0)};

// Colours distinct per channel (max3 has a kink where channels tie). Roughness values sit
// between LUT texel centres (0.5546875 = 71/128 is halfway between two), so the bilinear
// lookup is differentiable there; near-bound values are 1e-3 inside their clamps.
TEST(Derivatives, ClothAllVariantsInterior) {
  for (ModelId m :
       {ModelId::kClothFilament, ModelId::kClothFilamentSubsurface, ModelId::kClothFilamentMobile,
        ModelId::kClothSeed, ModelId::kClothSeedSubsurface}) {
    for (const auto& c : kConfigs) {
      Check<10>(m, {0.6, 0.35, 0.2, 0.8, 0.7, 0.5, 0.5546875, 0.3, 0.15, 0.05}, c, kRtol);
    }
  }
}

TEST(Derivatives, ClothNearBounds) {
  for (const auto& c : kConfigs) {
    // roughness just inside its clamp, colours near 0 and 1
    Check<10>(ModelId::kClothFilament, {0.999, 0.02, 0.5, 0.98, 0.01, 0.3, 0.0461, 0, 0, 0}, c,
              kRtol);
    Check<10>(ModelId::kClothFilamentSubsurface,
              {0.999, 0.02, 0.5, 0.98, 0.01, 0.3, 0.9987, 0.995, 0.01, 0.5}, c, kRtol);
    // sqrt(base) at a small base colour: derivative large but finite and correct
    Check<10>(ModelId::kClothSeed, {0.01, 0.2, 0.9, 0.5, 0.5, 0.5, 0.0531, 0, 0, 0}, c, kRtol);
  }
}

TEST(Derivatives, StandardInteriorAndNearBounds) {
  for (const auto& c : kConfigs) {
    Check<5>(ModelId::kStandard, {0.6, 0.35, 0.2, 0.5546875, 0.0}, c, kRtol);
    Check<5>(ModelId::kStandard, {0.6, 0.35, 0.2, 0.0461, 0.3}, c, kRtol);
    Check<5>(ModelId::kStandard, {0.98, 0.02, 0.5, 0.9987, 0.97}, c, kRtol);
  }
}

TEST(Derivatives, PhysicalSheenInteriorAndNearBounds) {
  for (const auto& c : kConfigs) {
    Check<9>(ModelId::kPhysicalSheen, {0.6, 0.35, 0.2, 0.5546875, 0.0, 0.5, 0.4, 0.3, 0.62}, c,
             kRtol);
    Check<9>(ModelId::kPhysicalSheen, {0.6, 0.35, 0.2, 0.0461, 0.1, 0.9, 0.4, 0.3, 0.0711}, c,
             kRtol);
    Check<9>(ModelId::kPhysicalSheen, {0.6, 0.35, 0.2, 0.9987, 0.0, 0.9, 0.4, 0.3, 0.9987}, c,
             kRtol);
  }
}

TEST(Derivatives, GltfSheenInteriorAndNearBounds) {
  for (const auto& c : kConfigs) {
    Check<9>(ModelId::kGltfSheen, {0.6, 0.35, 0.2, 0.5546875, 0.0, 0.5, 0.4, 0.3, 0.62}, c, kRtol);
    Check<9>(ModelId::kGltfSheen, {0.6, 0.35, 0.2, 0.0461, 0.2, 0.9, 0.4, 0.3, 0.0711}, c, kRtol);
    Check<9>(ModelId::kGltfSheen, {0.6, 0.35, 0.2, 0.9987, 0.0, 0.9, 0.4, 0.3, 0.9837}, c, kRtol);
  }
}

// physical-aniso: 15 parameters (in-plane tangent cosines: EvaluateFlat's default frame);
// anisotropy strength and rotation off zero so their derivatives act, specular colour below
// the 25 where min(0.04 c, 1) kinks.
TEST(Derivatives, PhysicalAnisoInteriorAndNearBounds) {
  for (const auto& c : kConfigs) {
    Check<15>(ModelId::kPhysicalAniso,
              {0.6, 0.35, 0.2, 0.5546875, 0.0, 0.5, 0.4, 0.3, 0.62, 0.55, 0.4, 0.8, 1.3, 0.9, 0.7},
              c, kRtol);
    Check<15>(ModelId::kPhysicalAniso,
              {0.6, 0.35, 0.2, 0.0461, 0.1, 0.9, 0.4, 0.3, 0.0711, 0.95, -2.1, 0.3, 5.0, 2.0, 1.0},
              c, kRtol);
    Check<15>(ModelId::kPhysicalAniso,
              {0.6, 0.35, 0.2, 0.9987, 0.0, 0.9, 0.4, 0.3, 0.9987, 0.02, 3.0, 0.999, 0.5, 0.6, 0.7},
              c, kRtol);
  }
}

TEST(Derivatives, GuardedSingularPointsGiveFiniteJets) {
  // The points cloth-models.md section 8 names: NoV = NoL = 0 (Neubelt), sin2h = 0 with
  // alpha > 0.5 (pow(0, g)), x = 0 inside the Charlie Lambda fit, sqrt(0) of a black base.
  using J = ceres::Jet<double, 2>;
  const J alpha(0.8, 0), x(0.0, 1);
  EXPECT_TRUE(ceres::isfinite(V_Neubelt(x, x)));
  EXPECT_TRUE(ceres::isfinite(V_Neubelt(x, x, NeubeltClamp::kOne)));
  EXPECT_TRUE(ceres::isfinite(D_Charlie(alpha, J(1.0), false)));
  EXPECT_TRUE(ceres::isfinite(D_Charlie(alpha, J(1.0), true)));
  EXPECT_TRUE(ceres::isfinite(L_CharlieLambda(x, alpha)));
  EXPECT_TRUE(ceres::isfinite(V_Charlie(x, J(0.5), alpha)));
  EXPECT_TRUE(ceres::isfinite(SafeSqrt(x)));
  EXPECT_TRUE(ceres::isfinite(D_GGX(J(0.0, 0), J(1.0, 1))));
}

// A functor whose Jet derivative is deliberately wrong (3x instead of 2x).
struct WrongDerivative {
  template <typename T>
  bool operator()(const T* x, T* out) const {
    if constexpr (std::is_same_v<T, double>) {
      out[0] = x[0] * x[0];
    } else {
      out[0] = T(x[0].a * x[0].a, x[0].v * 3.0 * x[0].a);
    }
    return true;
  }
};

TEST(Derivatives, CheckerCanFail) {
  // A functor with a deliberately wrong derivative must be rejected by the same harness.
  ceres::AutoDiffCostFunction<WrongDerivative, 1, 1> cost(new WrongDerivative);
  ceres::NumericDiffOptions nd;
  ceres::GradientChecker checker(&cost, kNoManifolds, nd);
  ceres::GradientChecker::ProbeResults results;
  const double x = 0.7;
  const double* blocks[] = {&x};
  EXPECT_FALSE(checker.Probe(blocks, 1e-5, &results));
}

}  // namespace
}  // namespace clothfit
