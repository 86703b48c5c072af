// tests/test_woven.cpp: woven-cloth BSDFs (Irawan-Marschner, Sadeghi), weave patterns,
// fabric files, and the chi^2 test machinery (tests/chi2.h). Figures are printed to stdout
// so docs/woven-cloth.md can quote them.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/reference/sadeghi.h"
#include "render/scene/sampler.h"
#include "render/reference/weave_pattern.h"
#include "tests/chi2.h"

namespace clothfit::render {
namespace {

const std::filesystem::path kDatasets =
    std::filesystem::path(__FILE__).parent_path().parent_path() / "datasets";

const std::vector<std::string> kWeaves = {"polyester",    "silk_shantung",  "cotton_denim",
                                          "cotton_twill", "wool_gabardine", "silk_charmeuse",
                                          "cotton_canvas"};

const std::vector<std::string> kChi2Weaves = {"polyester", "cotton_denim", "cotton_canvas",
                                              "silk_charmeuse"};

Vec3d SampleUniformHemisphereForTest(Pcg32& rng) {
  const double z = rng.Uniform(), phi = 2.0 * kPi * rng.Uniform();
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(phi), r * std::sin(phi), z};
}

std::string WeavePath(const std::string& stem) {
  return (kDatasets / "weaves" / (stem + ".weave")).string();
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return s;
}

Vec3d Dir(double theta_deg, double phi_deg) {
  const double t = theta_deg * kPi / 180.0, p = phi_deg * kPi / 180.0;
  return {std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

// A warp and a weft point of the tile (first cell of each type, 0.3/0.6 into it), in uv with
// repeat 1, found through the pattern so the tests follow the pattern's layout.
std::vector<Point2d> TestPoints(const IrawanBsdf& b) {
  std::vector<Point2d> pts;
  for (YarnType want : {YarnType::kWarp, YarnType::kWeft}) {
    for (int i = 0; i < 64; ++i) {
      const Point2d uv{(i % 8 + 0.37) / (8.0 * b.repeat_u()),
                       (i / 8 + 0.61) / (8.0 * b.repeat_v())};
      if (b.pattern().yarns[size_t(b.Locate(uv).yarn)].type == want) {
        pts.push_back(uv);
        break;
      }
    }
  }
  return pts;
}

// ---------------------------------------------------------------- weave patterns

TEST(WovenPattern, DerivedCentresReproducePublishedPolyesterCentres) {
  const WeavePattern p = LoadWeave(WeavePath("polyester"));
  ASSERT_EQ(p.yarns.size(), 4u);
  // Published: warp (0.25, 0.25), (0.75, 0.75); weft (0.25, 0.75), (0.75, 0.25).
  const double expect[4][2] = {{0.25, 0.25}, {0.75, 0.75}, {0.25, 0.75}, {0.75, 0.25}};
  for (int i = 0; i < 4; ++i) {
    EXPECT_DOUBLE_EQ(p.yarns[size_t(i)].center_u, expect[i][0]) << "yarn " << i + 1;
    EXPECT_DOUBLE_EQ(p.yarns[size_t(i)].center_v, expect[i][1]) << "yarn " << i + 1;
  }
}

TEST(WovenPattern, DerivedCentresAreTheCentresOfEachIdsCells) {
  // Independent derivation: mean of the cell centres of each id (Y up, row 0 on top).
  for (const std::string& stem : kWeaves) {
    const WeavePattern p = LoadWeave(WeavePath(stem));
    const int W = p.tile_width, H = p.tile_height;
    for (size_t i = 0; i < p.yarns.size(); ++i) {
      double sx = 0, sy = 0;
      int n = 0;
      for (int r = 0; r < H; ++r) {
        for (int c = 0; c < W; ++c) {
          if (p.IdAt(c, r) == int(i) + 1) {
            sx += c + 0.5;
            sy += (H - 1 - r) + 0.5;
            ++n;
          }
        }
      }
      ASSERT_GT(n, 0);
      EXPECT_NEAR(p.yarns[i].center_u, sx / n / W, 1e-12) << stem << " yarn " << i + 1;
      EXPECT_NEAR(p.yarns[i].center_v, sy / n / H, 1e-12) << stem << " yarn " << i + 1;
    }
  }
  // Two hand-checked values: denim id 5 is column 2, rows 1-5 (Y in [0, 5)).
  const WeavePattern d = LoadWeave(WeavePath("cotton_denim"));
  EXPECT_DOUBLE_EQ(d.yarns[4].center_u, 2.5 / 3.0);
  EXPECT_DOUBLE_EQ(d.yarns[4].center_v, 2.5 / 6.0);
  // Shantung weft id 3: columns 0-3, rows 0-3 (Y in [4, 8)).
  const WeavePattern s = LoadWeave(WeavePath("silk_shantung"));
  EXPECT_DOUBLE_EQ(s.yarns[2].center_u, 2.0 / 6.0);
  EXPECT_DOUBLE_EQ(s.yarns[2].center_v, 6.0 / 8.0);
}

TEST(WovenPattern, SegmentExtentsMatchYarnGeometry) {
  // Across the yarn every segment spans exactly its width (so |v| <= pi/2), along it at most
  // its length: a check that the presets' warp/weft assignment follows the draft.
  for (const std::string& stem : kWeaves) {
    WeavePattern p = LoadWeave(WeavePath(stem));
    const auto cells = DeriveSegmentCentres(&p, stem);
    for (size_t i = 0; i < p.yarns.size(); ++i) {
      const int nx = cells[i].col1 - cells[i].col0 + 1, ny = cells[i].row1 - cells[i].row0 + 1;
      const bool warp = p.yarns[i].type == YarnType::kWarp;
      EXPECT_DOUBLE_EQ(warp ? nx : ny, p.yarns[i].width) << stem << " yarn " << i + 1;
      EXPECT_LE(warp ? ny : nx, p.yarns[i].length) << stem << " yarn " << i + 1;
    }
  }
}

TEST(WovenPattern, EveryPresetRoundTrips) {
  for (const std::string& stem : kWeaves) {
    const WeavePattern p = LoadWeave(WeavePath(stem));
    const std::string text = WriteWeave(p);
    const WeavePattern q = ParseWeave(text, stem + " (written)");
    EXPECT_TRUE(p == q) << stem;
    EXPECT_EQ(WriteWeave(q), text) << stem;
  }
}

void ExpectWeaveError(const std::string& text, const std::string& where, const std::string& what) {
  try {
    ParseWeave(text, "bad.weave");
    ADD_FAILURE() << "no error; expected " << where << ": ..." << what;
  } catch (const WeavePatternError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(where + ":", 0), 0u) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
}

TEST(WovenPattern, MalformedFilesGiveFileAndLine) {
  const std::string good = ReadText(WeavePath("polyester"));
  // Line numbers in polyester.weave: 1-2 comments, 3 header, 4 name, 5 alpha, ..., 16 period,
  // 17 tile, 18 pattern, 19-20 rows, 21-24 yarns.
  auto replace_line = [&](int line, const std::string& with) {
    std::string out;
    int n = 1;
    size_t start = 0;
    while (start < good.size()) {
      size_t end = good.find('\n', start);
      if (end == std::string::npos) end = good.size();
      out += (n == line ? with : good.substr(start, end - start)) + "\n";
      start = end + 1;
      ++n;
    }
    return out;
  };
  ASSERT_EQ(replace_line(5, "alpha 0.015"), good);
  ExpectWeaveError(replace_line(3, "clothfit-weave 2"), "bad.weave:3", "header");
  ExpectWeaveError(replace_line(5, "alpha zero"), "bad.weave:5", "alpha");
  ExpectWeaveError(replace_line(7, "ss 1"), "bad.weave:7", "0 <= ss < 1");
  ExpectWeaveError(replace_line(6, "alpha 0.1"), "bad.weave:6", "duplicate 'alpha'");
  ExpectWeaveError(replace_line(6, "gamma 4"), "bad.weave:6", "unknown keyword 'gamma'");
  ExpectWeaveError(replace_line(19, "3 2 1"), "bad.weave:19", "3 ids; expected 2");
  ExpectWeaveError(replace_line(20, "1 5"), "bad.weave:18", "not in [1, 4]");
  ExpectWeaveError(replace_line(20, "1 1"), "bad.weave:18", "yarn id 4 is unused");
  ExpectWeaveError(replace_line(20, "1 x"), "bad.weave:20", "yarn id");
  ExpectWeaveError(
      replace_line(21, "yarn 1 warp psi 0 umax 22 kappa -1.5 width 1 length 1 kd 0 0 0 ks 0 0 0"),
      "bad.weave:21", "kappa must be >= -1");
  ExpectWeaveError(
      replace_line(21, "yarn 1 warp psi 0 umax 80 kappa 0 width 2 length 1 kd 0 0 0 ks 0 0 0"),
      "bad.weave:21", "w sin(umax) must be < l");
  ExpectWeaveError(
      replace_line(21, "yarn 1 warp psi 0 umax 22 kappa 0 width 1 length 1 kd 0 0 ks 0 0 0"),
      "bad.weave:21", "kd");
  ExpectWeaveError(
      replace_line(21, "yarn 1 wrap psi 0 umax 22 kappa 0 width 1 length 1 kd 0 0 0 ks 0 0 0"),
      "bad.weave:21", "'warp' or 'weft'");
  ExpectWeaveError(replace_line(21, "yarn 1 warp psi 0 umax 22"), "bad.weave:21", "missing");
  ExpectWeaveError(
      replace_line(21,
                   "yarn 1 warp psi 0 umax 22 kappa 0 width 1 length 1 kd 0 0 0 ks 0 0 0 "
                   "center 0.5 0.5"),
      "bad.weave:21", "disagrees with the centre derived");
  ExpectWeaveError(replace_line(24, ""), "bad.weave:18", "not in [1, 3]");  // id 4: no yarn
  ExpectWeaveError(
      replace_line(22, "yarn 1 warp psi 0 umax 22 kappa 0 width 1 length 1 kd 0 0 0 ks 0 0 0"),
      "bad.weave:22", "duplicate yarn 1");
  ExpectWeaveError(
      "clothfit-weave 1\nalpha 0.01\nbeta 1\nss 0\nhWidth 0.5\nwarpArea 1\nweftArea 1\n"
      "tile 3 1\npattern\n1 2 1\n"
      "yarn 1 warp psi 0 umax 20 kappa 0 width 1 length 1 kd 0 0 0 ks 0 0 0\n"
      "yarn 2 weft psi 0 umax 20 kappa 0 width 1 length 1 kd 0 0 0 ks 0 0 0\n",
      "bad.weave:9", "do not form one rectangle");
  ExpectWeaveError(good.substr(0, good.find("pattern") + 12), "bad.weave:20", "pattern ends");
  ExpectWeaveError("", "bad.weave:1", "header");
  // Session 28: a pattern shorter or longer than its tile says. Before, the yarn line after a
  // missing row was "a pattern row with 17 ids", and an extra row "unknown keyword '4'".
  ExpectWeaveError(
      replace_line(20, ""), "bad.weave:21",
      "pattern has 1 rows, but 'tile 2 2' (line 17) declares 2; this line starts 'yarn'");
  ExpectWeaveError(replace_line(17, "tile 2 1"), "bad.weave:20",
                   "a pattern row after the 1 rows that 'tile 2 1' (line 17) declares");
}

// ---------------------------------------------------------------- Irawan model pieces

TEST(WovenIrawan, SpineRadiusMatchesNumericCurvature) {
  // For each conic the radius at inclination u equals 1/|curvature| of the spine, measured
  // numerically from the spine's height profile z(x) built independently: slope(x) = tan u.
  for (double kappa : {0.0, 0.4, -0.3, -0.7, 2.0}) {
    const double umax = 30.0 * kPi / 180.0, w = 1.0, l = 3.0;
    const double hx = 0.5 * l - 0.5 * w * std::sin(umax);
    // u(x) along the spine by integrating dx/du = R(u) cos(u) from 0 to umax: its end must be hx.
    const int n = 20000;
    double x = 0.0;
    for (int i = 0; i < n; ++i) {
      const double u = (i + 0.5) * umax / n;
      x += SpineRadius(u, umax, kappa, w, l) * std::cos(u) * umax / n;
    }
    EXPECT_NEAR(x, hx, 1e-6 * hx) << "kappa " << kappa;
  }
  // The three branches meet continuously at rhat = 0 and rhat = 1.
  const double umax = 30.0 * kPi / 180.0;
  const double k0 = -1.0 / (1.0 + 1.0 / std::tan(umax));  // rhat = 0
  for (double u : {0.0, 0.2, 0.5}) {
    EXPECT_NEAR(SpineRadius(u, umax, k0 + 1e-7, 1, 3), SpineRadius(u, umax, k0 - 1e-7, 1, 3), 1e-4);
    EXPECT_NEAR(SpineRadius(u, umax, 1e-8, 1, 3), SpineRadius(u, umax, 0.0, 1, 3), 1e-5);
  }
}

TEST(WovenIrawan, WarpRunsAlongUAndWeftAlongV) {
  const IrawanBsdf b(LoadWeave(WeavePath("cotton_denim")), 1.0, 1.0);
  const auto pts = TestPoints(b);
  ASSERT_EQ(pts.size(), 2u);
  const double eps = 1e-4;
  for (const Point2d& uv : pts) {
    const IrawanPoint p = b.Locate(uv);
    const bool warp = b.pattern().yarns[size_t(p.yarn)].type == YarnType::kWarp;
    const IrawanPoint pu = b.Locate({uv.x + eps, uv.y}), pv = b.Locate({uv.x, uv.y + eps});
    // Moving along u moves along a warp yarn (cells along u: tile_height per repeat).
    if (warp) {
      EXPECT_NEAR(pu.along - p.along, eps * b.pattern().tile_height, 1e-9);
      EXPECT_NEAR(pv.along - p.along, 0.0, 1e-9);
    } else {
      EXPECT_NEAR(pv.along - p.along, -eps * b.pattern().tile_width, 1e-9);
      EXPECT_NEAR(pu.along - p.along, 0.0, 1e-9);
    }
  }
  // And the fibres: the yarn frame's y axis (the yarn direction) is the shading x axis for
  // warp and the shading y axis (up to sign) for weft.
  const Vec3d warp_dir = FromYarnFrame({0, 1, 0}, YarnType::kWarp);
  const Vec3d weft_dir = FromYarnFrame({0, 1, 0}, YarnType::kWeft);
  EXPECT_NEAR(std::abs(warp_dir.x), 1.0, 1e-15);
  EXPECT_NEAR(std::abs(weft_dir.y), 1.0, 1e-15);
}

TEST(WovenIrawan, SpecularNormalisationGivesUnitBihemisphericalAlbedo) {
  // Independent estimate (other seed, 400 000 draws) of pi * E[spec * specNorm] under
  // cosine-distributed wi, wo over the tile: the documented normalisation makes it 1.
  for (const std::string& stem : kChi2Weaves) {
    const IrawanBsdf b(LoadWeave(WeavePath(stem)), 1.0, 1.0);
    Pcg32 rng(99, 7);
    const int n = 400000;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
      const Point2d uv{16.0 * rng.Uniform(), 16.0 * rng.Uniform()};
      const Vec3d wi = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
      const Vec3d wo = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
      sum += b.SpecularIntegrand(b.Locate(uv), wo, wi) * b.specular_normalisation();
    }
    const double albedo = kPi * sum / n;
    std::printf("[woven] %s: specNorm %.6g, independent bi-hemispherical spec albedo %.4f\n",
                stem.c_str(), b.specular_normalisation(), albedo);
    EXPECT_NEAR(albedo, 1.0, 0.1) << stem;
  }
}

// ---------------------------------------------------------------- all models

struct Model {
  std::string name;
  std::shared_ptr<Bsdf> bsdf;
  std::vector<Point2d> uvs;
};

std::vector<Model> AllModels() {
  std::vector<Model> m;
  for (const std::string& stem : kWeaves) {
    auto b = std::make_shared<IrawanBsdf>(LoadWeave(WeavePath(stem)), 1.0, 1.0);
    m.push_back({"irawan:" + stem, b, TestPoints(*b)});
  }
  for (const SadeghiFabric& f : SadeghiPresets()) {
    m.push_back({"sadeghi:" + f.name, std::make_shared<SadeghiBsdf>(f), {{0.3, 0.7}}});
  }
  return m;
}

TEST(WovenBsdf, SampleAgreesWithEvalAndPdf) {
  Pcg32 rng(5, 5);
  for (const Model& m : AllModels()) {
    int checked = 0;
    for (int i = 0; i < 4000; ++i) {
      const Vec3d wo = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
      const ShadingPoint sp{m.uvs[size_t(i) % m.uvs.size()]};
      BsdfSample s;
      if (!m.bsdf->Sample(wo, {rng.Uniform(), rng.Uniform()}, rng.Uniform(), sp, &s)) continue;
      ++checked;
      const Rgbd f = m.bsdf->Eval(wo, s.wi, sp);
      const double pdf = m.bsdf->Pdf(wo, s.wi, sp);
      ASSERT_NEAR(s.pdf, pdf, 1e-9 * pdf) << m.name;
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(s.f[c], f[c], 1e-9 * std::abs(f[c]) + 1e-300) << m.name;
    }
    EXPECT_GT(checked, 3000) << m.name;
  }
}

TEST(WovenBsdf, EdgeCosinesGiveFiniteNonNegativeValues) {
  const double cosines[] = {0.0, 1e-8, 1e-4, 0.5, 1.0 - 1e-7, 1.0, 1.0 + 1e-7};
  for (const Model& m : AllModels()) {
    for (double co : cosines) {
      for (double ci : cosines) {
        for (double phi : {0.0, 0.7, 2.0, 3.1}) {
          const double so = std::sqrt(std::max(0.0, 1.0 - co * co));
          const double si = std::sqrt(std::max(0.0, 1.0 - ci * ci));
          const Vec3d wo(so, 0.0, co), wi(si * std::cos(phi), si * std::sin(phi), ci);
          for (const Point2d& uv : m.uvs) {
            const Rgbd f = m.bsdf->Eval(wo, wi, {uv});
            const double p = m.bsdf->Pdf(wo, wi, {uv});
            for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(f[c]) && f[c] >= 0.0) << m.name;
            ASSERT_TRUE(std::isfinite(p) && p >= 0.0) << m.name;
          }
        }
      }
    }
  }
}

TEST(WovenBsdf, IrawanIsReciprocal) {
  // Every Irawan term is symmetric in wi <-> wo (h, |wi + wo|, wi.wo, Seeliger) and specNorm is
  // a constant, so the BSDF as implemented is reciprocal (Mitsuba's returns f cos(theta_o),
  // which is not; we return f).
  Pcg32 rng(11, 3);
  for (const std::string& stem : kWeaves) {
    const IrawanBsdf b(LoadWeave(WeavePath(stem)), 1.0, 1.0);
    for (int i = 0; i < 2000; ++i) {
      const Vec3d wo = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
      const Vec3d wi = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
      const ShadingPoint sp{{rng.Uniform(), rng.Uniform()}};
      const Rgbd a = b.Eval(wo, wi, sp), c = b.Eval(wi, wo, sp);
      for (int k = 0; k < 3; ++k) ASSERT_NEAR(a[k], c[k], 1e-12 * (1.0 + a[k])) << stem;
    }
  }
}

TEST(WovenBsdf, SadeghiAsymmetryIsTheDocumentedOne) {
  // One untilted thread (a_2 = 0): Q(wo) = wo.z = P(wo), so f(wo, wi) = a f_s M cos(theta_i) /
  // wi.z with a symmetric fibre kernel f_s M: f(wo, wi) / f(wi, wo) = (cos theta_i / wi.z) /
  // (cos theta_o / wo.z), theta = longitudinal angle to the thread (x axis).
  SadeghiFabric f = SadeghiPreset("linen_plain");
  f.thread[0].offsets = {0.0};
  f.thread[1].a = 0.0;
  const SadeghiBsdf b(f);
  Pcg32 rng(4, 4);
  for (int i = 0; i < 2000; ++i) {
    const Vec3d wo = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
    const Vec3d wi = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
    const double a = b.Eval(wo, wi, {}).g, c = b.Eval(wi, wo, {}).g;
    if (a <= 1e-12 || c <= 1e-12) continue;
    const double ci = std::sqrt(1.0 - wi.x * wi.x), co = std::sqrt(1.0 - wo.x * wo.x);
    ASSERT_NEAR(a / c, (ci / wi.z) / (co / wo.z), 1e-9 * (a / c));
  }
  // The published (tilted) fabrics are not reciprocal: report how much.
  for (const SadeghiFabric& pf : SadeghiPresets()) {
    const SadeghiBsdf pb(pf);
    double worst = 0.0;
    Pcg32 r2(8, 8);
    for (int i = 0; i < 2000; ++i) {
      const Vec3d wo = SampleCosineHemisphere({r2.Uniform(), r2.Uniform()});
      const Vec3d wi = SampleCosineHemisphere({r2.Uniform(), r2.Uniform()});
      const double a = pb.Eval(wo, wi, {}).r + pb.Eval(wo, wi, {}).g;
      const double c = pb.Eval(wi, wo, {}).r + pb.Eval(wi, wo, {}).g;
      if (a > 1e-6 && c > 1e-6) worst = std::max(worst, std::abs(std::log(a / c)));
    }
    std::printf("[woven] sadeghi %s: max |log f(wo,wi)/f(wi,wo)| = %.3f (not reciprocal)\n",
                pf.name.c_str(), worst);
  }
}

// The Sadeghi BSDF evaluated term by term as sadeghi.h writes it (asin, atan2, cos of the
// angles): SadeghiBsdf::Eval computes the same through trigonometric identities and a per-wo
// memo, so the two must agree to rounding.
Rgbd SadeghiDirect(const SadeghiFabric& f, const Vec3d& wo, const Vec3d& wi) {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return Rgbd(0, 0, 0);
  const double deg = kPi / 180.0, sigma_m = SadeghiBsdf::kMaskingSigmaDeg * deg;
  auto gauss = [](double s, double x) {
    return std::exp(-x * x / (2.0 * s * s)) / (s * std::sqrt(2.0 * kPi));
  };
  double q = (1.0 - f.thread[0].a - f.thread[1].a) * wo.z;
  Rgbd sum(0, 0, 0);
  for (int j = 0; j < 2; ++j) {
    const SadeghiThread& th = f.thread[j];
    const Vec3d d = j == 0 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0), n(0, 0, 1);
    for (double off : th.offsets) {
      const Vec3d t = d * std::cos(off * deg) + n * std::sin(off * deg);
      const Vec3d nk = d * -std::sin(off * deg) + n * std::cos(off * deg);
      const Vec3d b = Cross(t, nk);
      const double weight = th.a / double(th.offsets.size());
      const double proj = std::max(0.0, Dot(wo, nk));
      q += weight * proj;
      if (proj <= 0.0) continue;
      const double ti = std::asin(std::clamp(Dot(wi, t), -1.0, 1.0));
      const double to = std::asin(std::clamp(Dot(wo, t), -1.0, 1.0));
      const double pi_ = std::atan2(Dot(wi, b), Dot(wi, nk));
      const double po = std::atan2(Dot(wo, b), Dot(wo, nk));
      double pd = pi_ - po;
      while (pd > kPi) pd -= 2.0 * kPi;
      while (pd < -kPi) pd += 2.0 * kPi;
      const double mi = std::max(0.0, std::cos(pi_)), mo = std::max(0.0, std::cos(po));
      const double uu = std::exp(-pd * pd / (2.0 * sigma_m * sigma_m));
      const double mask = (1.0 - uu) * mi * mo + uu * std::min(mi, mo);
      if (mask <= 0.0) continue;
      const double th_h = 0.5 * (ti + to), cd = std::cos(0.5 * (ti - to));
      const double chp = std::cos(0.5 * pd);
      const double fr = FresnelDielectric(cd * chp, th.eta), ft = 1.0 - fr;
      const double fs = fr * chp * gauss(th.gamma_s * deg, th_h);
      const double vol = ft * ft * ((1.0 - th.kd) * gauss(th.gamma_v * deg, th_h) + th.kd) /
                         std::max(std::cos(ti) + std::cos(to), 1e-4);
      const double w = weight * proj * mask * std::cos(ti) / std::max(cd * cd, 1e-4);
      sum += Rgbd::Splat(w * fs) + th.albedo * (w * vol);
    }
  }
  if (!(q > 0.0)) return Rgbd(0, 0, 0);
  return sum * (1.0 / (q * wi.z));
}

