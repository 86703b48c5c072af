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
  // The file's halves as the renderer's reader recovers them (render/scene/image_io.h,
  // ReferenceHalvesFromImage: B = (K mean - kA A) / (K - kA)).
  io::ReferenceHalves r;
  try {
    r = io::ReferenceHalvesFromImage(img, what);
  } catch (const io::IoError& e) {
    throw std::invalid_argument(e.what());
  }
  h.present = true;
  h.half_batches = r.half_batches;
  h.batches = r.batches;
  h.a = RgbImage(img.width, img.height);
  h.b = RgbImage(img.width, img.height);
  h.a.rgb = std::move(r.a);
  h.b.rgb = std::move(r.b);
  return h;
}

}  // namespace clothfit::metrics
