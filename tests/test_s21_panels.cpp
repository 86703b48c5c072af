// s21-panels: sun mode "panels" (render/scene/sun.h kPanelDetectParams, docs/sun.md "Panels"):
// after the auto sun, broad bright sources (studio softboxes) are split off the map as more
// directional lights. Checks: on a map with a compact sun and softboxes, auto finds the sun
// only and panels finds the sun plus each box, with the box's direction and its excess
// irradiance in closed form; the split conserves the map's power exactly (the sun-free map +
// every light) and in the preview's exact IBL (to Monte Carlo noise); the loop stops at
// kMaxPanelLights and when nothing is left; the mode's names, the card key and bad values; the
// shared synthetic map (tests/data/s21_panels_synthetic.json) that web/test/sun.test.mjs
// splits too; every installed HDRI conserves energy under panels.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "render/preview/preview.h"
#include "render/scene/environment.h"
#include "render/scene/scene.h"
#include "render/scene/sun.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

using Vec3d = Vec3<double>;

struct Source {
  double elevation_deg, u, radius_deg;
  std::array<double, 3> radiance;
};

Vec3d Centre(const Source& s) { return Environment::UvToDirection(s.u, s.elevation_deg / 180.0 + 0.5); }

double RowSolidAngle(int j, int W, int H) {
  return (2.0 * kPi / W) * (std::sin(kPi / 2 - kPi * j / H) - std::sin(kPi / 2 - kPi * (j + 1) / H));
}

// The map's formula (also in web/test/sun.test.mjs for the shared map): per texel centre d,
// the first source whose hard-edged disc holds d (d . centre >= cos radius), else the sky
// sky_c (1 + 0.5 d.y) + 0.01 (i mod 7), stored as float32, top row first.
std::vector<float> SourcesMap(int W, int H, const std::vector<Source>& src,
                              const std::array<double, 3>& sky) {
  std::vector<float> px(size_t(W) * size_t(H) * 3);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const Vec3d d = Environment::UvToDirection((i + 0.5) / W, 1.0 - (j + 0.5) / H);
      const Source* hit = nullptr;
      for (const Source& s : src)
        if (Dot(d, Centre(s)) >= std::cos(s.radius_deg * kPi / 180.0)) {
          hit = &s;
          break;
        }
      for (int c = 0; c < 3; ++c)
        px[(size_t(j) * size_t(W) + size_t(i)) * 3 + size_t(c)] =
            float(hit ? hit->radiance[size_t(c)]
                      : sky[size_t(c)] * (1.0 + 0.5 * d.y) + 0.01 * (i % 7));
    }
  return px;
}

double Power(const std::vector<float>& px, int W, int H) {  // sum Y dw
  double p = 0.0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const size_t t = (size_t(j) * size_t(W) + size_t(i)) * 3;
      p += (0.2126 * double(px[t]) + 0.7152 * double(px[t + 1]) + 0.0722 * double(px[t + 2])) * RowSolidAngle(j, W, H);
    }
  return p;
}

double AngleDeg(const std::array<double, 3>& a, const Vec3d& b) {
  return std::acos(std::clamp(a[0] * b.x + a[1] * b.y + a[2] * b.z, -1.0, 1.0)) * 180.0 / kPi;
}

constexpr std::array<double, 3> kSky{0.2, 0.3, 0.45};
// A compact sun (1 degree) and two softboxes (5 and 4 degrees) near the horizon, as in a studio.
const std::vector<Source> kStudio = {{40.0, 0.62, 1.0, {3000.0, 2800.0, 2500.0}},
                                     {10.0, 0.20, 5.0, {40.0, 40.0, 38.0}},
                                     {15.0, 0.85, 4.0, {30.0, 32.0, 35.0}}};

