// The weave-map EXR reader (render/preview/weave_maps.h ReadWeaveMaps): the five ratio channels,
// the optional relief normals and the optional view bands (session 14: channels view{k}.*,
// metadata clothfit:view_cosines), then a few samples as the preview takes them.
#include <cmath>

#include "render/preview/weave_maps.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  const std::string path = fuzz::WriteInput("maps.weave.exr", data, size);
  fuzz::Run([&] {
    const render::WeaveMaps m = render::ReadWeaveMaps(path);
    for (const render::WeaveMaps::Footprint fp :
         {render::WeaveMaps::Footprint{0.0, 1, 0.0, 0.0}, render::WeaveMaps::Footprint{0.5, 3, 1e-3, 2e-4}})
      for (double nov : {0.0, 0.3, 0.7, 1.0}) {
        const auto s = m.SampleView(0.013, 0.029, fp, nov);
        for (double x : s)
          if (!(x >= 0.0) || !std::isfinite(x)) fuzz::Bug("a sample is negative or not finite", path);
      }
  });
  return 0;
}
