#include "fit/metrics/reference_halves.h"

#include <cmath>
#include <stdexcept>

namespace clothfit::metrics {
namespace {

int Channel(const io::Image& img, const std::string& name) {
  for (int c = 0; c < img.channels(); ++c)
    if (img.channel_names[size_t(c)] == name) return c;
  return -1;
}

int IntMetadata(const io::Image& img, const std::string& key, const std::string& what) {
  const auto it = img.metadata.find(key);
  if (it == img.metadata.end())
    throw std::invalid_argument(what + ": has half.R/G/B channels but no metadata \"" + key + "\"");
  size_t used = 0;
  long v = 0;
  try {
    v = std::stol(it->second, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != it->second.size() || v < 1 || v > (1L << 30))
    throw std::invalid_argument(what + ": metadata \"" + key + "\" = '" + it->second +
                                "' is not a positive integer");
  return int(v);
}

}  // namespace

double HalfDifferenceToFullStderr(int kA, int K) {
  if (kA < 1 || kA >= K)
    throw std::invalid_argument("half batches " + std::to_string(kA) + " of " +
                                std::to_string(K) + ": need 1 <= half_batches < batches");
  return std::sqrt(double(kA) * double(K - kA)) / double(K);
}

ReferenceHalves ExtractHalves(const io::Image& img, const std::string& what) {
  ReferenceHalves h;
  const int hc[3] = {Channel(img, "half.R"), Channel(img, "half.G"), Channel(img, "half.B")};
  const int found = (hc[0] >= 0) + (hc[1] >= 0) + (hc[2] >= 0);
  if (found == 0) return h;
  if (found != 3)
    throw std::invalid_argument(what + ": has some but not all of the channels half.R, half.G, half.B");
  const int mc[3] = {Channel(img, "R"), Channel(img, "G"), Channel(img, "B")};
  if (mc[0] < 0 || mc[1] < 0 || mc[2] < 0)
    throw std::invalid_argument(what + ": has half.R/G/B but not R, G, B");
  h.half_batches = IntMetadata(img, "clothfit:half_batches", what);
  h.batches = IntMetadata(img, "clothfit:batches", what);
  if (h.half_batches >= h.batches)
    throw std::invalid_argument(what + ": metadata clothfit:half_batches (" +
                                std::to_string(h.half_batches) + ") must be < clothfit:batches (" +
                                std::to_string(h.batches) + ")");
  h.present = true;
  h.a = RgbImage(img.width, img.height);
  h.b = RgbImage(img.width, img.height);
  const double K = h.batches, kA = h.half_batches;
  const size_t nc = size_t(img.channels());
  for (size_t p = 0; p < h.a.pixel_count(); ++p)
    for (size_t c = 0; c < 3; ++c) {
      const double mean = img.pixels[p * nc + size_t(mc[c])];
      const double a = img.pixels[p * nc + size_t(hc[c])];
      h.a.rgb[p * 3 + c] = float(a);
      h.b.rgb[p * 3 + c] = float((K * mean - kA * a) / (K - kA));
    }
  return h;
}

}  // namespace clothfit::metrics