TEST(S21Panels, AutoFindsTheSunOnlyPanelsFindTheSoftboxes) {
  const int W = 1024, H = 512;
  const std::vector<float> px = SourcesMap(W, H, kStudio, kSky);
  const Environment env = Environment::FromPixels(W, H, px, 1.0, 0.0, "/test/s21-studio");
  const auto a = SplitEnvironmentSun(env, SunMode::kAuto);
  ASSERT_TRUE(a->split.found) << a->summary;
  EXPECT_EQ(a->lights.size(), 1u) << a->summary;
  EXPECT_TRUE(a->panels.empty());
  const auto p = SplitEnvironmentSun(env, SunMode::kPanels);
  std::printf("S21Panels studio-like map: %s\n", p->summary.c_str());
  ASSERT_EQ(p->panels.size(), 2u) << p->summary;
  ASSERT_EQ(p->lights.size(), 3u);
  EXPECT_EQ(p->lights[0].name, "environment sun");
  EXPECT_EQ(p->lights[1].name, "environment panel 1");
  EXPECT_LT(AngleDeg(p->split.map_direction, Centre(kStudio[0])), 0.05);
  // Brightest first: box 1 (radiance 40), then box 2. Each one's light is its excess over the
  // fill (the annulus's lower median: sky) times the disc texels' solid angle.
  for (int k = 0; k < 2; ++k) {
    const Source& s = kStudio[size_t(k + 1)];
    const SunSplit& q = p->panels[size_t(k)];
    EXPECT_LT(AngleDeg(q.map_direction, Centre(s)), 0.3) << q.summary;
    double omega = 0.0;
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i)
        if (Dot(Environment::UvToDirection((i + 0.5) / W, 1.0 - (j + 0.5) / H), Centre(s)) >=
            std::cos(s.radius_deg * kPi / 180.0))
          omega += RowSolidAngle(j, W, H);
    EXPECT_NEAR(q.solid_angle, omega, 1e-12) << q.summary;
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(q.irradiance[size_t(c)], (s.radiance[size_t(c)] - double(q.fill[size_t(c)])) * omega,
                  1e-9 * q.irradiance[size_t(c)])
          << "panel " << k << " channel " << c;
    EXPECT_EQ(p->lights[size_t(k + 1)].type, Light::Type::kDirectional);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(p->lights[size_t(k + 1)].color[size_t(c)] * p->lights[size_t(k + 1)].intensity,
                  q.irradiance[size_t(c)], 1e-9 * q.irradiance[size_t(c)]);
  }
  // The sun's own split is the same in both modes (panels only add).
  for (int c = 0; c < 3; ++c)
    EXPECT_EQ(a->split.irradiance[size_t(c)], p->split.irradiance[size_t(c)]);
  // Mutation guard: with auto's parameters the boxes are not found (they are not compact).
  std::vector<float> free_px;
  const SunSplit no = DetectSun(W, H, px.data(), 1.0, 0.0, {}, &free_px);
  ASSERT_TRUE(no.found);
  EXPECT_FALSE(DetectSun(W, H, free_px.data(), 1.0, 0.0).found);
}

// The map's power = the sun-free map's + every light's luminance irradiance / intensity.
TEST(S21Panels, TheSplitConservesTheMapsPower) {
  const int W = 1024, H = 512;
  const double intensity = 1.7, rotation = 0.9;
  const std::vector<float> px = SourcesMap(W, H, kStudio, kSky);
  const Environment env = Environment::FromPixels(W, H, px, intensity, rotation, "/test/s21-power");
  const auto p = SplitEnvironmentSun(env, SunMode::kPanels);
  ASSERT_EQ(p->lights.size(), 3u) << p->summary;
  double e_lum = 0.0;
  for (const Light& l : p->lights)
    e_lum += l.intensity * (0.2126 * l.color[0] + 0.7152 * l.color[1] + 0.0722 * l.color[2]);
  const double before = Power(px, W, H), after = Power(p->environment->pixels(), W, H);
  std::printf("S21Panels power: map %.9g, sun-free %.9g + lights %.9g\n", before, after,
              e_lum / intensity);
  EXPECT_NEAR(after + e_lum / intensity, before, 1e-9 * before);
  EXPECT_LT(after, 0.5 * before);  // most of the power is in the lights
  // The rotation turns the lights, not the map: the world direction is R_y(rotation) map's.
  const Vec3d m = Centre(kStudio[1]);
  const Vec3d w(std::cos(rotation) * m.x + std::sin(rotation) * m.z, m.y,
                -std::sin(rotation) * m.x + std::cos(rotation) * m.z);
  const std::array<double, 3> towards{-p->lights[1].direction[0], -p->lights[1].direction[1],
                                      -p->lights[1].direction[2]};
  EXPECT_LT(AngleDeg(towards, w), 0.3);
}

