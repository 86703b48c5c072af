// clothfit convert with weave maps (issue 12, deliverable 4; docs/convert.md, "Weave maps in
// glTF and three.js"): a physical-aniso preset's maps baked into glTF / three.js textures, the
// woven model refused for the engine targets, the `preset-maps` target.
//
// The textures are decoded here independently of the writer: the PNG bytes through
// libpng (io::ReadImage), the sRGB curve from IEC 61966-2-1, the anisotropy texel as
// three.js r187 / KHR_materials_anisotropy decode it (normalize(2 rg - 1), rotated by
// anisotropyRotation, strength x b), the frame through brdf/physical_aniso.h MakeFrame; the
// expected values come from the preview's own sampling of the maps (WeaveMaps::SampleLevel at
// each texel centre, level 0) and the preview's mapping (render/preview/preview.cpp
// AnisoFromWeave: warp >= weft -> direction t, else b; strength |warp - weft| / (warp + weft);
// base colour x kd ratio).
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "brdf/physical_aniso.h"
#include "fit/convert/convert.h"
#include "fit/convert/convert_io.h"
#include "render/scene/png.h"
#include "fit/convert/weave_textures.h"
#include "render/preview/weave_maps.h"
#include "render/scene/image_io.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;
using render::ModelKind;

fs::path TempDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() /
                     ("clothfit_test_convert_weave_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

json ReadJsonFile(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

double Decode(double s) {  // IEC 61966-2-1, independent of the writer's table
  return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
}

ConvertReport RunBatch(const std::vector<std::string>& args, const fs::path& out,
                       std::vector<std::string> targets) {
  ConvertOptions o;
  o.out_dir = out.string();
  o.targets = std::move(targets);
  return RunConvert(ExpandInputs(args), o);
}

// Synthetic weave maps: warp/weft weights with both dominances and equal texels, kd ratios
// that exceed 1 (so the factor scaling is exercised), deterministic.
render::WeaveMaps SyntheticMaps(int size, double repeats, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<float> l0(size_t(size) * size_t(size) * render::WeaveMaps::kChannels);
  for (int j = 0; j < size; ++j)
    for (int i = 0; i < size; ++i) {
      float* t = &l0[(size_t(j) * size_t(size) + size_t(i)) * render::WeaveMaps::kChannels];
      const bool warp_on_top = ((i / 2) + (j / 4)) % 2 == 0;  // a weave-like layout, not symmetric
      t[0] = float(warp_on_top ? 1.0 + u(rng) : 0.2 * u(rng));
      t[1] = float(warp_on_top ? 0.2 * u(rng) : 1.0 + u(rng));
      if (i == 3 && j == 5) t[1] = t[0];  // a tie: strength 0
      for (int c = 0; c < 3; ++c) t[2 + c] = float(0.6 + 0.8 * u(rng) + (warp_on_top ? 0.1 * c : 0));
    }
  return render::WeaveMaps::FromLevel0(size, repeats, std::move(l0));
}

render::MaterialPreset AnisoPreset(double a, double rot) {
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kPhysicalAniso);
  const double v[15] = {0.4, 0.29, 0.2, 0.62, 0.0, 0.3, 0.25, 0.2, 0.55,
                        a,   rot,  0.7, 1.0,  0.8, 0.6};
  p.values.assign(v, v + 15);
  return p;
}

// Writes <dir>/<name>.json (a preset) with its maps in <dir>/<name>.weave.exr.
void WritePresetWithMapsFile(const fs::path& dir, const std::string& name,
                             render::MaterialPreset p, const render::WeaveMaps& maps) {
  const std::string exr = (dir / (name + ".weave.exr")).string();
  render::WriteWeaveMaps(exr, maps);
  p.extra["weave_maps"] = render::WeaveMapsPresetField(exr, maps);
  render::WritePreset((dir / (name + ".json")).string(), p);
}

// The texture a glTF textureInfo names: file, after checking sampler and transform.
fs::path GltfTexture(const json& g, const json& info, const fs::path& dir, double repeats) {
  EXPECT_EQ(info.value("texCoord", 0), 0);
  const json& tt = info.at("extensions").at("KHR_texture_transform");
  EXPECT_DOUBLE_EQ(tt.at("scale").at(0).get<double>(), repeats);
  EXPECT_DOUBLE_EQ(tt.at("scale").at(1).get<double>(), repeats);
  EXPECT_FALSE(tt.contains("offset") || tt.contains("rotation"));
  const json& tex = g.at("textures").at(info.at("index").get<size_t>());
  const json& smp = g.at("samplers").at(tex.at("sampler").get<size_t>());
  EXPECT_EQ(smp.at("wrapS").get<int>(), 10497);      // REPEAT
  EXPECT_EQ(smp.at("wrapT").get<int>(), 10497);
  EXPECT_EQ(smp.at("minFilter").get<int>(), 9987);   // LINEAR_MIPMAP_LINEAR
  EXPECT_EQ(smp.at("magFilter").get<int>(), 9729);   // LINEAR
  return dir / g.at("images").at(tex.at("source").get<size_t>()).at("uri").get<std::string>();
}

// The 8-bit codes of a PNG as io::ReadImage decodes it (values v = code / 255, no transfer).
std::vector<int> Codes(const fs::path& png, int size) {
  const io::Image img = io::ReadImage(png.string());
  EXPECT_EQ(img.width, size);
  EXPECT_EQ(img.height, size);
  EXPECT_EQ(img.channels(), 3);
  EXPECT_FALSE(img.float_source);
  std::vector<int> q(img.pixels.size());
  for (size_t k = 0; k < q.size(); ++k) {
    q[k] = int(std::lround(double(img.pixels[k]) * 255.0));
    EXPECT_NEAR(double(img.pixels[k]) * 255.0, double(q[k]), 1e-3) << "not an 8-bit value";
  }
  return q;
}

// Half the larger of the two linear steps around sRGB code q: the 8-bit quantisation bound.
double HalfStep(int q) {
  const double d = Decode(q / 255.0);
  const double lo = q > 0 ? d - Decode((q - 1) / 255.0) : 0.0;
  const double hi = q < 255 ? Decode((q + 1) / 255.0) - d : 0.0;
  return 0.5 * std::max(lo, hi);
}

struct Expected {
  std::array<double, 3> base;  // linear
  double ux, uy, anisotropy;   // the preview's anisotropy frame (physical_aniso::MakeFrame)
};

// What the preview shades at the centre of texel (i, j), level 0.
Expected Preview(const render::MaterialPreset& p, const render::WeaveMaps& maps, int i, int j) {
  const double s = double(maps.size) * maps.uv_repeats;
  const auto w = maps.SampleLevel((i + 0.5) / s, (j + 0.5) / s, 0);
  Expected e{};
  for (int c = 0; c < 3; ++c) e.base[size_t(c)] = p.values[size_t(c)] * w[size_t(2 + c)];
  physical_aniso::Params<double> pp = physical_aniso::FromFlat(p.values.data());
  physical_aniso::AnisoSample<double> as;
  const bool warp = w[0] >= w[1];
  as.dx = warp ? 1.0 : 0.0;
  as.dy = warp ? 0.0 : 1.0;
  as.b = w[0] + w[1] > 0.0 ? std::abs(w[0] - w[1]) / (w[0] + w[1]) : 0.0;
  const auto f = physical_aniso::MakeFrame(pp, as);
  e.ux = f.ux;
  e.uy = f.uy;
  e.anisotropy = f.anisotropy;
  return e;
}

void CheckTexturesAgainstPreview(const render::MaterialPreset& p, const render::WeaveMaps& maps,
                                 const std::vector<int>& base_q, const std::array<double, 3>& factor,
                                 const std::vector<int>& aniso_q, double strength, double rotation,
                                 const std::string& what) {
  const int n = maps.size;
  double worst_base = 0.0, worst_dir = 0.0, worst_strength = 0.0;
  physical_aniso::Params<double> tp = physical_aniso::FromFlat(p.values.data());
  tp.anisotropy_strength = strength;
  tp.anisotropy_rotation = rotation;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const Expected e = Preview(p, maps, i, j);
      const size_t t = (size_t(j) * size_t(n) + size_t(i)) * 3;
      for (int c = 0; c < 3; ++c) {
        const int q = base_q[t + size_t(c)];
        const double got = factor[size_t(c)] * Decode(q / 255.0);
        const double want = std::min(e.base[size_t(c)], 1.0);
        const double bound = factor[size_t(c)] * HalfStep(q) + 1e-9;
        EXPECT_LE(std::abs(got - want), bound)
            << what << ": base colour texel (" << i << ", " << j << ") channel " << c;
        worst_base = std::max(worst_base, std::abs(got - want));
      }
      // three.js / KHR decode of the anisotropy texel, then the same frame construction.
      physical_aniso::AnisoSample<double> as;
      as.dx = 2.0 * aniso_q[t] / 255.0 - 1.0;
      as.dy = 2.0 * aniso_q[t + 1] / 255.0 - 1.0;
      as.b = aniso_q[t + 2] / 255.0;
      const auto f = physical_aniso::MakeFrame(tp, as);
      if (e.anisotropy > 0.0) {  // the direction is irrelevant where the strength is 0
        EXPECT_NEAR(f.ux, e.ux, 1e-9) << what << ": direction texel (" << i << ", " << j << ")";
        EXPECT_NEAR(f.uy, e.uy, 1e-9) << what << ": direction texel (" << i << ", " << j << ")";
        worst_dir = std::max(worst_dir, std::hypot(f.ux - e.ux, f.uy - e.uy));
      }
      EXPECT_LE(std::abs(f.anisotropy - e.anisotropy), strength / 510.0 + 1e-12)
          << what << ": strength texel (" << i << ", " << j << ")";
      worst_strength = std::max(worst_strength, std::abs(f.anisotropy - e.anisotropy));
    }
  std::printf("%s: max |error| base colour %.3g (linear), direction %.3g, strength %.3g\n",
              what.c_str(), worst_base, worst_dir, worst_strength);
}

