// brdf/stress.h: numerical stress test of every model (clothfit stress).
//
// For each model, evaluates values in double and float and ceres::Jet<double, 10>
// derivatives over random inputs (random directions, random raw cosines in [-0.25, 1.25],
// parameters uniform in and 10 % beyond their documented range) and adversarial ones
// (cosines from {0, 1e-8, 1e-4, 1 - 1e-7, 1, 1 + 1e-7, -1e-8, -0.3}, parameters at their
// bounds, 0 and 1, and beyond the clamps). Counts non-finite values or derivatives and
// negative values of the direct reflectance and of the uniform-environment IBL response,
// and the maximum float-vs-double relative deviation |f - d| / max(|d|, 1e-3).
// One more row (session 19), "woven lobe: microcylinder": woven's microcylinder yarn lobe
// (brdf/yarn_lobe.h) over random and bound-valued fabrics and adversarial directions (grazing,
// along a fibre, mirror, below the surface), double only: non-finite and negative values.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "brdf/models.h"

namespace clothfit::stress {

struct ModelReport {
  std::string model;
  int64_t evaluations = 0;
  int64_t non_finite = 0;  // any value or Jet derivative not finite
  int64_t negative = 0;    // any value < 0
  double max_rel_float_dev = 0.0;
  std::string first_failure;          // description of the first failing input, if any
  std::string worst_float_deviation;  // the input with the largest float-vs-double deviation
};

struct Report {
  std::vector<ModelReport> models;
  int64_t evaluations = 0, non_finite = 0, negative = 0;
};

// Runs `evals` evaluations in total, split evenly across models; deterministic for a seed
// whatever the thread count. `progress(done, total)` may be empty.
Report Run(int64_t evals, uint64_t seed,
           const std::function<void(int64_t, int64_t)>& progress = {});

}  // namespace clothfit::stress
