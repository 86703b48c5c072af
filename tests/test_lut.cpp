// The tables: channels against independent quadrature, texel-centre placement, sampling.
#include <gtest/gtest.h>

#include "brdf/lut.h"
#include "brdf/terms.h"
#include "tests/quadrature.h"

namespace clothfit {
namespace {

using testing::HemisphereIntegral;

double QuadGgx(double NoV, double r, bool bias) {
  const double a = r * r;
  return HemisphereIntegral(
      NoV,
      [a, bias](const Cosines<double>& c) {
        if (c.NoL <= 0) return 0.0;
        const double Fc = Pow5(1.0 - c.LoH);
        return D_GGX(a, c.NoH) * V_SmithGGXCorrelated(a, c.NoV, c.NoL) * (bias ? Fc : 1.0 - Fc);
      },
      2048, 1024);
}

double QuadCloth(double NoV, double r) {
  const double a = r * r;
  return HemisphereIntegral(NoV, [a](const Cosines<double>& c) {
    return c.NoL <= 0 ? 0.0 : D_Charlie(a, c.NoH, false) * V_Neubelt(c.NoV, c.NoL);
  });
}

double QuadSheenAlbedo(double NoV, double r) {
  const double a = r * r;
  return HemisphereIntegral(NoV, [a](const Cosines<double>& c) {
    return c.NoL <= 0 ? 0.0 : D_Charlie(a, c.NoH, false) * V_Charlie(c.NoV, c.NoL, a);
  });
}

// A 16 x 16 table: texel centres (i + 0.5)/16. Points chosen away from the grazing edge and
// from near-delta GGX (r >= 0.3), where a uniform-grid quadrature is itself trustworthy.
class LutVsQuadrature : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dfg_ = new Table2D(lut::ComputeDfg({16}));
    sheen_ = new Table2D(lut::ComputeSheenAlbedo({16}));
  }
  static void TearDownTestSuite() {
    delete dfg_;
    delete sheen_;
  }
  static Table2D* dfg_;
  static Table2D* sheen_;
};
Table2D* LutVsQuadrature::dfg_ = nullptr;
Table2D* LutVsQuadrature::sheen_ = nullptr;

TEST_F(LutVsQuadrature, ChannelsMatchIndependentQuadratureAtTexelCentres) {
  for (int j : {5, 8, 11, 15}) {    // r = 0.34, 0.53, 0.72, 0.97
    for (int i : {3, 8, 12, 15}) {  // NoV = 0.22, 0.53, 0.78, 0.97
      const double NoV = Table2D::Centre(i, 16), r = Table2D::Centre(j, 16);
      EXPECT_NEAR(dfg_->at(i, j, 0), QuadGgx(NoV, r, false), 1e-3) << "A at " << NoV << "," << r;
      EXPECT_NEAR(dfg_->at(i, j, 1), QuadGgx(NoV, r, true), 1e-3) << "B at " << NoV << "," << r;
      EXPECT_NEAR(dfg_->at(i, j, 2), QuadCloth(NoV, r), 1e-3) << "DG at " << NoV << "," << r;
      EXPECT_NEAR(sheen_->at(i, j, 0), QuadSheenAlbedo(NoV, r), 1e-3) << "E at " << NoV << "," << r;
    }
  }
}

TEST_F(LutVsQuadrature, TexelCentresAreAtIPlusHalfOverN) {
  // The value stored in texel (i, j) is the integral at ((i + 0.5)/N, (j + 0.5)/N), and it
  // is distinguishably NOT the integral at the texel corner i/N or at (i + 1)/N (the
  // suspected one-texel offset of Filament's row mapping).
  const int i = 2, j = 4;  // NoV = 0.156, r = 0.28: DG varies fast here
  const double stored = dfg_->at(i, j, 2);
  const double at_centre = QuadCloth(Table2D::Centre(i, 16), Table2D::Centre(j, 16));
  const double at_corner = QuadCloth(i / 16.0, j / 16.0);
  const double at_next_row = QuadCloth(Table2D::Centre(i, 16), (j + 1.5) / 16.0);
  EXPECT_NEAR(stored, at_centre, 1e-3);
  EXPECT_GT(std::abs(stored - at_corner), 3e-3);
  EXPECT_GT(std::abs(stored - at_next_row), 3e-3);
}

TEST_F(LutVsQuadrature, SamplingAtACentreReturnsTheTexel) {
  for (int c = 0; c < 3; ++c)
    EXPECT_FLOAT_EQ(float(dfg_->Sample(Table2D::Centre(7, 16), Table2D::Centre(9, 16), c)),
                    dfg_->at(7, 9, c));
}

TEST(Table2D, BilinearBetweenCentresAndClampToEdge) {
  Table2D t(2, 2, 1);
  t.at(0, 0, 0) = 0.f;
  t.at(1, 0, 0) = 1.f;
  t.at(0, 1, 0) = 2.f;
  t.at(1, 1, 0) = 3.f;
  EXPECT_DOUBLE_EQ(t.Sample(0.5, 0.25, 0), 0.5);  // halfway between u centres 0.25 and 0.75
  EXPECT_DOUBLE_EQ(t.Sample(0.5, 0.5, 0), 1.5);
  EXPECT_DOUBLE_EQ(t.Sample(0.0, 0.0, 0), 0.0);  // clamp to edge below the first centre
  EXPECT_DOUBLE_EQ(t.Sample(1.0, 1.0, 0), 3.0);  // and above the last
  EXPECT_DOUBLE_EQ(t.Sample(-5.0, 0.75, 0), 2.0);
  EXPECT_DOUBLE_EQ(t.Sample(std::nan(""), 0.25, 0), 0.0);  // NaN coordinates clamp too
}

TEST(Lut, DefaultTablesHaveDocumentedShapeAndAxes) {
  const Table2D& dfg = lut::DefaultDfg();
  EXPECT_EQ(dfg.width, 128);
  EXPECT_EQ(dfg.height, 128);
  EXPECT_EQ(dfg.channels, 3);
  EXPECT_NE(dfg.u_axis.find("NoV"), std::string::npos);
  EXPECT_NE(dfg.v_axis.find("roughness"), std::string::npos);
  const Table2D& e = lut::DefaultSheenAlbedo();
  EXPECT_EQ(e.width, 32);
  EXPECT_EQ(e.channels, 1);
}

}  // namespace
}  // namespace clothfit