TEST(WovenBsdf, SadeghiEvalMatchesTheDirectFormula) {
  for (const SadeghiFabric& f : SadeghiPresets()) {
    const SadeghiBsdf b(f);
    Pcg32 rng(21, 5);
    double worst = 0.0;
    int nonzero = 0;
    for (int i = 0; i < 4000; ++i) {
      const Vec3d wo = SampleUniformHemisphereForTest(rng);
      // Several wi per wo: exercises the per-wo memo, and a second BSDF in between must not
      // leak its state into this one.
      for (int k = 0; k < 3; ++k) {
        const Vec3d wi = SampleUniformHemisphereForTest(rng);
        const Rgbd got = b.Eval(wo, wi, {}), want = SadeghiDirect(f, wo, wi);
        if (k == 1) (void)SadeghiBsdf(SadeghiPreset("velvet")).Eval(wi, wo, {});
        for (int c = 0; c < 3; ++c) {
          const double scale = std::max(std::abs(want[c]), 1e-12);
          worst = std::max(worst, std::abs(got[c] - want[c]) / scale);
          nonzero += want[c] > 1e-9 ? 1 : 0;
        }
      }
    }
    EXPECT_GT(nonzero, 1000) << f.name;
    EXPECT_LT(worst, 1e-9) << f.name;
  }
}