TEST(ConvertWeave, PhysicalAnisoMapsAreBakedIntoGltfAndThreejsTexturesWithinQuantisation) {
  const fs::path d = TempDir("gltf");
  fs::create_directories(d / "in");
  const double repeats = 7.0;
  const render::MaterialPreset p = AnisoPreset(0.6, 0.3);
  WritePresetWithMapsFile(d / "in", "aniso", p, SyntheticMaps(16, repeats, 7));
  // The maps as the preview reads them (renormalised on read, like LoadPresetWeaveMaps).
  const render::WeaveMaps maps = render::ReadWeaveMaps((d / "in" / "aniso.weave.exr").string());
  const ConvertReport r = RunBatch({(d / "in").string()}, d / "out", {"gltf", "threejs"});
  ASSERT_EQ(r.converted, 1) << (r.items.empty() ? "" : r.items[0].reason);

  // ---- glTF ----
  const json g = ReadJsonFile(d / "out" / "aniso.gltf");
  const json& m = g.at("materials").at(0);
  const auto used = g.at("extensionsUsed").get<std::vector<std::string>>();
  EXPECT_NE(std::find(used.begin(), used.end(), "KHR_texture_transform"), used.end());
  const json& pbr = m.at("pbrMetallicRoughness");
  const json& an = m.at("extensions").at("KHR_materials_anisotropy");
  const fs::path base_png = GltfTexture(g, pbr.at("baseColorTexture"), d / "out", repeats);
  const fs::path aniso_png = GltfTexture(g, an.at("anisotropyTexture"), d / "out", repeats);
  std::array<double, 3> factor{};
  for (int c = 0; c < 3; ++c) {
    factor[size_t(c)] = pbr.at("baseColorFactor").at(size_t(c)).get<double>();
    EXPECT_LE(factor[size_t(c)], 1.0);  // glTF's range
  }
  EXPECT_DOUBLE_EQ(pbr.at("baseColorFactor").at(3).get<double>(), 1.0);
  const double strength = an.at("anisotropyStrength").get<double>();
  const double rotation = an.at("anisotropyRotation").get<double>();
  EXPECT_LE(strength, 0.6 + 1e-12);
  const std::vector<int> base_q = Codes(base_png, 16), aniso_q = Codes(aniso_png, 16);
  CheckTexturesAgainstPreview(p, maps, base_q, factor, aniso_q, strength, rotation, "glTF");

  // The colour texture carries an sRGB chunk; the data texture no colour chunk at all.
  const std::string bb = Slurp(base_png), ab = Slurp(aniso_png);
  EXPECT_NE(bb.find("sRGB"), std::string::npos);
  for (const char* chunk : {"sRGB", "gAMA", "iCCP", "cHRM"})
    EXPECT_EQ(ab.find(chunk), std::string::npos) << chunk << " chunk in the anisotropy texture";

  // ---- three.js: same files, same numbers (the factor is an exact 8-bit sRGB value) ----
  const json t = ReadJsonFile(d / "out" / "aniso.three.json");
  EXPECT_DOUBLE_EQ(t.at("anisotropy").get<double>(), strength);
  EXPECT_DOUBLE_EQ(t.at("anisotropyRotation").get<double>(), rotation);
  const render::MaterialPreset tp = ReadThreejsPhysical((d / "out" / "aniso.three.json").string());
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(tp.values[size_t(c)], factor[size_t(c)], 1e-12);
  auto find_texture = [&](const std::string& uuid) {
    for (const json& x : t.at("textures"))
      if (x.at("uuid") == uuid) return x;
    ADD_FAILURE() << "texture " << uuid << " not in textures";
    return json();
  };
  auto image_url = [&](const std::string& uuid) {
    for (const json& x : t.at("images"))
      if (x.at("uuid") == uuid) return x.at("url").get<std::string>();
    ADD_FAILURE() << "image " << uuid << " not in images";
    return std::string();
  };
  const json map = find_texture(t.at("map").get<std::string>());
  const json amap = find_texture(t.at("anisotropyMap").get<std::string>());
  EXPECT_EQ(d / "out" / image_url(map.at("image")), base_png);
  EXPECT_EQ(d / "out" / image_url(amap.at("image")), aniso_png);
  for (const json* x : {&map, &amap}) {
    EXPECT_DOUBLE_EQ(x->at("repeat").at(0).get<double>(), repeats);
    EXPECT_DOUBLE_EQ(x->at("repeat").at(1).get<double>(), repeats);
    EXPECT_EQ(x->at("wrap").at(0).get<int>(), 1000);  // RepeatWrapping
    EXPECT_EQ(x->at("minFilter").get<int>(), 1008);   // LinearMipmapLinearFilter
    EXPECT_FALSE(x->at("flipY").get<bool>());
  }
  EXPECT_EQ(map.at("colorSpace"), "srgb");
  EXPECT_EQ(amap.at("colorSpace"), "");
  std::array<double, 3> tfactor{tp.values[0], tp.values[1], tp.values[2]};
  CheckTexturesAgainstPreview(p, maps, base_q, tfactor, aniso_q, t.at("anisotropy").get<double>(),
                              t.at("anisotropyRotation").get<double>(), "three.js");
  fs::remove_all(d);
}

