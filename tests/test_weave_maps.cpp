// Weave maps (issue 12, deliverable 2): the map data type and its GPU-style sampling
// (render/preview/weave_maps.h), the bake from the reference weave (fit/weave_maps.h), and the
// preview with maps (uniform maps = no maps, bit for bit; the coarsest mip = the uniform model).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "fit/weave_maps.h"
#include "render/preview/preview.h"
#include "render/preview/weave_maps.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/scene/embree_scene.h"
#include "render/scene/image_io.h"
#include "tests/preview_fixtures.h"

namespace clothfit::render {
namespace {

namespace fs = std::filesystem;
constexpr int C = WeaveMaps::kChannels;

std::vector<float> RandomLevel0(int size, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.1f, 2.0f);
  std::vector<float> v(size_t(size) * size_t(size) * C);
  for (float& x : v) x = u(rng);
  return v;
}

// datasets/fabrics/canvas.json (an Irawan fabric: its bsdf is an IrawanBsdf).
Fabric CanvasFabric() {
  return LoadFabric((fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics" / "canvas.json").string());
}

TEST(WeaveMaps, LevelZeroIsNormalisedAndMipsAreBoxAverages) {
  const WeaveMaps m = WeaveMaps::FromLevel0(8, 3.0, RandomLevel0(8, 1));
  ASSERT_EQ(m.level_count(), 4);  // 8, 4, 2, 1
  for (int ch = 0; ch < C; ++ch) {
    double mean = 0;
    for (int t = 0; t < 64; ++t) mean += double(m.levels[0][size_t(t * C + ch)]);
    EXPECT_NEAR(mean / 64, 1.0, 1e-6);
    EXPECT_NEAR(m.levels[3][size_t(ch)], 1.0, 1e-6);  // the 1 x 1 level is the tile mean
    // level 1 texel (1, 2) = mean of level 0 texels (2..3, 4..5)
    const auto at0 = [&](int i, int j) { return double(m.levels[0][size_t((j * 8 + i) * C + ch)]); };
    EXPECT_NEAR(m.levels[1][size_t((2 * 4 + 1) * C + ch)],
                0.25 * (at0(2, 4) + at0(3, 4) + at0(2, 5) + at0(3, 5)), 1e-6);
  }
  EXPECT_THROW(WeaveMaps::FromLevel0(6, 1.0, std::vector<float>(36 * C, 1.f)), std::invalid_argument);
  EXPECT_THROW(WeaveMaps::FromLevel0(4, 1.0, std::vector<float>(16 * C, 0.f)), std::invalid_argument);
  std::vector<float> neg(16 * C, 1.f);
  neg[3] = -1.f;
  EXPECT_THROW(WeaveMaps::FromLevel0(4, 1.0, neg), std::invalid_argument);
}

TEST(WeaveMaps, SamplingIsBilinearWithRepeatAtTexelCentres) {
  const double R = 5.0;
  const int S = 16;
  const WeaveMaps m = WeaveMaps::FromLevel0(S, R, RandomLevel0(S, 2));
  auto texel = [&](int i, int j, int ch) { return double(m.levels[0][size_t((j * S + i) * C + ch)]); };
  auto uv = [&](double i, double j) { return std::array<double, 2>{i / (S * R), j / (S * R)}; };
  for (int ch = 0; ch < C; ++ch) {
    const auto c = uv(3.5, 7.5);  // centre of texel (3, 7)
    EXPECT_NEAR(m.Sample(c[0], c[1], 0.0)[size_t(ch)], texel(3, 7, ch), 1e-6);
    // REPEAT: one period (1 / R in uv) further, and negative uv
    EXPECT_NEAR(m.Sample(c[0] + 2.0 / R, c[1] - 1.0 / R, 0.0)[size_t(ch)], texel(3, 7, ch), 1e-6);
    // halfway between texel centres (3, 7) and (4, 7)
    const auto h = uv(4.0, 7.5);
    EXPECT_NEAR(m.Sample(h[0], h[1], 0.0)[size_t(ch)], 0.5 * (texel(3, 7, ch) + texel(4, 7, ch)), 1e-6);
    // wrap across the tile edge: between texel S-1 and texel 0
    const auto w = uv(0.0, 7.5);
    EXPECT_NEAR(m.Sample(w[0], w[1], 0.0)[size_t(ch)], 0.5 * (texel(S - 1, 7, ch) + texel(0, 7, ch)),
                1e-6);
    // trilinear: lambda 0.5 is the mean of levels 0 and 1 at the same uv
    const double l0 = m.SampleLevel(c[0], c[1], 0)[size_t(ch)], l1 = m.SampleLevel(c[0], c[1], 1)[size_t(ch)];
    EXPECT_NEAR(m.Sample(c[0], c[1], 0.5)[size_t(ch)], 0.5 * (l0 + l1), 1e-6);
    // beyond the last level: the tile mean
    EXPECT_NEAR(m.Sample(c[0], c[1], 99.0)[size_t(ch)], 1.0, 1e-6);
  }
  // LOD: one texel per pixel -> 0; four texels per pixel along y -> 2; footprint scale 2 -> 3.
  const double t = 1.0 / (S * R);
  EXPECT_NEAR(m.Lod({t, 0, 0, 0.5 * t}), 0.0, 1e-12);
  EXPECT_NEAR(m.Lod({t, 0, 0, 4 * t}), 2.0, 1e-12);
  EXPECT_NEAR(m.Lod({t, 0, 0, 4 * t}, 2.0), 3.0, 1e-12);
  EXPECT_NEAR(m.Lod({0.25 * t, 0, 0, 0.25 * t}), 0.0, 1e-12);  // magnification: level 0
  EXPECT_DOUBLE_EQ(m.Lod({INFINITY, 0, 0, 0}), 4.0);            // top level (16 -> 1)
}

TEST(WeaveMaps, FileRoundTripAndErrorsNameTheFile) {
  const fs::path dir = fs::temp_directory_path() / "clothfit_weave_maps_test";
  fs::create_directories(dir);
  const WeaveMaps m = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 3));
  const std::string path = (dir / "m.weave.exr").string();
  WriteWeaveMaps(path, m);
  const WeaveMaps r = ReadWeaveMaps(path);
  EXPECT_EQ(r.size, 8);
  EXPECT_DOUBLE_EQ(r.uv_repeats, 40.0);
  ASSERT_EQ(r.levels[0].size(), m.levels[0].size());
  for (size_t k = 0; k < r.levels[0].size(); ++k) EXPECT_NEAR(r.levels[0][k], m.levels[0][k], 1e-6);

  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  EXPECT_EQ(LoadPresetWeaveMaps(p), nullptr);  // no field: no maps
  p.extra["weave_maps"] = WeaveMapsPresetField(path, m);
  const auto loaded = LoadPresetWeaveMaps(p);
  ASSERT_NE(loaded, nullptr);
  EXPECT_EQ(loaded->size, 8);
  p.extra["weave_maps"]["file"] = (dir / "missing.exr").string();
  try {
    LoadPresetWeaveMaps(p);
    FAIL() << "no error for a missing maps file";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("missing.exr"), std::string::npos) << e.what();
  }
  p.extra["weave_maps"] = 3;
  try {
    LoadPresetWeaveMaps(p);
    FAIL() << "no error for a malformed field";
  } catch (const MaterialError& e) {
    EXPECT_NE(std::string(e.what()).find("weave_maps"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

TEST(WeaveMaps, UvDerivativesMatchTheNeighbouringPixelsOnTheSphere) {
  const Scene s = SphereWithLight(64);
  EmbreeScene bvh(s);
  int checked = 0;
  for (int py = 20; py < 44; py += 3)
    for (int px = 20; px < 44; px += 3) {
      auto uv_at = [&](double x, double y, Hit* out) {
        std::array<double, 3> o, d;
        s.CameraRay(x, y, o, d);
        *out = bvh.Intersect(o, d);
        return bvh.Attributes(*out).uv;
      };
      Hit h, hx, hy;
      const auto c = uv_at(px + 0.5, py + 0.5, &h), cx = uv_at(px + 1.5, py + 0.5, &hx),
                 cy = uv_at(px + 0.5, py + 1.5, &hy);
      ASSERT_TRUE(h.valid && hx.valid && hy.valid);
      const auto d = UvDerivatives(s, h, px + 0.5, py + 0.5);
      // Same surface, one pixel apart: the plane extrapolation agrees with the true uv
      // differences to first order (the sphere curves within a pixel only slightly).
      const double tol = 0.1 * (std::abs(cx[0] - c[0]) + std::abs(cy[1] - c[1])) + 1e-5;
      if (std::abs(cx[0] - c[0]) > 0.25 || std::abs(cy[0] - c[0]) > 0.25) continue;  // u seam
      EXPECT_NEAR(d[0], cx[0] - c[0], tol);
      EXPECT_NEAR(d[1], cx[1] - c[1], tol);
      EXPECT_NEAR(d[2], cy[0] - c[0], tol);
      EXPECT_NEAR(d[3], cy[1] - c[1], tol);
      ++checked;
    }
  EXPECT_GT(checked, 40);
}

// The bake on canvas: every channel has a tile mean of 1, the warp channel is high where the
// reference's Locate puts a warp yarn on top and the weft channel where it puts a weft yarn,
// and the per-texel fit lowers the BRDF-space error against one uniform WeaveSample.
TEST(WeaveBake, FollowsTheReferenceWeaveAndLowersTheTexelError) {
  const Fabric f = CanvasFabric();
  const auto* irawan = dynamic_cast<const IrawanBsdf*>(f.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  fit::WeaveBakeOptions o;
  o.size = 16;
  const fit::WeaveBakeResult r = fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o);
  ASSERT_EQ(r.maps.size, 16);
  EXPECT_LT(r.error_mapped, r.error_uniform);
  double warp_on_warp = 0, warp_on_weft = 0, weft_on_warp = 0, weft_on_weft = 0;
  int n_warp = 0, n_weft = 0;
  const double R = irawan->repeat_u();
  for (int j = 0; j < 16; ++j)
    for (int i = 0; i < 16; ++i) {
      const IrawanPoint p = irawan->Locate({(i + 0.5) / (16 * R), (j + 0.5) / (16 * R)});
      const float* t = &r.maps.levels[0][size_t((j * 16 + i) * C)];
      for (int ch = 0; ch < C; ++ch) ASSERT_TRUE(std::isfinite(t[ch]) && t[ch] >= 0.f);
      if (irawan->pattern().yarns[size_t(p.yarn)].type == YarnType::kWarp) {
        warp_on_warp += double(t[0]);
        weft_on_warp += double(t[1]);
        ++n_warp;
      } else {
        warp_on_weft += double(t[0]);
        weft_on_weft += double(t[1]);
        ++n_weft;
      }
    }
  ASSERT_GT(n_warp, 0);
  ASSERT_GT(n_weft, 0);
  EXPECT_GT(warp_on_warp / n_warp, warp_on_weft / n_weft);
  EXPECT_GT(weft_on_weft / n_weft, weft_on_warp / n_warp);
  EXPECT_THROW(fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kCloth), o),
               std::invalid_argument);

  // Indicator maps: warp + weft indicators sum to 1 per texel before normalisation, so
  // warp / mean_warp x mean_warp + weft / mean_weft x mean_weft = 1; a texel whose centre and
  // all sub-positions lie on one yarn type has 0 on the other channel.
  o.indicator = true;
  const fit::WeaveBakeResult ind = fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o);
  EXPECT_NEAR(ind.mean_warp + ind.mean_weft, 1.0, 1e-9);
  int zeros = 0;
  for (int t = 0; t < 256; ++t) {
    const float* x = &ind.maps.levels[0][size_t(t * C)];
    EXPECT_NEAR(double(x[0]) * ind.mean_warp + double(x[1]) * ind.mean_weft, 1.0, 1e-5);
    zeros += (x[0] == 0.f) + (x[1] == 0.f);
  }
  EXPECT_GT(zeros, 100);
}

std::vector<double> WovenParams() {
  return {0.47, 0.41, 0.31, 0.54, 0.51, 0.46, 0.6, 0.75, -9.0, 0.54, 0.07, 1.6, 0.1, 0.05, 0.02, 0.6,
          0.0};  // diffuse_roughness (session 18; all 17 woven values, session 19)
}

std::vector<Rgb<double>> Frame(const Scene& s, const PreviewOptions& o) {
  auto cache = PreviewCache::Build(s, nullptr, o);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*cache, WovenParams().data(), out);
  return out;
}

