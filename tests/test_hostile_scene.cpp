// Issue 14, the scene/preset/convert readers: each reproducer of fuzz-crashers.tar.gz through
// the reader it broke (render::LoadScene, LoadSceneCard, ReadPreset, fit::ReadMaterials).
// Before the fixes these tests crash (heap overflow, stack overflow, Embree abort), allocate
// gigabytes, or accept bad data; ctest runs each in its own process.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>

#include "fit/convert/convert.h"
#include "fit/convert/convert_io.h"
#include "render/scene/input_limits.h"
#include "render/scene/material.h"
#include "render/scene/scene.h"
#include "tests/hostile_fixtures.h"

namespace clothfit {
namespace {
namespace fs = std::filesystem;
using testing::Repro;
using testing::Scratch;

// LoadScene must throw a SceneError whose message holds every part of `parts`.
void ExpectSceneError(const std::string& card, std::initializer_list<const char*> parts) {
  const auto t0 = std::chrono::steady_clock::now();
  try {
    (void)render::LoadScene(card);
    ADD_FAILURE() << card << ": accepted";
  } catch (const render::SceneError& e) {
    const std::string m = e.what();
    for (const char* p : parts) EXPECT_NE(m.find(p), std::string::npos) << p << " not in: " << m;
    EXPECT_TRUE(limits::IsValidUtf8(m));
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 3.0)
      << card;
}

TEST(GltfRegression, AccessorCountWrapIsRejectedBeforeAllocation) {
  ExpectSceneError(Repro("gltf-accessor-count-wrap/a.json"),
                   {"a_count_wrap.gltf", "POSITION", "kMaxSceneVertices"});
  ExpectSceneError(Repro("gltf-accessor-count-wrap/d.json"),
                   {"d_uv_wrap.gltf", "TEXCOORD_0", "differs from POSITION"});
  ExpectSceneError(Repro("gltf-accessor-count-wrap/e.json"),
                   {"e_tan_wrap.gltf", "TANGENT", "differs from POSITION"});
}

TEST(GltfRegression, OffsetWrapIsRejected) {
  ExpectSceneError(Repro("gltf-offset-wrap-oob-read/f.json"),
                   {"f_view_offset_wrap.gltf", "bufferViews[1]", "runs past the end"});
  ExpectSceneError(Repro("gltf-offset-wrap-oob-read/k.json"),
                   {"k_acc_offset_wrap.gltf", "accessors[1]", "runs past the end"});
}

TEST(GltfRegression, CountsBeyondBufferOrBudgetAreRejected) {
  ExpectSceneError(Repro("gltf-accessor-huge-count-no-bufferview/b.json"),
                   {"b_big_zero.gltf", "kMaxSceneVertices"});
  for (const char* d : {"gltf-crash-4a0e719a0f", "gltf-crash-30005b73b7", "gltf-crash-125cd194d6",
                        "gltf-crash-71ac654868"})
    ExpectSceneError(Repro(std::string(d) + "/card.json"), {"scene.gltf", "accessors["});
  ExpectSceneError(Repro("glb-hang-ab25d4fe2c/card.json"),
                   {"scene.glb", "NORMAL", "differs from POSITION"});
}

TEST(GltfRegression, DeepExtrasFailTheSceneCleanly) {
  ExpectSceneError(Repro("gltf-crash-3e0026d6a3/card.json"), {"scene.gltf", "kMaxJsonDepth"});
  ExpectSceneError(Repro("glb-crash-a44c758c25/card.json"), {"scene.glb", "kMaxJsonDepth"});
}

TEST(GltfRegression, FarCameraRejectedAtLoad) {
  ExpectSceneError(Repro("gltf-far-camera-embree-abort/card.json"),
                   {"far_camera.gltf", "cameras[0]", "kMaxWorldCoordinate"});
  ExpectSceneError(Repro("glb-crash-e26fe4f559/card.json"), {"scene.glb", "kMaxWorldCoordinate"});
}

TEST(SceneCardRegression, DeepValuesAreRejectedByTheDepthLimit) {
  for (const char* f :
       {"card-crash-4e5a7878ad/card.json", "card-crash-7e700e9159/card.json",
        "card-deep-nesting-stack-overflow/deep_100000.json",
        "card-deep-nesting-stack-overflow/deeparr_100000.json"}) {
    try {
      (void)render::LoadSceneCard(Repro(f));
      ADD_FAILURE() << f << ": accepted";
    } catch (const render::SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("kMaxJsonDepth"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(fs::path(f).filename().string()), std::string::npos);
    }
  }
}

TEST(SceneCardRegression, WrongTypedValueIsDescribedNotDumped) {
  const fs::path d = Scratch("card_show");
  const std::string card = (d / "c.json").string();
  {
    std::ofstream o(card);
    o << R"({"version": 1, "gltf": "x.gltf", "width": [[[1]], 2, "\u001b[31m"],
             "tone_mapping": "\u001b]0;pwn\u0007"})";
  }
  try {
    (void)render::LoadSceneCard(card);
    FAIL();
  } catch (const render::SceneError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("an array (3 elements)"), std::string::npos) << m;
    EXPECT_EQ(m.find('\x1b'), std::string::npos) << m;
  }
  fs::remove_all(d);
}

