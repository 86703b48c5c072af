#include <gtest/gtest.h>
#include "brdf/terms.h"
TEST(Terms, LambertIsInvPi) { EXPECT_NEAR(clothfit::Fd_Lambert<double>(), 0.3183098861837907, 1e-15); }