TEST(S21Panels, StopsAtTheLimitAndWhenNothingIsLeft) {
  const int W = 512, H = 256;
  std::vector<Source> many;
  for (int k = 0; k < 10; ++k)  // ten 4-degree boxes around the horizon, 36 degrees apart
    many.push_back({12.0, (k + 0.5) / 10.0, 4.0, {20.0 + k, 20.0 + k, 20.0 + k}});
  const Environment env =
      Environment::FromPixels(W, H, SourcesMap(W, H, many, kSky), 1.0, 0.0, "/test/s21-many");
  const auto p = SplitEnvironmentSun(env, SunMode::kPanels);
  EXPECT_FALSE(p->split.found);
  EXPECT_EQ(p->panels.size(), size_t(kMaxPanelLights)) << p->summary;
  EXPECT_EQ(p->lights.size(), size_t(kMaxPanelLights));
  EXPECT_EQ(p->lights[0].name, "environment panel 1");
  // Brightest first: the first panel is the box with radiance 29 (k = 9, u 0.95).
  EXPECT_LT(AngleDeg(p->panels[0].map_direction, Centre(many[9])), 0.5) << p->panels[0].summary;
  // A map with no source: nothing split, the caller's own map back, the summary says so.
  const Environment flat = Environment::FromPixels(W, H, SourcesMap(W, H, {}, kSky), 1.0, 0.0,
                                                   "/test/s21-flat");
  const auto f = SplitEnvironmentSun(flat, SunMode::kPanels);
  EXPECT_FALSE(f->found());
  EXPECT_EQ(f->environment.get(), &flat);
  EXPECT_NE(f->summary.find("panels: 0"), std::string::npos) << f->summary;
}

// The preview's exact IBL (Monte Carlo over the map) of the split map + lights equals that of
// the full map, to Monte Carlo noise (two seeds of the full map).
TEST(S21Panels, SplitMapPlusLightsConservesTheExactIbl) {
  const int W = 512, H = 256;
  const std::vector<Source> boxes = {{20.0, 0.70, 5.0, {60.0, 55.0, 50.0}},
                                     {5.0, 0.45, 6.0, {30.0, 30.0, 30.0}}};
  const Environment env =
      Environment::FromPixels(W, H, SourcesMap(W, H, boxes, kSky), 1.0, 0.0, "/test/s21-ibl");
  ASSERT_EQ(SplitEnvironmentSun(env, SunMode::kPanels)->panels.size(), 2u);
  Scene s = CameraScene(24, 24, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 64, 32, true, 0.f));
  s.card.environment = EnvironmentSpec{};
  const std::vector<double> x = {0.6, 0.5, 0.4, 0.9, 0.0};  // rough: a light = its texels
  auto mean_g = [&](SunMode mode, int seed, bool* split) {
    PreviewOptions o;
    o.model = ModelKind::kStandard;
    o.ibl_engine = IblEngine::kFilament;
    o.exact_ibl_samples = 1024;
    o.exact_ibl_seed = seed;
    o.env_sun = mode;
    auto cache = PreviewCache::Build(s, &env, o);
    if (split) *split = cache->sun_split;
    std::vector<Rgb<double>> out;
    EvaluatePreview(*cache, x.data(), out);
    double g = 0.0;
    for (const Rgb<double>& v : out) g += v.g;
    return g / double(out.size());
  };
  bool split = false;
  const double m1 = mean_g(SunMode::kOff, 1, nullptr), m2 = mean_g(SunMode::kOff, 2, nullptr);
  const double mp = mean_g(SunMode::kPanels, 1, &split);
  EXPECT_TRUE(split);
  const double noise = std::abs(m1 - m2) / m1, diff = std::abs(mp - 0.5 * (m1 + m2)) / m1;
  std::printf("S21Panels exact IBL: mean G full %.6f / %.6f, split + lights %.6f; rel. diff "
              "%.5f, seed noise %.5f\n", m1, m2, mp, diff, noise);
  EXPECT_LT(diff, std::max(3.0 * noise, 0.005));
}

