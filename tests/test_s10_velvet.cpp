// s10-velvet: the sheen nap prototype (render/preview/sheen_tilt.h, PreviewOptions::
// sheen_tilt_degrees; docs/velvet.md). Checks: tilt 0 leaves the cache and frame untouched; a
// tiny tilt (the tilted path, n_s ~ n) reproduces the models' own frames (the regrouped
// direct and IBL expressions, the albedo scaling, the tilted radiance table); the tilted sheen
// follows n_s = cos(theta) n + sin(theta) t, recomputed independently per pixel; mirrored
// tangents at +theta equal the original tangents at -theta, while +theta and -theta differ (a
// nap, not a symmetric change); bad options fail naming the problem.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "brdf/cloth.h"
#include "brdf/lut.h"
#include "brdf/terms.h"
#include "brdf/woven.h"
#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

// cloth flat parameters: base colour, sheen colour, roughness, subsurface colour.
std::vector<double> ClothFlat(double base = 0.05) {
  return {base, base * 0.8, base * 0.6, 0.6, 0.55, 0.5, 0.35, 0.0, 0.0, 0.0};
}
// woven flat parameters (twist 0: t -> -t is then a symmetry of the yarn lobes), sheen on.
std::vector<double> WovenFlat() {
  return {0.05, 0.04, 0.03, 0.3, 0.28, 0.25, 0.6, 0.7, 0.0, 0.6, 0.1, 2.0, 0.5, 0.45, 0.4, 0.35,
          0.0};  // diffuse_roughness (session 18; all 17 woven values, session 19)
}

std::vector<Rgb<double>> Frame(const Scene& s, const Environment* env, const PreviewOptions& o,
                               const std::vector<double>& x) {
  auto cache = PreviewCache::Build(s, env, o);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  return out;
}

// Largest |a - b| / (|b| + floor) over pixels and channels; the frames must have one size.
double MaxRelDiff(const std::vector<Rgb<double>>& a, const std::vector<Rgb<double>>& b,
                  double floor) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0.0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    for (int ch = 0; ch < 3; ++ch)
      m = std::max(m, std::abs(a[i][ch] - b[i][ch]) / (std::abs(b[i][ch]) + floor));
  return m;
}

// The lit sphere with the mesh tangents mirrored (xyz and w negated: the frame (t, b, n)
// becomes (-t, b, n)).
Scene MirroredTangents(Scene s) {
  for (Mesh& m : s.meshes)
    for (auto& t : m.tangents) t = {-t[0], -t[1], -t[2], -t[3]};
  return s;
}

