// The three.js r187 IBL emulation (render/preview/threejs_ibl.h).
#include <gtest/gtest.h>

#include <cmath>

#include "render/preview/threejs_ibl.h"
#include "render/scene/scene.h"

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

// RasterBarycentrics: a small camera (not the identity frame) and triangles in front of it.
Scene RasterScene() {
  Scene s;
  s.card.width = 64;
  s.card.height = 48;
  s.camera.position = {0.3, -0.2, 2.0};
  const double a = 0.3;  // camera turned about +Y: forward (-sin a, 0, -cos a)
  s.camera.forward = {-std::sin(a), 0.0, -std::cos(a)};
  s.camera.up = {0.0, 1.0, 0.0};
  s.camera.right = {std::cos(a), 0.0, -std::sin(a)};  // forward x up
  s.camera.yfov = 0.7;
  return s;
}

// The world point seen at image point (sx, sy) at view depth w (distance along forward).
Vec3<double> Unproject(const Scene& s, double sx, double sy, double w) {
  std::array<double, 3> o, d;
  s.CameraRay(sx, sy, o, d);
  const Vec3<double> D(d[0], d[1], d[2]), F(s.camera.forward[0], s.camera.forward[1], s.camera.forward[2]);
  return Vec3<double>(o[0], o[1], o[2]) + D * (w / Dot(D, F));
}

// Without snapping the barycentrics are the camera ray's hit on the triangle's plane
// (perspective-correct interpolation), inside and outside the triangle.
TEST(RasterBarycentrics, UnsnappedEqualsTheRayPlaneHit) {
  const Scene s = RasterScene();
  const std::array<Vec3<double>, 3> P{Unproject(s, 10.3, 8.7, 1.2), Unproject(s, 50.1, 12.2, 3.5),
                                      Unproject(s, 20.6, 40.9, 2.1)};
  for (const auto& q : {std::array<double, 2>{25.5, 20.5}, {5.5, 44.5}, {60.5, 2.5}}) {
    double b[3];
    ASSERT_TRUE(RasterBarycentrics(s, P, q[0], q[1], -1, b));
    std::array<double, 3> o, d;
    s.CameraRay(q[0], q[1], o, d);
    const Vec3<double> O(o[0], o[1], o[2]), D(d[0], d[1], d[2]);
    const Vec3<double> X = P[0] * b[0] + P[1] * b[1] + P[2] * b[2];
    const Vec3<double> n = Cross(P[1] - P[0], P[2] - P[0]);
    EXPECT_NEAR(Dot(X - P[0], n), 0.0, 1e-12);               // on the plane
    EXPECT_NEAR(Length(Cross(X - O, D)), 0.0, 1e-9);          // on the ray
    EXPECT_NEAR(b[0] + b[1] + b[2], 1.0, 1e-12);
  }
}

// With 4 sub-pixel bits, a vertex 1/64 pixel off the 1/16 grid rasterises as if it were on
// the grid point nearest to it (same depth): the barycentrics equal the exact ones of the
// snapped triangle, and differ from the exact ones of the unsnapped triangle.
TEST(RasterBarycentrics, SnapsVerticesToTheSubpixelGrid) {
  const Scene s = RasterScene();
  // Window y = H - image y; grid points are multiples of 1/16 in window coordinates.
  const double H = s.card.height;
  auto at = [&](double wx, double wy, double w) { return Unproject(s, wx, H - wy, w); };
  const std::array<Vec3<double>, 3> on{at(10.25, 8.5, 1.2), at(50.0625, 12.125, 3.5),
                                       at(20.5, 40.875, 2.1)};
  const std::array<Vec3<double>, 3> off{at(10.25 + 1.0 / 64, 8.5 - 1.0 / 64, 1.2),
                                        at(50.0625 - 1.0 / 48, 12.125, 3.5),
                                        at(20.5, 40.875 + 1.0 / 40, 2.1)};
  for (const auto& q : {std::array<double, 2>{25.5, 20.5}, {30.5, 30.5}, {62.5, 1.5}}) {
    double snapped[3], exact_on[3], exact_off[3];
    ASSERT_TRUE(RasterBarycentrics(s, off, q[0], q[1], kSwiftShaderSubpixelBits, snapped));
    ASSERT_TRUE(RasterBarycentrics(s, on, q[0], q[1], -1, exact_on));
    ASSERT_TRUE(RasterBarycentrics(s, off, q[0], q[1], -1, exact_off));
    double d_on = 0, d_off = 0;
    for (int k = 0; k < 3; ++k) {
      d_on = std::max(d_on, std::abs(snapped[k] - exact_on[k]));
      d_off = std::max(d_off, std::abs(snapped[k] - exact_off[k]));
    }
    EXPECT_LT(d_on, 1e-9) << q[0] << " " << q[1];
    EXPECT_GT(d_off, 1e-5) << q[0] << " " << q[1];
  }
  // On-grid vertices are not moved.
  double a[3], b[3];
  ASSERT_TRUE(RasterBarycentrics(s, on, 25.5, 20.5, kSwiftShaderSubpixelBits, a));
  ASSERT_TRUE(RasterBarycentrics(s, on, 25.5, 20.5, -1, b));
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], 1e-9);
  // A vertex behind the camera: no barycentrics.
  std::array<Vec3<double>, 3> behind = on;
  behind[1] = Vec3<double>(0.3, -0.2, 2.0) + Vec3<double>(std::sin(0.3), 0.0, std::cos(0.3));
  EXPECT_FALSE(RasterBarycentrics(s, behind, 25.5, 20.5, 4, a));
}

}  // namespace
}  // namespace clothfit::render
