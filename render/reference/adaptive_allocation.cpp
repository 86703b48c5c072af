#include "render/reference/adaptive_allocation.h"

#include <algorithm>
#include <cmath>
#include <functional>

namespace clothfit::render::adaptive {

double TileErrorModel(double e, double n, double n_p, double gamma) {
  return e * std::pow(n / n_p, n < n_p ? -0.5 * gamma : -0.5);
}

namespace {

// The n minimising c n + lambda e(n) (e(n) = TileErrorModel): closed form on each power-law
// piece, n = (lambda e (g/2) n_p^(g/2) / c)^(1/(1+g/2)), clamped to the piece.
double TileCountFor(double e, double c, double lambda, double n_p, double gamma, double lo,
                    double hi) {
  c = std::max(c, 1e-6);
  if (!(e > 0.0)) return lo;
  auto piece = [&](double g, double a, double b) {
    const double n =
        std::pow(lambda * e * 0.5 * g * std::pow(n_p, 0.5 * g) / c, 1.0 / (1.0 + 0.5 * g));
    return std::clamp(n, a, b);
  };
  const double n_lo = std::clamp(n_p, lo, hi);
  const double n1 = piece(gamma, lo, n_lo), n2 = piece(1.0, n_lo, hi);
  auto f = [&](double n) { return c * n + lambda * TileErrorModel(e, n, n_p, gamma); };
  return f(n1) <= f(n2) ? n1 : n2;
}

// The variance of the mean of a tile's m one-per-cell samples from its cell pairs' squared
// differences (collapsed strata; unpaired cells count as the average pair's cells).
double MeanVariance(double pair2, int pairs, int m) {
  if (pairs < 1 || m < 1) return 0.0;
  return pair2 * (double(m) / (2.0 * pairs)) / (double(m) * m);
}

}  // namespace

Allocation Allocate(const std::vector<TilePilot>& tiles, const Params& p) {
  const size_t n = tiles.size();
  Allocation out;
  out.spp.assign(n, p.hi);
  out.tile_error.assign(n, 0.0);
  if (n == 0) return out;
  const int tiles_x = std::max(1, p.tiles_x);
  const int tiles_y = int((n + size_t(tiles_x) - 1) / size_t(tiles_x));

  // Per tile: the raw error estimate (both halves), the variance of that estimate (the
  // within-tile spread of s_p over the pilot pixels / their count) and the cost.
  std::vector<double> e_hat(n, 0.0), v_hat(n, 0.0), cost(n, 0.0), w(n, 0.0);
  std::vector<int> m(n, 0);
  double wsum = 0.0, px = 0.0, se_all = 0.0, cost_all = 0.0, val_all = 0.0;
  double vw = 0.0, vsum = 0.0, vvar = 0.0;  // stratified value and its variance
  for (size_t t = 0; t < n; ++t) {
    const TilePilot& tp = tiles[t];
    w[t] = tp.weight;
    wsum += tp.weight;
    m[t] = tp.pixels[0] + tp.pixels[1];
    if (m[t] == 0) continue;
    const double se = tp.se[0] + tp.se[1];
    const double val = tp.value[0] + tp.value[1];
    e_hat[t] = se / m[t];
    v_hat[t] = MeanVariance(tp.se_pair2, tp.pairs, m[t]);
    cost[t] = tp.cost;
    px += m[t];
    se_all += se;
    val_all += val;
    cost_all += tp.cost * m[t];
    vw += tp.weight;
    vsum += tp.weight * val / m[t];
    vvar += tp.weight * tp.weight * MeanVariance(tp.value_pair2, tp.pairs, m[t]);
  }
  if (!(px > 0.0)) return out;  // no pilot pixels at all: the budget everywhere
  const double mean_err = se_all / px, mean_cost = cost_all / px;
  for (size_t t = 0; t < n; ++t)
    if (m[t] == 0) e_hat[t] = mean_err, cost[t] = mean_cost;
  // The image's mean value: version 4 the plain mean over pilot pixels; version 5 the tiles'
  // means weighted by their pixels (stratified; its variance sum_t (w_t / W)^2 var_t, var_t
  // the collapsed-strata variance of the tile's mean (TilePilot): the pilot pixels are a
  // one-per-cell random sample of the tile's pixels, their random cell positions make them so).
  const double V = p.robust ? vsum / vw : val_all / px;
  out.value = V;
  out.value_rel_sd = V > 0.0 ? std::sqrt(vvar) / vw / V : 0.0;

  // Version 5: shrink each tile's estimate towards the mean of its (up to 8) neighbours,
  // mu_t, by the reliability R the two halves measure (linear empirical Bayes: E[e_t | data]
  // = mu_t + R (e_hat_t - mu_t), R = tau^2 / (tau^2 + var(e_hat_t))). The halves' estimates
  // e1, e2 are independent given the tile, so cov(e1 - mu, e2 - mu) / var(e1 - mu) estimates
  // the reliability of a half; Spearman-Brown gives that of both halves: 2 R_h / (1 + R_h).
  // Without it, the allocation under-samples exactly the tiles whose pilot happened to
  // under-estimate (selection on noise: the achieved error exceeds the predicted one).
  std::vector<double> e(e_hat);
  std::vector<double> post_var(n, 0.0);
  if (p.robust) {
    std::vector<double> mu(n, mean_err);
    for (int ty = 0; ty < tiles_y; ++ty)
      for (int tx = 0; tx < tiles_x; ++tx) {
        const size_t t = size_t(ty) * size_t(tiles_x) + size_t(tx);
        if (t >= n) continue;
        double s = 0.0, k = 0.0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int x = tx + dx, y = ty + dy;
            if ((dx == 0 && dy == 0) || x < 0 || y < 0 || x >= tiles_x || y >= tiles_y) continue;
            const size_t u = size_t(y) * size_t(tiles_x) + size_t(x);
            if (u >= n || m[u] == 0) continue;
            s += e_hat[u] * m[u];
            k += m[u];
          }
        if (k > 0.0) mu[t] = s / k;
      }
    double num = 0.0, den = 0.0;
    for (size_t t = 0; t < n; ++t) {
      const TilePilot& tp = tiles[t];
      if (tp.pixels[0] == 0 || tp.pixels[1] == 0) continue;
      const double d1 = tp.se[0] / tp.pixels[0] - mu[t], d2 = tp.se[1] / tp.pixels[1] - mu[t];
      num += d1 * d2;
      den += 0.5 * (d1 * d1 + d2 * d2);
    }
    const double rh = den > 0.0 ? std::clamp(num / den, 0.0, 1.0) : 1.0;
    const double R = 2.0 * rh / (1.0 + rh);
    out.reliability = R;
    for (size_t t = 0; t < n; ++t) {
      if (m[t] == 0) continue;
      e[t] = std::max(0.0, mu[t] + R * (e_hat[t] - mu[t]));
      post_var[t] = R * v_hat[t];  // the linear predictor's mean squared error
    }
  }
  for (size_t t = 0; t < n; ++t) {
    e[t] *= p.calibration;
    post_var[t] *= p.calibration * p.calibration;
  }
  out.tile_error = e;

