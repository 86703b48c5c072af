// .weave pattern reader: render::ParseWeave.
#include "render/reference/weave_pattern.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  clothfit::fuzz::Run([&] { (void)clothfit::render::ParseWeave(text, "fuzz.weave"); });
  return 0;
}
