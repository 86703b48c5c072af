// Fabric definition reader: render::ParseFabric, as if the file sat in datasets/fabrics/ (so
// the default ../weaves/<preset>.weave resolves to the real library).
#include "render/reference/fabric.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  static const std::string path = clothfit::fuzz::DatasetsDir() + "/fabrics/fuzz.json";
  clothfit::fuzz::Run([&] { (void)clothfit::render::ParseFabric(text, path); });
  return 0;
}
