// Issue 14: each reproducer of fuzz-crashers.tar.gz (and the synthesized cases without one)
// through the reader it broke. Before the fixes these tests crash (stack overflow, heap
// overflow, Embree abort), allocate gigabytes, or pass bad data silently; each gtest runs in its
// own process under ctest, so a crash fails only its own test.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <string>

#include "fit/convert/convert.h"
#include "fit/metrics/metrics.h"
#include "render/reference/fabric.h"
#include "render/scene/embree_scene.h"
#include "render/scene/environment.h"
#include "render/scene/gltf_tinygltf.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
#include "tests/hostile_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit {
namespace {
namespace fs = std::filesystem;
using testing::Repro;
using testing::Scratch;

bool Contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

long MaxRssKb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// ---- Defect 3: deep glTF/.glb extras reach tinygltf's recursive value conversion ----------

TEST(GltfRegression, DeepExtrasRejectedBeforeTinygltf) {
  for (const char* f : {"gltf-crash-3e0026d6a3/scene.gltf", "glb-crash-a44c758c25/scene.glb",
                        "convert-gltf-crash-58d6b55bf9/m.gltf",
                        "convert-glb-crash-be25eaa4ce/m.glb",
                        "gltf-deep-nesting-tinygltf/deep_extras.gltf"}) {
    tinygltf::Model model;
    std::string err, warn;
    EXPECT_FALSE(render::LoadGltfModel(Repro(f), &model, &err, &warn)) << f;
    EXPECT_TRUE(Contains(err, "nested deeper than 64")) << f << ": " << err;
    EXPECT_TRUE(Contains(err, "kMaxJsonDepth")) << err;
  }
}

TEST(GltfRegression, ExternalBufferOutsideTheDirectoryIsNotRead) {
  const fs::path d = Scratch("gltf_buffer");
  fs::create_directories(d / "scene");
  {
    std::ofstream o(d / "secret.bin", std::ios::binary);
    o << std::string(12, '\0');
  }
  {
    std::ofstream o(d / "scene/x.gltf");
    o << R"({"asset": {"version": "2.0"}, "buffers": [{"uri": "../secret.bin", "byteLength": 12}]})";
  }
  tinygltf::Model model;
  std::string err, warn;
  EXPECT_FALSE(render::LoadGltfModel((d / "scene/x.gltf").string(), &model, &err, &warn));
  EXPECT_TRUE(Contains(err, "outside")) << err;
  // Allowed explicitly, the same file loads.
  limits::PathPolicy allow{d / "scene", true};
  tinygltf::Model model2;
  EXPECT_TRUE(render::LoadGltfModel((d / "scene/x.gltf").string(), &model2, &err, &warn, &allow))
      << err;
  fs::remove_all(d);
}

// ---- Defect 4: rays Embree would assert on -----------------------------------------------

TEST(EmbreeRegression, FarOriginIsACountedMissNotAnAbort) {
  render::Scene s = render::CameraScene(4, 4, {0, 0, 3}, {0, 0, -1}, 0.8);
  s.meshes.push_back(render::SphereMesh(1.0, 8, 8, true, 0.5f));
  const render::EmbreeScene es(s);
  EXPECT_TRUE(es.Intersect({0, 0, 3}, {0, 0, -1}).valid);
  EXPECT_FALSE(es.Intersect({0, 1e19, 0}, {0, -1, 0}).valid);  // libembree3: ray.valid() abort
  EXPECT_FALSE(es.Intersect({0, 0, 3}, {NAN, 0, -1}).valid);
  EXPECT_FALSE(es.Intersect({0, 0, 3}, {0, 0, 0}).valid);
  EXPECT_TRUE(es.Occluded({-9.3e18, 0, 0}, {1, 0, 0}, 0.0, 1.0));
  EXPECT_EQ(es.invalid_rays(), 4);
  EXPECT_TRUE(render::EmbreeScene::RayValid({1e6, 0, 0}, {1, 0, 0}, 0.0,
                                            std::numeric_limits<double>::infinity()));
}

// ---- Defect 6: image readers allocate from the header ------------------------------------

void ExpectImageRefused(const std::string& path, const std::string& why) {
  const long rss0 = MaxRssKb();
  const auto t0 = std::chrono::steady_clock::now();
  try {
    io::ReadImage(path);
    ADD_FAILURE() << path << " accepted";
  } catch (const io::IoError& e) {
    EXPECT_TRUE(Contains(e.what(), fs::path(path).filename().string())) << e.what();
    EXPECT_TRUE(Contains(e.what(), why)) << e.what();
  }
  EXPECT_LT(Seconds(t0), 2.0) << path;
  EXPECT_LT(MaxRssKb() - rss0, 100 * 1024) << path << ": allocated before validating";
}

TEST(ImageRegression, HugeHeadersRejectedBeforeAllocation) {
  ExpectImageRefused(Repro("ref-exr-crash-4f3eadf2db/ref.exr"), "kMaxImageBytes");
  ExpectImageRefused(Repro("ref-exr-hang-6eea2bfd12/ref.exr"), "kMaxImageBytes");
  ExpectImageRefused(Repro("map-png-huge-header/back_albedo.png"), "kMaxImageBytes");
  ExpectImageRefused(Repro("map-png-hang-679fb932f0/back_albedo.png"), "kMaxImageBytes");
}

uint32_t Crc32(const unsigned char* p, size_t n) {  // PNG's CRC (ISO 3309), bitwise
  uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
  }
  return c ^ 0xFFFFFFFFu;
}

