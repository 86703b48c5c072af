// The preview's environment lighting is continuous where the surface reflects the
// environment's poles (issue #15, point 6): an equirect lookup that clamps v at the top row
// returns a value that depends on the azimuth at the pole, so a reflected direction crossing
// the zenith jumped between two top-row texels half a turn apart.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "render/preview/prefilter.h"
#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "render/scene/image_io.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

// An environment with a bright zenith lobe and a horizon whose colour changes with azimuth (so
// the top rows of the coarse prefiltered levels differ around the pole), written as an EXR.
std::string ZenithEnvironment() {
  const std::string path =
      (std::filesystem::temp_directory_path() / "clothfit_zenith_env.exr").string();
  io::Image img;
  img.width = 256;
  img.height = 128;
  img.channel_names = {"R", "G", "B"};
  img.pixels.resize(size_t(img.width) * size_t(img.height) * 3);
  for (int j = 0; j < img.height; ++j) {
    for (int i = 0; i < img.width; ++i) {
      const Vec3<double> d =
          Environment::UvToDirection((i + 0.5) / img.width, 1.0 - (j + 0.5) / img.height);
      const double phi = std::atan2(d.z, d.x);
      // Smooth everywhere, so every step in the preview is the lookup's: a Gaussian lobe of
      // ~20 degrees around the zenith.
      const double zenith_angle = std::acos(std::clamp(d.y, -1.0, 1.0));
      const double cap = 6.0 * std::exp(-std::pow(zenith_angle / 0.35, 2));
      // and a softbox 30 degrees off the zenith, as in a studio map: the coarse levels' top
      // rows then differ strongly with azimuth.
      const Vec3<double> box(std::sin(0.52), std::cos(0.52), 0.0);
      const double box_angle = std::acos(std::clamp(Dot(d, box), -1.0, 1.0));
      const double softbox = 4.0 * std::exp(-std::pow(box_angle / 0.3, 2));
      const double horizon = 0.15 + 0.6 * std::max(0.0, std::cos(phi)) * (1.0 - std::abs(d.y));
      const size_t p = (size_t(j) * size_t(img.width) + size_t(i)) * 3;
      img.pixels[p + 0] = float(cap + softbox + horizon);
      img.pixels[p + 1] = float(cap + softbox + 0.8 * horizon);
      img.pixels[p + 2] = float(cap + softbox + 0.3 + 0.2 * std::sin(phi));
    }
  }
  io::WriteExr(path, img);
  return path;
}

// Largest "excess step" between neighbouring pixels of a row or column: the difference
// between two neighbours minus the mean of the differences on either side. A smooth image
// gives a small multiple of its third derivative; a step of height s gives ~ s.
double MaxExcessStep(const std::vector<double>& v, const std::vector<bool>& ok) {
  double worst = 0.0;
  for (size_t i = 1; i + 2 < v.size(); ++i) {
    if (!ok[i - 1] || !ok[i] || !ok[i + 1] || !ok[i + 2]) continue;
    const double d0 = v[i] - v[i - 1], d1 = v[i + 1] - v[i], d2 = v[i + 2] - v[i + 1];
    worst = std::max(worst, std::abs(d1 - 0.5 * (d0 + d2)));
  }
  return worst;
}

// Largest relative excess step over the pixels that reflect the zenith's surroundings, per
// roughness node, for an N x N view of a constant-albedo sphere.
std::vector<double> ZenithSteps(const Environment& env, ModelKind model, int N) {
  // A sphere seen from the side: the points at 45 degrees of latitude reflect the zenith.
  Scene s = CameraScene(N, N, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 256, 128, true, 0.5f));
  PreviewOptions o;
  o.model = model;
  auto cache = PreviewCache::Build(s, &env, o);
  std::vector<int> index(size_t(N) * size_t(N), -1);
  for (size_t i = 0; i < cache->pixels.size(); ++i) {
    // Only the pixels whose mirror direction is within 30 degrees of the zenith (the
    // silhouette's steep but genuine gradients are elsewhere).
    const int px = cache->pixels[i] % N, py = cache->pixels[i] / N;
    std::array<double, 3> org, dir;
    s.CameraRay(px + 0.5, py + 0.5, org, dir);
    const Vec3<double> o3(org[0], org[1], org[2]), d3(dir[0], dir[1], dir[2]);
    const double b = Dot(o3, d3), c = Dot(o3, o3) - 0.25, disc = b * b - c;
    if (disc <= 0.0) continue;
    const Vec3<double> n = Normalize(o3 + d3 * (-b - std::sqrt(disc)));
    const Vec3<double> R = d3 - n * (2.0 * Dot(n, d3));
    if (R.y > std::cos(30.0 * kPi / 180.0)) index[size_t(cache->pixels[i])] = int(i);
  }
  std::vector<double> steps;
  const int K = o.roughness_nodes;
  for (int k = 0; k < K; ++k) {
    const double r = double(k) / double(K - 1);
    // Constant albedo 0.5; cloth: sheen colour 1; standard: dielectric.
    std::vector<double> x = model == ModelKind::kCloth
                                ? std::vector<double>{0.5, 0.5, 0.5, 1, 1, 1, r, 0, 0, 0}
                                : std::vector<double>{0.5, 0.5, 0.5, r, 0.0};
    std::vector<Rgb<double>> px;
    EvaluatePreview(*cache, x.data(), px);
    double worst = 0.0, peak = 0.0;
    for (int line = 0; line < N; ++line) {
      for (int axis = 0; axis < 2; ++axis) {  // columns, then rows
        std::vector<double> v;
        std::vector<bool> ok;
        for (int t = 0; t < N; ++t) {
          const int xx = axis == 0 ? line : t, yy = axis == 0 ? t : line;
          const int i = index[size_t(yy) * size_t(N) + size_t(xx)];
          ok.push_back(i >= 0);
          v.push_back(i >= 0 ? px[size_t(i)][1] : 0.0);
          if (i >= 0) peak = std::max(peak, px[size_t(i)][1]);
        }
        worst = std::max(worst, MaxExcessStep(v, ok));
      }
    }
    steps.push_back(peak > 0.0 ? worst / peak : 0.0);
  }
  return steps;
}

// A step in the image keeps its height when the resolution doubles; a smooth image's excess
// step shrinks (at least linearly, for a kink). Before the pole fix (prefilter.h, Level::
// Bilinear), cloth at r = 0.56 had a step of 7 % of the pixel at 160 px (0.0585 linear); after
// it, at most 1.4 % at 192 px, shrinking with resolution except ~0.9 % at r = 0.22-0.28 (same
// before and after the fix: not the pole; the 1 % allowance below is that, stated).
TEST(PreviewSeam, EnvironmentLightingIsContinuousThroughTheZenithAtEveryRoughnessNode) {
  const Environment env = Environment::Load(ZenithEnvironment(), 1.0, 0.0);
  for (ModelKind model : {ModelKind::kCloth, ModelKind::kStandard}) {
    const std::vector<double> coarse = ZenithSteps(env, model, 96);
    const std::vector<double> fine = ZenithSteps(env, model, 192);
    for (size_t k = 0; k < coarse.size(); ++k) {
      const double r = double(k) / double(coarse.size() - 1);
      EXPECT_LT(fine[k], 0.7 * coarse[k] + 0.01)
          << ToString(model) << " r = " << r << ": a step that does not shrink with resolution";
      EXPECT_LT(fine[k], 0.025) << ToString(model) << " r = " << r;
    }
  }
}

}  // namespace
}  // namespace clothfit::render
