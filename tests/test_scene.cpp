// Scenes: the canonical scenes load as generated (scripts/gen-scenes), the camera ray follows
// the pixel-centre convention, the card scales lights, node hierarchies flatten, and bad input
// (cards and glTF files) gives errors naming the file and the field, never a crash.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "render/scene/gltf_tinygltf.h"
#include "render/scene/scene.h"

namespace clothfit::render {
namespace {
namespace fs = std::filesystem;
using Json = nlohmann::json;
using V3 = std::array<double, 3>;

double Dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double Len(const V3& a) { return std::sqrt(Dot(a, a)); }
V3 D(const std::array<float, 3>& a) { return {double(a[0]), double(a[1]), double(a[2])}; }
V3 Normalized(const V3& a) { return {a[0] / Len(a), a[1] / Len(a), a[2] / Len(a)}; }
V3 Sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 Cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Degrees(double radians) { return radians * 180.0 / kPi; }

fs::path ScenesDir() {
  if (const char* env = std::getenv("CLOTHFIT_SOURCE_DIR")) {
    return fs::path(env) / "datasets" / "scenes";
  }
  return fs::path(__FILE__).parent_path().parent_path() / "datasets" / "scenes";
}

// A fresh temporary directory per test, removed at the end.
class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("clothfit_test_scene_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  const fs::path& path() const { return path_; }
  std::string Write(const std::string& name, const std::string& text) const {
    const fs::path p = path_ / name;
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }

 private:
  fs::path path_;
};

// Sets (or unsets, value nullopt) an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, std::optional<std::string> value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value) {
      ::setenv(name, value->c_str(), 1);
    } else {
      ::unsetenv(name);
    }
  }
  ~ScopedEnv() {
    if (old_) {
      ::setenv(name_, old_->c_str(), 1);
    } else {
      ::unsetenv(name_);
    }
  }

 private:
  const char* name_;
  std::optional<std::string> old_;
};

Json ReadJson(const fs::path& p) {
  std::ifstream in(p);
  return Json::parse(in);
}

// A valid card for `gltf`, with `edit` applied.
Json Card(const std::string& gltf, const std::function<void(Json&)>& edit = {}) {
  Json card = {{"version", 1},
               {"gltf", gltf},
               {"width", 64},
               {"height", 64},
               {"environment", {{"path", "procedural-sky"}}},
               {"tone_mapping", "ACESFilmic"},
               {"exposure", 1.0},
               {"fabric_material", 0}};
  if (edit) edit(card);
  return card;
}