TEST(WovenPreview, UniformMapsAreBitIdenticalToNoMaps) {
  const Scene s = SphereWithLight(32);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto plain = PreviewCache::Build(s, nullptr, o);
  EXPECT_TRUE(plain->weave.empty());
  const auto a = Frame(s, o);
  o.weave_maps = std::make_shared<WeaveMaps>(
      WeaveMaps::FromLevel0(8, 10.0, std::vector<float>(64 * C, 0.7f)));  // normalised to 1
  auto mapped = PreviewCache::Build(s, nullptr, o);
  EXPECT_EQ(mapped->weave.size(), mapped->pixels.size() * C);
  const auto b = Frame(s, o);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(a[i][ch], b[i][ch]) << "pixel " << i;
}

// Non-uniform maps change the pixels; seen through the coarsest mip (a footprint far larger
// than a period) they give the uniform model back, which is what keeps the fit's block means.
TEST(WovenPreview, MapsVaryThePixelsAndTheirCoarsestMipIsTheUniformModel) {
  const Scene s = SphereWithLight(32);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  const auto uniform = Frame(s, o);
  o.weave_maps = std::make_shared<WeaveMaps>(WeaveMaps::FromLevel0(16, 10.0, RandomLevel0(16, 4)));
  const auto mapped = Frame(s, o);
  double diff = 0;
  for (size_t i = 0; i < uniform.size(); ++i)
    for (int ch = 0; ch < 3; ++ch) diff += std::abs(mapped[i][ch] - uniform[i][ch]);
  EXPECT_GT(diff / double(uniform.size()), 1e-3);
  o.weave_footprint_scale = 1e6;
  const auto coarse = Frame(s, o);
  for (size_t i = 0; i < uniform.size(); ++i)
    for (int ch = 0; ch < 3; ++ch)
      EXPECT_NEAR(coarse[i][ch], uniform[i][ch], 1e-5 * std::abs(uniform[i][ch]) + 1e-7);
}

