// render/sampler.h: deterministic per-pixel random streams. The stream of pixel p, sample s
// depends only on (seed, p, s), never on thread scheduling, so the same seed gives a
// bit-identical image with any number of threads.
#pragma once

#include <cstdint>

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