// Review s21: the preview shares prefiltered chains by the map's source name, so each mode's
// light-free map must carry its own name. A panels preview built after an auto preview of the
// same map (one process, the Filament split-sum engine) must equal one built on a fresh copy of
// the map (another source name, so nothing shared); with one name for both it drew the auto
// map's chains, boxes included, under the panel lights.
TEST(S21Panels, EachModeHasItsOwnPrefilteredMap) {
  const int W = 256, H = 128;
  const std::vector<Source> src = {{40.0, 0.62, 2.0, {3000.0, 2800.0, 2500.0}},
                                   {10.0, 0.20, 9.0, {40.0, 40.0, 38.0}}};
  const std::vector<float> px = SourcesMap(W, H, src, kSky);
  const Environment a = Environment::FromPixels(W, H, px, 1.0, 0.0, "/test/s21-cache-a");
  const Environment b = Environment::FromPixels(W, H, px, 1.0, 0.0, "/test/s21-cache-b");
  ASSERT_GE(SplitEnvironmentSun(a, SunMode::kPanels)->panels.size(), 1u)
      << SplitEnvironmentSun(a, SunMode::kPanels)->summary;
  Scene s = CameraScene(16, 16, {0, 0, 3}, {0, 0, -1}, 0.4);
  s.meshes.push_back(SphereMesh(0.5, 32, 16, true, 0.f));
  s.card.environment = EnvironmentSpec{};
  const std::vector<double> x = {0.6, 0.5, 0.4, 0.3, 0.0};
  auto frame = [&](const Environment& env, SunMode mode) {
    PreviewOptions o;
    o.model = ModelKind::kStandard;
    o.ibl_engine = IblEngine::kFilament;
    o.env_sun = mode;
    auto cache = PreviewCache::Build(s, &env, o);
    std::vector<Rgb<double>> out;
    EvaluatePreview(*cache, x.data(), out);
    return out;
  };
  const std::vector<Rgb<double>> auto_a = frame(a, SunMode::kAuto);
  const std::vector<Rgb<double>> panels_a = frame(a, SunMode::kPanels);
  const std::vector<Rgb<double>> panels_b = frame(b, SunMode::kPanels);
  ASSERT_EQ(panels_a.size(), panels_b.size());
  double diff = 0.0, moved = 0.0;
  for (size_t i = 0; i < panels_a.size(); ++i) {
    diff = std::max(diff, std::abs(panels_a[i].g - panels_b[i].g));
    moved = std::max(moved, std::abs(panels_a[i].g - auto_a[i].g));
  }
  EXPECT_EQ(diff, 0.0) << "the panels preview depends on an earlier auto preview of the map";
  EXPECT_GT(moved, 1e-4);  // and the modes differ at all
}

TEST(S21Panels, ModeNamesCardKeyAndBadValues) {
  EXPECT_EQ(ParseSunMode("panels", "--env-sun"), SunMode::kPanels);
  EXPECT_STREQ(SunModeName(SunMode::kPanels), "panels");
  EXPECT_STREQ(SunModeName(SunMode::kAuto), "auto");
  EXPECT_STREQ(SunModeName(SunMode::kOff), "off");
  try {
    ParseSunMode("softboxes", "--env-sun");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("\"panels\""), std::string::npos) << e.what();
  }
  const auto dir = std::filesystem::temp_directory_path();
  const std::string card = (dir / ("clothfit_s21_panels_" + std::to_string(::getpid()) + ".json")).string();
  std::ofstream(card) << R"({"version": 1, "gltf": "x.gltf", "environment": {"path": "studio", "sun": "panels"}})";
  EXPECT_EQ(LoadSceneCard(card).environment->sun, SunMode::kPanels);
  std::ofstream(card) << R"({"version": 1, "gltf": "x.gltf", "environment": {"path": "studio", "sun": "Panels"}})";
  try {
    LoadSceneCard(card);
    ADD_FAILURE();
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("environment.sun"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("\"panels\""), std::string::npos) << e.what();
  }
  std::filesystem::remove(card);
}

