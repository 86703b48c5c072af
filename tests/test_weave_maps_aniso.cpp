// The three.js anisotropyMap that a physical-aniso preset with weave maps draws with
// (render/preview/weave_maps.h WeaveMaps::aniso_levels / SampleAnisotropy; web/clothfit.js
// anisotropyFromWeave builds the same texture): encoding per texel, box mips of the ENCODED
// values, trilinear sampling, three.js's decode normalize(2 rg - 1) b (branch s6-web).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "render/preview/weave_maps.h"

namespace clothfit::render {
namespace {

constexpr int C = WeaveMaps::kChannels;

// A 2 x 2 tile: texel (0, 0) warp-dominated (3 : 1), (1, 0) weft-dominated (1 : 3), (0, 1)
// and (1, 1) equal (2 : 2); both channels have mean 2, so the ratios are these / 2. kd = 1.
WeaveMaps Tile() {
  const float w[4][2] = {{3, 1}, {1, 3}, {2, 2}, {2, 2}};
  std::vector<float> l0(4 * C, 1.f);
  for (int t = 0; t < 4; ++t) {
    l0[size_t(t * C)] = w[t][0];
    l0[size_t(t * C + 1)] = w[t][1];
  }
  return WeaveMaps::FromLevel0(2, 1.0, l0);  // warp, weft renormalised to mean 1 (both / 2)
}

TEST(WeaveMapsAniso, EncodingAtTexelCentresIsDirectionTimesStrength) {
  const WeaveMaps m = Tile();
  ASSERT_EQ(m.aniso_levels.size(), 2u);
  auto at = [&](int i, int j) {  // texel centre (i + 0.5) / 2, level 0
    return m.SampleAnisotropy((i + 0.5) / 2.0, (j + 0.5) / 2.0, 0.0);
  };
  EXPECT_NEAR(at(0, 0)[0], 0.5, 1e-7);  // along t, strength |3 - 1| / 4
  EXPECT_NEAR(at(0, 0)[1], 0.0, 1e-7);
  EXPECT_NEAR(at(1, 0)[0], 0.0, 1e-7);  // along b
  EXPECT_NEAR(at(1, 0)[1], 0.5, 1e-7);
  EXPECT_NEAR(at(0, 1)[0], 0.0, 1e-7);  // warp == weft: along t (warp >= weft), strength 0
  EXPECT_NEAR(at(0, 1)[1], 0.0, 1e-7);
  EXPECT_NEAR(at(1, 1)[0], 0.0, 1e-7);
  EXPECT_NEAR(at(1, 1)[1], 0.0, 1e-7);
}

TEST(WeaveMapsAniso, CoarseLevelFiltersTheEncodedTextureNotWarpAndWeft) {
  const WeaveMaps m = Tile();
  // 1 x 1 level: the average of the encoded texels, rg = ((1 + .5 + 1 + 1) / 4, (.5 + 1 + .5 +
  // .5) / 4) = (0.875, 0.625), b = (0.5 + 0.5 + 0 + 0) / 4 = 0.25; decoded: normalize(0.75, 0.25) 0.25.
  const auto v = m.SampleAnisotropy(0.3, 0.8, 1.0);
  const double len = std::hypot(0.75, 0.25);
  EXPECT_NEAR(v[0], 0.75 / len * 0.25, 1e-6);
  EXPECT_NEAR(v[1], 0.25 / len * 0.25, 1e-6);
  // Deriving it from the filtered warp/weft instead (both average to 1) would give strength 0.
  const auto s = m.Sample(0.3, 0.8, 1.0);
  EXPECT_NEAR(s[0], s[1], 1e-6);
  // Halfway between the levels: the lerp of the two levels' ENCODED values, then the decode.
  const auto h = m.SampleAnisotropy(0.25, 0.25, 0.5);  // texel (0, 0) centre at level 0
  const double r = 0.5 * (1.0 + 0.875), g = 0.5 * (0.5 + 0.625), b = 0.5 * (0.5 + 0.25);
  const double l2 = std::hypot(2 * r - 1, 2 * g - 1);
  EXPECT_NEAR(h[0], (2 * r - 1) / l2 * b, 1e-6);
  EXPECT_NEAR(h[1], (2 * g - 1) / l2 * b, 1e-6);
}

}  // namespace
}  // namespace clothfit::render
