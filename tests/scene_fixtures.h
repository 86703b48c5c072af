// tests/scene_fixtures.h: small programmatic scenes for renderer tests.
#pragma once

#include <cmath>

#include "render/scene/scene.h"

namespace clothfit::render {

// UV sphere centred at the origin; normals point outward (the tracer is two-sided).
inline Mesh SphereMesh(double radius, int seg_u, int seg_v, bool fabric, float albedo) {
  Mesh m;
  m.name = "sphere";
  m.is_fabric = fabric;
  m.base_color = {albedo, albedo, albedo};
  for (int j = 0; j <= seg_v; ++j) {
    const double v = double(j) / seg_v, theta = v * kPi;
    for (int i = 0; i <= seg_u; ++i) {
      const double u = double(i) / seg_u, phi = u * 2.0 * kPi;
      const double x = std::sin(theta) * std::cos(phi), y = std::cos(theta),
                   z = std::sin(theta) * std::sin(phi);
      m.positions.push_back({float(radius * x), float(radius * y), float(radius * z)});
      m.normals.push_back({float(x), float(y), float(z)});
      m.uvs.push_back({float(u), float(v)});
      m.tangents.push_back({float(-std::sin(phi)), 0.f, float(std::cos(phi)), 1.f});
    }
  }
  for (int j = 0; j < seg_v; ++j)
    for (int i = 0; i < seg_u; ++i) {
      const uint32_t a = uint32_t(j * (seg_u + 1) + i), b = a + 1,
                     c = uint32_t((j + 1) * (seg_u + 1) + i), d = c + 1;
      m.indices.insert(m.indices.end(), {a, c, b, b, c, d});
    }
  return m;
}

inline Scene CameraScene(int w, int h, std::array<double, 3> pos, std::array<double, 3> fwd,
                  double yfov) {
  Scene s;
  s.card.width = w;
  s.card.height = h;
  s.camera.position = pos;
  s.camera.forward = fwd;
  s.camera.up = {0, 1, 0};
  s.camera.right = {-fwd[2], 0, fwd[0]};  // forward x up for fwd in the xz plane
  s.camera.yfov = yfov;
  return s;
}

// A 64 x 64 fabric sphere under one directional key light (intensity 2.5, from the upper
// right front), ACES Filmic display: the small fit scene of the foreign-reference and
// noise-floor tests.
inline Scene KeyLitAcesSphere() {
  Scene s = CameraScene(64, 64, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 64, 32, true, 0.f));
  Light key;
  key.type = Light::Type::kDirectional;
  key.intensity = 2.5;
  key.direction = {0.4, -0.5, -0.768};
  s.lights = {key};
  s.card.tone_mapping = "ACESFilmic";
  return s;
}

// A fabric sphere filling most of a size x size frame, no punctual light (the exact-IBL and
// woven FIS tests light it by an environment only).
inline Scene UnlitSphere(int size = 40) {
  Scene s = CameraScene(size, size, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 64, 32, true, 0.f));
  return s;
}

}  // namespace clothfit::render