// The preset's weave_maps.anisotropy (the maps' max anisotropy, session 9) reaches the outputs:
// every three.js texture's "anisotropy" (ObjectLoader sets texture.anisotropy from it) and the
// glTF material's extras (glTF samplers have no such field); a preset without the key gives 1,
// three.js's default. Session 10 (it was written as 1 whatever the preset said).
TEST(ConvertWeave, MapAnisotropyIsCarriedToThreejsTexturesAndGltfExtras) {
  for (const int aniso : {0, 8}) {  // 0: the key absent
    const fs::path d = TempDir("aniso" + std::to_string(aniso));
    fs::create_directories(d / "in");
    const render::WeaveMaps maps = SyntheticMaps(16, 5.0, 3);
    const std::string exr = (d / "in" / "a.weave.exr").string();
    render::WriteWeaveMaps(exr, maps);
    render::MaterialPreset p = AnisoPreset(0.5, 0.0);
    p.extra["weave_maps"] = render::WeaveMapsPresetField(exr, maps);
    if (aniso > 0) p.extra["weave_maps"]["anisotropy"] = aniso;
    render::WritePreset((d / "in" / "a.json").string(), p);
    const ConvertReport r = RunBatch({(d / "in").string()}, d / "out", {"gltf", "threejs"});
    ASSERT_EQ(r.converted, 1) << (r.items.empty() ? "" : r.items[0].reason);
    const int expected = aniso > 0 ? aniso : 1;
    const json t = ReadJsonFile(d / "out" / "a.three.json");
    ASSERT_EQ(t.at("textures").size(), 2u);
    for (const json& x : t.at("textures")) EXPECT_EQ(x.at("anisotropy").get<int>(), expected);
    EXPECT_EQ(t.at("userData").at("clothfit").at("weave_textures").at("max_anisotropy").get<int>(),
              expected);
    const json g = ReadJsonFile(d / "out" / "a.gltf");
    EXPECT_EQ(g.at("materials").at(0).at("extras").at("clothfit_weave_textures")
                  .at("max_anisotropy").get<int>(),
              expected);
    fs::remove_all(d);
  }
}

