// render/reference/adaptive_allocation.h: the per-tile sample allocation of adaptive sampling
// (RenderSettings::target_error; docs/reference-renderer.md, "Adaptive sampling, version 5").
//
// Input: the stage-2 pilot of every tile (pixels on independent streams, never averaged into
// the image), split into two halves (a checkerboard of the pilot's cells). Output: each tile's
// spp, a function of the pilot only, so the image stays the ordinary fixed-n estimator in every
// pixel (no stopping bias).
//
// Conventions: a pixel's "error" s_p is the mean over R, G, B of its standard error (standard
// error of the pixel mean, from 16 batch means); its "value" v_p the mean over R, G, B of its
// mean. The image's error is the mean of s_p over all pixels divided by the mean of v_p (the
// summary's "% of mean", a fraction: 0.02 = 2 %).
#pragma once

#include <vector>

namespace clothfit::render::adaptive {

// The stage-2 pilot of one tile: one pilot pixel per cell (a stride x stride block, at a
// random position in it), cells in two halves (a checkerboard), sums by half (0, 1). For the
// variance of the tile's means, cells are paired (cells 2k and 2k + 1 of a row, one in each
// half): the collapsed-strata estimator (Cochran, Sampling Techniques, 3rd ed., 5A.12) of
// the variance of a mean of one-per-stratum samples is sum over pairs of the squared pair
// differences / m^2 (conservative: it includes the pair's strata-mean difference).
struct TilePilot {
  double weight = 0.0;  // pixels of the tile (the image's pixels, not the pilot's)
  double cost = 0.0;    // cost per camera sample (rays + first-vertex environment samples)
  int pixels[2] = {0, 0};
  double se[2] = {0.0, 0.0};     // sums of s_p
  double value[2] = {0.0, 0.0};  // sums of v_p
  int pairs = 0;                 // cell pairs
  double se_pair2 = 0.0, value_pair2 = 0.0;  // sums over pairs of (a - b)^2
};

struct Params {
  double n_pilot = 32.0;  // the stage-2 pilot's spp (16 batches)
  double gamma = 1.0;     // error ~ spp^(-gamma/2) below n_pilot (see TileErrorModel)
  double target = 0.02;   // the image's relative error to meet
  int lo = 32, hi = 512;  // spp range (multiples of 16)
  int tiles_x = 1;        // tiles per row (row-major tiles): the neighbourhoods
  // Version 5 (true): empirical-Bayes shrinkage of each tile's error towards its neighbours
  // with the reliability the two pilot halves measure, and the target met by an upper
  // confidence bound, z one-sided standard normal quantiles above the predicted error
  // (z = 1.645: 95 % under the normal approximation). false: the version-4 rule (each tile's
  // raw pilot error, the predicted error itself <= target; z unused).
  bool robust = true;
  double z = 1.645;
  double calibration = 1.0;  // multiplies every tile's error (RenderSettings::pilot_calibration)
};

struct Allocation {
  std::vector<int> spp;             // per tile, multiples of 16 in [lo, hi]
  std::vector<double> tile_error;   // the error at n_pilot the allocation used (shrunk)
  double value = 0.0;               // the pilot's image mean value (stratified by tile)
  double value_rel_sd = 0.0;        // its relative standard deviation
  double predicted = 0.0;           // predicted relative error (mean of the model)
  double predicted_rel_sd = 0.0;    // relative sd of the predicted error (tiles' posterior)
  double upper = 0.0;               // the bound the counts meet (= predicted when !robust)
  double reliability = 1.0;         // R: share of a tile's estimate kept (1 = no shrinkage)
};

// Tile t's mean standard error at n spp, from e measured at n_p: e (n / n_p)^(-g/2), g = gamma
// below n_p (stratification, the rate the pilots measured), 1 above it (no gain extrapolated).
double TileErrorModel(double e, double n, double n_p, double gamma);

// The allocation (minimum sum_t weight_t cost_t n_t subject to the bound); tiles without pilot
// pixels take the image's mean error and cost.
Allocation Allocate(const std::vector<TilePilot>& tiles, const Params& p);

}  // namespace clothfit::render::adaptive
