// tests/test_s19_microcylinder.cpp: the shared microcylinder kernel (brdf/microcylinder.h) and
// woven's "sadeghi-microcylinder" far-field lobe (brdf/yarn_lobe.h, fit/yarn_farfield.h),
// session 19.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "brdf/microcylinder.h"
#include "brdf/yarn_lobe.h"
#include "fit/yarn_farfield.h"
#include "render/reference/fabric.h"
#include "render/reference/sadeghi.h"
#include "render/scene/material.h"
#include "tests/preset_fixtures.h"

namespace clothfit {
namespace {

using json = nlohmann::json;

std::string FabricPath(const std::string& name) {
  return std::string(CLOTHFIT_TEST_SOURCE_DIR) + "/datasets/fabrics/" + name;
}

Vec3<double> RandomUpper(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double z = 0.01 + 0.99 * u(rng), phi = 2.0 * kPi * u(rng);
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// The split is the reference renderer's BSDF: for every published fabric (threads of any
// colour), surface + A_1 volume_1 + A_2 volume_2 (EvalSplit once per thread, the other's
// volume_scale 0) equals SadeghiBsdf::Eval at random direction pairs, to rounding.
TEST(S19Microcylinder, EvalSplitIsTheReferenceBsdf) {
  for (const render::SadeghiFabric& fab : render::SadeghiPresets()) {
    const render::SadeghiBsdf bsdf(fab);
    const microcylinder::Thread only0[2] = {render::MicrocylinderThread(fab.thread[0], 1.0),
                                            render::MicrocylinderThread(fab.thread[1], 0.0)};
    const microcylinder::Thread only1[2] = {render::MicrocylinderThread(fab.thread[0], 0.0),
                                            render::MicrocylinderThread(fab.thread[1], 1.0)};
    const std::vector<microcylinder::Tangent> tangents = microcylinder::MakeTangents(only0);
    std::mt19937_64 rng(19);
    int lit = 0;
    for (int i = 0; i < 4000; ++i) {
      const Vec3<double> wo = RandomUpper(rng), wi = RandomUpper(rng);
      double a[2], b[2];
      microcylinder::EvalSplit(tangents, only0, wo, wi, a);
      microcylinder::EvalSplit(tangents, only1, wo, wi, b);
      EXPECT_EQ(a[0], b[0]);  // the surface term does not depend on volume_scale
      const render::Rgbd f = bsdf.Eval(wo, wi, render::ShadingPoint{});
      for (int c = 0; c < 3; ++c) {
        const double split = a[0] + fab.thread[0].albedo[c] * a[1] + fab.thread[1].albedo[c] * b[1];
        ASSERT_NEAR(split, f[c], 1e-12 * std::max(1.0, std::abs(f[c]))) << fab.name << " pair " << i;
      }
      lit += f[1] > 0.0;
    }
    EXPECT_GT(lit, 1000) << fab.name;  // the pairs are not all masked
  }
}

// Both directions must be above the surface; the value is finite at grazing angles.
TEST(S19Microcylinder, BelowTheSurfaceIsZeroAndGrazingIsFinite) {
  const render::SadeghiFabric& fab = render::SadeghiPreset("velvet");
  const microcylinder::Thread th[2] = {render::MicrocylinderThread(fab.thread[0]),
                                       render::MicrocylinderThread(fab.thread[1])};
  const auto tangents = microcylinder::MakeTangents(th);
  double out[2];
  microcylinder::EvalSplit(tangents, th, {0, 0.6, -0.8}, {0, 0, 1}, out);
  EXPECT_EQ(out[0], 0.0);
  EXPECT_EQ(out[1], 0.0);
  microcylinder::EvalSplit(tangents, th, {0, 0, 1}, {0.6, 0, -0.8}, out);
  EXPECT_EQ(out[0], 0.0);
  EXPECT_EQ(out[1], 0.0);
  for (double z : {1e-9, 1e-6, 1e-3}) {
    const double r = std::sqrt(1.0 - z * z);
    for (const auto& [wo, wi] : {std::pair<Vec3<double>, Vec3<double>>{{r, 0, z}, {-r, 0, z}},
                                 {{0, r, z}, {0, -r, z}},
                                 {{r, 0, z}, {r, 0, z}},
                                 {{0, 0, 1}, {0, r, z}}}) {
      microcylinder::EvalSplit(tangents, th, wo, wi, out);
      EXPECT_TRUE(std::isfinite(out[0]) && std::isfinite(out[1])) << z;
      EXPECT_GE(out[0], 0.0);
      EXPECT_GE(out[1], 0.0);
    }
  }
}

// The lobe of a dataset fabric (MicrocylinderDescription) is its BSDF: out[0] + albedo out[1]
// = SadeghiBsdf::Eval, including satin, whose two threads differ in strength only (the
// weaker's volume_scale carries the ratio).
TEST(S19Microcylinder, DatasetLobeIsTheFabricBsdf) {
  for (const char* name : {"velvet.json", "linen.json", "satin.json"}) {
    const fit::MicrocylinderLobe m = fit::MicrocylinderDescription(FabricPath(name), 8);
    ASSERT_EQ(m.lobe.kind, yarn_lobe::FarField::Kind::kMicrocylinder);
    EXPECT_NO_THROW(yarn_lobe::Validate(m.lobe, name));
    const yarn_lobe::Lobe lobe(m.lobe);
    const render::Fabric fabric = render::LoadFabric(FabricPath(name));
    std::mt19937_64 rng(7);
    for (int i = 0; i < 2000; ++i) {
      const Vec3<double> wo = RandomUpper(rng), wi = RandomUpper(rng);
      double v[2];
      lobe.Eval(wo, wi, v);
      const render::Rgbd f = fabric.bsdf->Eval(wo, wi, render::ShadingPoint{});
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(v[0] + m.albedo[c] * v[1], f[c], 1e-9 * std::max(1.0, std::abs(f[c])))
            << name << " pair " << i << " channel " << c;
    }
  }
  const fit::MicrocylinderLobe satin = fit::MicrocylinderDescription(FabricPath("satin.json"), 8);
  const double s0 = satin.lobe.threads[0].volume_scale, s1 = satin.lobe.threads[1].volume_scale;
  EXPECT_EQ(std::max(s0, s1), 1.0);
  EXPECT_LT(std::min(s0, s1), 1.0);
  EXPECT_GT(std::min(s0, s1), 0.0);
}

// Lobe::Eval keeps the wo-only work per thread between calls: interleaving two lobes (and a copy)
// at one wo and many wi gives each lobe's own values (EvalSplit on its unmerged tangents).
TEST(S19Microcylinder, EvalCacheFollowsTheLobeAndWo) {
  const fit::MicrocylinderLobe a = fit::MicrocylinderDescription(FabricPath("velvet.json"), 2);
  const fit::MicrocylinderLobe b = fit::MicrocylinderDescription(FabricPath("satin.json"), 2);
  const yarn_lobe::Lobe la(a.lobe), lb(b.lobe);
  const yarn_lobe::Lobe la_copy = la;
  const auto ta = microcylinder::MakeTangents(a.lobe.threads), tb = microcylinder::MakeTangents(b.lobe.threads);
  std::mt19937_64 rng(11);
  for (int i = 0; i < 300; ++i) {
    const Vec3<double> wo = i % 3 == 0 ? RandomUpper(rng) : Vec3<double>(0.0, 0.6, 0.8);
    const Vec3<double> wi = RandomUpper(rng);
    double x[2], y[2], z[2], ex[2], ey[2];
    la.Eval(wo, wi, x);
    lb.Eval(wo, wi, y);
    la_copy.Eval(wo, wi, z);
    microcylinder::EvalSplit(ta, a.lobe.threads, wo, wi, ex);
    microcylinder::EvalSplit(tb, b.lobe.threads, wo, wi, ey);
    for (int k = 0; k < 2; ++k) {
      ASSERT_NEAR(x[k], ex[k], 1e-12 * std::max(1.0, ex[k])) << i;
      ASSERT_NEAR(y[k], ey[k], 1e-12 * std::max(1.0, ey[k])) << i;
      ASSERT_EQ(x[k], z[k]) << i;
    }
  }
}

// A fabric whose threads differ in hue has no one volume colour: refused, naming the file;
// a non-sadeghi fabric is refused too.
TEST(S19Microcylinder, DescriptionRefusesWhatItCannotCarry) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "clothfit_s19";
  std::filesystem::create_directories(dir);
  const std::string shot = (dir / "shot.json").string();
  std::ofstream(shot) << R"({"format": "clothfit-fabric", "version": 1, "name": "shot",
    "model": "sadeghi", "preset": "silk_shot", "uv_repeats": 80})";
  try {
    fit::MicrocylinderDescription(shot, 4);
    ADD_FAILURE() << "silk_shot accepted";
  } catch (const std::invalid_argument& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(shot), std::string::npos) << m;
    EXPECT_NE(m.find("hue"), std::string::npos) << m;
  }
  EXPECT_THROW(fit::MicrocylinderDescription(FabricPath("canvas.json"), 4), std::invalid_argument);
}