// A texture that does NOT follow the preview (transposed rows and columns) must fail the same
// comparison: the check is sensitive to the texel convention, not only to value ranges.
TEST(ConvertWeave, TheComparisonDetectsATransposedTexture) {
  const render::MaterialPreset p = AnisoPreset(0.6, 0.3);
  const render::WeaveMaps maps = SyntheticMaps(16, 7.0, 11);
  const WeaveTextures w = BakePhysicalAnisoTextures(p, maps);
  auto transposed = [](const std::vector<unsigned char>& a, int n) {
    std::vector<int> b(a.size());
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c)
          b[(size_t(j) * size_t(n) + size_t(i)) * 3 + size_t(c)] =
              a[(size_t(i) * size_t(n) + size_t(j)) * 3 + size_t(c)];
    return b;
  };
  const std::array<double, 3> f{w.base_factor[0], w.base_factor[1], w.base_factor[2]};
  ::testing::TestPartResultArray failures;
  {
    ::testing::ScopedFakeTestPartResultReporter rep(
        ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD, &failures);
    CheckTexturesAgainstPreview(p, maps, transposed(w.base_color, 16), f,
                                transposed(w.anisotropy, 16), w.anisotropy_strength,
                                w.anisotropy_rotation, "transposed");
  }
  EXPECT_GT(failures.size(), 100) << "a transposed texture passed the texel comparison";
  // And the untransposed bake passes it (the in-memory bytes, before any file).
  std::vector<int> bq(w.base_color.begin(), w.base_color.end());
  std::vector<int> aq(w.anisotropy.begin(), w.anisotropy.end());
  CheckTexturesAgainstPreview(p, maps, bq, f, aq, w.anisotropy_strength, w.anisotropy_rotation,
                              "in memory");
}