// Relief normal maps: file round trip, normalised trilinear sampling, a flat map leaves the
// preview unchanged (to float rounding), and the bake's normals are the yarn geometry's.
TEST(WeaveMaps, ReliefNormalsRoundTripAndAFlatMapChangesNothing) {
  WeaveMaps m = WeaveMaps::FromLevel0(4, 10.0, std::vector<float>(16 * C, 1.f));
  std::vector<float> n(16 * 3);
  for (int t = 0; t < 16; ++t) {
    n[size_t(t * 3)] = t % 2 ? 0.6f : -0.6f;
    n[size_t(t * 3 + 2)] = 0.8f;
  }
  m.SetNormals(n);
  const auto s = m.SampleNormal(0.5 / 40, 0.5 / 40, 0.0);  // centre of texel (0, 0)
  EXPECT_NEAR(s[0], -0.6, 1e-6);
  EXPECT_NEAR(s[2], 0.8, 1e-6);
  const auto top = m.SampleNormal(0.3, 0.7, 99.0);  // the mean vector (0, 0, 0.8), normalised
  EXPECT_NEAR(top[0], 0.0, 1e-6);
  EXPECT_NEAR(top[2], 1.0, 1e-6);
  const fs::path dir = fs::temp_directory_path() / "clothfit_weave_normals_test";
  fs::create_directories(dir);
  WriteWeaveMaps((dir / "n.exr").string(), m);
  const WeaveMaps r = ReadWeaveMaps((dir / "n.exr").string());
  ASSERT_TRUE(r.has_normals());
  for (size_t k = 0; k < n.size(); ++k) EXPECT_NEAR(r.normal_levels[0][k], n[k], 1e-6);
  fs::remove_all(dir);

  const Scene sc = SphereWithLight(24);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  const auto plain = Frame(sc, o);
  auto flat = std::make_shared<WeaveMaps>(WeaveMaps::FromLevel0(4, 10.0, std::vector<float>(16 * C, 1.f)));
  std::vector<float> up(16 * 3, 0.f);
  for (int t = 0; t < 16; ++t) up[size_t(t * 3 + 2)] = 1.f;
  flat->SetNormals(up);
  o.weave_maps = flat;
  const auto mapped = Frame(sc, o);
  ASSERT_EQ(plain.size(), mapped.size());
  for (size_t i = 0; i < plain.size(); ++i)
    for (int ch = 0; ch < 3; ++ch)
      EXPECT_NEAR(mapped[i][ch], plain[i][ch], 1e-6 * std::abs(plain[i][ch]) + 1e-9);
  // A tilted map changes the shading.
  auto tilted = std::make_shared<WeaveMaps>(*flat);
  tilted->SetNormals(n);
  o.weave_maps = tilted;
  const auto t2 = Frame(sc, o);
  double diff = 0;
  for (size_t i = 0; i < plain.size(); ++i) diff += std::abs(t2[i][0] - plain[i][0]);
  EXPECT_GT(diff / double(plain.size()), 1e-3);
}