// The preset carries the lobe exactly: PresetToJson -> ParsePreset gives the same values and
// summary; each bad field is named with the file.
TEST(S19Microcylinder, PresetRoundTripAndBadFields) {
  render::MaterialPreset p = render::DefaultPreset(render::ModelKind::kWoven);
  p.woven.ibl = ::clothfit::woven::IblMode::kSplit;
  p.yarn_lobe = std::make_shared<const yarn_lobe::FarField>(
      fit::MicrocylinderDescription(FabricPath("satin.json"), 4).lobe);
  const json good = render::PresetToJson(p);
  const json& y = good["woven"]["yarn_lobe"];
  EXPECT_EQ(y["model"], "sadeghi-microcylinder");
  ASSERT_EQ(y["threads"].size(), 2u);
  EXPECT_EQ(y["threads"][0].size(), 7u);
  const render::MaterialPreset q = render::ParsePreset(json::parse(good.dump()), "p.json");
  ASSERT_TRUE(q.yarn_lobe);
  EXPECT_EQ(q.yarn_lobe->kind, yarn_lobe::FarField::Kind::kMicrocylinder);
  EXPECT_EQ(q.yarn_lobe->ibl.ibl, p.yarn_lobe->ibl.ibl);
  const yarn_lobe::Lobe a(*p.yarn_lobe), b(*q.yarn_lobe);
  std::mt19937_64 rng(3);
  for (int i = 0; i < 200; ++i) {
    const Vec3<double> wo = RandomUpper(rng), wi = RandomUpper(rng);
    double x[2], z[2];
    a.Eval(wo, wi, x);
    b.Eval(wo, wi, z);
    EXPECT_EQ(x[0], z[0]);
    EXPECT_EQ(x[1], z[1]);
  }
  const std::vector<testing::BadLobeField> cases = {
      {"eta 3", [](json& j) { j["threads"][0]["eta"] = 3.0; }, "woven.yarn_lobe.threads[0].eta"},
      {"eta string", [](json& j) { j["threads"][1]["eta"] = "1.5"; }, "woven.yarn_lobe.threads[1].eta"},
      {"kd -1", [](json& j) { j["threads"][1]["kd"] = -1.0; }, "woven.yarn_lobe.threads[1].kd"},
      {"gamma_s 0", [](json& j) { j["threads"][0]["gamma_s"] = 0.0; }, "woven.yarn_lobe.threads[0].gamma_s"},
      {"gamma_v 91", [](json& j) { j["threads"][1]["gamma_v"] = 91.0; }, "woven.yarn_lobe.threads[1].gamma_v"},
      {"a sum", [](json& j) { j["threads"][0]["a"] = 0.9; j["threads"][1]["a"] = 0.9; }, "woven.yarn_lobe.threads"},
      {"volume_scale 2", [](json& j) { j["threads"][0]["volume_scale"] = 2.0; }, "woven.yarn_lobe.threads[0].volume_scale"},
      {"no offsets", [](json& j) { j["threads"][1]["offsets"] = json::array(); }, "woven.yarn_lobe.threads[1].offsets"},
      {"offset 100", [](json& j) { j["threads"][0]["offsets"] = {0.0, 100.0}; }, "woven.yarn_lobe.threads[0].offsets[1]"},
      {"65 offsets", [](json& j) { j["threads"][0]["offsets"] = std::vector<double>(65, 1.0); }, "woven.yarn_lobe.threads[0].offsets"},
      {"missing key", [](json& j) { j["threads"][0].erase("kd"); }, "woven.yarn_lobe.threads[0]"},
      {"extra thread key", [](json& j) { j["threads"][1]["colour"] = 1; }, "woven.yarn_lobe.threads[1]"},
      {"3 threads", [](json& j) { j["threads"].push_back(j["threads"][0]); }, "woven.yarn_lobe.threads"},
      {"unknown key", [](json& j) { j["nodes"] = 4; }, "woven.yarn_lobe.nodes"},
      {"model", [](json& j) { j["model"] = "sadeghi"; }, "woven.yarn_lobe.model"},
      {"summary short", [](json& j) { j["ibl"]["summary"].erase(0); }, "woven.yarn_lobe.ibl.summary"},
  };
  testing::ExpectBadLobeFieldsNamed(good, cases);
}