TEST(ConvertWeave, BaseColourAboveOneClipsAndIsCounted) {
  render::MaterialPreset p = AnisoPreset(0.6, 0.0);
  p.values[0] = 0.95;  // x a kd ratio up to ~1.5: not expressible with factor, texel <= 1
  const render::WeaveMaps maps = SyntheticMaps(16, 3.0, 5);
  const WeaveTextures w = BakePhysicalAnisoTextures(p, maps);
  EXPECT_DOUBLE_EQ(w.base_factor[0], 1.0);
  EXPECT_GT(w.clipped_texels, 0);
  EXPECT_GT(w.base_max_abs_error, 0.01);  // the clipping is reported, not hidden
  EXPECT_LT(w.base_factor[1], 1.0);       // the other channels keep their exact encoding
}

TEST(ConvertWeave, PngEncoderRoundTripsEveryCodeThroughTheReader) {
  const fs::path d = TempDir("png");
  std::vector<unsigned char> px(16 * 16 * 3);
  for (size_t k = 0; k < px.size(); ++k) px[k] = static_cast<unsigned char>((k * 7) % 256);
  for (int k = 0; k < 256; ++k) px[size_t(k) * 3 % px.size()] = static_cast<unsigned char>(k);
  WritePngFile((d / "x.png").string(), 16, 16, 3, px, false);
  const std::vector<int> q = Codes(d / "x.png", 16);
  for (size_t k = 0; k < px.size(); ++k) ASSERT_EQ(q[k], int(px[k])) << k;
  EXPECT_THROW(io::EncodePng(16, 16, 2, px, false), std::invalid_argument);
  EXPECT_THROW(io::EncodePng(16, 15, 3, px, false), std::invalid_argument);
  fs::remove_all(d);
}