// Directional albedo rho(wo) = int f cos dwi by MIS sampling; `uv_random` averages over the
// tile (Irawan's fineness variation is a spatial glint, only its average is bounded).
struct Albedo {
  double mean[3] = {0, 0, 0};
  double stderr_max = 0.0;
};
Albedo DirectionalAlbedo(const Bsdf& b, const Vec3d& wo, const Point2d* uv, int n, uint64_t seed) {
  Pcg32 rng(seed, 17);
  double s[3] = {0, 0, 0}, s2[3] = {0, 0, 0};
  for (int i = 0; i < n; ++i) {
    const ShadingPoint sp{uv ? *uv : Point2d{rng.Uniform(), rng.Uniform()}};
    BsdfSample bs;
    if (!b.Sample(wo, {rng.Uniform(), rng.Uniform()}, rng.Uniform(), sp, &bs)) continue;
    for (int c = 0; c < 3; ++c) {
      const double v = bs.f[c] * bs.wi.z / bs.pdf;
      s[c] += v;
      s2[c] += v * v;
    }
  }
  Albedo a;
  for (int c = 0; c < 3; ++c) {
    a.mean[c] = s[c] / n;
    a.stderr_max =
        std::max(a.stderr_max, std::sqrt(std::max(0.0, s2[c] / n - a.mean[c] * a.mean[c]) / n));
  }
  return a;
}

