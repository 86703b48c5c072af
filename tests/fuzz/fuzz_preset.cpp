// Material preset reader: render::ReadPreset, then the round trip the tool does when it writes
// a preset back (PresetToJson, DumpJson).
#include "render/scene/material.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  const std::string path = fuzz::WriteInput("preset.json", data, size);
  fuzz::Run([&] {
    const render::MaterialPreset p = render::ReadPreset(path);
    (void)limits::DumpJson(render::PresetToJson(p));
  });
  return 0;
}