TEST(WeaveBake, ReliefNormalsFollowTheYarnGeometry) {
  const Fabric f = CanvasFabric();
  const auto* irawan = dynamic_cast<const IrawanBsdf*>(f.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  fit::WeaveBakeOptions o;
  o.size = 16;
  o.relief = true;
  const fit::WeaveBakeResult r = fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o);
  ASSERT_TRUE(r.maps.has_normals());
  const double R = irawan->repeat_u();
  double tilt = 0;
  ASSERT_GT(R, 0.0);
  for (int j = 0; j < 16; ++j)
    for (int i = 0; i < 16; ++i) {
      const float* nv = &r.maps.normal_levels[0][size_t((j * 16 + i) * 3)];
      EXPECT_GT(nv[2], 0.f);
      const double len = std::sqrt(double(nv[0]) * double(nv[0]) + double(nv[1]) * double(nv[1]) +
                                   double(nv[2]) * double(nv[2]));
      EXPECT_LE(len, 1.0 + 1e-6);
      tilt += 1.0 - double(nv[2]) / len;
      // On a warp yarn (along +u = +x) the normal turns about the yarn: the cross-section
      // tilts it along y (weft direction), the inclination along x; at the segment's centre
      // line (across = 0) the y component vanishes.
      const IrawanPoint p = irawan->Locate({(i + 0.5) / (16 * R), (j + 0.5) / (16 * R)});
      if (irawan->pattern().yarns[size_t(p.yarn)].type == YarnType::kWarp &&
          std::abs(p.v) > 0.8) {  // near the yarn's edge: clearly tilted across the yarn
        EXPECT_GT(std::abs(double(nv[1])), std::abs(double(nv[0]))) << i << "," << j;
      }
    }
  EXPECT_GT(tilt / 256, 0.01);  // the relief is not flat
  EXPECT_TRUE(std::isfinite(r.error_mapped));
}