TEST(ConvertWeave, WovenPresetIsRefusedForGltfAndThreejsNamingTheModel) {
  const fs::path d = TempDir("woven");
  fs::create_directories(d / "in");
  WritePresetWithMapsFile(d / "in", "woven", render::DefaultPreset(ModelKind::kWoven),
                          SyntheticMaps(16, 5.0, 3));
  for (const char* target : {"gltf", "threejs"}) {
    const ConvertReport r = RunBatch({(d / "in").string()}, d / ("out_" + std::string(target)),
                                     {target});
    // Refused by design, not failed (session 27): nothing requested can be written.
    EXPECT_EQ(r.failed, 0) << target;
    ASSERT_EQ(r.refused, 1) << target;
    EXPECT_EQ(r.items.at(0).status, "refused");
    ASSERT_EQ(r.items.at(0).refused.size(), 1u);
    EXPECT_EQ(r.items.at(0).refused[0].first, target);
    const std::string& why = r.items.at(0).refused[0].second;
    EXPECT_NE(why.find("woven.json: model: 'woven'"), std::string::npos) << why;
    EXPECT_NE(why.find("no exact glTF or three.js form"), std::string::npos) << why;
    EXPECT_NE(why.find("--to preset-maps carries it exactly"), std::string::npos) << why;
    EXPECT_FALSE(fs::exists(d / ("out_" + std::string(target)) / "woven.gltf"));
  }
  fs::remove_all(d);
}

// Session 27 audit, item 3: `convert <fit folder> --to preset,threejs,gltf,filament,preset-maps`
// failed the whole woven material ("use --to preset-maps", which was requested) and the
// folder's report.json, exit 2. Per target now: the targets that can be written are, the
// refused ones are reported per material and target; clothfit's non-material documents are
// ignored with a note; neither is a failure.
TEST(ConvertWeave, WovenPresetWritesTheTargetsItCanAndReportsTheRefusedOnes) {
  const fs::path d = TempDir("woven_partial");
  fs::create_directories(d / "in");
  WritePresetWithMapsFile(d / "in", "woven", render::DefaultPreset(ModelKind::kWoven),
                          SyntheticMaps(16, 5.0, 3));
  {  // the fit folder's other JSON documents
    std::ofstream(d / "in" / "report.json") << R"({"schema": "clothfit.report", "version": 1})";
    std::ofstream(d / "in" / "convert-log.json")
        << R"({"tool": "clothfit 0.1.0", "targets": ["preset"], "items": []})";
  }
  const ConvertReport r = RunBatch({(d / "in").string()}, d / "out",
                                   {"preset", "threejs", "gltf", "filament", "preset-maps"});
  EXPECT_EQ(r.failed, 0) << SummaryTable(r);
  EXPECT_EQ(r.converted, 1);
  EXPECT_EQ(r.ignored, 2);
  EXPECT_EQ(r.refused_targets, 2);
  const ItemResult* w = nullptr;
  for (const ItemResult& i : r.items) {
    if (i.material == "woven") w = &i;
    if (i.status == "ignored") {
      ASSERT_EQ(i.notes.size(), 1u);
      EXPECT_NE(i.notes[0].find(": not a material: "), std::string::npos) << i.notes[0];
    }
  }
  ASSERT_TRUE(w);
  EXPECT_EQ(w->status, "converted");
  for (const char* f : {"woven.preset.json", "woven.mat", "woven.maps.preset.json",
                        "woven.maps.weave.exr"})
    EXPECT_TRUE(fs::exists(d / "out" / f)) << f;
  for (const char* f : {"woven.gltf", "woven.three.json", "woven.meshcloth.json"})
    EXPECT_FALSE(fs::exists(d / "out" / f)) << f;
  ASSERT_EQ(w->refused.size(), 2u);
  EXPECT_EQ(w->refused[0].first, "threejs");
  EXPECT_EQ(w->refused[1].first, "gltf");
  EXPECT_NE(w->refused[0].second.find("its preset-maps output carries it exactly"),
            std::string::npos)
      << w->refused[0].second;
  const nlohmann::json log = ReportJson(r, ConvertOptions{});
  EXPECT_EQ(log["refused_targets"], 2);
  EXPECT_EQ(log["ignored"], 2);
  bool logged = false;
  for (const auto& i : log["items"])
    if (i["material"] == "woven") logged = i["refused"].contains("gltf") && i["refused"].contains("threejs");
  EXPECT_TRUE(logged);
  const std::string summary = SummaryTable(r);
  EXPECT_NE(summary.find("| refused targets (by design; listed below) | 2 |"), std::string::npos)
      << summary;
  EXPECT_NE(summary.find("| woven | threejs, gltf | "), std::string::npos) << summary;
  EXPECT_NE(summary.find("| ignored (not a material) | 2 |"), std::string::npos) << summary;
  // A second run: up to date, the refusals reported again.
  const ConvertReport again = RunBatch({(d / "in").string()}, d / "out",
                                       {"preset", "threejs", "gltf", "filament", "preset-maps"});
  EXPECT_EQ(again.skipped, 1);
  EXPECT_EQ(again.refused_targets, 2);
  EXPECT_EQ(again.failed, 0);
  fs::remove_all(d);
}