// Bake's finer wi grid: wi_sub = 1 is the bin-centre midpoint rule; for satin's 2.5-degree
// surface lobe the description's wi_sub brings the summary's albedo near a much finer
// integral (16x), where the bin centres alone miss it.
TEST(S19Microcylinder, FinerWiGridForNarrowLobes) {
  const fit::MicrocylinderLobe m = fit::MicrocylinderDescription(FabricPath("satin.json"), 4);
  EXPECT_GT(m.wi_sub, 1);
  const yarn_lobe::Lobe lobe(m.lobe);
  auto eval = [&lobe](const Vec3<double>& wo, const Vec3<double>& wi, double v[2]) { lobe.Eval(wo, wi, v); };
  const yarn_table::Table one = yarn_lobe::Bake(eval, 4, 8, false, 1);
  const yarn_table::Table def = yarn_lobe::Bake(eval, 4, 8, false);
  EXPECT_EQ(one.ibl, def.ibl);
  const yarn_table::Table fine = yarn_lobe::Bake(eval, 4, 8, false, 16);
  EXPECT_EQ(m.lobe.ibl.n_theta, 4);
  const size_t D = 4 * 8;
  double err_sub = 0.0, err_one = 0.0;
  for (size_t o = 0; o < D; ++o) {  // the surface lobe's albedo (k = 0) per wo bin
    const double a_fine = double(fine.ibl[o * 5]), a_sub = double(m.lobe.ibl.ibl[o * 5]),
                 a_one = double(one.ibl[o * 5]);
    err_sub = std::max(err_sub, std::abs(a_sub - a_fine) / std::max(a_fine, 1e-3));
    err_one = std::max(err_one, std::abs(a_one - a_fine) / std::max(a_fine, 1e-3));
  }
  std::printf("satin surface albedo, worst relative error vs wi_sub 16: wi_sub %d %.4f, wi_sub 1 %.4f\n",
              m.wi_sub, err_sub, err_one);
  EXPECT_LT(err_sub, 0.05);
  EXPECT_LT(err_sub, 0.5 * err_one);
}

