// tests/preview_fixtures.h: the lit sphere shared by the preview tests (test_preview.cpp,
// test_woven_preview.cpp, test_weave_maps.cpp): a 0.5 m fabric UV sphere at the origin seen
// from (0, 0, 3) with a 0.4 rad field of view, one directional light (intensity 3, colour
// (1, 0.9, 0.8), direction (0.4, -0.5, -0.768)), no environment.
#pragma once

#include "render/scene/lights.h"
#include "render/scene/scene.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {

inline Scene SphereWithLight(int size) {
  Scene s = CameraScene(size, size, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 96, 48, true, 0.f));
  Light l;
  l.type = Light::Type::kDirectional;
  l.intensity = 3.0;
  l.color = {1.0, 0.9, 0.8};
  l.direction = {0.4, -0.5, -0.768};
  s.lights.push_back(l);
  return s;
}

}  // namespace clothfit::render