TEST(ImageRegression, ForgedPngHeaderWithinTheBudgetIsRefusedByItsFileSize) {
  // A real 8x8 PNG whose IHDR is rewritten to 4000x4000 (256 MiB as float: inside the budget,
  // but 48 MB of raw rows cannot come from a ~100-byte file).
  const fs::path d = Scratch("png_forged");
  const std::string path = (d / "forged.png").string();
  io::WritePng8(path, 8, 8, std::vector<float>(8 * 8 * 3, 0.5f));
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_EQ(bytes.substr(12, 4), "IHDR");
  auto put_be = [&](size_t at, uint32_t v) {
    for (int k = 0; k < 4; ++k) bytes[at + size_t(k)] = char((v >> (24 - 8 * k)) & 0xFF);
  };
  put_be(16, 4000);
  put_be(20, 4000);
  put_be(29, Crc32(reinterpret_cast<const unsigned char*>(bytes.data()) + 12, 17));
  {
    std::ofstream o(path, std::ios::binary | std::ios::trunc);
    o << bytes;
  }
  ExpectImageRefused(path, "kMaxPngExpansion");
  fs::remove_all(d);
}

// ---- Defect 7: finite but huge environment texels -----------------------------------------

TEST(EnvironmentRegression, RadianceAboveTheLimitIsRejectedAtLoad) {
  const fs::path d = Scratch("env_huge");
  io::Image img;
  img.width = 8;
  img.height = 4;
  img.channel_names = {"R", "G", "B"};
  img.pixels.assign(8 * 4 * 3, 3e38f);
  const std::string path = (d / "huge.exr").string();
  io::WriteExr(path, img);
  try {
    render::Environment::Load(path, 1.0, 0.0);
    FAIL() << "3e38 texels accepted";
  } catch (const io::IoError& e) {
    EXPECT_TRUE(Contains(e.what(), "huge.exr")) << e.what();
    EXPECT_TRUE(Contains(e.what(), "kMaxRadiance")) << e.what();
  }
  // Within the limit the same map loads (1e6 x intensity 1e3 = 1e9).
  img.pixels.assign(8 * 4 * 3, 1e6f);
  io::WriteExr(path, img);
  EXPECT_NO_THROW(render::Environment::Load(path, 1e3, 0.0));
  EXPECT_THROW(render::Environment::Load(path, 1e13, 0.0), std::invalid_argument);
  fs::remove_all(d);
}

// ---- Defect 9: compare treats display-encoded PNGs as linear ------------------------------

TEST(CompareRegression, IntegerImagesAreRejected) {
  const fs::path d = Scratch("compare_png");
  const std::string png = (d / "a.png").string(), exr = (d / "a.exr").string();
  io::WritePng8(png, 4, 4, std::vector<float>(48, 0.5f));
  io::Image img;
  img.width = img.height = 4;
  img.channel_names = {"R", "G", "B"};
  img.pixels.assign(48, 0.25f);
  io::WriteExr(exr, img);
  try {
    metrics::CompareFiles(png, exr, "", {});
    FAIL() << "8-bit PNG compared as linear";
  } catch (const std::invalid_argument& e) {
    EXPECT_TRUE(Contains(e.what(), "a.png")) << e.what();
    EXPECT_TRUE(Contains(e.what(), "uint8")) << e.what();
  }
  EXPECT_THROW(metrics::CompareFiles(exr, png, "", {}), std::invalid_argument);
  EXPECT_NO_THROW(metrics::CompareFiles(exr, exr, "", {}));
  fs::remove_all(d);
}

