// Scene card (.json) reader: render::LoadSceneCard.
#include "render/scene/scene.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = clothfit::fuzz::WriteInput("card.json", data, size);
  clothfit::fuzz::Run([&] { (void)clothfit::render::LoadSceneCard(path); });
  return 0;
}
