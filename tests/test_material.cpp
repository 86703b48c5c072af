// Material presets: round trip, conventions recorded, clear errors naming file and field.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "render/scene/material.h"

namespace clothfit::render {
namespace {
namespace fs = std::filesystem;

std::string WriteTemp(const std::string& name, const std::string& text) {
  const fs::path p = fs::temp_directory_path() / ("clothfit_mat_" + std::to_string(::getpid()) + name);
  std::ofstream(p) << text;
  return p.string();
}

std::string ErrorOf(const std::string& text) {
  const std::string path = WriteTemp("err.json", text);
  try {
    ReadPreset(path);
  } catch (const MaterialError& e) {
    fs::remove(path);
    return e.what();
  }
  fs::remove(path);
  return "";
}

TEST(Material, RoundTripEveryModelKeepsValuesAndConventions) {
  for (ModelKind m : {ModelKind::kCloth, ModelKind::kStandard, ModelKind::kPhysicalSheen,
                      ModelKind::kGltfSheen}) {
    MaterialPreset p = DefaultPreset(m);
    for (size_t i = 0; i < p.values.size(); ++i) p.values[i] = 0.1 + 0.07 * double(i);
    if (m == ModelKind::kCloth) {
      p.cloth.variant = cloth::Variant::kSeedThreejs;
      p.cloth.sheen_default = cloth::SheenDefault::kSqrtBaseColor;
      p.cloth.subsurface = true;
    }
    p.extra["fit"] = {{"cost", 0.5}};
    const std::string path = WriteTemp("rt.json", "");
    WritePreset(path, p);
    const MaterialPreset q = ReadPreset(path);
    EXPECT_EQ(q.model, m);
    EXPECT_EQ(q.values, p.values);
    EXPECT_EQ(q.extra["fit"]["cost"], 0.5);
    if (m == ModelKind::kCloth) {
      EXPECT_EQ(q.cloth.variant, cloth::Variant::kSeedThreejs);
      EXPECT_EQ(q.cloth.sheen_default, cloth::SheenDefault::kSqrtBaseColor);
      EXPECT_TRUE(q.cloth.subsurface);
    }
    std::ifstream f(path);
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("alpha = r^2"), std::string::npos);
    EXPECT_NE(text.find("linear sRGB"), std::string::npos);
    fs::remove(path);
  }
}

TEST(Material, MissingParametersTakeTableDefaults) {
  const std::string path = WriteTemp("d.json",
      R"({"schema":"clothfit.preset","version":1,"model":"cloth","parameters":{"roughness":0.4}})");
  const MaterialPreset p = ReadPreset(path);
  EXPECT_EQ(p.values[size_t(p.Offset("roughness"))], 0.4);
  EXPECT_EQ(p.values[0], 1.0);  // base_color default
  fs::remove(path);
}

TEST(Material, ErrorsNameTheFileAndTheField) {
  const std::string head = R"({"schema":"clothfit.preset","version":1,)";
  EXPECT_NE(ErrorOf(head + R"("model":"velvet","parameters":{}})").find("model"), std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth","parameters":{"sheen":0.5}})")
                .find("parameters.sheen: unknown parameter"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth","parameters":{"base_color":[0.5,1.5,0.2]}})")
                .find("parameters.base_color[1]"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth","parameters":{"base_color":[0.5,0.2]}})")
                .find("array of 3"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth","parameters":{"roughness":"rough"}})")
                .find("parameters.roughness: expected a number"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"standard","cloth":{},"parameters":{}})").find("cloth:"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth","cloth":{"varient":"x"},"parameters":{}})")
                .find("cloth.varient: unknown key"),
            std::string::npos);
  EXPECT_NE(ErrorOf(R"({"schema":"clothfit.preset","version":2,"model":"cloth","parameters":{}})")
                .find("version"),
            std::string::npos);
  EXPECT_NE(ErrorOf(head + R"("model":"cloth"})").find("parameters"), std::string::npos);
  const std::string malformed = ErrorOf("{\n  \"schema\": \"clothfit.preset\",\n  \"version\": 1,,\n}");
  EXPECT_NE(malformed.find(":3:"), std::string::npos) << malformed;  // line 3
  EXPECT_NE(malformed.find("malformed JSON"), std::string::npos);
  try {
    ReadPreset("/nonexistent/m.json");
    FAIL();
  } catch (const MaterialError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/m.json"), std::string::npos);
  }
}

// s27: a misspelt top-level field was kept as an unknown key and the material drawn without it
// (a user's "weave_map" lost the weave maps). Near misses of a known field are refused, naming
// the field they resemble; other unknown keys are still carried through (forward compatibility).
TEST(Material, MisspeltTopLevelFieldIsRefusedUnknownOnesAreKept) {
  const std::string head = R"({"schema":"clothfit.preset","version":1,)";
  const struct {
    const char* text;
    const char* expect;
  } cases[] = {
      {R"("model":"woven","weave_map":{"uri":"x.exr"},"parameters":{}})",
       "weave_map: unknown field; did you mean 'weave_maps'?"},
      {R"("model":"woven","Woven":{},"parameters":{}})", "Woven: unknown field; did you mean 'woven'?"},
      {R"("model":"cloth","parameters":{},"paramters":{"roughness":0.3}})",
       "paramters: unknown field; did you mean 'parameters'?"},
      {R"("model":"cloth","parameters":{},"provenence":{}})", "did you mean 'provenance'?"},
      {R"("model":"cloth","parameters":{},"Fit":{}})", "did you mean 'fit'?"},
      {R"("model":"woven","parameters":{},"waeve_maps":{}})", "did you mean 'weave_maps'?"},
  };
  for (const auto& c : cases) {
    const std::string e = ErrorOf(head + c.text);
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.text << " -> " << e;
    EXPECT_NE(e.find("clothfit_mat_"), std::string::npos) << e;  // names the file
  }
  // Far from every known field: kept and written back, as before.
  const std::string path = WriteTemp("fwd.json",
      head + R"("model":"cloth","parameters":{},"future_block":{"a":1},"side":"double","name":"n",)"
             R"("size":1,"mode":2,"names":3,"mod\u00e9l":4})");
  const MaterialPreset p = ReadPreset(path);
  EXPECT_EQ(p.extra.at("future_block")["a"], 1);
  EXPECT_EQ(p.extra.at("side"), "double");
  EXPECT_EQ(p.extra.at("size"), 1);  // short names are refused by case only
  EXPECT_EQ(p.extra.at("mode"), 2);
  EXPECT_EQ(p.extra.at("names"), 3);
  EXPECT_EQ(p.extra.at("mod\u00e9l"), 4);  // non-ASCII keys never
  fs::remove(path);
}

TEST(Material, NonFiniteValuesAreNeverWritten) {
  MaterialPreset p = DefaultPreset(ModelKind::kCloth);
  p.values[6] = std::nan("");
  const std::string path = WriteTemp("nan.json", "");
  fs::remove(path);
  EXPECT_THROW(WritePreset(path, p), MaterialError);
  EXPECT_FALSE(fs::exists(path));
}

}  // namespace
}  // namespace clothfit::render
