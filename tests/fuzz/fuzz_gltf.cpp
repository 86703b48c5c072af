// glTF / .glb scene reader: render::LoadScene on a fixed 16x16 card naming the fuzzed file
// (tinygltf through LoadGltfModel, then accessors, nodes, camera, lights). Built twice:
// fuzz_gltf (FUZZ_EXT ".gltf") and fuzz_glb (".glb").
#include <cmath>

#include "render/scene/scene.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  static const std::string card = [] {
    const std::string c = (fuzz::Scratch() / "card.json").string();
    std::ofstream o(c);
    o << R"({"version": 1, "gltf": "scene)" FUZZ_EXT R"(", "width": 16, "height": 16,
            "fabric_material": 0, "camera": 0, "uv_metres_per_unit": 1.0})";
    return c;
  }();
  fuzz::WriteInput(std::string("scene") + FUZZ_EXT, data, size);
  fuzz::Run([&] {
    const render::Scene s = render::LoadScene(card);
    // On success every position must be in the documented world range.
    for (const auto& m : s.meshes)
      for (const auto& p : m.positions)
        for (float x : p)
          if (!(std::abs(double(x)) <= limits::kMaxWorldCoordinate))
            fuzz::Bug("position outside kMaxWorldCoordinate accepted", std::to_string(x));
  });
  return 0;
}
