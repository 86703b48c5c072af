// The stress command's guarantee on a reduced count, and its determinism.
#include <gtest/gtest.h>

#include "brdf/stress.h"

namespace clothfit {
namespace {

TEST(Stress, EveryModelFiniteAndNonNegative) {
  // divisible by the 10 models and the microcylinder lobe's row (session 19)
  static_assert(kAllModels.size() + 1 == 11, "pick an evaluation count divisible by the rows");
  const stress::Report r = stress::Run(88000, 7);
  EXPECT_EQ(r.evaluations, 88000);
  ASSERT_EQ(r.models.size(), kAllModels.size() + 1);
  EXPECT_EQ(r.models.back().model, "woven lobe: microcylinder");
  for (const auto& m : r.models) {
    EXPECT_EQ(m.non_finite, 0) << m.model << ": " << m.first_failure;
    EXPECT_EQ(m.negative, 0) << m.model << ": " << m.first_failure;
    EXPECT_GT(m.evaluations, 0);
  }
}

TEST(Stress, DeterministicPerSeed) {
  const stress::Report a = stress::Run(16000, 3), b = stress::Run(16000, 3);
  ASSERT_EQ(a.models.size(), b.models.size());
  for (size_t i = 0; i < a.models.size(); ++i)
    EXPECT_EQ(a.models[i].max_rel_float_dev, b.models[i].max_rel_float_dev);
}

}  // namespace
}  // namespace clothfit
