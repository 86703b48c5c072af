// The simple materials of render/reference/simple_bsdf.h (GGX conductor as Cycles' Glossy BSDF)
// and their fabric JSON: chi^2 of the visible-normal sampler, sample/eval/pdf consistency,
// reciprocity, the GGX normalisation, stored values, and JSON errors.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "render/reference/fabric.h"
#include "render/reference/simple_bsdf.h"
#include "tests/chi2.h"

namespace clothfit::render {
namespace {

Vec3d Dir(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

TEST(SimpleBsdf, GgxVisibleNormalSamplingPassesChi2) {
  const double roughness[] = {0.2, 0.5, 0.9};
  const double theta_o[] = {0.3, 1.0, 1.45};
  const int n_tests = 9;
  for (double r : roughness) {
    const GgxConductorBsdf bsdf(Rgbd(1, 1, 1), r);
    for (double t : theta_o) {
      const Vec3d wo = Dir(t, 0.7);
      const ShadingPoint sp{};
      testing::Chi2Config cfg;
      cfg.n_tests = n_tests;
      cfg.n_samples = 400000;
      auto sample = [&](const Point2d& u, double uc, Vec3d* wi, double* pdf) {
        BsdfSample s;
        if (!bsdf.Sample(wo, u, uc, sp, &s)) return false;
        *wi = s.wi;
        *pdf = s.pdf;
        return true;
      };
      const testing::PdfFn pdf = [&](const Vec3d& wi) { return bsdf.Pdf(wo, wi, sp); };
      const testing::Chi2Result res = testing::RunChi2(sample, pdf, cfg);
      EXPECT_TRUE(res.passed) << "roughness " << r << " theta_o " << t << ": " << res.message;
    }
  }
}

TEST(SimpleBsdf, GgxConsistentReciprocalAndNormalised) {
  const GgxConductorBsdf bsdf(Rgbd(0.9, 0.7, 0.4), 0.5);
  const ShadingPoint sp{};
  const Vec3d wo = Dir(0.8, 0.1), wi = Dir(0.4, 2.5);
  // Reciprocity f(wo, wi) = f(wi, wo).
  const Rgbd a = bsdf.Eval(wo, wi, sp), b = bsdf.Eval(wi, wo, sp);
  EXPECT_NEAR(a.r, b.r, 1e-12 * a.r);
  // Sample returns Eval and Pdf of its own direction.
  BsdfSample s;
  ASSERT_TRUE(bsdf.Sample(wo, {0.3, 0.6}, 0.5, sp, &s));
  EXPECT_NEAR(s.pdf, bsdf.Pdf(wo, s.wi, sp), 1e-12 * s.pdf);
  EXPECT_NEAR(s.f.g, bsdf.Eval(wo, s.wi, sp).g, 1e-12 * s.f.g);
  // Normalisation: integral of D(h) cos(h) over the hemisphere = 1 (midpoint rule).
  Ggx g;
  g.alpha = 0.25;
  const int n = 4000;
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double th = (i + 0.5) * 0.5 * kPi / n;
    sum += g.D(std::cos(th)) * std::cos(th) * std::sin(th) * (0.5 * kPi / n) * 2.0 * kPi;
  }
  EXPECT_NEAR(sum, 1.0, 1e-3);
  // Stored value (Walter 2007 eqs. 33-34 evaluated by hand at alpha = 0.25, normal incidence
  // and exit): D(1) = 1 / (pi alpha^2) = 5.0929582, G1 = 1, f = colour D / 4.
  const Rgbd f0 = bsdf.Eval({0, 0, 1}, {0, 0, 1}, sp);
  EXPECT_NEAR(f0.r, 0.9 * 5.0929582 / 4.0, 1e-6);
  // Below the horizon: nothing.
  EXPECT_EQ(bsdf.Eval(wo, {0.0, 0.6, -0.8}, sp).r, 0.0);
  EXPECT_EQ(bsdf.Pdf(wo, {0.0, 0.6, -0.8}, sp), 0.0);
}

TEST(SimpleBsdf, FabricJsonSelectsAndValidates) {
  const std::string head = R"({"format": "clothfit-fabric", "version": 1, "name": "x", )";
  const Fabric l = ParseFabric(head + R"("model": "lambert", "albedo": [0.5, 0.4, 0.3]})", "l.json");
  EXPECT_EQ(l.bsdf->Name(), "lambert");
  const Fabric g =
      ParseFabric(head + R"("model": "ggx_conductor", "colour": [1, 1, 1], "roughness": 0.4})", "g.json");
  EXPECT_EQ(g.bsdf->Name(), "ggx_conductor");
  EXPECT_NEAR(static_cast<const GgxConductorBsdf&>(*g.bsdf).alpha(), 0.16, 1e-12);
  for (const std::string bad : {
           R"("model": "lambert", "albedo": [0.5, 0.4]})",
           R"("model": "lambert", "albedo": [0.5, 0.4, 1.5]})",
           R"("model": "lambert", "albedo": [0.5, 0.4, 0.3], "uv_repeats": 4})",
           R"("model": "lambert", "albedo": [0.5, 0.4, 0.3], "roughness": 0.2})",
           R"("model": "ggx_conductor", "colour": [1, 1, 1]})",
           R"("model": "ggx_conductor", "colour": [1, 1, 1], "roughness": -0.1})",
           R"("model": "irawan", "preset": "cotton_canvas", "uv_repeats": 4, "albedo": [1, 1, 1]})",
       }) {
    EXPECT_THROW(ParseFabric(head + bad, "bad.json"), FabricError) << bad;
  }
}

}  // namespace
}  // namespace clothfit::render
