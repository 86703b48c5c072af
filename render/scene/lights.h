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

// The horizon fade of a small disc light (session 22; docs/sun.md "Terminator fade").
// A source of angular radius r (sin_radius = sin r) whose centre is at n.l = NoL crosses the
// surface's horizon while |NoL| < sin r: part of its disc is below the horizon. Treating the disc
// as flat (small r), in units of sin r along the normal-ward axis its visible part is the circular
// segment y > a, a = -NoL / sin r, of area A = acos(a) - a sqrt(1 - a^2) (the unit disc: pi) and
// centroid y_c = 2 (1 - a^2)^(3/2) / (3 A). The light is then drawn as `visible` = A / pi of its
// irradiance, from the direction at the visible part's centroid, n.l' = NoL + sin r y_c (> 0).
// For a cosine-weighted (Lambert) surface `visible` x NoL' is the disc's exact irradiance in the
// flat-disc approximation; for other lobes it is the lobe at the centroid. NoL >= sin r: the disc
// is whole (visible 1, NoL unchanged); NoL <= -sin r: hidden (visible 0). Continuous in NoL, so a
// lobe that does not vanish at n.l = 0 (woven's yarn lobes) shows no seam at the terminator.
// web/clothfit.js wovenClipDiscAtHorizon is the same formula.
struct HorizonClip {
  double visible = 1.0;  // fraction of the disc above the horizon
  double NoL = 0.0;      // n.l' of the direction the light is drawn from
};
inline HorizonClip ClipDiscAtHorizon(double NoL, double sin_radius) {
  HorizonClip c;
  c.NoL = NoL;
  if (!(sin_radius > 0.0) || NoL >= sin_radius) return c;
  if (NoL <= -sin_radius) {
    c.visible = 0.0;
    return c;
  }
  const double a = -NoL / sin_radius;  // in (-1, 1)
  const double q = std::sqrt(std::max(1.0 - a * a, 0.0));
  const double A = std::acos(a) - a * q;
  c.visible = A * kInvPi;
  const double yc = A > 0.0 ? 2.0 * q * q * q / (3.0 * A) : 1.0;
  c.NoL = std::max(NoL + sin_radius * yc, 0.0);
  return c;
}

// The unit direction in the plane of n and l whose cosine with n is NoL_new (l itself if l is
// along n). Used to draw a clipped disc from its visible part's centroid.
inline Vec3<double> TiltToCosine(const Vec3<double>& l, const Vec3<double>& n, double NoL_new) {
  const double NoL = Dot(n, l);
  Vec3<double> u = l - n * NoL;
  const double len = std::sqrt(Dot(u, u));
  if (!(len > 1e-12)) return l;
  u = u * (1.0 / len);
  const double s = std::sqrt(std::max(1.0 - NoL_new * NoL_new, 0.0));
  return n * NoL_new + u * s;
}

}  // namespace clothfit::render