TEST(WovenBsdf, AlbedoUnderUniformLightIsAtMostOne) {
  for (const Model& m : AllModels()) {
    const bool irawan = m.name.rfind("irawan", 0) == 0;
    double worst = 0.0;
    std::string line;
    for (double theta : {0.0, 30.0, 60.0, 80.0}) {
      const Vec3d wo = Dir(theta, 35.0);
      const Albedo a = DirectionalAlbedo(*m.bsdf, wo, irawan ? nullptr : &m.uvs[0], 40000, 3);
      const double mx = std::max({a.mean[0], a.mean[1], a.mean[2]});
      worst = std::max(worst, mx);
      char buf[96];
      std::snprintf(buf, sizeof(buf), " %g:%.3f", theta, mx);
      line += buf;
      EXPECT_LE(mx, 1.0 + 4.0 * a.stderr_max + 0.01) << m.name << " theta_o " << theta;
    }
    std::printf("[woven] albedo %s (max channel, theta_o:value)%s\n", m.name.c_str(), line.c_str());
  }
}

// ---------------------------------------------------------------- chi^2 sampling tests

struct Chi2Case {
  std::string label;
  std::shared_ptr<Bsdf> bsdf;
  Vec3d wo;
  Point2d uv;
};

std::vector<Chi2Case> Chi2Cases() {
  std::vector<Chi2Case> cases;
  const Vec3d wos[] = {Dir(30.0, 20.0), Dir(70.0, 200.0)};
  for (const std::string& stem : kChi2Weaves) {
    auto b = std::make_shared<IrawanBsdf>(LoadWeave(WeavePath(stem)), 1.0, 1.0);
    const auto pts = TestPoints(*b);
    for (size_t k = 0; k < pts.size(); ++k) {
      for (int w = 0; w < 2; ++w) {
        cases.push_back(
            {"irawan:" + stem + (k == 0 ? " warp" : " weft") + " wo" + std::to_string(w), b, wos[w],
             pts[k]});
      }
    }
  }
  for (const SadeghiFabric& f : SadeghiPresets()) {
    auto b = std::make_shared<SadeghiBsdf>(f);
    for (int w = 0; w < 2; ++w) {
      cases.push_back({"sadeghi:" + f.name + " wo" + std::to_string(w), b, wos[w], {0.5, 0.5}});
    }
  }
  return cases;
}

