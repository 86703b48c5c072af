#include <gtest/gtest.h>

#include "brdf/cloth.h"
#include "fit/parameter_layout.h"

namespace clothfit {
namespace {

TEST(ParameterLayout, BlocksFollowTheModelTable) {
  const fit::ParameterLayout l = fit::MakeLayout(cloth::kParameterTable, {"subsurface_color"});
  ASSERT_EQ(l.blocks.size(), 4u);
  EXPECT_EQ(l.flat_size, 10);
  EXPECT_EQ(l.Find("roughness").offset, 6);
  EXPECT_EQ(l.Find("roughness").lower, 0.045);
  EXPECT_TRUE(l.Find("subsurface_color").locked);
  EXPECT_FALSE(l.Find("base_color").locked);
  const auto x = l.Defaults(cloth::kParameterTable);
  EXPECT_EQ(x[6], 1.0);
}

TEST(ParameterLayout, UnknownLockNamesTheParameterAndTheValidOnes) {
  try {
    fit::MakeLayout(cloth::kParameterTable, {"sheen"});
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'sheen'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("sheen_color"), std::string::npos);
  }
}

}  // namespace
}  // namespace clothfit
