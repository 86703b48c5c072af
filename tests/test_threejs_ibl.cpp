// The three.js r187 IBL emulation (render/preview/threejs_ibl.h).
#include <gtest/gtest.h>

#include <cmath>

#include "render/preview/threejs_ibl.h"

namespace clothfit::render {
namespace {

TEST(ThreejsIbl, RoundToHalf) {
  EXPECT_EQ(RoundToHalf(1.0f), 1.0f);
  EXPECT_EQ(RoundToHalf(1.0f + 1.0f / 4096.f), 1.0f);         // below half an ulp (2^-10)
  EXPECT_EQ(RoundToHalf(1.0f + 3.0f / 2048.f), 1.0f + 2.0f / 1024.f);  // 1.5 ulp -> ties to even
  EXPECT_EQ(RoundToHalf(70000.f), 65504.f);
  EXPECT_EQ(RoundToHalf(-0.5f), -0.5f);
}

// Checkpoints of three.js r187's DFGLUTData (docs/preview-threejs.md): (r, NoV) -> (A, B).
TEST(ThreejsIbl, DfgTableMatchesThreejsCheckpoints) {
  const Table2D& t = ThreejsDfgTable();
  ASSERT_EQ(t.width, 16);
  struct C { double r, nov, A, B; };
  const C cs[] = {{1 / 32., 1 / 32., 0.1471, 0.8521}, {31 / 32., 1 / 32., 0.8599, 0.0390},
                  {17 / 32., 17 / 32., 0.8218, 0.0165}, {9 / 32., 25 / 32., 0.9893, 0.0010},
                  {31 / 32., 31 / 32., 0.3452, 0.0001}, {1 / 32., 31 / 32., 1.0000, 0.0000}};
  for (const C& c : cs) {
    EXPECT_NEAR(t.Sample(c.nov, c.r, 0), c.A, 3e-3) << c.r << " " << c.nov;  // 2.5e-3 at NoV 1/32
    EXPECT_NEAR(t.Sample(c.nov, c.r, 1), c.B, 2e-3) << c.r << " " << c.nov;
  }
}

TEST(ThreejsIbl, ConstantEnvironmentIsConstantAtEveryMip) {
  const Environment env = Environment::Constant({0.25, 0.5, 1.0}, 64);
  const ThreejsPmrem p(env);
  EXPECT_EQ(p.face_size(), 256);
  EXPECT_EQ(p.max_lod(), 5);
  for (double mip : {0.0, 0.44, 1.0, 2.5, 3.0, 4.2, 5.0}) {
    for (const Vec3<double>& d : {Vec3<double>(1, 0, 0), Vec3<double>(0.3, -0.8, 0.5),
                                  Vec3<double>(1, 1, 1), Vec3<double>(-0.2, 0.1, -1)}) {
      const Rgb<double> c = p.Sample(d, mip);
      EXPECT_NEAR(c.r, 0.25, 1e-3);
      EXPECT_NEAR(c.g, 0.5, 2e-3);
      EXPECT_NEAR(c.b, 1.0, 3e-3);
    }
  }
}

// Seamless filtering: a lookup just either side of a cube edge (and at a corner) agrees.
TEST(ThreejsIbl, CubeLookupIsContinuousAcrossEdges) {
  const Environment env = Environment::ProceduralSky(1.0, 0.0, 256);
  const ThreejsPmrem p(env);
  const double e = 1e-7;
  for (double mip : {0.0, 1.5, 3.0, 5.0}) {
    const Rgb<double> a = p.Sample({1, 1 - e, 0.3}, mip), b = p.Sample({1 - e, 1, 0.3}, mip);
    EXPECT_NEAR(a.r, b.r, 1e-3 * (1 + std::abs(a.r)));
    const Rgb<double> c = p.Sample({1, 1 - e, 1 - e}, mip), d = p.Sample({1 - e, 1 - e, 1}, mip);
    EXPECT_NEAR(c.g, d.g, 1e-3 * (1 + std::abs(c.g)));
  }
}

}  // namespace
}  // namespace clothfit::render
