// The tables: channels against independent quadrature, texel-centre placement, sampling.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

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
  const double stored = double(dfg_->at(i, j, 2));
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

// The on-disk table cache: a hit is bit-identical to a fresh computation; a corrupted file
// (checksum) and a file left by a different integrator (valid checksum, different values at
// the spot texels) are both detected and replaced.
class TableCache : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("clothfit_table_cache_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    const char* old = std::getenv("CLOTHFIT_TABLE_CACHE");
    had_old_ = old != nullptr;
    if (old) old_ = old;
    setenv("CLOTHFIT_TABLE_CACHE", dir_.c_str(), 1);
  }
  void TearDown() override {
    if (had_old_) setenv("CLOTHFIT_TABLE_CACHE", old_.c_str(), 1);
    else unsetenv("CLOTHFIT_TABLE_CACHE");
    std::filesystem::remove_all(dir_);
  }
  std::filesystem::path file() const { return dir_ / "dfg-16.bin"; }
  static bool Same(const Table2D& a, const Table2D& b) {
    return a.data.size() == b.data.size() &&
           std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(float)) == 0;
  }
  std::filesystem::path dir_;
  std::string old_;
  bool had_old_ = false;
};

TEST_F(TableCache, HitIsBitIdenticalToAFreshComputation) {
  const Table2D fresh = lut::ComputeDfg({16});
  const Table2D first = lut::CachedDfg({16});  // miss: computes and writes
  ASSERT_TRUE(std::filesystem::exists(file()));
  const Table2D second = lut::CachedDfg({16});  // hit
  EXPECT_TRUE(Same(fresh, first));
  EXPECT_TRUE(Same(fresh, second));
  EXPECT_EQ(second.u_axis, fresh.u_axis);
  EXPECT_EQ(second.v_axis, fresh.v_axis);
}

TEST_F(TableCache, CorruptedFileIsDetectedAndReplaced) {
  const Table2D fresh = lut::CachedDfg({16});
  {
    std::fstream f(file(), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(200);
    f.put('\x7f');  // inside the float data: the checksum no longer matches
  }
  EXPECT_TRUE(Same(lut::CachedDfg({16}), fresh));
  std::ofstream(file(), std::ios::trunc) << "garbage";  // truncated / foreign file
  EXPECT_TRUE(Same(lut::CachedDfg({16}), fresh));
}

TEST_F(TableCache, FileFromAnotherIntegratorIsDetectedBySpotTexels) {
  const Table2D fresh = lut::CachedDfg({16});
  // Rewrite the file as a different integrator would have: every value scaled by 1.001, the
  // header and a *valid* checksum kept, so only the spot check can notice.
  std::ifstream in(file(), std::ios::binary);
  std::string header;
  std::getline(in, header);
  std::vector<float> v(fresh.data.size());
  in.read(reinterpret_cast<char*>(v.data()), std::streamsize(v.size() * sizeof(float)));
  in.close();
  for (float& x : v) x *= 1.001f;
  uint64_t h = 0xcbf29ce484222325ull;
  const auto* p = reinterpret_cast<const unsigned char*>(v.data());
  for (size_t i = 0; i < v.size() * sizeof(float); ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  std::ofstream out(file(), std::ios::binary | std::ios::trunc);
  out << header << "\n";
  out.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(float)));
  out.write(reinterpret_cast<const char*>(&h), sizeof h);
  out.close();
  EXPECT_TRUE(Same(lut::CachedDfg({16}), fresh));
}

}  // namespace
}  // namespace clothfit