// ---- Defect 8 (fabric part): the preset name cannot walk out of the weave library ---------

TEST(FabricRegression, PresetNameMustBePlain) {
  const std::string text =
      R"({"format": "clothfit-fabric", "version": 1, "name": "x", "model": "irawan",
          "preset": "../../../etc/x", "uv_repeats": 10})";
  try {
    render::ParseFabric(text, "/tmp/f.json");
    FAIL() << "traversing preset accepted";
  } catch (const render::FabricError& e) {
    EXPECT_TRUE(Contains(e.what(), "plain name")) << e.what();
  }
  const std::string deep = R"({"format": )" + std::string(100000, '[') + std::string(100000, ']') + "}";
  try {
    render::ParseFabric(deep, "/tmp/deep.json");
    FAIL();
  } catch (const render::FabricError& e) {
    EXPECT_TRUE(Contains(e.what(), "kMaxJsonDepth")) << e.what();
  }
}

// Session 28: a fabric's name is printed (summary line, progress bar) and stored (EXR metadata):
// control bytes in it are refused, naming the file and field, shown escaped.
TEST(FabricRegression, NameMustBePrintable) {
  for (const std::string& name : {std::string("x\\u001b[31mred"), std::string("a\\nb"),
                                  std::string("tab\\there"), std::string("del\\u007f")}) {
    const std::string text = R"({"format": "clothfit-fabric", "version": 1, "name": ")" + name +
                             R"(", "model": "lambert", "albedo": [0.5, 0.5, 0.5]})";
    try {
      render::ParseFabric(text, "/tmp/f.json");
      FAIL() << "name " << name << " accepted";
    } catch (const render::FabricError& e) {
      EXPECT_TRUE(Contains(e.what(), "/tmp/f.json")) << e.what();
      EXPECT_TRUE(Contains(e.what(), "field 'name'")) << e.what();
      EXPECT_FALSE(Contains(e.what(), "\x1b[")) << "unescaped ESC in the message";
    }
  }
  const std::string ok =
      R"({"format": "clothfit-fabric", "version": 1, "name": "Leinen \u00e9t\u00e9 #2",
          "model": "lambert", "albedo": [0.5, 0.5, 0.5]})";
  EXPECT_EQ(render::ParseFabric(ok, "/tmp/f.json").name, "Leinen \u00e9t\u00e9 #2");
}

// ---- Defects 5 and 8 (hash part) in a convert batch ---------------------------------------

TEST(ConvertRegression, InvalidUtf8IsEscapedAndTheLogDumps) {
  const fs::path d = Scratch("convert_utf8");
  fs::copy(Repro("convert-invalid-utf8-no-log/cat"), d / "cat", fs::copy_options::recursive);
  fit::ConvertOptions o;
  o.out_dir = (d / "out").string();
  o.jobs = 2;
  const fit::ConvertReport rep = fit::RunConvert(fit::ExpandInputs({(d / "cat").string()}), o);
  EXPECT_EQ(rep.failed, 1);
  EXPECT_EQ(rep.converted, 2);
  for (const auto& i : rep.items) {
    if (i.status != "failed") continue;
    EXPECT_TRUE(Contains(i.reason, "bad_utf8.json")) << i.reason;
    EXPECT_TRUE(Contains(i.reason, "\\xFF")) << i.reason;
    EXPECT_TRUE(limits::IsValidUtf8(i.reason));
  }
  // The strict dump (what the log writer used) must work: no raw invalid byte is carried.
  EXPECT_NO_THROW((void)fit::ReportJson(rep, o).dump(2));
  fs::remove_all(d);
}

TEST(ConvertRegression, ProcMapFailsFastInsteadOfHashingForever) {
  const fs::path d = Scratch("convert_pagemap");
  fs::copy(Repro("convert-map-uri-any-path"), d / "in", fs::copy_options::recursive);
  fit::ConvertOptions o;
  o.out_dir = (d / "out").string();
  const auto t0 = std::chrono::steady_clock::now();
  const fit::ConvertReport rep =
      fit::RunConvert(fit::ExpandInputs({(d / "in/s_pagemap.json").string()}), o);
  EXPECT_LT(Seconds(t0), 3.0);
  ASSERT_EQ(rep.items.size(), 1u);
  EXPECT_EQ(rep.items[0].status, "failed");
  EXPECT_TRUE(Contains(rep.items[0].reason, "pagemap")) << rep.items[0].reason;
  fs::remove_all(d);
}

}  // namespace
}  // namespace clothfit
