// fit/reference.h: reading references from any renderer (docs/references.md).
//
// A reference gives, per pixel, a radiance x (linear RGB), a coverage weight w in [0, 1] and a
// standard error of x. Layouts:
//   clothfit (a `fabric` channel): x = RGB (the whole pixel), w = 1 if fabric >= 0.999 else 0
//   premultiplied alpha (OpenEXR's rule; Cycles, Mitsuba): x = RGB / A, w = A
//   straight alpha: x = RGB, w = A
//   no coverage: x = RGB, w = 1
// Optional half.R/G/B (+ metadata clothfit:half_batches, clothfit:batches): two independent
// half-sample images, kept as Reference::half_a / half_b (fit/metrics/reference_halves.h); the
// fit's noise floor comes from them when no second reference is given.
// Missing stderr.*: estimated from the image (Immerkaer 1996, relative to the radiance), or
// zero with NoiseMode::kNone.
// Only linear images are references: an 8/16-bit PNG (or an EXR with integer channels) holds
// display-encoded values, which the fit would take for radiance; it is refused
// (RequireLinearImage; `clothfit compare` refuses it the same way, fit/metrics/compare.cpp).
#pragma once

#include <string>
#include <vector>

#include "render/scene/scene.h"

namespace clothfit::io {
struct Image;
}  // namespace clothfit::io

namespace clothfit::fit {

struct Reference;

enum class AlphaMode { kAuto, kPremultiplied, kStraight };
enum class NoiseMode { kAuto, kImage, kNone };

struct ReferenceOptions {
  AlphaMode alpha = AlphaMode::kAuto;
  std::string coverage_channel;  // "" = auto (fabric, else A), "none" = every pixel covered
  NoiseMode noise = NoiseMode::kAuto;  // kAuto: stderr.* if present, else kImage
};

AlphaMode ParseAlphaMode(const std::string& s);  // throws std::invalid_argument
NoiseMode ParseNoiseMode(const std::string& s);  // throws std::invalid_argument

// Reads a reference (see above). Throws io::IoError naming the file on missing/corrupt files
// and FitError on a display-encoded image (RequireLinearImage), missing R/G/B, a missing named
// coverage channel, NaN/Inf radiance, or inconsistent half channels / metadata.
Reference ReadReference(const std::string& path, const ReferenceOptions& options);

// Throws FitError "<path>: a reference must be linear radiance (float or half EXR, or
// Radiance HDR); this is a uint8 png ..." unless `image` (read from `path` by io::ReadImage)
// was stored as floats (io::Image::float_source): the one check of every reference that `fit`
// and `evaluate` read (--references, --references2, a preset's fit.scenes).
void RequireLinearImage(const io::Image& image, const std::string& path);

// Immerkaer's noise estimate (CVIU 64(2), 1996) of one channel of a reference, relative to
// the radiance: sqrt(pi/2) / 6 x mean |Laplacian-difference response| / mean radiance, over
// the pixels whose 3 x 3 neighbourhood has weight > 0.5. Returns 0 when no such pixel exists.
double EstimateRelativeNoise(const Reference& ref, int channel);

// True when the file has the channels half.R, half.G and half.B (reads the whole file).
// Throws io::IoError naming the file when it cannot be read.
bool HasHalfChannels(const std::string& path);

// A weave period: a length in metres ("0.002", "2mm", "0.2cm", "0.002m") or in UV units
// ("0.05uv"). Throws std::invalid_argument naming the flag on anything else or <= 0.
struct WeavePeriod {
  double value = 0.0;
  bool uv = false;
};
WeavePeriod ParseWeavePeriod(const std::string& s);

// The period in UV units on one scene: as is for `uv`, else metres / uv_metres_per_unit.
// Throws std::invalid_argument naming the card when a length needs a card without
// uv_metres_per_unit.
double WeavePeriodUv(const WeavePeriod& p, const render::Scene& scene, const std::string& card);

}  // namespace clothfit::fit
