// Session 11: the far-field yarn lobe measurement (fit/yarn_farfield.h, PreviewOptions::
// yarn_lobe; docs/fitting.md "The far-field yarn lobe (session 11)").
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

// preview_fixtures.h (material.h's woven::Options) before the reference renderer's headers,
// whose render::woven namespace would shadow clothfit::woven inside namespace render.
#include "tests/preview_fixtures.h"
#include "fit/image_fit.h"
#include "fit/yarn_farfield.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/reference/weave_pattern.h"

namespace clothfit {
namespace {

namespace fs = std::filesystem;
using render::ModelKind;
using render::PreviewCache;
using render::PreviewOptions;

std::string Fabric(const char* name) {
  return (fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics" / name).string();
}

// A lobe that depends on both directions in the tangent frame (so a swapped axis, a dropped
// component or a wrong warp/weft weight shows).
void TestLobe(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) {
  out[0] = 0.3 * wi.z * (0.2 + wo.x * wo.x) + 0.05 * (1.0 + wi.x);
  out[1] = 0.1 * (1.0 + wi.y) * (0.5 + wo.y * wo.y);
}

// The kernel adds ks (x) [2 m T_w + 2 (1 - m) T_f] NoL E to the model's terms without its yarn
// lobes, with T evaluated at the pixel's own local directions (recomputed here from the
// camera ray, independently of the cache's cosines).
TEST(S11FarField, KernelAddsTheLobeValuesInTheTangentFrame) {
  const render::Scene s = render::SphereWithLight(24);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  o.yarn_lobe = TestLobe;
  const auto cache = PreviewCache::Build(s, nullptr, o);
  ASSERT_GT(cache->pixels.size(), 100u);
  const Rgb<double> ks(0.2, 0.4, 0.6);
  const double m = 0.3;
  const auto x = render::WovenFlat({0.3, 0.2, 0.1}, ks, 0.5, 0.7, m, 0.05, 2.0);
  auto x0 = x;
  x0[3] = x0[4] = x0[5] = 0.0;  // specular_color 0: diffuse only
  std::vector<Rgb<double>> full, rest;
  render::EvaluatePreview(*cache, x.data(), full);
  render::EvaluatePreview(*cache, x0.data(), rest);
  int lit = 0;
  render::ForEachPixelGeometry(s, *cache, [&](size_t i, const render::PixelGeometry& g) {
    const Vec3<double> wo(Dot(g.t, g.v), Dot(g.b, g.v), Dot(g.n, g.v));
    const Vec3<double> wi(Dot(g.t, g.light.wi), Dot(g.b, g.light.wi), Dot(g.n, g.light.wi));
    double T[2] = {0.0, 0.0};
    if (wo.z > 0.0 && wi.z > 0.0) TestLobe(wo, wi, T);
    const double w = 2.0 * m * T[0] + 2.0 * (1.0 - m) * T[1];
    const double NoL = std::max(0.0, wi.z);
    lit += NoL > 0.0 && w > 0.0;
    for (int c = 0; c < 3; ++c) {
      const double expect = rest[i][c] + ks[c] * w * NoL * s.lights[0].color[c] * g.light.scale;
      EXPECT_NEAR(full[i][c], expect, 2e-4 * std::max(1.0, std::abs(expect))) << "pixel " << i;
    }
  });
  EXPECT_GT(lit, 50);
}

TEST(S11FarField, RefusedWhereItHasNoPath) {
  const render::Scene s = render::SphereWithLight(8);
  PreviewOptions o;
  o.model = ModelKind::kCloth;
  o.yarn_lobe = TestLobe;
  EXPECT_THROW(PreviewCache::Build(s, nullptr, o), std::invalid_argument);
  o.model = ModelKind::kWoven;
  const render::Environment env = render::DiscEnvironment(64, 32, {0, 1, 0}, 20, {4, 4, 4}, {0.2, 0.2, 0.2});
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);  // split sum
  o.exact_ibl_samples = 16;
  EXPECT_NO_THROW(PreviewCache::Build(s, &env, o));
  o.woven.yarn_layer = woven::YarnLayer::kAlbedoScaled;
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
}

// The far-field lobe is the period average of the reference BSDF's specular term:
// E_uv[Eval(wo, wi, uv)] = sum_k ks_k T_k(wo, wi) + E_uv[kd] / pi, with the left side from
// IrawanBsdf::Eval at random surface points (the path tracer's own evaluation).
TEST(S11FarField, IsThePeriodAverageOfTheReferenceBsdf) {
  const std::string path = Fabric("twill.json");
  const fit::YarnFarField ff(path, 4096);
  const render::Fabric fab = render::LoadFabric(path);
  const auto* irawan = dynamic_cast<const render::IrawanBsdf*>(fab.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const Vec3<double> dirs[][2] = {
      {Normalize(Vec3<double>(0.3, 0.1, 0.9)), Normalize(Vec3<double>(-0.4, 0.05, 0.8))},
      {Normalize(Vec3<double>(0.1, 0.6, 0.5)), Normalize(Vec3<double>(-0.2, -0.7, 0.4))},
      {Normalize(Vec3<double>(0.9, 0.2, 0.2)), Normalize(Vec3<double>(-0.85, -0.1, 0.3))}};
  for (const auto& d : dirs) {
    const int N = 200000;
    Rgb<double> mean(0, 0, 0), kd(0, 0, 0), ks_w(0, 0, 0), ks_f(0, 0, 0);
    int nw = 0, nf = 0;
    for (int k = 0; k < N; ++k) {
      render::ShadingPoint sp;
      sp.uv = {U(rng) * 3.0, U(rng) * 3.0};
      mean = mean + irawan->Eval(d[0], d[1], sp) * (1.0 / N);
      const render::IrawanPoint p = irawan->Locate(sp.uv);
      const auto& y = irawan->pattern().yarns[size_t(p.yarn)];
      kd = kd + y.kd * (1.0 / N);
      if (y.type == render::YarnType::kWarp) ks_w = ks_w + y.ks, ++nw;
      else ks_f = ks_f + y.ks, ++nf;
    }
    ASSERT_GT(nw, 0);
    ASSERT_GT(nf, 0);
    double T[2];
    ff.Eval(d[0], d[1], T);
    EXPECT_GT(T[0] + T[1], 0.0);
    for (int c = 0; c < 3; ++c) {
      const double expect = ks_w[c] / nw * T[0] + ks_f[c] / nf * T[1] + kd[c] * kInvPi;
      EXPECT_NEAR(mean[c], expect, 0.03 * expect) << "channel " << c;
    }
  }
}

// ks is a relative albedo (irawan.h: with ks = 1 the tile-averaged bi-hemispherical specular
// albedo is 1), so E over cosine-distributed wo, wi of pi (T_w + T_f) is 1, up to the
// reference's own estimate of specNorm (10 000 draws of a heavy-tailed integrand: measured 1.00
// canvas, 1.065 twill, hence the 0.1); a plain weave (canvas) splits it about evenly between
// warp and weft.
TEST(S11FarField, NormalisedAsTheReference) {
  for (const char* name : {"canvas.json", "twill.json"}) {
    const fit::YarnFarField ff(Fabric(name), 64);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    auto cosine = [&]() {
      const double u1 = U(rng), u2 = U(rng), r = std::sqrt(u1), phi = 2 * kPi * u2;
      return Vec3<double>(r * std::cos(phi), r * std::sin(phi), std::sqrt(1 - u1));
    };
    const int N = 40000;
    double sum = 0.0;
    for (int k = 0; k < N; ++k) {
      double T[2];
      ff.Eval(cosine(), cosine(), T);
      sum += T[0] + T[1];
    }
    EXPECT_NEAR(kPi * sum / N, 1.0, 0.1) << name;
  }
  const fit::YarnFarField canvas(Fabric("canvas.json"), 64);
  EXPECT_NEAR(canvas.WarpAlbedoShare(20000), 0.5, 0.1);
  EXPECT_THROW(fit::YarnFarField(Fabric("velvet.json")), std::invalid_argument);
  EXPECT_THROW(fit::YarnFarField(Fabric("canvas.json"), 15), std::invalid_argument);
}

}  // namespace
}  // namespace clothfit

namespace clothfit {
namespace {

// A table filled from a known function: nodes reproduce it, phi wraps, and the IBL summary of
// a constant lobe is the cosine lobe's (A = c pi, mean direction n, mean cosine 2/3).
TEST(S11YarnTable, NodesWrapAndIblSummary) {
  yarn_table::Table t;
  t.n_theta = 8;
  t.n_phi = 16;
  const size_t D = size_t(t.n_theta * t.n_phi);
  t.lobe.assign(2 * D * D, 0.f);
  t.ibl.assign(2 * D * 5, 0.f);
  auto f = [](const Vec3<double>& wo, const Vec3<double>& wi, int k) {
    return k == 0 ? 0.5 + 0.25 * wo.x * wi.y + 0.1 * wi.z + 0.2 * wo.y : 0.3;
  };
  const double dth = 0.5 * kPi / t.n_theta, dph = 2 * kPi / t.n_phi;
  for (size_t o = 0; o < D; ++o) {
    const Vec3<double> wo = t.Direction(int(o) / t.n_phi, int(o) % t.n_phi);
    double A[2] = {0, 0};
    Vec3<double> m[2] = {{0, 0, 0}, {0, 0, 0}};
    for (size_t i = 0; i < D; ++i) {
      const int it = int(i) / t.n_phi;
      const Vec3<double> wi = t.Direction(it, int(i) % t.n_phi);
      const double w = wi.z * std::sin((it + 0.5) * dth) * dth * dph;
      for (int k = 0; k < 2; ++k) {
        t.lobe[(size_t(k) * D + o) * D + i] = float(f(wo, wi, k));
        A[k] += f(wo, wi, k) * w;
        m[k] = m[k] + wi * (f(wo, wi, k) * w);
      }
    }
    for (int k = 0; k < 2; ++k) {
      float* e = &t.ibl[(size_t(k) * D + o) * 5];
      const Vec3<double> d = Normalize(m[k]);
      e[0] = float(A[k]);
      e[1] = float(d.x);
      e[2] = float(d.y);
      e[3] = float(d.z);
      e[4] = float(yarn_table::RoughnessForMeanCosine(Length(m[k]) / A[k]));
    }
  }
  ASSERT_TRUE(t.Valid());
  for (int it : {0, 3, 7})
    for (int ip : {0, 5, 15}) {
      const Vec3<double> wo = t.Direction(it, ip), wi = t.Direction(7 - it, (ip + 3) % t.n_phi);
      double v[2];
      t.Eval(wo, wi, v);
      EXPECT_NEAR(v[0], f(wo, wi, 0), 1e-6);
      EXPECT_NEAR(v[1], 0.3, 1e-6);
    }
  // phi = 0 lies half-way between the last phi bin (centre -11.25 deg) and the first (+11.25):
  // the periodic interpolation gives the mean of the two (f depends on wo.y, which differs in
  // sign between them), at theta on a bin centre
  const Vec3<double> wi = t.Direction(5, 3);
  const Vec3<double> c0 = t.Direction(3, 0), c15 = t.Direction(3, 15);
  const double th = std::acos(c0.z);
  const Vec3<double> a(std::sin(th), 0.0, std::cos(th));
  double va[2];
  t.Eval(a, wi, va);
  EXPECT_NEAR(va[0], 0.5 * (f(c0, wi, 0) + f(c15, wi, 0)), 1e-6);
  EXPECT_GT(std::abs(f(c0, wi, 0) - f(c15, wi, 0)), 0.04);  // the two bins differ
  double below[2];
  t.Eval(a, Vec3<double>(0.1, 0.1, -0.5), below);
  EXPECT_EQ(below[0], 0.0);
  yarn_table::IblLobe node[2];
  t.Ibl(t.Direction(2, 5), node);  // a node: the stored summary of lobe 0 (not constant in wo)
  const float* e = &t.ibl[(size_t(0) * D + 2 * 16 + 5) * 5];
  EXPECT_NEAR(node[0].albedo, e[0], 1e-6);
  EXPECT_NEAR(node[0].dir.x, e[1], 1e-6);
  EXPECT_NEAR(node[0].dir.y, e[2], 1e-6);
  EXPECT_NEAR(node[0].roughness, e[4], 1e-6);
  // BinTaps: one tap per bin (none dropped here: every bin has weight), weights = the summary's
  // albedo integrand, each tap at its bin centre with its row's roughness
  std::vector<yarn_table::IblTap> taps;
  const std::vector<double> rows = t.BinRoughness();
  ASSERT_EQ(rows.size(), 8u);
  EXPECT_LT(rows[0], rows[7]);  // bins near the pole are smaller: a sharper read
  t.BinTaps(t.Direction(2, 5), rows, &taps);
  ASSERT_EQ(taps.size(), D);
  double sw[2] = {0, 0};
  for (const auto& tp : taps) sw[0] += tp.weight[0], sw[1] += tp.weight[1];
  EXPECT_NEAR(sw[0], double(e[0]), 1e-5 * double(e[0]));
  EXPECT_NEAR(sw[1], 0.3 * kPi, 0.01 * 0.3 * kPi);
  EXPECT_NEAR(taps[size_t(3 * 16 + 4)].dir.x, t.Direction(3, 4).x, 1e-12);
  EXPECT_EQ(taps[size_t(3 * 16 + 4)].roughness, rows[3]);
  yarn_table::IblLobe lobes[2];
  t.Ibl(Normalize(Vec3<double>(0.3, -0.2, 0.8)), lobes);
  EXPECT_NEAR(lobes[1].albedo, 0.3 * kPi, 0.01 * 0.3 * kPi);  // midpoint rule of cos over 8 x 16 bins
  EXPECT_NEAR(lobes[1].dir.z, 1.0, 1e-6);
  EXPECT_NEAR(lobes[1].roughness, yarn_table::RoughnessForMeanCosine(2.0 / 3.0), 0.01);
}

// The prefiltered lobe's mean cosine falls monotonically with roughness, and the inversion
// returns the roughness it was given.
TEST(S11YarnTable, MeanCosineInversion) {
  double prev = 1.1;
  for (double r = 0.05; r <= 1.0; r += 0.05) {
    const double mu = yarn_table::PrefilteredMeanCosine(r);
    EXPECT_LT(mu, prev) << r;
    prev = mu;
    EXPECT_NEAR(yarn_table::RoughnessForMeanCosine(mu), r, 1e-4) << r;
  }
  EXPECT_GT(yarn_table::PrefilteredMeanCosine(0.05), 0.99);
  // r = 1: D = 1 / pi, h ~ cos(theta_h), l = reflect: with c = cos theta_h, n.l = 2c^2 - 1 on
  // c^2 > 1/2; mu = int (2c^2-1)^2 c s / int (2c^2-1) c s over theta_h in [0, pi/4]
  // = [with x = c^2: int_{1/2}^1 (2x-1)^2 dx / int_{1/2}^1 (2x-1) dx] = (1/6) / (1/4) = 2/3
  EXPECT_NEAR(yarn_table::PrefilteredMeanCosine(1.0), 2.0 / 3.0, 1e-4);
}

// Bake: the lobe entries are the far-field at the bin centres, the IBL albedo their cosine
// integral.
TEST(S11YarnTable, BakeIsTheFarFieldAtTheBinCentres) {
  const fit::YarnFarField ff(Fabric("canvas.json"), 4);
  const yarn_table::Table t = ff.Bake(6, 12);
  ASSERT_TRUE(t.Valid());
  const size_t D = 72;
  double A = 0.0;
  for (size_t i = 0; i < D; ++i) {
    const int it = int(i) / 12;
    const Vec3<double> wo = t.Direction(2, 5), wi = t.Direction(it, int(i) % 12);
    double v[2];
    ff.Eval(wo, wi, v);
    EXPECT_FLOAT_EQ(t.lobe[(0 * D + 2 * 12 + 5) * D + i], float(v[0]));
    EXPECT_FLOAT_EQ(t.lobe[(1 * D + 2 * 12 + 5) * D + i], float(v[1]));
    const double dth = 0.5 * kPi / 6;
    A += v[0] * wi.z * std::sin((it + 0.5) * dth) * dth * (2 * kPi / 12);
  }
  EXPECT_NEAR(t.ibl[(0 * D + 2 * 12 + 5) * 5], A, 1e-5 * std::max(1.0, A));
  // the mean direction and the roughness of its mean cosine, recomputed
  Vec3<double> m(0, 0, 0);
  for (size_t i = 0; i < D; ++i) {
    const int it = int(i) / 12;
    const Vec3<double> wi = t.Direction(it, int(i) % 12);
    double v[2];
    ff.Eval(t.Direction(2, 5), wi, v);
    const double dth = 0.5 * kPi / 6;
    m = m + wi * (v[0] * wi.z * std::sin((it + 0.5) * dth) * dth * (2 * kPi / 12));
  }
  const float* e = &t.ibl[(0 * D + 2 * 12 + 5) * 5];
  const Vec3<double> d = Normalize(m);
  EXPECT_NEAR(e[1], d.x, 1e-5);
  EXPECT_NEAR(e[2], d.y, 1e-5);
  EXPECT_NEAR(e[3], d.z, 1e-5);
  EXPECT_NEAR(e[4], yarn_table::RoughnessForMeanCosine(Length(m) / A), 1e-4);
}

// The split-sum read follows the lobe's direction in the tangent frame: with a bright disc at
// the zenith, a lobe along +n (local z) is brightest where the normal points up, a lobe along b
// (local y) where b points up.
TEST(S11YarnTable, SplitSumReadsAlongTheLobeDirection) {
  render::Scene s = render::SphereWithLight(16);
  s.lights[0].intensity = 0.0;
  const render::Environment env =
      render::DiscEnvironment(128, 64, {0, 1, 0}, 25, {8, 8, 8}, {0.05, 0.05, 0.05});
  auto frame = [&](const Vec3<double>& dir) {
    PreviewOptions o;
    o.model = ModelKind::kWoven;
    o.ibl_engine = render::IblEngine::kThreejs;
    o.yarn_lobe = TestLobe;
    o.yarn_ibl = [dir](const Vec3<double>&, yarn_table::IblLobe out[2]) {
      out[0].albedo = 1.0;
      out[0].dir = dir;
      out[0].roughness = 0.2;
      out[1].albedo = 0.0;
    };
    std::unique_ptr<PreviewCache> cache;
    const auto x = render::WovenFlat({0.0, 0.0, 0.0}, {1, 1, 1}, 0.5, 0.7, 1.0, 0.05, 2.0);
    const auto out = render::PreviewFrame(s, env, o, x, &cache);
    // the brightest pixel's world normal . up and tangent . up
    size_t best = 0;
    for (size_t i = 0; i < out.size(); ++i)
      if (out[i][0] > out[best][0]) best = i;
    double nup = 0, dup = 0;  // at the brightest pixel: n.up and the lobe's world direction.up
    render::ForEachPixelGeometry(s, *cache, [&](size_t i, const render::PixelGeometry& g) {
      if (i == best) nup = g.n.y, dup = (g.t * dir.x + g.b * dir.y + g.n * dir.z).y;
    });
    return std::pair<double, double>(nup, dup);
  };
  const auto along_n = frame({0, 0, 1});
  const auto along_b = frame({0, -1, 0});  // local -y = -b
  EXPECT_GT(along_n.second, 0.9);  // the brightest pixel reads the disc at the zenith
  EXPECT_GT(along_b.second, 0.9);
  EXPECT_GT(std::abs(along_n.first - along_b.first), 0.3);  // at different places on the sphere
}

// The split-sum path of the yarn lobes: under a constant environment every prefiltered read is
// that constant, so the yarn term is ks (x) [2 m A_w + 2 (1 - m) A_f] L.
TEST(S11YarnTable, SplitSumWeightsUnderAConstantSky) {
  // the lit sphere with its light at intensity 0 (ForEachPixelGeometry reads lights[0])
  render::Scene s = render::SphereWithLight(16);
  s.lights[0].intensity = 0.0;
  const render::Environment env =
      render::EnvironmentFrom(64, 32, [](const Vec3<double>&) { return Rgb<double>(0.7, 0.7, 0.7); });
  for (int variant = 0; variant < 4; ++variant) {
    const render::IblEngine engine =
        variant % 2 ? render::IblEngine::kThreejs : render::IblEngine::kFilament;
    PreviewOptions o;
    o.model = ModelKind::kWoven;
    o.ibl_engine = engine;
    o.yarn_lobe = TestLobe;
    if (variant < 2) {
      o.yarn_ibl = render::SyntheticYarnIbl;
    } else {  // the same weights as three reads (yarn_ibl_taps): they sum
      o.yarn_ibl_taps = [](const Vec3<double>& wo, std::vector<yarn_table::IblTap>* taps) {
        taps->clear();
        yarn_table::IblTap a, b, c;
        a.weight[0] = 0.25 + 0.2 * wo.x;
        a.dir = Normalize(Vec3<double>(0.3, 0.1, 0.9));
        a.roughness = 0.2;
        b.weight[0] = 0.15;
        b.weight[1] = 0.04;
        b.dir = {0.0, 0.0, 1.0};
        c.weight[1] = 0.06;
        c.dir = Normalize(Vec3<double>(-0.5, 0.2, 0.6));
        c.roughness = 0.6;
        taps->insert(taps->end(), {a, b, c});
      };
    }
    const auto cache = PreviewCache::Build(s, &env, o);
    ASSERT_EQ(cache->yarn_ibl.size(), cache->pixels.size() * 6);
    const Rgb<double> ks(0.2, 0.4, 0.6);
    const double m = 0.3;
    const auto x = render::WovenFlat({0.3, 0.2, 0.1}, ks, 0.5, 0.7, m, 0.05, 2.0);
    auto x0 = x;
    x0[3] = x0[4] = x0[5] = 0.0;
    std::vector<Rgb<double>> full, rest;
    render::EvaluatePreview(*cache, x.data(), full);
    render::EvaluatePreview(*cache, x0.data(), rest);
    render::ForEachPixelGeometry(s, *cache, [&](size_t i, const render::PixelGeometry& g) {
      const double Aw = 0.4 + 0.2 * Dot(g.t, g.v);
      const double w = 2.0 * m * Aw + 2.0 * (1.0 - m) * 0.1;
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(full[i][c] - rest[i][c], ks[c] * w * 0.7, 0.02 * ks[c] * w * 0.7) << i;
    });
  }
}

}  // namespace
}  // namespace clothfit

namespace clothfit {
namespace {

// The deterministic quadrature (the shader-shaped evaluation) is the same tile average as the
// Monte Carlo over positions: canvas (2 x 2 tile, segments of one cell) and twill (warp floats
// of several cells, a weft wider than its cell: the band's overlap with the cells matters).
TEST(S11FarField, QuadratureEqualsTheTileAverage) {
  for (const char* name : {"canvas.json", "twill.json"}) {
    const fit::YarnFarField ff(Fabric(name), 4096);
    const Vec3<double> dirs[][2] = {
        {Normalize(Vec3<double>(0.3, 0.1, 0.9)), Normalize(Vec3<double>(-0.4, 0.05, 0.8))},
        {Normalize(Vec3<double>(0.1, 0.6, 0.5)), Normalize(Vec3<double>(-0.2, -0.7, 0.4))},
        {Normalize(Vec3<double>(0.05, -0.97, 0.2)), Normalize(Vec3<double>(-0.1, 0.95, 0.26))},
        {Normalize(Vec3<double>(0.9, 0.2, 0.2)), Normalize(Vec3<double>(-0.85, -0.1, 0.3))}};
    for (const auto& d : dirs) {
      double mc[2] = {0, 0}, q[2];
      for (int rep = 0; rep < 32; ++rep) {  // 32 x 4096 positions (the hash varies with wo)
        const Vec3<double> wo = Normalize(d[0] + Vec3<double>(1e-9 * rep, 0, 0));
        double v[2];
        ff.Eval(wo, d[1], v);
        mc[0] += v[0] / 32;
        mc[1] += v[1] / 32;
      }
      ff.EvalQuadrature(d[0], d[1], q, 64);
      for (int k = 0; k < 2; ++k)
        EXPECT_NEAR(q[k], mc[k], 0.03 * std::max(mc[k], 0.05 * (mc[0] + mc[1]))) << name << " lobe " << k;
    }
    double z[2];
    EXPECT_THROW(ff.EvalQuadrature(dirs[0][0], dirs[0][1], z, 0), std::invalid_argument);
  }
}

}  // namespace
}  // namespace clothfit

namespace clothfit {
namespace {

// fit.yarn_lobe_settings round-trips, names the bad field, and ApplyYarnLobe configures the fit
// as the mode says (evaluate draws what fit drew).
TEST(S11YarnLobeSettings, RoundTripErrorsAndModes) {
  fit::YarnLobeSettings s;
  s.mode = "quadrature";
  s.fabric = Fabric("canvas.json");
  s.nodes = 8;
  s.table_theta = 4;
  const fit::YarnLobeSettings r = fit::YarnLobeSettingsFromJson(fit::ToJson(s), "p.json: fit.x");
  EXPECT_EQ(r.mode, s.mode);
  EXPECT_EQ(r.fabric, s.fabric);
  EXPECT_EQ(r.nodes, 8);
  EXPECT_EQ(r.table_theta, 4);
  nlohmann::json bad = fit::ToJson(s);
  bad["nodes"] = 0;
  try {
    fit::YarnLobeSettingsFromJson(bad, "p.json: fit.x");
    ADD_FAILURE() << "nodes 0 accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("p.json: fit.x.nodes"), std::string::npos) << e.what();
  }
  fit::FitOptions o;
  EXPECT_TRUE(fit::ApplyYarnLobe(r, &o).find("yarn table 4 x 8") != std::string::npos);
  EXPECT_TRUE(o.yarn_far_field && o.yarn_table && o.yarn_table_ibl_only);
  EXPECT_EQ(o.yarn_quadrature_nodes, 8);
  EXPECT_NE(std::find(o.locked.begin(), o.locked.end(), "forward_scattering"), o.locked.end());
  fit::YarnLobeSettings f = r;
  f.mode = "farfield";
  fit::FitOptions of;
  EXPECT_TRUE(fit::ApplyYarnLobe(f, &of).empty());
  EXPECT_TRUE(of.yarn_far_field && !of.yarn_table && of.yarn_quadrature_nodes == 0);
  f.mode = "nonsense";
  EXPECT_THROW(fit::ApplyYarnLobe(f, &of), std::invalid_argument);
  f.mode = "table";
  f.table_theta = 64;
  f.table_jitter = 4096;
  EXPECT_THROW(fit::ApplyYarnLobe(f, &of), std::invalid_argument);  // the bake budget
}

}  // namespace
}  // namespace clothfit

namespace clothfit {
namespace {

// SpecularBandAverage is the mean of SpecularIntegrand over the band coordinate uniform in
// [-e, e], including e smaller than the yarn (the band then overlaps the cells only partly):
// a staple yarn (cotton canvas, band across) and a filament yarn (silk charmeuse, band along).
TEST(S11FarField, BandAverageIsTheMeanOverTheBandCoordinate) {
  const fs::path weaves = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "weaves";
  const Vec3<double> dirs[][2] = {
      {Normalize(Vec3<double>(0.3, 0.1, 0.9)), Normalize(Vec3<double>(-0.4, 0.05, 0.8))},
      {Normalize(Vec3<double>(0.1, 0.6, 0.5)), Normalize(Vec3<double>(-0.2, -0.7, 0.4))},
      {Normalize(Vec3<double>(0.6, -0.3, 0.5)), Normalize(Vec3<double>(-0.1, 0.5, 0.7))}};
  int nonzero = 0;
  for (const char* name : {"cotton_canvas.weave", "silk_charmeuse.weave"}) {
    const render::IrawanBsdf b(render::LoadWeave((weaves / name).string()), 1.0, 1.0);
    const render::Yarn& y = b.pattern().yarns[0];
    const bool staple = y.psi != 0.0;
    const double umax = y.umax * kPi / 180.0;
    for (double e : {0.5 * (staple ? y.width : y.length), 0.3, 0.12}) {
      for (double s : {-0.6, 0.1, 0.7}) {
        render::IrawanPoint p;
        p.yarn = 0;
        p.umax = umax;
        if (staple) {
          p.u = s * umax;
          p.sin_u = std::sin(p.u);
          p.cos_u = std::cos(p.u);
          p.spine_radius = render::SpineRadius(std::abs(p.u), umax, y.kappa, y.width, y.length);
        } else {
          p.v = s * 0.5 * kPi;
          p.across = s * 0.5 * y.width;
        }
        for (const auto& d : dirs) {
          const int M = 20000;
          double mean = 0.0;
          for (int k = 0; k < M; ++k) {  // the band coordinate over [-e, e], midpoints
            const double c = (-1.0 + (2.0 * k + 1.0) / M) * e;
            if (staple) p.across = c;
            else p.along = c;
            mean += b.SpecularIntegrand(p, d[0], d[1]) / M;
          }
          const double avg = b.SpecularBandAverage(p, d[0], d[1], e);
          EXPECT_NEAR(avg, mean, 2e-3 * std::max(mean, 1e-3)) << name << " e " << e << " s " << s;
          nonzero += mean > 0.0;
        }
      }
    }
  }
  EXPECT_GT(nonzero, 10);  // the directions meet highlights
}

}  // namespace
}  // namespace clothfit

