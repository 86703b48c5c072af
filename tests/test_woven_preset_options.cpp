// The preset's "woven" object (render/scene/material.h; brdf/woven.h woven::Options): read with
// the same keys and meaning as web/clothfit.js loadClothfitPreset (yarn_layer, tint_warp,
// tint_weft), refused with the file and field named when unknown or out of range, written back
// by PresetToJson, and used by the preview (a non-default value changes the frame).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "render/preview/preview.h"
#include "render/scene/material.h"
#include "render/scene/scene.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

nlohmann::json WovenPreset(const nlohmann::json& woven) {
  nlohmann::json j = {{"schema", "clothfit.preset"}, {"version", 1}, {"model", "woven"},
                      {"parameters", {{"specular_color", {0.7, 0.6, 0.5}}, {"roughness", 0.4}}}};
  if (!woven.is_null()) j["woven"] = woven;
  return j;
}

TEST(WovenPresetOptions, ReadsTheSameKeysAsTheWebLoader) {
  const MaterialPreset d = ParsePreset(WovenPreset(nullptr), "d.json");
  EXPECT_EQ(d.woven.yarn_layer, woven::YarnLayer::kAdditive);
  EXPECT_EQ(d.woven.tint_warp[0], 1.0);
  const MaterialPreset p = ParsePreset(
      WovenPreset({{"yarn_layer", "albedo-scaled"}, {"tint_warp", {0.2, 0.5, 1.0}},
                   {"tint_weft", {1.0, 0.9, 0.3}}}),
      "p.json");
  EXPECT_EQ(p.woven.yarn_layer, woven::YarnLayer::kAlbedoScaled);
  EXPECT_EQ(p.woven.tint_warp[0], 0.2);
  EXPECT_EQ(p.woven.tint_warp[1], 0.5);
  EXPECT_EQ(p.woven.tint_weft[2], 0.3);
  EXPECT_FALSE(p.extra.contains("woven"));  // interpreted, not kept as an unknown key
  // Written back and read again unchanged.
  const MaterialPreset q = ParsePreset(PresetToJson(p), "q.json");
  EXPECT_EQ(q.woven.yarn_layer, p.woven.yarn_layer);
  for (int c = 0; c < 3; ++c) {
    EXPECT_EQ(q.woven.tint_warp[c], p.woven.tint_warp[c]);
    EXPECT_EQ(q.woven.tint_weft[c], p.woven.tint_weft[c]);
  }
}

void ExpectError(const nlohmann::json& j, const std::string& field, const std::string& what) {
  try {
    ParsePreset(j, "bad.json");
    ADD_FAILURE() << "accepted: " << j.dump();
  } catch (const MaterialError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("bad.json"), std::string::npos) << m;
    EXPECT_NE(m.find(field), std::string::npos) << m;
    EXPECT_NE(m.find(what), std::string::npos) << m;
  }
}

TEST(WovenPresetOptions, RefusesUnknownKeysAndValues) {
  ExpectError(WovenPreset({{"yarn", "additive"}}), "woven.yarn", "unknown key");
  ExpectError(WovenPreset({{"yarn_layer", "scaled"}}), "woven.yarn_layer", "albedo-scaled");
  ExpectError(WovenPreset({{"yarn_layer", 1}}), "woven.yarn_layer", "additive");
  ExpectError(WovenPreset({{"tint_warp", {1.0, 1.0}}}), "woven.tint_warp", "3 numbers");
  ExpectError(WovenPreset({{"tint_weft", {1.0, -0.1, 1.0}}}), "woven.tint_weft[1]", ">= 0");
  ExpectError(WovenPreset({{"tint_weft", {1.0, "x", 1.0}}}), "woven.tint_weft[1]", "number");
  ExpectError(WovenPreset("additive"), "woven", "object");
  nlohmann::json cloth = {{"schema", "clothfit.preset"}, {"version", 1}, {"model", "cloth"},
                          {"parameters", nlohmann::json::object()}, {"woven", nlohmann::json::object()}};
  ExpectError(cloth, "woven", "only allowed with model");
}

// A lit woven quad (tangents along +x) seen from an angle: the preview's fabric pixels.
std::vector<Rgb<double>> Preview(const MaterialPreset& p) {
  Scene s = CameraScene(24, 24, {0.0, -1.2, 2.5}, {0.0, 0.43, -0.9}, 0.6);
  Mesh m;
  m.name = "fabric";
  m.is_fabric = true;
  m.double_sided = true;
  m.base_color = {0.5f, 0.5f, 0.5f};
  m.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.normals.assign(4, {0.f, 0.f, 1.f});
  m.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  m.tangents.assign(4, {1.f, 0.f, 0.f, 1.f});
  m.indices = {0, 1, 2, 0, 2, 3};
  s.meshes.push_back(m);
  Light key;
  key.type = Light::Type::kDirectional;
  key.direction = {-0.3, 0.4, -0.85};
  key.intensity = 3.0;
  s.lights.push_back(key);
  PreviewOptions o;
  o.model = p.model;
  o.woven = p.woven;
  const auto c = PreviewCache::Build(s, nullptr, o);
  std::vector<Rgb<double>> out;
  EvaluatePreview(*c, p.values.data(), out);
  return out;
}

double MaxDiff(const std::vector<Rgb<double>>& a, const std::vector<Rgb<double>>& b) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0.0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i)
    for (int c = 0; c < 3; ++c) d = std::max(d, std::abs(a[i][c] - b[i][c]));
  return d;
}

TEST(WovenPresetOptions, NonDefaultOptionsPreviewDifferently) {
  const auto base = Preview(ParsePreset(WovenPreset(nullptr), "d.json"));
  ASSERT_GT(base.size(), 100u);
  double peak = 0.0;
  for (const auto& c : base) peak = std::max({peak, c[0], c[1], c[2]});
  ASSERT_GT(peak, 0.01);
  // The defaults written out explicitly: the same frame.
  EXPECT_EQ(MaxDiff(base, Preview(ParsePreset(WovenPreset({{"yarn_layer", "additive"},
                                                           {"tint_warp", {1, 1, 1}},
                                                           {"tint_weft", {1, 1, 1}}}),
                                              "e.json"))),
            0.0);
  // Each non-default option changes it.
  for (const nlohmann::json& w : {nlohmann::json{{"yarn_layer", "albedo-scaled"}},
                                  nlohmann::json{{"tint_warp", {0.2, 1.0, 1.0}}},
                                  nlohmann::json{{"tint_weft", {1.0, 1.0, 0.2}}}}) {
    EXPECT_GT(MaxDiff(base, Preview(ParsePreset(WovenPreset(w), "w.json"))), 1e-3 * peak)
        << w.dump();
  }
}

}  // namespace
}  // namespace clothfit::render