testing::Chi2Result RunCase(const Chi2Case& c, int n_tests, const testing::PdfFn* pdf_override) {
  testing::Chi2Config cfg;
  cfg.n_tests = n_tests;
  cfg.seed = 1234;
  const ShadingPoint sp{c.uv};
  auto sample = [&](const Point2d& u, double uc, Vec3d* wi, double* pdf) {
    BsdfSample s;
    if (!c.bsdf->Sample(c.wo, u, uc, sp, &s)) return false;
    *wi = s.wi;
    *pdf = s.pdf;
    return true;
  };
  const testing::PdfFn pdf = [&](const Vec3d& wi) { return c.bsdf->Pdf(c.wo, wi, sp); };
  return testing::RunChi2(sample, pdf_override ? *pdf_override : pdf, cfg);
}

TEST(WovenChi2, EverySamplingRoutinePasses) {
  auto cases = Chi2Cases();
  if (const char* only = std::getenv("CLOTHFIT_CHI2_ONLY")) {
    std::vector<Chi2Case> keep;
    for (const auto& c : cases) {
      if (c.label.find(only) != std::string::npos) keep.push_back(c);
    }
    cases = keep;
  }
  const auto start = std::chrono::steady_clock::now();
  double min_p = 1.0;
  for (const Chi2Case& c : cases) {
    const testing::Chi2Result r = RunCase(c, int(cases.size()), nullptr);
    std::printf("[woven] chi2 %-48s p = %.4f  mass = %.4f  failed = %lld\n", c.label.c_str(),
                r.p_value, r.pdf_mass, static_cast<long long>(r.failed_samples));
    EXPECT_TRUE(r.passed) << c.label << ": " << r.message;
    min_p = std::min(min_p, r.p_value);
  }
  const double secs =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("[woven] chi2: %zu cases x 10^6 samples, min p = %.4f, %.1f s\n", cases.size(), min_p,
              secs);
}

