// tests/preview_fixtures.h: the lit sphere shared by the preview tests (test_preview.cpp,
// test_woven_preview.cpp, test_weave_maps.cpp): a 0.5 m fabric UV sphere at the origin seen
// from (0, 0, 3) with a 0.4 rad field of view, one directional light (intensity 3, colour
// (1, 0.9, 0.8), direction (0.4, -0.5, -0.768)), no environment; and the independent
// per-pixel recomputation those tests compare the preview's cache against.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "brdf/math.h"
#include "render/preview/preview.h"
#include "render/scene/embree_scene.h"
#include "render/scene/environment.h"
#include "render/scene/image_io.h"
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

// What a pixel centre sees, recomputed without the preview's cache: the camera ray through
// the pixel centre traced with Embree, the viewer-side shading normal n, the view vector v,
// the reference renderer's tangent frame (t Gram-Schmidt'd against n, b = tangent_sign n x t),
// the first light's sample at the hit, and the shading cosines of (n, v, that light).
struct PixelGeometry {
  Vec3<double> n, v, t, b;
  LightSample light;
  Cosines<double> cosines;
  TangentCosines<double> tangent_cosines;
};

// Calls fn(i, geometry) for every cached pixel i of `cache`, in order; fails the test (and
// stops) when a pixel's camera ray misses the scene.
template <class Fn>
void ForEachPixelGeometry(const Scene& s, const PreviewCache& cache, Fn&& fn) {
  EmbreeScene bvh(s);
  for (size_t i = 0; i < cache.pixels.size(); ++i) {
    const int px = cache.pixels[i] % s.card.width, py = cache.pixels[i] / s.card.width;
    std::array<double, 3> org, dir;
    s.CameraRay(px + 0.5, py + 0.5, org, dir);
    const Hit h = bvh.Intersect(org, dir);
    ASSERT_TRUE(h.valid) << "pixel " << i;
    const SurfaceAttributes a = bvh.Attributes(h);
    PixelGeometry g;
    g.n = Vec3<double>(a.normal[0], a.normal[1], a.normal[2]);
    g.v = Vec3<double>(-dir[0], -dir[1], -dir[2]);
    if (Dot(g.n, g.v) < 0) g.n = g.n * -1.0;
    const Vec3<double> t(a.tangent[0], a.tangent[1], a.tangent[2]);
    g.t = Normalize(t - g.n * Dot(t, g.n));
    g.b = Cross(g.n, g.t) * a.tangent_sign;
    g.light = EvaluateLight(s.lights[0], Vec3<double>(a.position[0], a.position[1], a.position[2]));
    const Vec3<double>& l = g.light.wi;
    const Vec3<double> hv = Normalize(g.v + l);
    g.cosines = {Dot(g.n, g.v), Dot(g.n, l), Dot(g.n, hv), Dot(l, hv)};
    g.tangent_cosines = {Dot(g.t, g.v), Dot(g.b, g.v), Dot(g.t, l),
                         Dot(g.b, l),   Dot(g.t, hv),  Dot(g.b, hv)};
    fn(i, g);
  }
}

// woven flat parameters (brdf/woven.h kParameterTable order), sheen off, sheen roughness 0.6.
inline std::vector<double> WovenFlat(Rgb<double> base, Rgb<double> spec, double r, double aniso,
                                     double m, double f0, double beta) {
  // The whole woven table (17 values since session 18's diffuse_roughness, 0 = Lambert): a
  // shorter vector was read past its end (session 19: S12YarnLobe.ConvertSamplesTheLobe then
  // depended on the heap's contents).
  return {base.r, base.g, base.b, spec.r, spec.g, spec.b, r,   aniso,
          0.0,    m,      f0,     beta,   0.0,    0.0,    0.0, 0.6, 0.0};
}

// A synthetic far-field split sum (PreviewOptions::yarn_ibl) for tests: a view-dependent warp
// lobe about the mirror direction and a constant, rough weft lobe about the normal.
inline void SyntheticYarnIbl(const Vec3<double>& wo, yarn_table::IblLobe out[2]) {
  out[0].albedo = 0.4 + 0.2 * wo.x;
  out[0].dir = Normalize(Vec3<double>(-wo.x, -wo.y, wo.z));
  out[0].roughness = 0.3;
  out[1].albedo = 0.1;
  out[1].dir = {0.0, 0.0, 1.0};
  out[1].roughness = 0.9;
}

// Builds the preview cache of (s, env, o) and evaluates it at x; `keep` receives the cache.
inline std::vector<Rgb<double>> PreviewFrame(const Scene& s, const Environment& env,
                                             const PreviewOptions& o, const std::vector<double>& x,
                                             std::unique_ptr<PreviewCache>* keep = nullptr) {
  auto cache = PreviewCache::Build(s, &env, o);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  if (keep) *keep = std::move(cache);
  return out;
}

// An equirect map written to a temporary EXR and loaded as the scenes load theirs.
inline Environment EnvironmentFrom(int W, int H,
                                   const std::function<Rgb<double>(const Vec3<double>&)>& f) {
  io::Image img;
  img.width = W;
  img.height = H;
  img.channel_names = {"R", "G", "B"};
  img.pixels.resize(size_t(W) * size_t(H) * 3);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const Rgb<double> c = f(Environment::UvToDirection((i + 0.5) / W, (j + 0.5) / H));
      for (int k = 0; k < 3; ++k)
        img.pixels[(size_t(j) * size_t(W) + size_t(i)) * 3 + size_t(k)] = float(c[k]);
    }
  // A new name per map: the preview shares prefiltered chains by source path within a process
  // (render/preview/preview.cpp SharedPrefilter), so two maps must never share one.
  static int serial = 0;
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("clothfit_test_env_" + std::to_string(::getpid()) + "_" +
                             std::to_string(serial++) + ".exr"))
                               .string();
  io::WriteExr(path, img);
  Environment env = Environment::Load(path, 1.0, 0.0);
  std::filesystem::remove(path);
  return env;
}

// A bright disc of `radius_deg` around the unit direction c on a dim constant sky.
inline Environment DiscEnvironment(int W, int H, const Vec3<double>& c, double radius_deg,
                                   const Rgb<double>& disc, const Rgb<double>& sky) {
  const double cos_r = std::cos(radius_deg * kPi / 180.0);
  return EnvironmentFrom(W, H, [&](const Vec3<double>& d) { return Dot(d, c) > cos_r ? disc : sky; });
}

// Options of a woven preview on the three.js IBL engine with the given yarn-lobe IBL mode.
inline PreviewOptions WovenThreejsOptions(::clothfit::woven::IblMode mode) {
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.ibl_engine = IblEngine::kThreejs;
  o.woven.ibl = mode;
  return o;
}

}  // namespace clothfit::render
