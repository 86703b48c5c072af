// convert catalogue entries: fit::ReadMaterials (presets, fabrics, SurfaceMaterial,
// TextureStack, glTF/.glb materials, by content and extension), then SampleSource and the
// log's JSON, as one batch item would. Built three times: FUZZ_EXT ".json", ".gltf", ".glb".
// The entry sits next to small maps (maps/*.png) so TextureStack map paths resolve.
#include "fit/convert/convert.h"
#include "fit/convert/convert_io.h"
#include "render/scene/image_io.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  static const bool maps_ready = [] {
    std::filesystem::create_directories(fuzz::Scratch() / "maps");
    for (const char* n : {"albedo", "normal", "roughness"})
      io::WritePng8((fuzz::Scratch() / "maps" / (std::string(n) + ".png")).string(), 4, 4,
                    std::vector<float>(48, 0.5f));
    return true;
  }();
  (void)maps_ready;
  const std::string path = fuzz::WriteInput(std::string("entry") + FUZZ_EXT, data, size);
  fuzz::Run([&] {
    const std::vector<fit::SourceMaterial> mats = fit::ReadMaterials(path);
    fit::ConvertReport rep;
    for (const auto& m : mats) {
      (void)fit::SampleSource(m);
      fit::ItemResult r;
      r.file = path;
      r.material = m.name;
      r.notes = m.notes;
      rep.items.push_back(r);
    }
    (void)limits::DumpJson(fit::ReportJson(rep, fit::ConvertOptions{}));
  });
  return 0;
}