// web/test/microcylinder-reference.json (tests/browser/unit.mjs compares the JS port and the
// generated GLSL with it) is what the C++ kernel computes today: every pair recomputed.
TEST(S19Microcylinder, WebFixtureIsTheKernel) {
  std::ifstream in(std::string(CLOTHFIT_TEST_SOURCE_DIR) + "/web/test/microcylinder-reference.json");
  ASSERT_TRUE(in.good());
  const json j = json::parse(in);
  size_t pairs = 0;
  for (const auto& [name, fab] : j.at("fabrics").items()) {
    microcylinder::Thread th[2];
    for (int k = 0; k < 2; ++k) {
      const json& t = fab.at("threads").at(size_t(k));
      th[k].eta = t.at("eta");
      th[k].kd = t.at("kd");
      th[k].gamma_s = t.at("gamma_s");
      th[k].gamma_v = t.at("gamma_v");
      th[k].a = t.at("a");
      th[k].volume_scale = t.at("volume_scale");
      th[k].offsets = t.at("offsets").get<std::vector<double>>();
    }
    const auto tangents = microcylinder::MakeTangents(th);
    for (const json& p : fab.at("pairs")) {
      const auto v = [](const json& a) { return Vec3<double>(a.at(0), a.at(1), a.at(2)); };
      double out[2];
      microcylinder::EvalSplit(tangents, th, v(p.at("wo")), v(p.at("wi")), out);
      for (int k = 0; k < 2; ++k) {
        const double want = p.at("out").at(size_t(k));
        ASSERT_NEAR(out[k], want, 1e-12 * std::max(1.0, std::abs(want))) << name << " " << p.dump();
      }
      ++pairs;
    }
  }
  EXPECT_GT(pairs, 600u);
}

}  // namespace
}  // namespace clothfit
