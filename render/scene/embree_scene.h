// render/scene/embree_scene.h: the scene's triangles in an Embree 3 BVH, shared by the reference
// path tracer (all rays) and the preview renderer (primary visibility, shadow rays).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>

#include "render/scene/scene.h"

namespace clothfit::render {

struct Hit {
  bool valid = false;
  double t = 0.0;
  int mesh = -1;                      // index into Scene::meshes
  int triangle = -1;                  // triangle index within the mesh
  double b1 = 0.0, b2 = 0.0;          // barycentrics of vertices 1 and 2 (vertex 0: 1 - b1 - b2)
  std::array<double, 3> ng{0, 0, 0};  // geometric normal, unit, as wound (not flipped)
};

// Interpolated surface attributes at a hit (world space).
struct SurfaceAttributes {
  std::array<double, 3> position{}, normal{}, tangent{};  // normal, tangent unit
  double tangent_sign = 1.0;                              // bitangent = sign * n x t
  std::array<double, 2> uv{};
};

class EmbreeScene {
 public:
  explicit EmbreeScene(const Scene& scene);
  ~EmbreeScene();
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  Hit Intersect(const std::array<double, 3>& org, const std::array<double, 3>& dir,
                double tnear = 0.0, double tfar = std::numeric_limits<double>::infinity()) const;
  bool Occluded(const std::array<double, 3>& org, const std::array<double, 3>& dir, double tnear,
                double tfar) const;
  SurfaceAttributes Attributes(const Hit& hit) const;
  // Scene bounding-sphere radius (for ray offsets).
  double scale() const { return scale_; }
  // Rays refused because Embree would reject them (origin beyond +-1e18, non-finite or zero
  // direction, bad tnear/tfar): Intersect reports a miss and Occluded reports "occluded"
  // instead of letting libembree3 abort on its `ray.valid()` assertion.
  long long invalid_rays() const;
  // True when Embree accepts the ray (the checks above).
  static bool RayValid(const std::array<double, 3>& org, const std::array<double, 3>& dir,
                       double tnear, double tfar);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  const Scene& scene_;
  double scale_ = 1.0;
};

}  // namespace clothfit::render