TEST(WovenChi2, RejectsADeliberatelyWrongPdf) {
  // (a) Cosine sampling checked against the uniform-hemisphere pdf.
  const Chi2Case lambert{
      "lambert", std::make_shared<LambertBsdf>(Rgbd(0.5, 0.5, 0.5)), Dir(30, 0), {0, 0}};
  const testing::PdfFn uniform = [](const Vec3d& wi) { return wi.z > 0 ? 0.5 * kInvPi : 0.0; };
  const auto ra = RunCase(lambert, 1, &uniform);
  std::printf("[woven] chi2 wrong pdf (uniform vs cosine): p = %.3g\n", ra.p_value);
  EXPECT_FALSE(ra.passed) << ra.message;
  // (b) The Irawan sampler against its own pdf perturbed by 3% cos(phi) (same total mass).
  auto b = std::make_shared<IrawanBsdf>(LoadWeave(WeavePath("cotton_denim")), 1.0, 1.0);
  const Chi2Case c{"denim", b, Dir(30, 20), TestPoints(*b)[0]};
  const testing::PdfFn tilted = [&](const Vec3d& wi) {
    const double phi = std::atan2(wi.y, wi.x);
    return b->Pdf(c.wo, wi, {c.uv}) * (1.0 + 0.03 * std::cos(phi));
  };
  const auto rb = RunCase(c, 1, &tilted);
  std::printf("[woven] chi2 wrong pdf (Irawan pdf x (1 + 0.03 cos phi)): p = %.3g\n", rb.p_value);
  EXPECT_FALSE(rb.passed) << rb.message;
}