  // For counts nt: the predicted mean error (absolute) and the variance of that prediction.
  struct Pred {
    double mean = 0.0, var = 0.0;
  };
  auto predict = [&](const std::function<double(size_t)>& count) {
    Pred pr;
    for (size_t t = 0; t < n; ++t) {
      const double f = TileErrorModel(1.0, count(t), p.n_pilot, p.gamma);
      pr.mean += w[t] * e[t] * f;
      pr.var += w[t] * w[t] * f * f * post_var[t];
    }
    pr.mean /= wsum;
    pr.var /= wsum * wsum;
    return pr;
  };
  // The bound the counts must meet, relative to the mean value: the predicted error, plus
  // (version 5) z standard deviations of the ratio predicted error / value (delta method, the
  // two treated as independent: the pixels that raise one raise the other, so this is
  // conservative).
  const double cv_v = p.robust ? out.value_rel_sd : 0.0;
  auto bound = [&](const Pred& pr) {
    if (!(V > 0.0)) return 0.0;
    if (!p.robust) return pr.mean / V;
    return (pr.mean + p.z * std::sqrt(pr.var + pr.mean * pr.mean * cv_v * cv_v)) / V;
  };
  // Counts are rounded up to multiples of 16 (the image's 16 batches) before the bound is
  // evaluated, so the bound holds for the counts actually rendered, and no tighter.
  auto round16 = [&](double x) {
    return double(std::clamp(16 * int(std::ceil(x / 16.0 - 1e-9)), p.lo, p.hi));
  };
  std::vector<double> nt(n, double(p.hi));
  auto counts = [&](double lambda) {
    for (size_t t = 0; t < n; ++t)
      nt[t] = TileCountFor(e[t], cost[t], lambda, p.n_pilot, p.gamma, p.lo, p.hi);
    if (p.robust)
      for (size_t t = 0; t < n; ++t) nt[t] = round16(nt[t]);
    return bound(predict([&](size_t t) { return nt[t]; }));
  };
  if (bound(predict([&](size_t) { return double(p.hi); })) > p.target) {
    std::fill(nt.begin(), nt.end(), double(p.hi));  // even the budget misses: the budget
  } else {
    double a = -60.0, b = 80.0;  // log lambda; the bound decreases as lambda grows
    for (int it = 0; it < 100; ++it) {
      const double mid = 0.5 * (a + b);
      (counts(std::exp(mid)) > p.target ? a : b) = mid;
    }
    counts(std::exp(b));
  }
  for (size_t t = 0; t < n; ++t) out.spp[t] = int(p.robust ? nt[t] : round16(nt[t]));
  const Pred pr = predict([&](size_t t) { return double(out.spp[t]); });
  out.predicted = V > 0.0 ? pr.mean / V : 0.0;
  out.predicted_rel_sd = pr.mean > 0.0 ? std::sqrt(pr.var) / pr.mean : 0.0;
  out.upper = bound(pr);
  return out;
}

}  // namespace clothfit::render::adaptive