TEST(PresetRegression, DeepExtraKeyIsRejectedByTheDepthLimit) {
  for (const char* f : {"preset-crash-49a53a32d4/p.json",
                        "preset-deep-extra-key-stack-overflow/preset_extra_300000.json"}) {
    try {
      (void)render::ReadPreset(Repro(f));
      ADD_FAILURE() << f << ": accepted";
    } catch (const render::MaterialError& e) {
      EXPECT_NE(std::string(e.what()).find("kMaxJsonDepth"), std::string::npos) << e.what();
    }
  }
}

TEST(ConvertRegression, DeepItemFailsAloneAndTheBatchCompletes) {
  const fs::path d = Scratch("convert_deep");
  fs::create_directories(d / "in");
  fs::copy(Repro("convert-deep-nesting-kills-batch/surface_deep.json"), d / "in/surface_deep.json");
  fs::copy(Repro("convert-glb-crash-be25eaa4ce/m.glb"), d / "in/m.glb");
  fs::copy(Repro("convert-invalid-utf8-no-log/cat/preset_0000.json"), d / "in/good.json");
  fit::ConvertOptions o;
  o.out_dir = (d / "out").string();
  const fit::ConvertReport rep = fit::RunConvert(fit::ExpandInputs({(d / "in").string()}), o);
  EXPECT_EQ(rep.failed, 2);
  EXPECT_EQ(rep.converted, 1);
  for (const auto& i : rep.items) {
    if (i.status == "failed") {
      EXPECT_NE(i.reason.find("nested deeper"), std::string::npos) << i.reason;
    }
  }
  EXPECT_NO_THROW((void)fit::ReportJson(rep, o).dump());
  fs::remove_all(d);
}

TEST(ConvertPaths, MapOutsideTheInputTreeIsRefusedUnlessAllowed) {
  const fs::path d = Scratch("convert_paths");
  fs::copy(Repro("convert-map-uri-any-path"), d / "in", fs::copy_options::recursive);
  try {
    (void)fit::ReadMaterials((d / "in/s_shadow.json").string(), {d / "in", false});
    FAIL() << "../../etc/shadow accepted";
  } catch (const fit::ConvertError& e) {
    EXPECT_NE(std::string(e.what()).find("maps.normal.uri"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("outside"), std::string::npos) << e.what();
  }
  // A map in a sibling directory: refused by default, accepted with --allow-outside-paths.
  fs::create_directories(d / "shared");
  fs::copy(d / "in/maps", d / "shared/maps", fs::copy_options::recursive);
  std::string text;
  {
    std::ifstream in(d / "in/s_shadow.json");
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  const size_t at = text.find("../../../../../etc/shadow");
  ASSERT_NE(at, std::string::npos);
  std::string first_map;
  for (const auto& e : fs::directory_iterator(d / "in/maps")) {
    first_map = e.path().filename().string();
    break;
  }
  text.replace(at, std::string("../../../../../etc/shadow").size(), "../shared/maps/" + first_map);
  {
    std::ofstream o(d / "in/s_sibling.json");
    o << text;
  }
  EXPECT_THROW((void)fit::ReadMaterials((d / "in/s_sibling.json").string(), {d / "in", false}),
               fit::ConvertError);
  EXPECT_NO_THROW((void)fit::ReadMaterials((d / "in/s_sibling.json").string(), {d / "in", true}));
  fs::remove_all(d);
}

}  // namespace
}  // namespace clothfit
