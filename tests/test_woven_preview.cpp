// The woven model in the preview: the cached tangent frame is the reference renderer's
// (t Gram-Schmidt'd against the viewer-side n, b = tangent_sign n x t), the direct light equals
// brdf/woven.h at every pixel, and the Jet frame with 10 free parameters is finite.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "brdf/lut.h"
#include "brdf/woven.h"
#include "render/preview/preview.h"
#include "render/scene/embree_scene.h"
#include "render/scene/lights.h"
#include "tests/preview_fixtures.h"

namespace clothfit::render {
namespace {

std::vector<double> WovenParams() {
  // the 17th value: diffuse_roughness 0 (Lambert); the tests below set it where they need it
  return {0.47, 0.41, 0.31, 0.54, 0.51, 0.46, 0.6, 0.75, -9.0, 0.54, 0.07, 1.6, 0.1, 0.05, 0.02, 0.6,
          0.0};
}

TEST(WovenPreview, DirectLightUsesTheReferenceTangentFrame) {
  const Scene s = SphereWithLight(32);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto cache = PreviewCache::Build(s, nullptr, o);
  ASSERT_EQ(cache->tangent_v.size(), cache->pixels.size() * 2);
  ASSERT_EQ(cache->light_tangent.size(), cache->light_samples.size() * 4);
  const auto x = WovenParams();
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, x.data(), out);
  ASSERT_GT(out.size(), 300u);
  const woven::Params<double> p = woven::FromFlat(x.data());
  ForEachPixelGeometry(s, *cache, [&](size_t i, const PixelGeometry& g) {
    const Cosines<double>& c = g.cosines;
    const TangentCosines<double>& tc = g.tangent_cosines;
    const LightSample& ls = g.light;
    EXPECT_NEAR(cache->tangent_v[i * 2], tc.ToV, 1e-6);
    EXPECT_NEAR(cache->tangent_v[i * 2 + 1], tc.BoV, 1e-6);
    Rgb<double> expected(0, 0, 0);
    if (c.NoL > 0)
      expected = woven::EvalDirect(p, {}, c, tc, woven::WeaveSample<double>{}, lut::DefaultDfg(),
                                   lut::DefaultWovenPhase());
    for (int ch = 0; ch < 3; ++ch) {
      const double e = expected[ch] * ls.scale * s.lights[0].color[size_t(ch)];
      EXPECT_NEAR(out[i][ch], e, 1e-5 * std::abs(e) + 1e-6) << "pixel " << i;
    }
  });
}

TEST(WovenPreview, JetFrameWithTenFreeParametersIsFinite) {
  const Scene s = SphereWithLight(24);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto cache = PreviewCache::Build(s, nullptr, o);
  using Jet = ceres::Jet<double, 10>;
  const auto x = WovenParams();
  std::vector<Jet> xj(x.size());
  for (size_t k = 0; k < x.size(); ++k) xj[k] = k < 10 ? Jet(x[k], int(k)) : Jet(x[k]);
  std::vector<Rgb<Jet>> out;
  EvaluatePreview(*cache, xj.data(), out);
  for (const auto& px : out)
    for (int ch = 0; ch < 3; ++ch) ASSERT_TRUE(ceres::isfinite(px[ch]));
}


// brdf/woven.h's split evaluation (per frame / per pixel / per light, the preview's fast kernel)
// equals EvalDirect and EvalIbl bit for bit: double, and the Jet's value and every derivative
// (== treats the two signs of a zero derivative as equal), with the sheen off (the exact skip),
// off but free (a zero colour with derivatives: the full path), and on; additive and
// albedo-scaled yarn layers; tints; weave samples; lights below the horizon.
template <typename T>
void ExpectSame(const T& a, const T& b, const char* what, int trial) {
  if constexpr (std::is_arithmetic_v<T>) {
    ASSERT_EQ(a, b) << what << " trial " << trial;
  } else {
    ASSERT_EQ(a.a, b.a) << what << " trial " << trial;
    for (int k = 0; k < a.v.size(); ++k) ASSERT_EQ(a.v[k], b.v[k]) << what << " d" << k << " trial " << trial;
  }
}

template <typename T>
void CheckSplitEvaluation(int free_from, int free_count, const std::array<double, 3>& sheen,
                          woven::YarnLayer layer) {
  using G = woven::GeomT<T>;
  std::mt19937 rng(1234 + free_from + int(layer));
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const Table2D& dfg = lut::DefaultDfg();
  const Table2D& phase = lut::DefaultWovenPhase();
  for (int trial = 0; trial < 300; ++trial) {
    std::vector<double> xs = WovenParams();
    xs[6] = 0.05 + 0.9 * U(rng);   // roughness
    xs[7] = U(rng);                // anisotropy
    xs[8] = -60 + 120 * U(rng);    // twist
    xs[9] = U(rng);                // warp share
    xs[10] = 0.3 * U(rng);         // f0
    xs[11] = 6 * U(rng);           // beta
    for (int k = 0; k < 3; ++k) xs[size_t(12 + k)] = sheen[size_t(k)] * U(rng);
    xs[16] = trial % 4 == 0 ? 0.0 : U(rng);  // diffuse roughness: Lambert (exact skip) or On
    std::vector<T> x(xs.size());
    for (size_t k = 0; k < xs.size(); ++k) {
      if constexpr (std::is_arithmetic_v<T>) {
        x[k] = xs[k];
      } else {
        const int slot = int(k) - free_from;
        x[k] = slot >= 0 && slot < free_count ? T(xs[k], slot) : T(xs[k]);
      }
    }
    woven::Options o;
    o.yarn_layer = layer;
    if (trial % 2) {
      o.tint_warp = {1.1, 0.9, 0.8};
      o.tint_weft = {0.7, 1.0, 1.2};
    }
    woven::WeaveSample<T> ws{};
    if (trial % 3 == 1) {
      ws.warp = Const<T>(0.2 + 2 * U(rng));
      ws.weft = Const<T>(0.2 + 2 * U(rng));
      ws.kd = Rgb<T>(Const<T>(0.5 + U(rng)), Const<T>(0.5 + U(rng)), Const<T>(0.5 + U(rng)));
    }
    const woven::Params<T> p = woven::FromFlat(x.data());
    const woven::FrameTerms<T> f = woven::PrepareFrame(p, o, dfg, phase);
    // Random directions in the frame (t, b, n) = (x, y, z); v above, l anywhere near the top.
    auto dir = [&](double zmin) {
      const double z = zmin + (1 - zmin) * U(rng), ph = 2 * kPi * U(rng);
      const double r = std::sqrt(std::max(0.0, 1 - z * z));
      return Vec3<double>(r * std::cos(ph), r * std::sin(ph), z);
    };
    const Vec3<double> v = dir(0.0), l = dir(-0.3);
    const Cosines<double> cd = CosinesFromDirections(v, l);
    const TangentCosines<double> td = TangentCosinesFromDirections(v, l);
    // The cosines as the preview stores them (float), then as each path takes them.
    auto fl = [](double a) { return double(float(a)); };
    const Cosines<T> c{Const<T>(fl(cd.NoV)), Const<T>(fl(cd.NoL)), Const<T>(fl(cd.NoH)),
                       Const<T>(fl(cd.LoH))};
    const TangentCosines<T> tc{Const<T>(fl(td.ToV)), Const<T>(fl(td.BoV)), Const<T>(fl(td.ToL)),
                               Const<T>(fl(td.BoL)), Const<T>(fl(td.ToH)), Const<T>(fl(td.BoH))};
    const Rgb<T> ref = woven::EvalDirect(p, o, f.lb, c, tc, ws, dfg, phase);
    const woven::ViewTerms<T> vt = woven::PrepareView(p, f, G(fl(cd.NoV)), G(fl(td.ToV)),
                                                      G(fl(td.BoV)), ws, dfg, phase);
    const Rgb<T> got = woven::EvalDirectLight(p, f, vt, ws, G(fl(cd.NoL)), G(fl(cd.NoH)),
                                              G(fl(cd.LoH)), G(fl(td.ToL)), G(fl(td.BoL)),
                                              G(fl(td.ToH)), G(fl(td.BoH)), dfg, phase);
    for (int ch = 0; ch < 3; ++ch) ExpectSame(got[ch], ref[ch], "direct", trial);
    const woven::WovenIblWeights<T> wi = woven::EvalIbl(p, o, f.lb, c.NoV, ws, dfg, phase);
    const woven::WovenIblWeights<T> wv = woven::EvalIblView(p, f, vt, ws);
    for (int ch = 0; ch < 3; ++ch) {
      ExpectSame(wv.warp[ch], wi.warp[ch], "ibl warp", trial);
      ExpectSame(wv.weft[ch], wi.weft[ch], "ibl weft", trial);
      ExpectSame(wv.diffuse[ch], wi.diffuse[ch], "ibl diffuse", trial);
      if (!f.sheen_off) ExpectSame(wv.sheen[ch], wi.sheen[ch], "ibl sheen", trial);
      else ExpectSame(wi.sheen[ch], Const<T>(0.0), "ibl sheen (off)", trial);
    }
  }
}

TEST(WovenPreview, SplitEvaluationEqualsEvalDirectAndEvalIbl) {
  using Jet = ceres::Jet<double, 10>;
  const std::array<double, 3> off{0, 0, 0}, on{0.3, 0.2, 0.1};
  for (const auto layer : {woven::YarnLayer::kAdditive, woven::YarnLayer::kAlbedoScaled}) {
    CheckSplitEvaluation<double>(0, 0, off, layer);
    CheckSplitEvaluation<double>(0, 0, on, layer);
    CheckSplitEvaluation<Jet>(0, 10, off, layer);   // stage 1: sheen off, not free
    CheckSplitEvaluation<Jet>(0, 10, on, layer);
    CheckSplitEvaluation<Jet>(6, 10, off, layer);   // sheen colour free at 0: full path
    CheckSplitEvaluation<Jet>(6, 10, on, layer);
    CheckSplitEvaluation<Jet>(7, 10, on, layer);    // the rough-diffuse stage: sigma free
  }
  // The exact skip is taken only when it is exact.
  woven::Params<Jet> p;
  EXPECT_TRUE(woven::PrepareFrame(p, {}, lut::DefaultDfg(), lut::DefaultWovenPhase()).sheen_off);
  p.sheen_color.g = Jet(0.0, 3);
  EXPECT_FALSE(woven::PrepareFrame(p, {}, lut::DefaultDfg(), lut::DefaultWovenPhase()).sheen_off);
  EXPECT_TRUE(woven::PrepareFrame(p, {}, lut::DefaultDfg(), lut::DefaultWovenPhase()).lambert);
  p.diffuse_roughness = Jet(0.0, 9);
  EXPECT_FALSE(woven::PrepareFrame(p, {}, lut::DefaultDfg(), lut::DefaultWovenPhase()).lambert);
}

// The preview's fast woven kernel gives the generic per-light kernel's frame (woven::EvalDirect
// and EvalIbl at every pixel and light, PreviewOptions::woven_reference_kernel): bit equal in
// double, Jet values and derivatives equal up to the sign of zero, with lights and an
// environment, maps or not, sheen off and on.
TEST(WovenPreview, FastKernelEqualsTheReferenceKernel) {
  const Scene s = SphereWithLight(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.4);
  using Jet = ceres::Jet<double, 10>;
  for (int combo = 0; combo < 4; ++combo) {  // maps off / on, x ibl split / bent (review s10)
    const int maps = combo & 1;
    PreviewOptions o;
    o.model = ModelKind::kWoven;
    o.prefilter_base_width = 128;
    o.prefilter_samples = 16;
    if (combo >= 2) {  // the bent tables, built for WovenParams()'s anisotropy and twist
      o.woven.ibl = woven::IblMode::kBent;
      o.woven.bent_anisotropy = WovenParams()[7];
      o.woven.bent_twist = WovenParams()[8];
    }
    if (maps) {
      std::vector<float> level0(8 * 8 * WeaveMaps::kChannels);
      std::mt19937 rng(7);
      std::uniform_real_distribution<float> U(0.2f, 1.8f);
      for (float& v : level0) v = U(rng);
      o.weave_maps = std::make_shared<WeaveMaps>(WeaveMaps::FromLevel0(8, 10.0, level0));
    }
    auto fast = PreviewCache::Build(s, &env, o);
    ASSERT_TRUE(fast->features.direct && fast->features.ibl);
    PreviewCache ref = *fast;
    ref.options.woven_reference_kernel = true;
    for (int sheen = 0; sheen < 3; ++sheen) {
      auto xs = WovenParams();
      if (sheen == 0) xs[12] = xs[13] = xs[14] = 0.0;
      if (sheen >= 1) xs[16] = 0.6;  // the rough diffuse On (session 18)
      std::vector<Rgb<double>> a, b;
      EvaluatePreview(*fast, xs.data(), a);
      EvaluatePreview(ref, xs.data(), b);
      ASSERT_EQ(a.size(), b.size());
      for (size_t i = 0; i < a.size(); ++i)
        for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(a[i][ch], b[i][ch]) << "pixel " << i;
      // Jets: sheen == 2 frees the sheen colour and the diffuse roughness (slots 5..7 and 9 =
      // parameters 12..14 and 16).
      std::vector<Jet> xj(xs.size());
      for (size_t k = 0; k < xs.size(); ++k) {
        const int slot = sheen == 2 ? (k >= 7 ? int(k) - 7 : -1) : int(k);
        xj[k] = slot >= 0 && slot < 10 ? Jet(xs[k], slot) : Jet(xs[k]);
      }
      std::vector<Rgb<Jet>> aj, bj;
      EvaluatePreview(*fast, xj.data(), aj);
      EvaluatePreview(ref, xj.data(), bj);
      ASSERT_EQ(aj.size(), bj.size());
      for (size_t i = 0; i < aj.size(); ++i)
        for (int ch = 0; ch < 3; ++ch) {
          ASSERT_EQ(aj[i][ch].a, bj[i][ch].a) << "pixel " << i;
          for (int k = 0; k < 10; ++k) ASSERT_EQ(aj[i][ch].v[k], bj[i][ch].v[k]) << "pixel " << i;
        }
    }
  }
}

}  // namespace
}  // namespace clothfit::render