TEST(WovenChi2, SurvivalFunctionMatchesKnownValues) {
  // Closed forms: dof 2: exp(-x/2); dof 1: erfc(sqrt(x/2)); dof 4: exp(-x/2)(1 + x/2).
  for (double x : {0.1, 1.0, 3.0, 10.0, 40.0}) {
    EXPECT_NEAR(testing::Chi2Survival(x, 2), std::exp(-0.5 * x), 1e-13);
    EXPECT_NEAR(testing::Chi2Survival(x, 1), std::erfc(std::sqrt(0.5 * x)), 1e-12);
    EXPECT_NEAR(testing::Chi2Survival(x, 4), std::exp(-0.5 * x) * (1 + 0.5 * x), 1e-12);
  }
  // Large dof: the median of chi2(k) is about k (1 - 2/(9k))^3.
  const double k = 3000;
  EXPECT_NEAR(testing::Chi2Survival(k * std::pow(1 - 2 / (9 * k), 3), k), 0.5, 1e-3);
}

// ---------------------------------------------------------------- variance

// Sample variance of the estimator of int f cos dwi (max channel) with the BSDF's MIS
// sampler and with cosine-only sampling, same sample count.
void CompareVariance(const Bsdf& b, const std::string& label, const Vec3d& wo, const Point2d& uv,
                     double* ratio) {
  const int n = 200000;
  Pcg32 rng(77, 1);
  double sm = 0, sm2 = 0, sc = 0, sc2 = 0;
  const ShadingPoint sp{uv};
  for (int i = 0; i < n; ++i) {
    BsdfSample s;
    double v = 0.0;
    if (b.Sample(wo, {rng.Uniform(), rng.Uniform()}, rng.Uniform(), sp, &s)) {
      v = s.f.g * s.wi.z / s.pdf;
    }
    sm += v;
    sm2 += v * v;
    const Vec3d wi = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
    const double c = b.Eval(wo, wi, sp).g * wi.z / CosineHemispherePdf(wi.z);
    sc += c;
    sc2 += c * c;
  }
  const double mm = sm / n, mc = sc / n;
  const double vm = sm2 / n - mm * mm, vc = sc2 / n - mc * mc;
  *ratio = vc / vm;
  std::printf(
      "[woven] variance %s: estimate MIS %.5f +- %.5f, cosine %.5f +- %.5f, "
      "variance ratio cosine/MIS = %.2f\n",
      label.c_str(), mm, std::sqrt(vm / n), mc, std::sqrt(vc / n), *ratio);
  EXPECT_NEAR(mm, mc, 5.0 * (std::sqrt(vm / n) + std::sqrt(vc / n))) << label;
}

TEST(WovenSampling, MisHasLowerVarianceThanCosineOnNarrowHighlights) {
  double ratio = 0.0;
  const IrawanBsdf charmeuse(LoadWeave(WeavePath("silk_charmeuse")), 1.0, 1.0);
  CompareVariance(charmeuse, "irawan:silk_charmeuse warp", Dir(45, 10), TestPoints(charmeuse)[0],
                  &ratio);
  EXPECT_GT(ratio, 1.5);
  const IrawanBsdf polyester(LoadWeave(WeavePath("polyester")), 1.0, 1.0);
  CompareVariance(polyester, "irawan:polyester warp", Dir(45, 10), TestPoints(polyester)[0],
                  &ratio);
  EXPECT_GT(ratio, 1.5);
  const SadeghiBsdf satin(SadeghiPreset("polyester_satin_charmeuse"));
  CompareVariance(satin, "sadeghi:polyester_satin_charmeuse", Dir(45, 10), {0.5, 0.5}, &ratio);
  EXPECT_GT(ratio, 1.5);
}

// ---------------------------------------------------------------- fabric files

TEST(WovenFabric, DatasetFabricsLoad) {
  const std::pair<const char*, const char*> expect[] = {
      {"canvas", "irawan"}, {"twill", "irawan"},  {"denim", "irawan"},
      {"linen", "sadeghi"}, {"satin", "sadeghi"}, {"velvet", "sadeghi"}};
  for (const auto& [name, model] : expect) {
    const Fabric f = LoadFabric((kDatasets / "fabrics" / (std::string(name) + ".json")).string());
    EXPECT_EQ(f.name, name);
    EXPECT_EQ(f.model, model);
    ASSERT_TRUE(f.bsdf != nullptr);
    EXPECT_DOUBLE_EQ(f.weave_period_uv, 1.0 / f.uv_repeats);
    const Rgbd v = f.bsdf->Eval(Dir(30, 0), Dir(30, 180), {{0.01, 0.02}});
    EXPECT_GT(v.r + v.g + v.b, 0.0) << name;
  }
}

