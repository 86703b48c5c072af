// Material preset reader: render::ReadPreset, then the round trip the tool does when it writes
// a preset back (PresetToJson, DumpJson), the weave maps' relative "uri" resolution and their
// max anisotropy (render::PresetMapAnisotropy, session 9).
#include "render/preview/weave_maps.h"
#include "render/scene/material.h"
#include "tests/fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace clothfit;
  const std::string path = fuzz::WriteInput("preset.json", data, size);
  fuzz::Run([&] {
    const render::MaterialPreset p = render::ReadPreset(path);
    (void)limits::DumpJson(render::PresetToJson(p));
    // A far-field yarn lobe (session 12) that passed validation is built and evaluated: its
    // values may be anything a double gives, but never a crash or a sanitizer report.
    if (p.yarn_lobe) {
      const yarn_lobe::Lobe lobe(*p.yarn_lobe);
      double t[2];
      lobe.Eval(Normalize(Vec3<double>(0.3, -0.2, 0.9)), Normalize(Vec3<double>(-0.5, 0.1, 0.6)), t);
      yarn_table::IblLobe l[2];
      p.yarn_lobe->ibl.Ibl(Normalize(Vec3<double>(0.1, 0.7, 0.2)), l);
    }
    // The weave maps' relative "uri" (render::ResolvePresetRelativeUri, every reader's rule).
    const auto wm = p.extra.find("weave_maps");
    if (wm != p.extra.end() && wm->is_object()) {
      for (const char* key : {"uri", "glint_uri"})
        if (wm->contains(key) && (*wm)[key].is_string())
          (void)render::ResolvePresetRelativeUri(path, std::string("weave_maps.") + key,
                                                 (*wm)[key].get<std::string>());
      // Last, so that its error (checked by fuzz::Run like every other) hides no uri check.
      (void)render::PresetMapAnisotropy(*wm, path);
    }
  });
  return 0;
}
