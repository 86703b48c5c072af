// Image layer (io::ReadImage: OpenEXR, libpng, the RGBE reader), then the conversions every caller does
// (metrics::ToRgb / ToMask, and the half-sample channels: metrics::ExtractHalves). Built three times: FUZZ_EXT ".exr", ".png", ".hdr".
#include "fit/metrics/metrics.h"
#include "fit/metrics/reference_halves.h"
#include "render/scene/image_io.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  const std::string path = fuzz::WriteInput(std::string("image") + FUZZ_EXT, data, size);
  fuzz::Run([&] {
    const io::Image img = io::ReadImage(path);
    const size_t need = size_t(img.width) * size_t(img.height) * size_t(img.channels());
    if (img.pixels.size() != need) fuzz::Bug("pixel count differs from the header", path);
    (void)metrics::ToRgb(img, path);
    (void)metrics::ToMask(img, path);
    // A reference's half-sample channels and their metadata (the noise floor's reader).
    (void)metrics::ExtractHalves(img, path);
  });
  return 0;
}