// The error message of LoadScene(card), or "" when it loads.
std::string LoadError(const std::string& card_path) {
  try {
    LoadScene(card_path);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << (haystack)

// A copy of a canonical glTF (edited) with a card next to it; returns the card path.
std::string CopyScene(const TempDir& dir, const std::string& name,
                      const std::function<void(Json&)>& edit_gltf,
                      const std::function<void(Json&)>& edit_card = {}) {
  Json gltf = ReadJson(ScenesDir() / (name + ".gltf"));
  if (edit_gltf) edit_gltf(gltf);
  dir.Write(name + ".gltf", gltf.dump());
  return dir.Write(name + ".json", Card(name + ".gltf", edit_card).dump(2));
}

void ExpectWellFormed(const Mesh& m) {
  const size_t n = m.positions.size();
  ASSERT_EQ(m.normals.size(), n) << m.name;
  ASSERT_EQ(m.uvs.size(), n) << m.name;
  ASSERT_EQ(m.tangents.size(), n) << m.name;
  ASSERT_EQ(m.indices.size() % 3, 0u) << m.name;
  for (uint32_t i : m.indices) ASSERT_LT(i, n) << m.name;
  for (size_t i = 0; i < n; ++i) {
    const V3 nn = D(m.normals[i]);
    const V3 t{double(m.tangents[i][0]), double(m.tangents[i][1]), double(m.tangents[i][2])};
    ASSERT_NEAR(Len(nn), 1.0, 1e-5) << m.name << " vertex " << i;
    ASSERT_NEAR(Len(t), 1.0, 1e-5) << m.name << " vertex " << i;
    ASSERT_NEAR(Dot(nn, t), 0.0, 1e-4) << m.name << " vertex " << i;
    ASSERT_EQ(std::abs(m.tangents[i][3]), 1.0f) << m.name << " vertex " << i;
  }
  // Front faces (counter-clockwise) agree with the shading normals.
  size_t agree = 0;
  for (size_t t = 0; t < m.indices.size(); t += 3) {
    const V3 a = D(m.positions[m.indices[t]]);
    const V3 face =
        Cross(Sub(D(m.positions[m.indices[t + 1]]), a), Sub(D(m.positions[m.indices[t + 2]]), a));
    if (Dot(face, D(m.normals[m.indices[t]])) > 0) ++agree;
  }
  EXPECT_EQ(agree, m.indices.size() / 3) << m.name;
}

void UvRange(const Mesh& m, double* u0, double* u1, double* v0, double* v1) {
  *u0 = *v0 = 1e30;
  *u1 = *v1 = -1e30;
  for (const auto& uv : m.uvs) {
    *u0 = std::min(*u0, double(uv[0]));
    *u1 = std::max(*u1, double(uv[0]));
    *v0 = std::min(*v0, double(uv[1]));
    *v1 = std::max(*v1, double(uv[1]));
  }
}

// ------------------------------------------------------------------------------------------------
// Canonical scenes.

TEST(SceneCanonical, CardsAgree) {
  for (const char* name : {"sphere", "drape", "swatch"}) {
    const SceneCard card = LoadSceneCard((ScenesDir() / (std::string(name) + ".json")).string());
    EXPECT_EQ(card.width, 256) << name;
    EXPECT_EQ(card.height, 256) << name;
    EXPECT_EQ(card.tone_mapping, "ACESFilmic") << name;
    EXPECT_EQ(card.exposure, 1.0) << name;
    EXPECT_EQ(card.fabric_material, 0) << name;
    EXPECT_EQ(card.light_scale, 1.0) << name;
    EXPECT_GT(card.uv_metres_per_unit, 0.0) << name;
    ASSERT_TRUE(card.environment.has_value()) << name;
    EXPECT_EQ(card.environment->name, "studio") << name;
    EXPECT_EQ(fs::path(card.gltf).filename().string(), std::string(name) + ".gltf");
    EXPECT_TRUE(fs::path(card.gltf).is_absolute());
  }
}

TEST(SceneCanonical, SphereAsGenerated) {
  const Scene s = LoadScene((ScenesDir() / "sphere.json").string());
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  EXPECT_EQ(m.name, "sphere");
  EXPECT_TRUE(m.is_fabric);
  EXPECT_EQ(m.positions.size(), 65u * 33u);
  EXPECT_EQ(m.indices.size(), 3u * (2u * 64u * 32u - 2u * 64u));
  ExpectWellFormed(m);
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const V3 p = D(m.positions[i]);
    ASSERT_NEAR(Len(p), 0.5, 1e-5);
    ASSERT_GT(Dot(Normalized(p), D(m.normals[i])), 0.9999);
  }
  double u0, u1, v0, v1;
  UvRange(m, &u0, &u1, &v0, &v1);
  EXPECT_EQ(u0, 0.0);
  EXPECT_EQ(u1, 2.0);
  EXPECT_EQ(v0, 0.0);
  EXPECT_EQ(v1, 1.0);
  // Equator: 1 UV unit = pi r = card.uv_metres_per_unit in both directions.
  EXPECT_NEAR(s.card.uv_metres_per_unit, kPi * 0.5, 1e-6);
  // Tangents run along +u (eastwards) with the bitangent cross(n, t) w towards the north pole
  // (decreasing glTF v), at a vertex on the equator.
  const size_t k = 16 * 65 + 10;
  const V3 b = Cross(D(m.normals[k]), {double(m.tangents[k][0]), double(m.tangents[k][1]),
                                              double(m.tangents[k][2])});
  EXPECT_GT(b[1] * double(m.tangents[k][3]), 0.99);

  EXPECT_NEAR(s.camera.position[0], 0.0, 1e-6);
  EXPECT_NEAR(s.camera.position[1], 0.6, 1e-6);
  EXPECT_NEAR(s.camera.position[2], 2.1, 1e-6);
  const V3 to_origin = Normalized({-0.0, -0.6, -2.1});
  EXPECT_GT(Dot(s.camera.forward, to_origin), 1.0 - 1e-9);
  EXPECT_NEAR(s.camera.yfov, 0.5, 1e-12);
  EXPECT_NEAR(Dot(s.camera.up, s.camera.forward), 0.0, 1e-12);
  EXPECT_GT(s.camera.up[1], 0.9);

  ASSERT_EQ(s.lights.size(), 2u);
  EXPECT_EQ(s.lights[0].name, "key");
  EXPECT_EQ(s.lights[0].type, Light::Type::kDirectional);
  EXPECT_EQ(s.lights[0].intensity, 3.0);
  EXPECT_GT(Dot(s.lights[0].direction, Normalized({1, -1, -1})), 1.0 - 1e-6);
  EXPECT_EQ(s.lights[1].name, "fill");
  EXPECT_EQ(s.lights[1].intensity, 0.8);
  EXPECT_GT(Dot(s.lights[1].direction, Normalized({-1, -0.3, -0.5})), 1.0 - 1e-6);
}

TEST(SceneCanonical, DrapeAsGenerated) {
  const Scene s = LoadScene((ScenesDir() / "drape.json").string());
  ASSERT_EQ(s.meshes.size(), 3u);
  const Mesh& cloth = s.meshes[0];
  EXPECT_EQ(cloth.name, "cloth");
  EXPECT_TRUE(cloth.is_fabric);
  EXPECT_FALSE(s.meshes[1].is_fabric);
  EXPECT_FALSE(s.meshes[2].is_fabric);
  EXPECT_EQ(cloth.positions.size(), 97u * 97u);
  for (const Mesh& m : s.meshes) ExpectWellFormed(m);
  double u0, u1, v0, v1;
  UvRange(cloth, &u0, &u1, &v0, &v1);
  EXPECT_NEAR(u0, 0.0, 1e-6);
  EXPECT_NEAR(u1, 1.3, 1e-6);
  EXPECT_NEAR(v0, 0.0, 1e-6);
  EXPECT_NEAR(v1, 1.3, 1e-6);
  EXPECT_EQ(s.card.uv_metres_per_unit, 1.0);
  // Draped: it covers the sphere (top at 0.72 m) and reaches down to the floor, and it has
  // folds: many normals point sideways and some face down-and-out.
  double ymin = 1e30, ymax = -1e30;
  int sideways = 0;
  for (size_t i = 0; i < cloth.positions.size(); ++i) {
    ymin = std::min(ymin, double(cloth.positions[i][1]));
    ymax = std::max(ymax, double(cloth.positions[i][1]));
    if (std::abs(cloth.normals[i][1]) < 0.3f) ++sideways;
  }
  EXPECT_NEAR(ymax, 0.724, 0.01);
  EXPECT_LT(ymin, 0.05);
  EXPECT_GT(sideways, 1000);

  ASSERT_EQ(s.lights.size(), 3u);
  const Light& key = s.lights[0];
  EXPECT_EQ(key.type, Light::Type::kSpot);
  EXPECT_EQ(key.intensity, 12.0);
  EXPECT_NEAR(key.inner_cone, 0.3, 1e-12);
  EXPECT_NEAR(key.outer_cone, 0.5, 1e-12);
  EXPECT_NEAR(key.position[0], -1.2, 1e-6);
  EXPECT_NEAR(key.position[1], 2.0, 1e-6);
  EXPECT_NEAR(key.position[2], 1.4, 1e-6);
  EXPECT_GT(Dot(key.direction, Normalized(Sub({0, 0.4, 0}, key.position))), 1.0 - 1e-6);
  EXPECT_NEAR(key.color[2], 0.92, 1e-12);
  EXPECT_EQ(s.lights[1].type, Light::Type::kDirectional);
  EXPECT_EQ(s.lights[2].type, Light::Type::kPoint);
  EXPECT_EQ(s.lights[2].range, 6.0);
  EXPECT_NEAR(s.lights[2].position[2], -1.2, 1e-6);
}

TEST(SceneCanonical, SwatchIsBacklitNearGrazing) {
  const Scene s = LoadScene((ScenesDir() / "swatch.json").string());
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  EXPECT_TRUE(m.is_fabric);
  ExpectWellFormed(m);
  for (const auto& n : m.normals) ASSERT_GT(n[1], 0.99999f);
  double u0, u1, v0, v1;
  UvRange(m, &u0, &u1, &v0, &v1);
  EXPECT_EQ(u1 - u0, 1.0);  // 1 m swatch, 1 m per UV unit
  EXPECT_EQ(v1 - v0, 1.0);
  EXPECT_EQ(s.card.uv_metres_per_unit, 1.0);
  // The camera sees the swatch centre 78 degrees from its normal.
  const V3 to_camera = Normalized(s.camera.position);
  EXPECT_NEAR(Degrees(std::acos(to_camera[1])), 78.0, 1e-6);
  EXPECT_GT(Dot(s.camera.forward, Normalized({0, -s.camera.position[1], -s.camera.position[2]})),
            1.0 - 1e-9);
  // The key light comes from behind the swatch (the far side), 75 degrees from the normal.
  ASSERT_EQ(s.lights.size(), 1u);
  const V3 to_light = {-s.lights[0].direction[0], -s.lights[0].direction[1],
                       -s.lights[0].direction[2]};
  EXPECT_NEAR(Degrees(std::acos(to_light[1])), 75.0, 1e-6);
  EXPECT_LT(to_light[2] * to_camera[2], 0.0);
}

// ------------------------------------------------------------------------------------------------
// Camera rays.

Scene RayScene(int width, int height, double yfov) {
  Scene s;
  s.card.width = width;
  s.card.height = height;
  s.camera.yfov = yfov;
  return s;  // camera at the origin looking down -Z, +Y up, +X right
}

TEST(SceneCamera, CentrePixelOfOddImageLooksForward) {
  const Scene s = RayScene(5, 3, 0.7);
  V3 o, d;
  s.CameraRay(2 + 0.5, 1 + 0.5, o, d);  // the centre pixel's centre
  EXPECT_NEAR(d[0], 0.0, 1e-15);
  EXPECT_NEAR(d[1], 0.0, 1e-15);
  EXPECT_NEAR(d[2], -1.0, 1e-15);
  EXPECT_EQ(o, (V3{0, 0, 0}));
}

TEST(SceneCamera, CornersMatchFovAndAspect) {
  const double yfov = 0.7, t = std::tan(0.35);
  const Scene s = RayScene(300, 200, yfov);
  V3 o, d;
  s.CameraRay(0.0, 0.0, o, d);  // top-left corner of the image: -X, +Y
  const V3 expect_tl = Normalized({-t * 1.5, t, -1});
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(d[c], expect_tl[c], 1e-14);
  s.CameraRay(300.0, 200.0, o, d);  // bottom-right
  const V3 expect_br = Normalized({t * 1.5, -t, -1});
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(d[c], expect_br[c], 1e-14);
  // Top edge centre: half the vertical field of view above the axis.
  s.CameraRay(150.0, 0.0, o, d);
  EXPECT_NEAR(std::acos(-d[2]), yfov / 2, 1e-14);
  EXPECT_GT(d[1], 0.0);
  // Row 0 is the top: a pixel centre in row 0 looks up, in the last row down.
  s.CameraRay(150.0, 0.5, o, d);
  EXPECT_GT(d[1], 0.0);
  s.CameraRay(150.0, 199.5, o, d);
  EXPECT_LT(d[1], 0.0);
}

TEST(SceneCamera, LoadedCameraCentreRayIsForward) {
  const Scene s = LoadScene((ScenesDir() / "sphere.json").string());
  V3 o, d;
  s.CameraRay(128.0, 128.0, o, d);
  EXPECT_GT(Dot(d, s.camera.forward), 1.0 - 1e-12);
  EXPECT_EQ(o, s.camera.position);
  EXPECT_NEAR(Dot(s.camera.right, s.camera.up), 0.0, 1e-12);
  EXPECT_NEAR(Dot(Cross(s.camera.forward, s.camera.up), s.camera.right), 1.0, 1e-12);
}

// ------------------------------------------------------------------------------------------------
// Light units and card scales.

TEST(SceneLights, CardScalesIntensitiesAndEnvironment) {
  TempDir dir;
  const std::string card = CopyScene(dir, "drape", {}, [](Json& c) {
    c["light_scale"] = 1.0 / 683.0;  // e.g. Blender's sun strength W/m^2 x 683
    c["environment"] = {
        {"path", "procedural-sky"}, {"intensity", 0.25}, {"rotation_y_degrees", 90.0}};
  });
  const Scene s = LoadScene(card);
  ASSERT_EQ(s.lights.size(), 3u);
  EXPECT_NEAR(s.lights[0].intensity, 12.0 / 683.0, 1e-15);  // candela -> W/sr, scaled
  EXPECT_NEAR(s.lights[1].intensity, 0.6 / 683.0, 1e-15);   // lux -> W/m^2, scaled
  EXPECT_NEAR(s.lights[2].intensity, 2.0 / 683.0, 1e-15);
  ASSERT_TRUE(s.card.environment.has_value());
  EXPECT_EQ(s.card.environment->path, "procedural-sky");
  EXPECT_TRUE(s.card.environment->found);
  EXPECT_EQ(s.card.environment->intensity, 0.25);
  EXPECT_NEAR(s.card.environment->rotation_y, kPi / 2, 1e-15);
}

TEST(SceneLights, DefaultsFollowGltf) {
  TempDir dir;
  const std::string card = CopyScene(dir, "drape", [](Json& g) {
    Json& lights = g["extensions"]["KHR_lights_punctual"]["lights"];
    lights[0]["spot"] = Json::object();  // glTF defaults: inner 0, outer pi/4
    lights[2].erase("color");
    lights[2].erase("intensity");
    lights[2].erase("range");
  });
  const Scene s = LoadScene(card);
  EXPECT_EQ(s.lights[0].inner_cone, 0.0);
  EXPECT_NEAR(s.lights[0].outer_cone, kPi / 4, 1e-9);
  EXPECT_EQ(s.lights[2].color, (V3{1, 1, 1}));
  EXPECT_EQ(s.lights[2].intensity, 1.0);
  EXPECT_EQ(s.lights[2].range, 0.0);  // infinite
}

// ------------------------------------------------------------------------------------------------
// Environment resolution.

TEST(SceneEnvironment, NameResolvesInTheDataCache) {
  TempDir dir;
  const std::string card = dir.Write("c.json", Card("x.gltf", [](Json& c) {
                                                 c["environment"] = {{"path", "studio"}};
                                               }).dump());
  {
    ScopedEnv env("CLOTHFIT_DATA", dir.path().string());
    const SceneCard missing = LoadSceneCard(card);
    EXPECT_FALSE(missing.environment->found);
    EXPECT_EQ(missing.environment->path, (dir.path() / "hdri" / "studio.exr").string());
    fs::create_directories(dir.path() / "hdri");
    dir.Write("hdri/studio.exr", "stub");
    const SceneCard found = LoadSceneCard(card);
    EXPECT_TRUE(found.environment->found);
    EXPECT_EQ(found.environment->path, (dir.path() / "hdri" / "studio.exr").string());
    EXPECT_EQ(found.environment->name, "studio");
  }
  {
    ScopedEnv data("CLOTHFIT_DATA", std::nullopt);
    ScopedEnv home("HOME", (dir.path() / "home").string());
    const SceneCard c = LoadSceneCard(card);
    EXPECT_EQ(c.environment->path,
              (dir.path() / "home" / ".cache" / "clothfit" / "hdri" / "studio.exr").string());
  }
}

TEST(SceneEnvironment, PathsResolveRelativeToTheCard) {
  TempDir dir;
  fs::create_directories(dir.path() / "maps");
  dir.Write("maps/sky.exr", "stub");
  const std::string card = dir.Write("c.json", Card("x.gltf", [](Json& c) {
                                                 c["environment"] = {{"path", "maps/sky.exr"}};
                                               }).dump());
  const SceneCard c = LoadSceneCard(card);
  EXPECT_EQ(c.environment->path, (dir.path() / "maps" / "sky.exr").string());
  EXPECT_TRUE(c.environment->found);
  // No environment at all: the background colour is what escaping rays see.
  const std::string none = dir.Write("n.json", Card("x.gltf", [](Json& j) {
                                                 j.erase("environment");
                                                 j["background"] = {0.1, 0.2, 0.3};
                                               }).dump());
  const SceneCard n = LoadSceneCard(none);
  EXPECT_FALSE(n.environment.has_value());
  EXPECT_EQ(n.background, (V3{0.1, 0.2, 0.3}));
}

TEST(SceneEnvironment, MissingMapDoesNotFailTheLoad) {
  TempDir dir;
  ScopedEnv env("CLOTHFIT_DATA", dir.path().string());
  const std::string card = CopyScene(dir, "swatch", {}, [](Json& c) {
    c["environment"] = {{"path", "no-such-map"}};
  });
  const Scene s = LoadScene(card);
  EXPECT_FALSE(s.card.environment->found);
  ASSERT_FALSE(s.warnings.empty());
  EXPECT_CONTAINS(s.warnings.back(), "no-such-map");
  EXPECT_CONTAINS(s.warnings.back(), "environment.path");
}

// ------------------------------------------------------------------------------------------------
// Geometry: repairs, hierarchy, binary glTF.

TEST(SceneGeometry, MissingNormalsAreComputed) {
  TempDir dir;
  const std::string card = CopyScene(dir, "sphere", [](Json& g) {
    g["meshes"][0]["primitives"][0]["attributes"].erase("NORMAL");
  });
  const Scene s = LoadScene(card);
  const Scene ref = LoadScene((ScenesDir() / "sphere.json").string());
  ASSERT_EQ(s.meshes.size(), 1u);
  ExpectWellFormed(s.meshes[0]);
  // Vertices in no triangle (one duplicated pole vertex at the seam) get an arbitrary normal.
  std::vector<char> used(s.meshes[0].positions.size(), 0);
  for (uint32_t i : s.meshes[0].indices) used[i] = 1;
  for (size_t i = 0; i < s.meshes[0].normals.size(); ++i) {
    if (!used[i]) continue;
    ASSERT_GT(Dot(D(s.meshes[0].normals[i]), D(ref.meshes[0].normals[i])), 0.99) << i;
  }
  ASSERT_FALSE(s.warnings.empty());
  EXPECT_CONTAINS(s.warnings[0], "NORMAL");
  EXPECT_CONTAINS(s.warnings[0], "sphere");
}

TEST(SceneGeometry, MissingTangentsAreGeneratedAsTheGeneratorDoes) {
  TempDir dir;
  const std::string card = CopyScene(dir, "drape", [](Json& g) {
    for (Json& mesh : g["meshes"]) mesh["primitives"][0]["attributes"].erase("TANGENT");
  });
  const Scene s = LoadScene(card);
  const Scene ref = LoadScene((ScenesDir() / "drape.json").string());
  ASSERT_EQ(s.meshes.size(), ref.meshes.size());
  for (size_t k = 0; k < s.meshes.size(); ++k) {
    const Mesh& a = s.meshes[k];
    const Mesh& b = ref.meshes[k];
    ExpectWellFormed(a);
    size_t same = 0;
    for (size_t i = 0; i < a.tangents.size(); ++i) {
      const V3 ta{double(a.tangents[i][0]), double(a.tangents[i][1]), double(a.tangents[i][2])};
      const V3 tb{double(b.tangents[i][0]), double(b.tangents[i][1]), double(b.tangents[i][2])};
      if (Dot(ta, tb) > 0.999 && a.tangents[i][3] == b.tangents[i][3]) ++same;
    }
    EXPECT_EQ(same, a.tangents.size()) << a.name;
  }
}

TEST(SceneGeometry, FabricWithoutUvsIsAnErrorNamingTheMesh) {
  TempDir dir;
  const std::string card = CopyScene(dir, "sphere", [](Json& g) {
    g["meshes"][0]["primitives"][0]["attributes"].erase("TEXCOORD_0");
  });
  const std::string err = LoadError(card);
  EXPECT_CONTAINS(err, (dir.path() / "sphere.gltf").string());
  EXPECT_CONTAINS(err, "mesh 'sphere'");
  EXPECT_CONTAINS(err, "TEXCOORD_0");
  EXPECT_CONTAINS(err, "fabric_material");
}

TEST(SceneGeometry, NonFabricWithoutUvsGetsZeroUvs) {
  TempDir dir;
  const std::string card = CopyScene(dir, "drape", [](Json& g) {
    g["meshes"][2]["primitives"][0]["attributes"].erase("TEXCOORD_0");
    g["meshes"][2]["primitives"][0]["attributes"].erase("TANGENT");
  });
  const Scene s = LoadScene(card);
  ExpectWellFormed(s.meshes[2]);
  for (const auto& uv : s.meshes[2].uvs) ASSERT_EQ(uv, (std::array<float, 2>{0, 0}));
}

// glTF 2.0 spec, 3.9.6 ("default material"): a primitive without `material` uses base colour
// 1, metallic 1, roughness 1, single-sided. clothfit (docs/scenes.md, "A glTF without
// materials"): in a glTF with no materials at all, that default slot is the fabric when the
// card's fabric_material is 0 (clothfit's fabric material applies, not the spec's metal);
// with materials present, a primitive without one is a non-fabric mesh with the default.
TEST(SceneGeometry, GltfWithoutMaterialsMakesTheDefaultMaterialTheFabric) {
  TempDir dir;
  const std::string card = CopyScene(dir, "sphere", [](Json& g) {
    g.erase("materials");
    g["meshes"][0]["primitives"][0].erase("material");
  });
  const Scene s = LoadScene(card);
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_TRUE(s.meshes[0].is_fabric);
  EXPECT_EQ(s.meshes[0].material, -1);
  EXPECT_EQ(s.meshes[0].base_color, (std::array<float, 3>{1, 1, 1}));
  EXPECT_FALSE(s.meshes[0].double_sided);
  ExpectWellFormed(s.meshes[0]);
  bool warned = false;
  for (const std::string& w : s.warnings) warned |= w.find("no materials") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST(SceneBadInput, GltfGivenAsTheCardIsNamedAsSuch) {
  TempDir dir;
  const std::string card = CopyScene(dir, "sphere", {});
  const std::string gltf = (dir.path() / "sphere.gltf").string();
  const std::string err = LoadError(gltf);
  EXPECT_CONTAINS(err, gltf);
  EXPECT_CONTAINS(err, "this is a glTF file, not a clothfit scene card");
  EXPECT_EQ(LoadError(card), "");
}

TEST(SceneGeometry, GltfWithoutMaterialsAndAnotherFabricSlotIsAnError) {
  TempDir dir;
  const std::string card = CopyScene(
      dir, "sphere",
      [](Json& g) {
        g.erase("materials");
        g["meshes"][0]["primitives"][0].erase("material");
      },
      [](Json& c) { c["fabric_material"] = 1; });
  const std::string err = LoadError(card);
  EXPECT_CONTAINS(err, "fabric_material");
  EXPECT_CONTAINS(err, "0 materials");
}

TEST(SceneGeometry, PrimitiveWithoutMaterialBesideOthersIsNotFabric) {
  TempDir dir;
  const std::string card =
      CopyScene(dir, "drape", [](Json& g) { g["meshes"][2]["primitives"][0].erase("material"); });
  const Scene s = LoadScene(card);
  ASSERT_EQ(s.meshes.size(), 3u);
  EXPECT_TRUE(s.meshes[0].is_fabric);
  EXPECT_FALSE(s.meshes[2].is_fabric);
  EXPECT_EQ(s.meshes[2].material, -1);
  EXPECT_EQ(s.meshes[2].base_color, (std::array<float, 3>{1, 1, 1}));
}

// A one-triangle glTF with a two-level hierarchy: parent `matrix`, child TRS.
std::string TriangleGltf(const Json& parent_matrix, const Json& child) {
  // Positions (0,0,0) (1,0,0) (0,1,0), normals +Z, UVs; no indices (non-indexed).
  const float data[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 1, 1, 1, 0, 0};
  std::string bytes(reinterpret_cast<const char*>(data), sizeof(data));
  static const char* kB64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string b64;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t v = uint32_t(uint8_t(bytes[i])) << 16;
    if (i + 1 < bytes.size()) v |= uint32_t(uint8_t(bytes[i + 1])) << 8;
    if (i + 2 < bytes.size()) v |= uint32_t(uint8_t(bytes[i + 2]));
    b64 += kB64[(v >> 18) & 63];
    b64 += kB64[(v >> 12) & 63];
    b64 += i + 1 < bytes.size() ? kB64[(v >> 6) & 63] : '=';
    b64 += i + 2 < bytes.size() ? kB64[v & 63] : '=';
  }
  Json child_node = child;
  child_node["mesh"] = 0;
  const Json g = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", {0, 2}}}}},
      {"nodes",
       {{{"matrix", parent_matrix}, {"children", {1}}},
        child_node,
        {{"camera", 0}, {"translation", {0, 0, 5}}}}},
      {"cameras", {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.1}}}}}},
      {"materials", {{{"name", "fabric"}}}},
      {"meshes",
       {{{"name", "tri"},
         {"primitives",
          {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}, {"TEXCOORD_0", 2}}},
            {"material", 0}}}}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", 3},
         {"type", "VEC3"},
         {"min", {0, 0, 0}},
         {"max", {1, 1, 0}}},
        {{"bufferView", 0},
         {"byteOffset", 36},
         {"componentType", 5126},
         {"count", 3},
         {"type", "VEC3"}},
        {{"bufferView", 0},
         {"byteOffset", 72},
         {"componentType", 5126},
         {"count", 3},
         {"type", "VEC2"}}}},
      {"bufferViews", {{{"buffer", 0}, {"byteLength", bytes.size()}}}},
      {"buffers",
       {{{"byteLength", bytes.size()}, {"uri", "data:application/octet-stream;base64," + b64}}}}};
  return g.dump();
}