// preset-maps: the source preset and its maps, self-contained; readable by the C++ preview's
// reader (absolute "file") and, after moving the directory, by convert's reader ("uri").
TEST(ConvertWeave, PresetMapsTargetCopiesTheMapsAndSurvivesAMove) {
  const fs::path d = TempDir("preset_maps");
  fs::create_directories(d / "in");
  const render::WeaveMaps maps = SyntheticMaps(16, 5.0, 9);
  WritePresetWithMapsFile(d / "in", "woven", render::DefaultPreset(ModelKind::kWoven), maps);
  const ConvertReport r = RunBatch({(d / "in").string()}, d / "out", {"preset-maps"});
  ASSERT_EQ(r.converted, 1) << (r.items.empty() ? "" : r.items[0].reason);
  const fs::path out = d / "out" / "woven.maps.preset.json";
  ASSERT_TRUE(fs::exists(out));
  ASSERT_TRUE(fs::exists(d / "out" / "woven.maps.weave.exr"));
  const render::MaterialPreset back = render::ReadPreset(out.string());
  EXPECT_EQ(back.model, ModelKind::kWoven);
  EXPECT_EQ(back.values, render::DefaultPreset(ModelKind::kWoven).values);
  EXPECT_EQ(back.extra.at("weave_maps").at("uri"), "woven.maps.weave.exr");
  const auto loaded = render::LoadPresetWeaveMaps(back, out.string());  // "uri" first
  ASSERT_TRUE(loaded);
  const render::WeaveMaps orig = render::ReadWeaveMaps((d / "in" / "woven.weave.exr").string());
  EXPECT_EQ(loaded->levels[0], orig.levels[0]);
  EXPECT_DOUBLE_EQ(loaded->uv_repeats, 5.0);
  // Remove the input and move the output: the relative "uri" still finds the copy.
  fs::remove_all(d / "in");
  fs::rename(d / "out", d / "moved");
  const auto mats = ReadMaterials((d / "moved" / "woven.maps.preset.json").string());
  ASSERT_EQ(mats.size(), 1u);
  ASSERT_TRUE(mats[0].weave_maps);
  EXPECT_EQ(mats[0].weave_maps->levels[0], orig.levels[0]);
  fs::remove_all(d);
}

TEST(ConvertWeave, WeaveMapsOutsideTheInputTreeAreRefused) {
  const fs::path d = TempDir("outside");
  fs::create_directories(d / "in");
  fs::create_directories(d / "elsewhere");
  const render::WeaveMaps maps = SyntheticMaps(16, 5.0, 9);
  const std::string exr = (d / "elsewhere" / "m.weave.exr").string();
  render::WriteWeaveMaps(exr, maps);
  render::MaterialPreset p = AnisoPreset(0.5, 0.0);
  p.extra["weave_maps"] = render::WeaveMapsPresetField(exr, maps);
  render::WritePreset((d / "in" / "p.json").string(), p);
  const ConvertReport r = RunBatch({(d / "in").string()}, d / "out", {"gltf"});
  ASSERT_EQ(r.failed, 1);
  EXPECT_NE(r.items.at(0).reason.find("weave_maps.file"), std::string::npos) << r.items.at(0).reason;
  fs::remove_all(d);
}