// Glint map: sampled in uv with repeat 1 at its own LOD; a map of 2 doubles the yarn specular
// (both lobes) and leaves the diffuse alone.
TEST(WeaveMaps, GlintMapScalesTheYarnSpecular) {
  WeaveMaps m = WeaveMaps::FromLevel0(4, 10.0, std::vector<float>(16 * C, 1.f));
  std::vector<float> g(64 * 64);
  for (size_t t = 0; t < g.size(); ++t) g[t] = float(t % 3);
  m.SetGlint(64, g);
  EXPECT_NEAR(m.SampleGlint((5 + 0.5) / 64, (7 + 0.5) / 64, {0, 0, 0, 0}), g[7 * 64 + 5], 1e-6);
  EXPECT_NEAR(m.SampleGlint(0.3, 0.2, {1.0, 0, 0, 0}), m.glint_levels.back()[0], 1e-6);

  const Scene sc = SphereWithLight(24);
  PreviewOptions o;
  o.model = ModelKind::kWoven;
  auto uni = std::make_shared<WeaveMaps>(WeaveMaps::FromLevel0(4, 10.0, std::vector<float>(16 * C, 1.f)));
  o.weave_maps = uni;
  auto c1 = PreviewCache::Build(sc, nullptr, o);
  auto two = std::make_shared<WeaveMaps>(*uni);
  two->SetGlint(16, std::vector<float>(256, 2.f));
  o.weave_maps = two;
  auto c2 = PreviewCache::Build(sc, nullptr, o);
  ASSERT_EQ(c1->weave.size(), c2->weave.size());
  for (size_t i = 0; i < c1->pixels.size(); ++i) {
    EXPECT_NEAR(c2->weave[i * C + 0], 2.0 * double(c1->weave[i * C + 0]), 1e-6);  // warp
    EXPECT_NEAR(c2->weave[i * C + 1], 2.0 * double(c1->weave[i * C + 1]), 1e-6);  // weft
    EXPECT_EQ(c2->weave[i * C + 2], c1->weave[i * C + 2]);                        // kd
  }
}