// The synthetic map web/test/sun.test.mjs splits too: the recorded figures of every light.
TEST(S21Panels, SharedSyntheticMapMatchesTheRecordedFigures) {
  std::ifstream in(std::string(CLOTHFIT_TEST_SOURCE_DIR) + "/tests/data/s21_panels_synthetic.json");
  ASSERT_TRUE(in) << "tests/data/s21_panels_synthetic.json";
  const nlohmann::json j = nlohmann::json::parse(in);
  const int W = j["width"], H = j["height"];
  std::vector<Source> src;
  for (const auto& s : j["sources"])
    src.push_back({s["elevation_deg"], s["u"], s["radius_deg"],
                   {double(s["radiance"][0]), double(s["radiance"][1]), double(s["radiance"][2])}});
  const std::array<double, 3> sky{double(j["sky"][0]), double(j["sky"][1]), double(j["sky"][2])};
  const Environment env = Environment::FromPixels(W, H, SourcesMap(W, H, src, sky),
                                                  double(j["intensity"]), double(j["rotation_y"]),
                                                  "/test/s21-shared");
  const auto p = SplitEnvironmentSun(env, SunMode::kPanels);
  std::vector<const SunSplit*> lights;
  if (p->split.found) lights.push_back(&p->split);
  for (const SunSplit& q : p->panels) lights.push_back(&q);
  nlohmann::json got = nlohmann::json::array();
  for (const SunSplit* q : lights)
    got.push_back({{"texels", q->texels},
                   {"irradiance", q->irradiance},
                   {"world_direction", q->world_direction},
                   {"fill", {double(q->fill[0]), double(q->fill[1]), double(q->fill[2])}}});
  std::printf("S21Panels shared map: %s\nS21Panels shared figures: %s\n", p->summary.c_str(),
              got.dump().c_str());
  const auto& e = j["expected"];
  EXPECT_EQ(p->split.found, bool(j["expected_sun"]));
  ASSERT_EQ(lights.size(), e.size());
  for (size_t k = 0; k < lights.size(); ++k) {
    EXPECT_EQ(lights[k]->texels, int(e[k]["texels"])) << "light " << k;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(lights[k]->irradiance[size_t(c)], double(e[k]["irradiance"][size_t(c)]),
                  1e-6 * lights[k]->irradiance[size_t(c)]) << "light " << k;
      EXPECT_NEAR(lights[k]->world_direction[size_t(c)], double(e[k]["world_direction"][size_t(c)]),
                  1e-6) << "light " << k;
      EXPECT_EQ(lights[k]->fill[size_t(c)], float(e[k]["fill"][size_t(c)])) << "light " << k;
    }
  }
}

// Every installed HDRI (~/.cache/clothfit/hdri, skipped when absent): what panels finds, and
// the power identity (up to the loader's clamped negative texels, docs/sun.md: 1 %).
TEST(S21Panels, InstalledMapsConserveEnergy) {
  const char* home = std::getenv("HOME");
  const std::filesystem::path dir = std::filesystem::path(home ? home : "") / ".cache/clothfit/hdri";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << dir << " missing";
  int maps = 0, with_panels = 0;
  for (const auto& f : std::filesystem::directory_iterator(dir)) {
    if (f.path().extension() != ".exr") continue;
    const Environment env = Environment::Load(f.path().string(), 1.0, 0.0);
    const auto p = SplitEnvironmentSun(env, SunMode::kPanels);
    ++maps;
    with_panels += !p->panels.empty();
    const double before = Power(env.pixels(), env.width(), env.height());
    double e_lum = 0.0, e_panels = 0.0;
    for (const Light& l : p->lights) {
      const double y = l.intensity * (0.2126 * l.color[0] + 0.7152 * l.color[1] + 0.0722 * l.color[2]);
      e_lum += y;
      if (l.name != "environment sun") e_panels += y;
    }
    std::printf("%-24s sun %s, %zu panel(s), carrying %.3f of the map's power\n",
                f.path().filename().string().c_str(), p->split.found ? "yes" : "no",
                p->panels.size(), e_panels / before);
    if (!p->found()) continue;
    const double after = Power(p->environment->pixels(), env.width(), env.height());
    EXPECT_NEAR(after + e_lum, before, 0.01 * before) << f.path();
  }
  std::printf("S21Panels: %d of %d installed maps have panels\n", with_panels, maps);
  EXPECT_GT(maps, 0);
}

}  // namespace
}  // namespace clothfit::render
