// render/reference/path_tracer.h: the reference renderer. Unidirectional path tracing with next-event
// estimation, environment importance sampling, MIS (power heuristic) between BSDF and
// environment sampling, Russian roulette, deterministic per-pixel streams and TBB tiles.
// At the camera ray's hit: first_env_samples environment samples (multi-sample MIS), and the
// random numbers of that vertex stratified across the pixel's batch (docs/reference-renderer.md).
//
// What is skipped when the scene does not need it: no environment -> no environment
// sampling (escaping rays see the card's background only from the camera); punctual lights
// are delta lights -> sampled once each, no MIS; AOV buffers only when requested.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "render/reference/bsdf.h"
#include "render/scene/environment.h"
#include "render/scene/scene.h"

namespace clothfit::render {

struct AovSet {
  bool normal = false, position = false, uv = false, tangent = false, depth = false;
  bool any() const { return normal || position || uv || tangent || depth; }
};

// Version of the reference renderer's sampling: bumped whenever a change alters the images a
// seed produces (even when the expectation is unchanged), so content-keyed caches of reference
// renders (bin/cmd_fit.cpp CachedReference) never mix renders of different renderers.
// 2: stratified first-vertex environment/BSDF numbers and two environment samples there.
// 3: Sadeghi evaluated through identities (same expectation, rounding-level changes) and
//    adaptive sampling (target_error; fixed-spp images are unchanged by it).
// 4: half images (half.R/G/B) in the EXR; per-reference environment samples and the
//    re-planned adaptive pilot (docs/reference-renderer.md, session 6).
// 5: adaptive allocation version 5 (shrunk per-tile errors, an upper confidence bound on the
//    predicted error, stage-2 pilot pixels at random cell positions) and the stratified second
//    coordinate for batch lengths that are not powers of two: fixed-spp images are unchanged
//    when every stratified set has a power-of-two size (the default environment samples 2 with
//    spp 32..512 in powers of two); other spp or --env-samples 3, 5, 6 change them.
inline constexpr int kReferenceRendererVersion = 5;

// Half images: of a pixel's K i.i.d. batch means, half A is the mean of the first
// HalfBatches(K) = floor(K / 2); the complement B = (K mean - kA A) / (K - kA) is the mean of
// the others, so A and B are two independent unbiased estimates of the pixel (their difference
// measures the noise without a second render).
inline int HalfBatches(int batches) { return batches / 2; }

struct RenderSettings {
  int spp = 64;
  int max_depth = 8;       // path vertices after the camera (1 = direct light only)
  int rr_start_depth = 3;  // Russian roulette from this depth on
  uint64_t seed = 1;
  int tile_size = 16;
  // Environment samples at the camera ray's hit (stratified over the pixel's batch; deeper
  // vertices take one). Only with batches of more than one sample (spp >= 32, a multiple of 16).
  // 2: measured best over the canonical scenes (docs/reference-renderer.md).
  int first_env_samples = 2;
  AovSet aovs;
  double max_sample_value = 0.0;  // > 0: clamp each sample's channels (biased; 0 = off)
  // Adaptive sampling (docs/reference-renderer.md, "Adaptive sampling"): > 0 = target for
  // the image's mean standard error relative to its mean value (the summary's "% of mean",
  // as a fraction: 0.02 = 2 %). A pilot pass with independent random streams decides each
  // tile's sample count (a multiple of 16 in [min_spp, spp]; spp is then the per-pixel
  // budget); the image is then rendered with those counts from fresh streams, so the
  // allocation never depends on the samples it averages (no stopping bias).
  double target_error = 0.0;
  int min_spp = 32;
  // Adaptive only: choose the first vertex's environment samples among 2, 4 and 8 from a
  // pilot (efficiency = 1 / (error^2 x cost)); false: first_env_samples.
  bool choose_env_samples = true;
  int pilot_spp = 32;  // unused since version 4 (the pilot's spp follow from the target; docs)
  // Version 5 (docs "Adaptive sampling, version 5", render/reference/adaptive_allocation.h):
  // each tile's pilot error shrunk towards its neighbours by the reliability the pilot's two
  // halves measure, stage-2 pilot pixels at random positions in their cells, and the target
  // met by the predicted error plus allocation_z standard deviations of that prediction.
  // false: the version-4 rule (for comparisons; the images of a seed differ).
  bool robust_allocation = true;
  double allocation_z = 1.645;
  // Multiplies the pilot's predicted per-tile spread (version 4: the pilot's batches are as
  // long as the image's, so 1; docs/reference-renderer.md "Adaptive sampling, version 4").
  double pilot_calibration = 1.0;
};

struct RenderResult {
  int width = 0, height = 0;
  std::vector<float> rgb;        // mean radiance, linear, 3 per pixel, top row first
  std::vector<float> std_error;  // standard error of the pixel mean per channel, from the
                                 // spread of `batches` i.i.d. batch means (see Render)
  int batches = 0;                // K, the same in every pixel (see Render)
  std::vector<float> half;        // half image A, 3 per pixel (HalfBatches)
  int half_batches = 0;           // kA = HalfBatches(batches)
  std::vector<float> coverage;   // fraction of camera samples hitting geometry (alpha)
  std::vector<float> fabric;     // fraction of camera samples hitting the fabric material
  // AOVs (first-hit, averaged over the pixel's samples that hit; empty unless requested)
  std::vector<float> normal, position, tangent;  // 3 per pixel
  std::vector<float> uv;                         // 2 per pixel
  std::vector<float> depth;                      // distance along the camera ray
  // Adaptive sampling (target_error > 0): samples per pixel of each tile (row-major tiles of
  // tile_size), the pilot's share of the time, and the target the pilot predicted to meet.
  std::vector<int> tile_spp;
  int tile_size = 0;
  double pilot_seconds = 0.0;
  double predicted_error = 0.0;  // the allocation's predicted mean std error / mean value
  double error_rate = 0.0;       // gamma: the pilot's error ~ spp^(-gamma/2) below its spp
  double predicted_upper = 0.0;  // the bound the allocation meets (version 5; <= target)
  double allocation_reliability = 1.0;  // R of the shrinkage (1: none)
  double pilot_value_rel_sd = 0.0;      // relative sd of the pilot's image mean value
  int env_samples = 0;           // environment samples used at the first vertex
  struct EnvCandidate {
    int env_samples;
    double relative_error;  // stage-1 pilot: mean std error / mean value at 32 spp
    double cost;            // rays per camera sample + env_samples (the cost model)
  };
  std::vector<EnvCandidate> env_candidates;  // adaptive stage 1 (docs)
  double mean_spp = 0.0;  // camera samples per pixel, pilot included
  // Statistics
  double seconds = 0.0;
  uint64_t rays = 0;                              // all rays traced (camera, bounce, shadow)
  double mean_relative_std_error = 0.0;           // mean over covered pixels of stderr / mean value
  double mean_std_error = 0.0, mean_value = 0.0;  // over all pixels and channels
};

// Material assignment: the fabric BSDF for meshes with is_fabric, Lambert(base_color) for
// every other mesh. `environment` may be null (no environment lighting).
class PathTracer {
 public:
  PathTracer(const Scene& scene, const Bsdf& fabric, const Environment* environment);
  ~PathTracer();
  // `progress(done_tiles, total_tiles)` may be empty; called from worker threads, serialised.
  // Throws std::invalid_argument naming the card, before allocating, when the EXR that
  // WriteRenderExr would write (width x height x RenderExrChannels x 4 bytes) is over
  // limits::kMaxImageBytes: io::ReadImage, and so fit, evaluate and compare, could not read it.
  RenderResult Render(const RenderSettings& settings,
                      const std::function<void(int, int)>& progress = {}) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Writes the result as one EXR: R, G, B, A (coverage), fabric, stderr.R/G/B, half.R/G/B (with
// metadata clothfit:batches and clothfit:half_batches; when K >= 2), and the
// requested AOVs (N.X/Y/Z, P.X/Y/Z, T.X/Y/Z, uv.U/V, Z), with metadata `extra`.
void WriteRenderExr(const std::string& path, const RenderResult& r,
                    const std::vector<std::pair<std::string, std::string>>& extra);
// The most channels WriteRenderExr writes with these AOVs: R, G, B, A, fabric, stderr.RGB,
// half.RGB and the AOVs' (N, P, T: 3 each; uv: 2; Z: 1).
int RenderExrChannels(const AovSet& aovs);

}  // namespace clothfit::render
