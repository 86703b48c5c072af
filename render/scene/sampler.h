// render/scene/sampler.h: deterministic per-pixel random streams. The stream of pixel p, sample s
// depends only on (seed, p, s), never on thread scheduling, so the same seed gives a
// bit-identical image with any number of threads.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

namespace clothfit::render {

// PCG32 (O'Neill 2014, "PCG: A Family of Simple Fast Space-Efficient Statistically Good
// Algorithms for Random Number Generation"), XSH-RR output.
class Pcg32 {
 public:
  Pcg32(uint64_t seed, uint64_t stream) {
    inc_ = (stream << 1u) | 1u;
    state_ = 0u;
    Next();
    state_ += seed;
    Next();
  }
  uint32_t Next() {
    const uint64_t old = state_;
    state_ = old * 6364136223846793005ull + inc_;
    const uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    const uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((-rot) & 31));
  }
  // Uniform double in [0, 1).
  double Uniform() { return double(Next()) * 0x1.0p-32; }

 private:
  uint64_t state_ = 0, inc_ = 0;
};

// Van der Corput radical inverse in base 2 (the second coordinate of a Hammersley set).
inline double RadicalInverse2(uint32_t i) {
  i = (i << 16u) | (i >> 16u);
  i = ((i & 0x55555555u) << 1u) | ((i & 0xAAAAAAAAu) >> 1u);
  i = ((i & 0x33333333u) << 2u) | ((i & 0xCCCCCCCCu) >> 2u);
  i = ((i & 0x0F0F0F0Fu) << 4u) | ((i & 0xF0F0F0F0u) >> 4u);
  i = ((i & 0x00FF00FFu) << 8u) | ((i & 0xFF00FF00u) >> 8u);
  return double(i) * 0x1.0p-32;
}

// Second coordinates of an n-point Hammersley set, stratified for any n: for n a power of two
// the radical inverses of 0..n-1 themselves (their values are k / n, one per 1/n stratum);
// otherwise (r_i + 1/2) / n with r_i the rank of RadicalInverse2(i) among the first n, which
// keeps their order and puts one point in every 1/n stratum (the first n radical inverses of a
// non-power of two leave gaps: for n = 6 none in [0.875, 1); docs/reference-renderer.md,
// "Adaptive sampling, version 5").
inline void StratifiedRadicalInverses(int n, std::vector<double>* out) {
  out->resize(size_t(n));
  if (n <= 0) return;
  const bool pow2 = (n & (n - 1)) == 0;
  for (int i = 0; i < n; ++i) (*out)[size_t(i)] = RadicalInverse2(uint32_t(i));
  if (pow2) return;
  std::vector<std::pair<double, int>> order(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) order[size_t(i)] = {(*out)[size_t(i)], i};
  std::sort(order.begin(), order.end());
  for (int r = 0; r < n; ++r) (*out)[size_t(order[size_t(r)].second)] = (r + 0.5) / n;
}

// Padded stratified points for one batch of M samples (pbrt's "padding" of low-dimensional
// sets, Pharr et al., PBR 3rd ed. 7.3). Group g has n_g points per sample, M n_g per batch:
// point j of sample m is point perm_g[m n_g + j] of an M n_g-point set, Cranley-Patterson
// rotated by a shift drawn per batch and group. 2-D groups use the Hammersley set
// ((i + 1/2) / N, StratifiedRadicalInverses), 1-D groups (i + 1/2) / N. Every point is marginally
// uniform on its unit square (the rotation), so any estimator stays unbiased; within a batch
// a group's points are stratified; groups are decorrelated from each other by independent
// random permutations; a batch draws everything from its own stream, so batch means stay
// i.i.d.
class BatchStrata {
 public:
  struct Group {
    int dim = 2;         // 1 or 2
    int per_sample = 1;  // points per sample
  };
  explicit BatchStrata(std::vector<Group> groups) : groups_(std::move(groups)) {
    perm_.resize(groups_.size());
    ys_.resize(groups_.size());
    shift_.resize(groups_.size() * 2, 0.0);
  }

  // A new batch of m_count samples from `rng` (permutations and shifts).
  void Reset(int m_count, Pcg32& rng) {
    for (size_t g = 0; g < groups_.size(); ++g) {
      const int n = m_count * groups_[g].per_sample;
      std::vector<uint32_t>& p = perm_[g];
      p.resize(size_t(n));
      for (int i = 0; i < n; ++i) p[size_t(i)] = uint32_t(i);
      for (int i = n - 1; i > 0; --i) {  // Fisher-Yates (multiply-shift bound, Lemire 2019)
        const auto j = uint32_t((uint64_t(rng.Next()) * uint64_t(i + 1)) >> 32);
        std::swap(p[size_t(i)], p[size_t(j)]);
      }
      if (groups_[g].dim == 2 && ys_[g].size() != size_t(n)) StratifiedRadicalInverses(n, &ys_[g]);
      shift_[2 * g] = rng.Uniform();
      shift_[2 * g + 1] = groups_[g].dim == 2 ? rng.Uniform() : 0.0;
    }
  }
  // Point j of group g for sample m: out[0] (and out[1] for a 2-D group).
  void Get(size_t g, int m, int j, double* out) const {
    const std::vector<uint32_t>& p = perm_[g];
    const uint32_t i = p[size_t(m) * size_t(groups_[g].per_sample) + size_t(j)];
    out[0] = Wrap((i + 0.5) / double(p.size()) + shift_[2 * g]);
    if (groups_[g].dim == 2) out[1] = Wrap(ys_[g][i] + shift_[2 * g + 1]);
  }

 private:
  // x in [0, 2) -> [0, 1).
  static double Wrap(double x) { return x >= 1.0 ? x - 1.0 : x; }
  std::vector<Group> groups_;
  std::vector<std::vector<uint32_t>> perm_;
  std::vector<std::vector<double>> ys_;  // StratifiedRadicalInverses of the group's size
  std::vector<double> shift_;
};

// SplitMix64 finaliser, to derive stream ids.
inline uint64_t Mix64(uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// The generator for (seed, pixel index, sample index). Both the state and the stream are
// hashes of all three: PCG sequences that share a state and differ only in the increment are
// correlated, which made the samples of one pixel correlated (and its standard-error
// estimate too small, caught by Reference.StandardErrorEstimateMatchesObservedSpread).
inline Pcg32 PixelSampler(uint64_t seed, uint64_t pixel, uint64_t sample) {
  const uint64_t key = Mix64(Mix64(seed) ^ Mix64(pixel + 0x632BE59BD9B4E019ull) ^
                             Mix64(sample * 0x9E3779B97F4A7C15ull + 0x85EBCA6Bull));
  return Pcg32(key, Mix64(key ^ 0xD1B54A32D192ED03ull));
}

}  // namespace clothfit::render
