// fit/metrics/reference_halves.h: the two half-sample images a reference carries (session 6).
//
// A clothfit reference estimates each pixel from K i.i.d. batch means (render/reference/
// path_tracer.cpp). Besides the mean (R, G, B) it may store channels half.R/G/B = the mean of
// the first kA = clothfit:half_batches of the clothfit:batches = K batch means ("A"). The other
// half is then recovered exactly from the full mean:
//     B = (K x mean - kA x A) / (K - kA).
// A and B are independent (disjoint batches). With sigma_b^2 the variance of one batch mean
// (per pixel and linear channel):
//     Var(A) = sigma_b^2 / kA,  Var(B) = sigma_b^2 / (K - kA),  Var(mean) = sigma_b^2 / K,
//     E|A - B|^2 = sigma_b^2 K / (kA (K - kA)),
// so the full reference's own standard error is
//     sigma_full = RMS(A - B) x sqrt(kA (K - kA)) / K       (= RMS(A - B) / 2 when kA = K / 2).
// This holds for any linear average of pixels (block means) as well; through a non-linear
// display transform it holds to first order.
#pragma once

#include <string>

#include "fit/metrics/metrics.h"
#include "render/scene/image_io.h"

namespace clothfit::metrics {

struct ReferenceHalves {
  bool present = false;   // false: the image has no half.R/G/B channels
  int half_batches = 0;   // kA
  int batches = 0;        // K
  RgbImage a, b;          // linear RGB of the two halves (same layout as the mean)
};

// Reads half.R/G/B and the metadata clothfit:half_batches / clothfit:batches from `image`
// and recovers B from R/G/B. Without half channels: present = false. Throws
// std::invalid_argument naming `what` (the file) and the field when some but not all half
// channels exist, R/G/B are missing, or the metadata is missing or not integers with
// 1 <= kA < K.
ReferenceHalves ExtractHalves(const io::Image& image, const std::string& what);

// sqrt(kA (K - kA)) / K: multiplies RMS(A - B) into the full reference's standard error
// (see above). Throws std::invalid_argument unless 1 <= kA < K.
double HalfDifferenceToFullStderr(int half_batches, int batches);

}  // namespace clothfit::metrics
