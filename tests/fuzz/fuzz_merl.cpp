// MERL BRDF table reader: fit::ParseMerl, then sampling it the way convert does.
#include "fit/convert/merl.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  fuzz::Run([&] {
    const fit::MerlTable t = fit::ParseMerl(bytes, "fuzz.binary");
    (void)fit::SampleMerl(t);
  });
  return 0;
}