// What a GPU's mip chain of the encoded anisotropy texture gives against the preview's mips of
// the warp/weft weights (render/preview/weave_maps.h box mips; direction and strength derived
// after filtering). Printed per level (docs/convert.md quotes the figures); asserted only where
// the two must agree: level 0 (the texel values themselves). With CLOTHFIT_WEAVE_EXR set, the
// maps of that file are measured too (e.g. a fitted canvas preset's <stem>.weave.exr).
void MeasureMipDifference(const render::WeaveMaps& maps, const std::string& what) {
  const render::MaterialPreset p = AnisoPreset(1.0, 0.0);  // strength 1: errors in units of a
  const WeaveTextures w = BakePhysicalAnisoTextures(p, maps);
  constexpr int C = render::WeaveMaps::kChannels;
  std::vector<double> gpu(w.anisotropy.begin(), w.anisotropy.end());  // UNORM codes, averaged
  int side = maps.size;
  for (int level = 0; level < maps.level_count(); ++level) {
    double worst = 0.0, sum2 = 0.0;
    const std::vector<float>& lv = maps.levels[size_t(level)];
    const size_t n = size_t(side) * size_t(side);
    for (size_t t = 0; t < n; ++t) {
      const double wa = double(lv[t * C]), wb = double(lv[t * C + 1]);
      const double sp = wa + wb > 0.0 ? std::abs(wa - wb) / (wa + wb) : 0.0;
      const double px = wa >= wb ? sp : 0.0, py = wa >= wb ? 0.0 : sp;  // preview: s dir
      double dx = 2.0 * gpu[t * 3] / 255.0 - 1.0, dy = 2.0 * gpu[t * 3 + 1] / 255.0 - 1.0;
      const double len = std::hypot(dx, dy);
      const double b = gpu[t * 3 + 2] / 255.0 * w.anisotropy_strength;
      dx = len > 0.0 ? dx / len * b : 0.0;
      dy = len > 0.0 ? dy / len * b : 0.0;
      // the rotation compensation e = atan(1/255): turn the GPU vector by +e
      const double e = w.anisotropy_rotation, gx = std::cos(e) * dx - std::sin(e) * dy,
                   gy = std::sin(e) * dx + std::cos(e) * dy;
      const double d = std::hypot(gx - px, gy - py);
      worst = std::max(worst, d);
      sum2 += d * d;
    }
    std::printf("%s: level %d (%dx%d): anisotropy vector |GPU - preview| max %.4f rms %.4f\n",
                what.c_str(), level, side, side, worst, std::sqrt(sum2 / double(n)));
    if (level == 0) {
      EXPECT_LE(worst, 1.0 / 510.0 + 1e-9) << what;
    }
    if (side == 1) break;
    const int s2 = side / 2;  // the GPU's box mip of the stored values
    std::vector<double> next(size_t(s2) * size_t(s2) * 3);
    for (int j = 0; j < s2; ++j)
      for (int i = 0; i < s2; ++i)
        for (int c = 0; c < 3; ++c) {
          auto at = [&](int ii, int jj) {
            return gpu[(size_t(jj) * size_t(side) + size_t(ii)) * 3 + size_t(c)];
          };
          next[(size_t(j) * size_t(s2) + size_t(i)) * 3 + size_t(c)] =
              0.25 * (at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) +
                      at(2 * i + 1, 2 * j + 1));
        }
    gpu.swap(next);
    side = s2;
  }
}

TEST(ConvertWeave, MipFilteringDifferenceFromThePreviewIsMeasured) {
  MeasureMipDifference(SyntheticMaps(16, 7.0, 7), "synthetic 16x16");
  if (const char* f = std::getenv("CLOTHFIT_WEAVE_EXR"))
    MeasureMipDifference(render::ReadWeaveMaps(f), f);
}

}  // namespace
}  // namespace clothfit::fit