void ExpectFabricError(const std::string& text, const std::string& what) {
  const std::string path = (kDatasets / "fabrics" / "test_bad.json").string();
  try {
    ParseFabric(text, path);
    ADD_FAILURE() << "no error; expected " << what;
  } catch (const FabricError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ":", 0), 0u) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
}

TEST(WovenFabric, ErrorsNameTheFileAndField) {
  const std::string head = R"({"format": "clothfit-fabric", "version": 1, "name": "x", )";
  ExpectFabricError("{\n  \"format\": \"clothfit-fabric\",\n  \"name\": ,\n}", "line 3, column");
  ExpectFabricError(head + R"("model": "irawan", "preset": "cotton_canvas"})", "'uv_repeats'");
  ExpectFabricError(head + R"("model": "irawan", "preset": "cotton_canvas", "uv_repeats": -2})",
                    "field 'uv_repeats' must be in (0, 10000]");
  ExpectFabricError(head + R"("model": "irawan", "preset": "cotton_canvas", "uv_repeats": "4"})",
                    "field 'uv_repeats' must be a number");
  ExpectFabricError(head + R"("model": "pbr", "preset": "cotton_canvas", "uv_repeats": 4})",
                    "field 'model'");
  ExpectFabricError(head + R"("model": "sadeghi", "preset": "tweed", "uv_repeats": 4})",
                    "field 'preset': unknown Sadeghi fabric 'tweed' (valid: linen_plain");
  ExpectFabricError(head + R"("model": "irawan", "preset": "no_such_weave", "uv_repeats": 4})",
                    "no_such_weave.weave: cannot open");
  // Session 27: where it looked, and how to point elsewhere (a fabric copied out of datasets/).
  ExpectFabricError(head + R"("model": "irawan", "preset": "no_such_weave", "uv_repeats": 4})",
                    "names ../weaves/no_such_weave.weave next to the fabric file's directory; copy "
                    "that file along, or give 'weave_file' with its path");
  ExpectFabricError(head + R"("model": "irawan", "preset": "x", "weave_file": "nope.weave", )"
                           R"("uv_repeats": 4})",
                    "'weave_file' is relative to the fabric file's directory");
  ExpectFabricError(head + R"("model": "irawan", "preset": "x", "uv_repeats": 4, "colour": 1})",
                    "unknown field 'colour'");
  ExpectFabricError(R"({"format": "clothfit-fabric", "version": 2})", "field 'version'");
  ExpectFabricError(head + R"("preset": "x", "uv_repeats": 4})", "missing field 'model'");
  ExpectFabricError("[1, 2]", "top level must be a JSON object");
}

// Session 28: Fabric::weave_path is the file the weave was read from, for content keys (the
// reference cache keyed ../weaves/<preset>.weave even when 'weave_file' named another file).
TEST(WovenFabric, WeavePathIsTheFileRead) {
  const auto dir = std::filesystem::temp_directory_path() / "clothfit_woven_weave_path";
  std::filesystem::create_directories(dir / "fabrics");
  std::filesystem::create_directories(dir / "weaves");
  std::ofstream(dir / "fabrics" / "mine.weave") << ReadText(WeavePath("polyester"));
  std::ofstream(dir / "weaves" / "polyester.weave") << ReadText(WeavePath("polyester"));
  const std::string own = (dir / "fabrics" / "own.json").string();
  std::ofstream(own) << R"({"format": "clothfit-fabric", "version": 1, "name": "own", )"
                     << R"("model": "irawan", "preset": "polyester", "weave_file": "mine.weave", )"
                     << R"("uv_repeats": 3})";
  EXPECT_EQ(LoadFabric(own).weave_path, (dir / "fabrics" / "mine.weave").string());
  const std::string by_preset = (dir / "fabrics" / "preset.json").string();
  std::ofstream(by_preset) << R"({"format": "clothfit-fabric", "version": 1, "name": "p", )"
                           << R"("model": "irawan", "preset": "polyester", "uv_repeats": 3})";
  EXPECT_EQ(LoadFabric(by_preset).weave_path, (dir / "weaves" / "polyester.weave").string());
  const std::string simple = (dir / "fabrics" / "lambert.json").string();
  std::ofstream(simple) << R"({"format": "clothfit-fabric", "version": 1, "name": "l", )"
                        << R"("model": "lambert", "albedo": [0.5, 0.5, 0.5]})";
  EXPECT_EQ(LoadFabric(simple).weave_path, "");
  std::filesystem::remove_all(dir);
}

TEST(WovenFabric, WeaveErrorsKeepTheirFileAndLine) {
  const auto dir = std::filesystem::temp_directory_path() / "clothfit_woven_test";
  std::filesystem::create_directories(dir);
  const std::string weave = (dir / "broken.weave").string();
  std::string text = ReadText(WeavePath("polyester"));
  text.replace(text.find("ss 0.5"), 6, "ss 1.5");
  std::ofstream(weave) << text;
  const std::string json = (dir / "f.json").string();
  std::ofstream(json) << R"({"format": "clothfit-fabric", "version": 1, "name": "b", )"
                      << R"("model": "irawan", "preset": "broken", "weave_file": "broken.weave", )"
                      << R"("uv_repeats": 3})";
  try {
    LoadFabric(json);
    ADD_FAILURE() << "no error";
  } catch (const FabricError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("broken.weave:7: ss must satisfy"), std::string::npos) << msg;
    EXPECT_EQ(msg.rfind(json + ":", 0), 0u) << msg;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace clothfit::render
