// Shared fixtures of the image-fit tests (tests/test_fit.cpp, tests/test_s13_woven_starts.cpp):
// a sphere lit by a key light and a rim light from behind, and references the preview itself
// renders from known parameters (so a fit can recover them exactly).
#pragma once

#include <vector>

#include "fit/image_fit.h"
#include "render/preview/preview.h"
#include "tests/scene_fixtures.h"

namespace clothfit::fit {

// size x size pixels; the rim light (from behind: grazing sheen, the rough diffuse's forward
// darkening) at `rim_intensity`.
inline render::Scene KeyRimSphereScene(int size, double rim_intensity) {
  render::Scene s = render::CameraScene(size, size, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(render::SphereMesh(0.5, 64, 32, true, 0.f));
  render::Light key, rim;
  key.type = rim.type = render::Light::Type::kDirectional;
  key.intensity = 2.5;
  key.direction = {0.4, -0.5, -0.768};
  rim.intensity = rim_intensity;
  rim.direction = {-0.6, 0.2, 0.77};
  s.lights = {key, rim};
  s.card.tone_mapping = "ACESFilmic";
  return s;
}

// A reference made by the preview itself with known parameters (no noise: std_error 0).
inline Reference PreviewReference(const render::Scene& s, const render::Environment* env,
                                  const render::MaterialPreset& truth) {
  render::PreviewOptions o;
  o.model = truth.model;
  o.cloth = truth.cloth;
  auto cache = render::PreviewCache::Build(s, env, o);
  std::vector<Rgb<double>> px;
  render::EvaluatePreview(*cache, truth.values.data(), px);
  Reference r;
  r.path = "synthetic";
  r.width = s.card.width;
  r.height = s.card.height;
  r.rgb = render::ComposeFrame(*cache, px);
  r.std_error.assign(r.rgb.size(), 0.f);
  r.fabric = cache->fabric_mask;
  return r;
}

}  // namespace clothfit::fit