TEST(SceneGeometry, HierarchyFlattensMatrixAndTrs) {
  TempDir dir;
  // Parent: translate (1, 2, 3) (column-major matrix). Child: scale 2, rotate 90 degrees
  // about +Y (q = (0, sin 45, 0, cos 45)), translate (0, 0, -1).
  const double h = std::sqrt(0.5);
  dir.Write("tri.gltf",
            TriangleGltf(
                {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 2, 3, 1},
                {{"scale", {2, 2, 2}}, {"rotation", {0, h, 0, h}}, {"translation", {0, 0, -1}}}));
  const std::string card = dir.Write("tri.json", Card("tri.gltf").dump());
  const Scene s = LoadScene(card);
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  // R_y(90) maps +X to -Z and +Z to +X.
  const V3 expect[3] = {{1, 2, 2}, {1, 2, 0}, {1, 4, 2}};
  for (int i = 0; i < 3; ++i) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.positions[i][c], expect[i][c], 1e-6) << i;
    EXPECT_NEAR(m.normals[i][0], 1.0f, 1e-6f);
  }
  ExpectWellFormed(m);
  EXPECT_EQ(s.meshes[0].indices, (std::vector<uint32_t>{0, 1, 2}));
  // Camera placed by a root node.
  EXPECT_NEAR(s.camera.position[2], 5.0, 1e-12);
  EXPECT_NEAR(s.camera.forward[2], -1.0, 1e-12);
}

