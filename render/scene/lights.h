// render/scene/lights.h: the punctual-light model shared by both renderers (units: render/scene/scene.h).
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>

#include "brdf/math.h"
#include "render/scene/scene.h"

namespace clothfit::render {

struct LightSample {
  Vec3<double> wi;     // unit direction from the point towards the light
  double scale = 0.0;  // intensity x distance attenuation x range window x spot cone
  double distance = std::numeric_limits<double>::infinity();
};

inline double SmoothStep(double e0, double e1, double x) {
  if (e1 <= e0) return x >= e1 ? 1.0 : 0.0;
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// Irradiance at p from `light` on a surface facing it is scale x color x max(n.wi, 0).
inline LightSample EvaluateLight(const Light& light, const Vec3<double>& p) {
  LightSample s;
  s.scale = light.intensity;
  if (light.type == Light::Type::kDirectional) {
    s.wi = Vec3<double>(-light.direction[0], -light.direction[1], -light.direction[2]);
    return s;
  }
  const Vec3<double> d = Vec3<double>(light.position[0], light.position[1], light.position[2]) - p;
  const double d2 = Dot(d, d);
  if (d2 <= 0.0) {
    s.scale = 0.0;
    return s;
  }
  s.distance = std::sqrt(d2);
  s.wi = d * (1.0 / s.distance);
  s.scale /= d2;  // inverse square (three.js decay = 2 for physically based lights)
  if (light.range > 0.0) {
    const double x = std::clamp(1.0 - std::pow(s.distance / light.range, 4.0), 0.0, 1.0);
    s.scale *= x * x;
  }
  if (light.type == Light::Type::kSpot) {
    const double cos_axis =
        -(s.wi.x * light.direction[0] + s.wi.y * light.direction[1] + s.wi.z * light.direction[2]);
    s.scale *= SmoothStep(std::cos(light.outer_cone), std::cos(light.inner_cone), cos_axis);
  }
  return s;
}

}  // namespace clothfit::render