TEST(S10Velvet, TiltZeroIsTheUntouchedPath) {
  const Scene s = SphereWithLight(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  for (ModelKind m : {ModelKind::kCloth, ModelKind::kWoven}) {
    PreviewOptions a, b;
    a.model = b.model = m;
    b.sheen_tilt_degrees = 0.0;
    auto ca = PreviewCache::Build(s, &env, a);
    auto cb = PreviewCache::Build(s, &env, b);
    EXPECT_TRUE(cb->sheen_tilt_radiance.empty());
    EXPECT_EQ(ca->tangent_v.size(), cb->tangent_v.size());  // cloth: none gathered
    const auto x = m == ModelKind::kCloth ? ClothFlat() : WovenFlat();
    std::vector<Rgb<double>> fa, fb;
    EvaluatePreview(*ca, x.data(), fa);
    EvaluatePreview(*cb, x.data(), fb);
    ASSERT_EQ(fa.size(), fb.size());
    for (size_t i = 0; i < fa.size(); ++i)
      for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(fa[i][ch], fb[i][ch]) << i;
  }
}

TEST(S10Velvet, TinyTiltReproducesTheModelsOwnFrames) {
  // 1e-6 degrees takes the tilted path with n_s = n to ~2e-8: every regrouped expression
  // (direct, split sum, albedo scaling, the table about n_s) must give the model's frame.
  const Scene s = SphereWithLight(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  for (ModelKind m : {ModelKind::kCloth, ModelKind::kWoven}) {
    PreviewOptions a, b;
    a.model = b.model = m;
    b.sheen_tilt_degrees = 1e-6;
    const auto x = m == ModelKind::kCloth ? ClothFlat() : WovenFlat();
    const auto fa = Frame(s, &env, a, x), fb = Frame(s, &env, b, x);
    ASSERT_GT(fa.size(), 300u);
    EXPECT_LT(MaxRelDiff(fb, fa, 1e-4), 1e-5) << ToString(m);
    auto cb = PreviewCache::Build(s, &env, b);
    EXPECT_EQ(cb->sheen_tilt_radiance.size(), cb->radiance.size());
  }
}

TEST(S10Velvet, TiltedSheenFollowsTheTiltedNormal) {
  // cloth, base colour 0 (sheen only), one directional light, no environment: each pixel is
  // sheen D(n_s.h) V(n_s.v, n_s.l) (n_s.l)+ x irradiance, n_s = cos(theta) n + sin(theta) t.
  const Scene s = SphereWithLight(32);
  const double theta = 35.0 * kPi / 180.0;
  PreviewOptions o;
  o.model = ModelKind::kCloth;
  o.sheen_tilt_degrees = 35.0;
  auto cache = PreviewCache::Build(s, nullptr, o);
  const auto x = ClothFlat(0.0);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  const cloth::Params<double> p{{x[0], x[1], x[2]}, {x[3], x[4], x[5]}, x[6], {x[7], x[8], x[9]}};
  int lit = 0;
  ForEachPixelGeometry(s, *cache, [&](size_t i, const PixelGeometry& g) {
    const Vec3<double> ns = g.n * std::cos(theta) + g.t * std::sin(theta);
    const Vec3<double>& l = g.light.wi;
    const Vec3<double> h = Normalize(g.v + l);
    double e = 0.0;
    if (g.cosines.NoL > 0.0) {  // lights below the surface stay culled
      const double r = cloth::ClampedRoughness(p.roughness, {});
      const double NoLs = std::max(Dot(ns, l), 0.0);
      e = cloth::SheenDV(r, cloth::ShadingNoV(Dot(ns, g.v), {}), NoLs, Dot(ns, h), {}) * NoLs;
      if (NoLs > 0.05) ++lit;
    }
    for (int ch = 0; ch < 3; ++ch) {
      const double want = e * p.sheen_color[ch] * g.light.scale * s.lights[0].color[size_t(ch)];
      EXPECT_NEAR(out[i][ch], want, 1e-4 * std::abs(want) + 1e-6) << "pixel " << i;
    }
  });
  EXPECT_GT(lit, 100);
}

TEST(S10Velvet, TiltedTablesMatchAMeshWhoseNormalsAreTilted) {
  // Independent route to n_s: rotate every vertex normal of the sphere towards its tangent by
  // theta (and the tangent with it) and build an untilted cache. Its NoV and radiance tables
  // must match the tilted cache's n_s.v and sheen_tilt_radiance (the tilted sheen's IBL input),
  // up to the interpolation of the rotated normals (fine mesh: small).
  const double deg = -30.0, th = deg * kPi / 180.0;
  const Scene s = SphereWithLight(32);
  Scene rot = s;
  for (Mesh& m : rot.meshes)
    for (size_t k = 0; k < m.normals.size(); ++k) {
      auto& n = m.normals[k];
      auto& t = m.tangents[k];
      const std::array<float, 3> n0 = n, t0 = {t[0], t[1], t[2]};
      for (int c = 0; c < 3; ++c) {
        n[size_t(c)] =
            float(std::cos(th) * double(n0[size_t(c)]) + std::sin(th) * double(t0[size_t(c)]));
        t[size_t(c)] =
            float(-std::sin(th) * double(n0[size_t(c)]) + std::cos(th) * double(t0[size_t(c)]));
      }
    }
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions tilted, plain;
  tilted.model = plain.model = ModelKind::kCloth;
  tilted.sheen_tilt_degrees = deg;
  auto ct = PreviewCache::Build(s, &env, tilted);
  auto cr = PreviewCache::Build(rot, &env, plain);
  ASSERT_EQ(ct->pixels, cr->pixels);
  ASSERT_EQ(ct->sheen_tilt_radiance.size(), cr->radiance.size());
  double worst_nov = 0.0, sum_rel = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < ct->pixels.size(); ++i) {
    const double nov_s =
        std::cos(th) * double(ct->NoV[i]) + std::sin(th) * double(ct->tangent_v[i * 2]);
    // near the silhouette the routes part most; where n_s.v < 0 the mesh route flips n_s
    if (double(cr->NoV[i]) < 0.2 || nov_s < 0.2) continue;
    worst_nov = std::max(worst_nov, std::abs(nov_s - double(cr->NoV[i])));
    for (size_t k = i * 99; k < (i + 1) * 99; ++k) {  // K = 33 nodes x 3
      sum_rel += double(std::abs(ct->sheen_tilt_radiance[k] - cr->radiance[k])) /
                 (double(cr->radiance[k]) + 1e-3);
      ++n;
    }
  }
  ASSERT_GT(n, 10000u);
  EXPECT_LT(worst_nov, 2e-3);
  EXPECT_LT(sum_rel / double(n), 5e-3);
  // ... and differs from the untilted table (the check is not vacuous).
  double diff = 0.0;
  for (size_t k = 0; k < ct->radiance.size(); ++k)
    diff += double(std::abs(ct->sheen_tilt_radiance[k] - ct->radiance[k])) /
            (double(ct->radiance[k]) + 1e-3);
  EXPECT_GT(diff / double(ct->radiance.size()), 0.03);
}

TEST(S10Velvet, MirroredTangentAtPlusTiltEqualsOriginalAtMinusTilt) {
  const Scene s = SphereWithLight(32);
  const Scene sm = MirroredTangents(s);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  for (ModelKind m : {ModelKind::kCloth, ModelKind::kWoven}) {
    PreviewOptions plus, minus;
    plus.model = minus.model = m;
    plus.sheen_tilt_degrees = 25.0;
    minus.sheen_tilt_degrees = -25.0;
    const auto x = m == ModelKind::kCloth ? ClothFlat() : WovenFlat();
    const auto mirrored_plus = Frame(sm, &env, plus, x);
    const auto original_minus = Frame(s, &env, minus, x);
    const auto original_plus = Frame(s, &env, plus, x);
    EXPECT_LT(MaxRelDiff(mirrored_plus, original_minus, 1e-4), 1e-9) << ToString(m);
    // ... and the tilt is a nap: +25 and -25 on the same mesh differ.
    EXPECT_GT(MaxRelDiff(original_plus, original_minus, 1e-4), 0.05) << ToString(m);
  }
}

TEST(S10Velvet, BadSheenTiltOptionsFailNamingTheProblem) {
  const Scene s = SphereWithLight(16);
  auto expect_throw = [&](PreviewOptions o, const std::string& what) {
    try {
      PreviewCache::Build(s, nullptr, o);
      ADD_FAILURE() << "no error for " << what;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  PreviewOptions o;
  o.model = ModelKind::kStandard;
  o.sheen_tilt_degrees = 10.0;
  expect_throw(o, "cloth and woven models only");
  o.model = ModelKind::kCloth;
  o.cloth.subsurface = true;
  expect_throw(o, "subsurface");
  o.cloth.subsurface = false;
  o.sheen_tilt_degrees = 95.0;
  expect_throw(o, "not in [-90, 90]");
  o.sheen_tilt_degrees = std::nan("");
  expect_throw(o, "not in [-90, 90]");
}

}  // namespace
}  // namespace clothfit::render