TEST(SceneGeometry, MirroringTransformKeepsFrontFacesAndNormals) {
  TempDir dir;
  dir.Write("tri.gltf",
            TriangleGltf({-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, Json::object()));
  const Scene s = LoadScene(dir.Write("tri.json", Card("tri.gltf").dump()));
  const Mesh& m = s.meshes[0];
  EXPECT_EQ(m.indices, (std::vector<uint32_t>{0, 2, 1}));
  for (const auto& n : m.normals) EXPECT_NEAR(n[2], 1.0f, 1e-6f);  // mirror in x keeps +Z
  ExpectWellFormed(m);
  // The tangent's handedness flips with the mirror: +u now runs along -X.
  EXPECT_NEAR(m.tangents[0][0], -1.0f, 1e-6f);
}

TEST(SceneGeometry, BinaryGltfLoadsLikeText) {
  TempDir dir;
  tinygltf::Model model;
  tinygltf::TinyGLTF io;
  std::string err, warn;
  ASSERT_TRUE(io.LoadASCIIFromFile(&model, &err, &warn, (ScenesDir() / "swatch.gltf").string()))
      << err;
  for (auto& b : model.buffers) b.uri.clear();
  const std::string glb = (dir.path() / "swatch.glb").string();
  ASSERT_TRUE(io.WriteGltfSceneToFile(&model, glb, false, false, false, true));
  const Scene s = LoadScene(dir.Write("swatch.json", Card("swatch.glb").dump()));
  const Scene ref = LoadScene((ScenesDir() / "swatch.json").string());
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_EQ(s.meshes[0].positions, ref.meshes[0].positions);
  EXPECT_EQ(s.meshes[0].tangents, ref.meshes[0].tangents);
  ASSERT_EQ(s.lights.size(), 1u);
  EXPECT_EQ(s.lights[0].direction, ref.lights[0].direction);
}

// ------------------------------------------------------------------------------------------------
// Bad input: errors name the file and the field.

TEST(SceneBadInput, MissingCard) {
  const std::string path = "/nonexistent/clothfit/card.json";
  try {
    LoadSceneCard(path);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_CONTAINS(e.what(), path);
    EXPECT_CONTAINS(e.what(), "not found");
  }
}

TEST(SceneBadInput, MalformedJsonReportsLineAndColumn) {
  TempDir dir;
  const std::string card =
      dir.Write("bad.json", "{\n  \"version\": 1,\n  \"gltf\": \"x.gltf\"\n  \"width\": 3\n}\n");
  const std::string err = LoadError(card);
  EXPECT_CONTAINS(err, card + ":4:");  // line 4; the column is where the parser stopped
  EXPECT_CONTAINS(err, "malformed JSON");
  const std::string empty = dir.Write("empty.json", "");
  // An empty file is refused by the bounded reader before any parse (issue 14), by name.
  EXPECT_CONTAINS(LoadError(empty), empty + ": ");
  EXPECT_CONTAINS(LoadError(empty), "is empty");
  const std::string array = dir.Write("array.json", "[1, 2]");
  EXPECT_CONTAINS(LoadError(array), "must be a JSON object");
}

// Writes Card("x.gltf") edited by `edit` and returns LoadSceneCard's error.
std::string CardError(const TempDir& dir, const std::function<void(Json&)>& edit) {
  const std::string path = dir.Write("card.json", Card("x.gltf", edit).dump(2));
  try {
    LoadSceneCard(path);
  } catch (const SceneError& e) {
    EXPECT_CONTAINS(e.what(), path);
    return e.what();
  }
  return "";
}

TEST(SceneBadInput, FieldErrorsNameTheField) {
  TempDir dir;
  struct Case {
    std::function<void(Json&)> edit;
    const char* field;
    const char* detail;
  };
  const std::vector<Case> cases = {
      {[](Json& c) { c["width"] = "256"; }, "'width'", "expected an integer"},
      {[](Json& c) { c["width"] = -5; }, "'width'", "[1, 16384]"},
      {[](Json& c) { c["height"] = 2.5; }, "'height'", "expected an integer"},
      {[](Json& c) { c["height"] = 0; }, "'height'", "[1, 16384]"},
      {[](Json& c) { c["width"] = 99999999999999ULL; }, "'width'", "[1, 16384]"},
      {[](Json& c) { c["tone_mapping"] = "Filmic"; }, "'tone_mapping'", "ACESFilmic"},
      {[](Json& c) { c["tone_mapping"] = 3; }, "'tone_mapping'", "expected a string"},
      {[](Json& c) { c["exposure"] = 0; }, "'exposure'", "> 0"},
      {[](Json& c) { c["light_scale"] = -1; }, "'light_scale'", ">= 0"},
      {[](Json& c) { c["fabric_material"] = -1; }, "'fabric_material'", "must be in"},
      {[](Json& c) { c["camera"] = true; }, "'camera'", "expected an integer"},
      {[](Json& c) {
         c["background"] = {1, 2};
       },
       "'background'", "3 numbers"},
      {[](Json& c) {
         c["background"] = {1, -2, 0};
       },
       "'background'", ">= 0"},
      {[](Json& c) { c["uv_metres_per_unit"] = 0; }, "'uv_metres_per_unit'", "> 0"},
      {[](Json& c) { c.erase("version"); }, "'version'", "missing"},
      {[](Json& c) { c["version"] = 2; }, "'version'", "not supported"},
      {[](Json& c) { c.erase("gltf"); }, "'gltf'", "missing"},
      {[](Json& c) { c["gltf"] = ""; }, "'gltf'", "empty"},
      {[](Json& c) { c["widht"] = 256; }, "'widht'", "unknown field"},
      {[](Json& c) { c["environment"] = "studio"; }, "'environment'", "expected an object"},
      {[](Json& c) { c["environment"] = Json::object(); }, "'environment.path'", "missing"},
      {[](Json& c) { c["environment"]["intensity"] = -1; }, "'environment.intensity'", ">= 0"},
      {[](Json& c) { c["environment"]["rotation"] = 3; }, "'environment.rotation'",
       "unknown field"},
      {[](Json& c) { c["environment"]["rotation_y_degrees"] = "90"; },
       "'environment.rotation_y_degrees'", "expected a number"},
  };
  for (const Case& c : cases) {
    const std::string err = CardError(dir, c.edit);
    EXPECT_CONTAINS(err, std::string("field ") + c.field);
    EXPECT_CONTAINS(err, c.detail);
  }
}

TEST(SceneBadInput, MissingGltf) {
  TempDir dir;
  const std::string card = dir.Write("c.json", Card("nope.gltf").dump());
  const std::string err = LoadError(card);
  EXPECT_CONTAINS(err, card);
  EXPECT_CONTAINS(err, "field 'gltf'");
  EXPECT_CONTAINS(err, (dir.path() / "nope.gltf").string());
}

TEST(SceneBadInput, GltfIndicesOutOfCardRange) {
  TempDir dir;
  const std::string cam = CopyScene(dir, "swatch", {}, [](Json& c) { c["camera"] = 3; });
  std::string err = LoadError(cam);
  EXPECT_CONTAINS(err, cam);
  EXPECT_CONTAINS(err, "field 'camera'");
  EXPECT_CONTAINS(err, "1 camera");
  const std::string mat = CopyScene(dir, "swatch", {}, [](Json& c) { c["fabric_material"] = 1; });
  err = LoadError(mat);
  EXPECT_CONTAINS(err, "field 'fabric_material'");
  EXPECT_CONTAINS(err, "1 material");
}

TEST(SceneBadInput, BrokenGltfFilesGiveErrorsNotCrashes) {
  TempDir dir;
  const std::string gltf = (dir.path() / "swatch.gltf").string();
  const std::vector<std::pair<std::function<void(Json&)>, const char*>> cases = {
      {[](Json& g) { g["accessors"][1]["count"] = 100000; }, "runs past the end"},
      {[](Json& g) { g["accessors"][1]["componentType"] = 5121; }, "component type"},
      {[](Json& g) { g["meshes"][0]["primitives"][0]["mode"] = 0; }, "mode 0"},
      {[](Json& g) { g["meshes"][0]["primitives"][0]["attributes"].erase("POSITION"); },
       "POSITION"},
      {[](Json& g) { g["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 99; },
       "out of range"},
      {[](Json& g) { g["nodes"][0]["children"] = {0}; }, "cycle"},
      {[](Json& g) {
         g["nodes"][0]["scale"] = {0, 0, 0};
       },
       "singular"},
      {[](Json& g) { g["extensions"]["KHR_lights_punctual"]["lights"][0]["type"] = "area"; },
       "area"},
      {[](Json& g) { g["cameras"][0]["perspective"]["yfov"] = -1; }, "yfov"},
      {[](Json& g) { g["buffers"][0]["uri"] = "data:application/octet-stream;base64,AAAA"; },
       "swatch.gltf"},
  };
  for (const auto& [edit, detail] : cases) {
    const std::string err = LoadError(CopyScene(dir, "swatch", edit));
    EXPECT_CONTAINS(err, gltf);
    EXPECT_CONTAINS(err, detail);
  }
  dir.Write("swatch.gltf", "{ not json");
  EXPECT_CONTAINS(LoadError(dir.Write("c.json", Card("swatch.gltf").dump())), gltf);
  dir.Write("swatch.gltf", "glTF\x02\0\0\0garbage");
  EXPECT_CONTAINS(LoadError(dir.Write("c.json", Card("swatch.gltf").dump())), gltf);
}

}  // namespace
}  // namespace clothfit::render

namespace clothfit::render {
namespace {

// Session 13: the card's "visibility" block (docs/scene-card.md): read with its defaults, and
// every bad field named with the card's path.
TEST(SceneVisibility, BlockIsReadAndBadFieldsAreNamed) {
  TempDir dir;
  const SceneCard none = LoadSceneCard(dir.Write("n.json", Card("x.gltf", [](Json&) {}).dump()));
  EXPECT_FALSE(none.visibility.has_value());
  const SceneCard on = LoadSceneCard(dir.Write("a.json", Card("x.gltf", [](Json& c) {
                                                  c["visibility"] = {{"shadows", true},
                                                                     {"light_map", true}};
                                                }).dump()));
  ASSERT_TRUE(on.visibility.has_value());
  EXPECT_TRUE(on.visibility->shadows);
  EXPECT_TRUE(on.visibility->light_map);
  EXPECT_EQ(on.visibility->size, 128);
  EXPECT_EQ(on.visibility->samples, 64);
  EXPECT_EQ(on.visibility->hit_samples, 8);
  EXPECT_EQ(on.visibility->bounces, 1);
  const SceneCard sized = LoadSceneCard(dir.Write("b.json", Card("x.gltf", [](Json& c) {
                                                     c["visibility"] = {
                                                         {"light_map", {{"size", 32}, {"bounces", 2}}}};
                                                   }).dump()));
  EXPECT_FALSE(sized.visibility->shadows);
  EXPECT_TRUE(sized.visibility->light_map);
  EXPECT_EQ(sized.visibility->size, 32);
  EXPECT_EQ(sized.visibility->bounces, 2);
  const std::pair<Json, std::string> bad[] = {
      {Json("yes"), "visibility"},
      {Json{{"shadows", 1}}, "visibility.shadows"},
      {Json{{"light_map", "on"}}, "visibility.light_map"},
      {Json{{"light_map", {{"size", 0}}}}, "visibility.light_map.size"},
      {Json{{"light_map", {{"size", 4096}}}}, "visibility.light_map.size"},
      {Json{{"light_map", {{"bounces", 9}}}}, "visibility.light_map.bounces"},
      {Json{{"light_map", {{"sise", 64}}}}, "sise"},
      {Json{{"ao_map", true}}, "ao_map"},
  };
  int k = 0;
  for (const auto& [v, field] : bad) {
    const Json& block = v;  // a named reference: clang 14 cannot capture a structured binding
    const std::string path = dir.Write("bad" + std::to_string(k++) + ".json",
                                       Card("x.gltf", [&](Json& c) { c["visibility"] = block; }).dump());
    try {
      LoadSceneCard(path);
      ADD_FAILURE() << "accepted " << v.dump();
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace clothfit::render