// Session 14: view-dependent weave maps (render/preview/weave_maps.h view bands; fit/weave_maps.h
// view_bands; docs/preview.md "View-dependent weave maps"). The CLI side: cli.s14_view_bands.
WeaveMaps WithViews() {
  WeaveMaps m = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 1));
  m.SetViews({0.9, 0.5, 0.1}, {RandomLevel0(8, 2), RandomLevel0(8, 3), RandomLevel0(8, 4)});
  return m;
}

// The blend is piecewise linear in NoV between the cosines and clamped outside; each band is
// sampled by the main maps' own filter (a one-band WeaveMaps built from that band's level 0
// gives the same value), isotropic and anisotropic footprints alike.
TEST(S14ViewBands, BlendIsLinearInNoVBetweenTheBandsAndClamped) {
  const WeaveMaps m = WithViews();
  ASSERT_TRUE(m.has_views());
  const WeaveMaps b0 = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 2));
  const WeaveMaps b1 = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 3));
  const WeaveMaps b2 = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 4));
  for (const WeaveMaps::Footprint fp :
       {WeaveMaps::Footprint{0.0, 1, 0.0, 0.0}, WeaveMaps::Footprint{1.3, 1, 0.0, 0.0},
        WeaveMaps::Footprint{0.4, 4, 0.002, 0.0005}}) {
    const double u = 0.0123, v = 0.0377;
    const auto s0 = b0.Sample(u, v, fp), s1 = b1.Sample(u, v, fp), s2 = b2.Sample(u, v, fp);
    const auto at = [&](double nov) { return m.SampleView(u, v, fp, nov); };
    for (int c = 0; c < C; ++c) {
      EXPECT_NEAR(at(0.9)[c], s0[c], 1e-12);
      EXPECT_NEAR(at(1.0)[c], s0[c], 1e-12);   // clamped above the frontal band
      EXPECT_NEAR(at(0.5)[c], s1[c], 1e-12);
      EXPECT_NEAR(at(0.1)[c], s2[c], 1e-12);
      EXPECT_NEAR(at(0.0)[c], s2[c], 1e-12);   // clamped below the grazing band
      EXPECT_NEAR(at(0.7)[c], 0.5 * s0[c] + 0.5 * s1[c], 1e-12);
      EXPECT_NEAR(at(0.2)[c], 0.25 * s1[c] + 0.75 * s2[c], 1e-12);
    }
  }
  for (double nov : {-1.0, 0.0, 0.05, 0.3, 0.77, 0.95, 2.0, std::nan("")}) {
    double sum = 0.0;
    for (double w : m.ViewWeights(nov)) {
      EXPECT_GE(w, 0.0);
      sum += w;
    }
    EXPECT_NEAR(sum, 1.0, 1e-15) << nov;
  }
  // Without bands SampleView is Sample.
  const WeaveMaps plain = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 1));
  const WeaveMaps::Footprint fp{0.7, 1, 0.0, 0.0};
  EXPECT_EQ(plain.SampleView(0.01, 0.02, fp, 0.3), plain.Sample(0.01, 0.02, fp));
  // Bad bands are refused before anything is set.
  WeaveMaps bad = WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 1));
  EXPECT_THROW(bad.SetViews({0.5, 0.9}, {RandomLevel0(8, 2), RandomLevel0(8, 3)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({0.9}, {RandomLevel0(8, 2)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({1.5, 0.5}, {RandomLevel0(8, 2), RandomLevel0(8, 3)}), std::invalid_argument);
  EXPECT_THROW(bad.SetViews({0.9, 0.5}, {RandomLevel0(8, 2), RandomLevel0(4, 3)}), std::invalid_argument);
  EXPECT_FALSE(bad.has_views());
}

// File: the bands and their cosines round-trip; the preset draws them only when it names the
// same cosines; a file whose metadata is malformed or whose band channels are missing is refused
// naming the file and what is wrong.
TEST(S14ViewBands, FileAndPresetRoundTripAndErrorsNameTheField) {
  const fs::path dir = fs::temp_directory_path() / "clothfit_s14_view_bands";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const WeaveMaps m = WithViews();
  const std::string path = (dir / "v.weave.exr").string();
  WriteWeaveMaps(path, m);
  const WeaveMaps r = ReadWeaveMaps(path);
  ASSERT_EQ(r.view_cosines.size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(r.view_cosines[k], m.view_cosines[k]);
    ASSERT_EQ(r.view_levels[k][0].size(), m.view_levels[k][0].size());
    for (size_t t = 0; t < r.view_levels[k][0].size(); ++t)
      EXPECT_NEAR(r.view_levels[k][0][t], m.view_levels[k][0][t], 1e-6);
  }

  MaterialPreset p = DefaultPreset(ModelKind::kWoven);
  p.extra["weave_maps"] = WeaveMapsPresetField(path, m);
  ASSERT_TRUE(p.extra["weave_maps"].contains("view_cosines"));
  EXPECT_TRUE(LoadPresetWeaveMaps(p)->has_views());
  auto expect_field_error = [&](const char* what) {
    try {
      LoadPresetWeaveMaps(p);
      ADD_FAILURE() << "no error: " << what;
    } catch (const MaterialError& e) {
      EXPECT_NE(std::string(e.what()).find("weave_maps.view_cosines"), std::string::npos) << e.what();
    }
  };
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.4, 0.1};
  expect_field_error("cosines differ from the file's");
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.5};
  expect_field_error("fewer bands than the file");
  p.extra["weave_maps"]["view_cosines"] = {0.5, 0.9, 0.1};
  expect_field_error("not decreasing");
  p.extra["weave_maps"]["view_cosines"] = "0.9 0.5 0.1";
  expect_field_error("not an array");
  // Read from a preset file, the error names that file as well.
  p.extra["weave_maps"]["view_cosines"] = {0.9, 1.5, 0.1};
  try {
    LoadPresetWeaveMaps(p, (dir / "named.json").string());
    ADD_FAILURE() << "no error for a cosine above 1";
  } catch (const MaterialError& e) {
    EXPECT_NE(std::string(e.what()).find("named.json: field weave_maps.view_cosines"), std::string::npos)
        << e.what();
  }
  p.extra["weave_maps"].erase("view_cosines");
  EXPECT_FALSE(LoadPresetWeaveMaps(p)->has_views());  // not named: not drawn

  // A file without bands but a preset that names them.
  const std::string plain_path = (dir / "plain.weave.exr").string();
  WriteWeaveMaps(plain_path, WeaveMaps::FromLevel0(8, 40.0, RandomLevel0(8, 1)));
  p.extra["weave_maps"]["file"] = plain_path;
  p.extra["weave_maps"]["view_cosines"] = {0.9, 0.5, 0.1};
  expect_field_error("the file has no bands");

  // Malformed metadata, missing channels (written with the generic EXR writer).
  io::Image img = io::ReadImage(path);
  auto expect_file_error = [&](const std::string& name, const char* needle) {
    const std::string q = (dir / name).string();
    io::WriteExr(q, img);
    try {
      ReadWeaveMaps(q);
      ADD_FAILURE() << "no error for " << name;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  const auto good = img.metadata["clothfit:view_cosines"];
  img.metadata["clothfit:view_cosines"] = "0.9 0.5x 0.1";
  expect_file_error("garbage.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.9";
  expect_file_error("one.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.9 0.8 0.7 0.6 0.5 0.4 0.3 0.2 0.1";
  expect_file_error("nine.weave.exr", "view_cosines");
  img.metadata["clothfit:view_cosines"] = "0.1 0.5 0.9";
  expect_file_error("increasing.weave.exr", "decreasing");
  img.metadata["clothfit:view_cosines"] = good + " 0.05";
  expect_file_error("fourbands.weave.exr", "view3.warp");
  fs::remove_all(dir);
}

// The bake: one map per view cosine, each a ratio map (tile mean 1), stored by decreasing
// cosine. Measured property of the canvas weave (docs/flip.md, session 14): the yarn lobes'
// per-texel contrast grows towards grazing views, which the all-views map averages away.
TEST(S14ViewBands, BakedBandsAreRatioMapsWhoseYarnContrastGrowsTowardsGrazing) {
  const Fabric f = CanvasFabric();
  const auto* irawan = dynamic_cast<const IrawanBsdf*>(f.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  fit::WeaveBakeOptions o;
  o.size = 16;
  o.view_bands = true;
  const fit::WeaveBakeResult r = fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o);
  ASSERT_EQ(r.maps.view_cosines.size(), 3u);
  EXPECT_NEAR(r.maps.view_cosines[0], 0.5 * (1.0 + std::sqrt(0.6)), 1e-12);
  EXPECT_NEAR(r.maps.view_cosines[1], 0.5, 1e-12);
  EXPECT_NEAR(r.maps.view_cosines[2], 0.5 * (1.0 - std::sqrt(0.6)), 1e-12);
  // The main maps are the all-views bake, unchanged by the option.
  fit::WeaveBakeOptions plain = o;
  plain.view_bands = false;
  EXPECT_EQ(fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), plain).maps.levels[0],
            r.maps.levels[0]);
  std::vector<double> spread;
  for (const auto& band : r.maps.view_levels) {
    const std::vector<float>& l0 = band[0];
    double mean[C] = {0, 0, 0, 0, 0}, var = 0.0;
    const size_t n = l0.size() / C;
    for (size_t t = 0; t < n; ++t)
      for (int c = 0; c < C; ++c) mean[c] += double(l0[t * C + size_t(c)]) / double(n);
    for (int c = 0; c < C; ++c) EXPECT_NEAR(mean[c], 1.0, 1e-5);
    for (size_t t = 0; t < n; ++t)
      var += (double(l0[t * C]) - 1.0) * (double(l0[t * C]) - 1.0) / double(n);
    spread.push_back(std::sqrt(var));  // the warp weight's standard deviation
  }
  EXPECT_LT(spread[0], spread[1]);
  EXPECT_LT(spread[1], spread[2]);
  o.relief = true;
  EXPECT_THROW(fit::BakeWeaveMaps(*irawan, DefaultPreset(ModelKind::kWoven), o), std::invalid_argument);
}

// Session 15: the view bands are solved in the main bake's texel loop from its targets (the
// reference BSDF is evaluated once per texel and pair). Each band must equal what a separate
// bake of that band alone (--weave-map-view-band k, the measurement flag) returns, bit for bit,
// with 3 and 4 view nodes (solving band k from band k+1's targets fails it; checked).
TEST(S15ViewBands, OnePassEqualsSeparateBakes) {
  const Fabric f = CanvasFabric();
  const auto* irawan = dynamic_cast<const IrawanBsdf*>(f.bsdf.get());
  ASSERT_NE(irawan, nullptr);
  for (const int mu : {3, 4}) {
    fit::WeaveBakeOptions o;
    o.size = 16;
    o.mu_nodes = mu;
    o.view_bands = true;
    const MaterialPreset preset = DefaultPreset(ModelKind::kWoven);
    const fit::WeaveBakeResult r = fit::BakeWeaveMaps(*irawan, preset, o);
    ASSERT_EQ(r.maps.view_levels.size(), size_t(mu));
    for (int k = 0; k < mu; ++k) {
      fit::WeaveBakeOptions ok = o;
      ok.view_bands = false;
      ok.view_band = k;
      const fit::WeaveBakeResult b = fit::BakeWeaveMaps(*irawan, preset, ok);
      // SetViews re-normalises each band's level 0 (a mean of 1 up to rounding) and rebuilds
      // its mips (FromLevel0); do the same to the separate bake.
      const auto ref = WeaveMaps::FromLevel0(b.maps.size, b.maps.uv_repeats, b.maps.levels.at(0)).levels;
      EXPECT_EQ(r.maps.view_levels[size_t(k)], ref) << "mu " << mu << " band " << k;
      EXPECT_NE(r.maps.view_levels[size_t(k)][0], r.maps.levels[0]) << "band " << k << " is the main maps";
    }
  }
}

}  // namespace
}  // namespace clothfit::render
