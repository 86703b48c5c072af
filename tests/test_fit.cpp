// Image fitting: synthetic recovery for every model, robustness to noise and outliers,
// explicit errors on bad input, where the cloth model beats the baselines (and where it does
// not), and fitted parameters that do not drift with the weave scale.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "fit/image_fit.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/reference/weave_pattern.h"
#include "render/scene/image_io.h"
#include "render/reference/path_tracer.h"
#include "tests/fit_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;
using render::ModelKind;

render::Scene TestScene(int size) { return KeyRimSphereScene(size, 1.5); }


struct Case {
  ModelKind model;
  std::vector<double> truth;
  std::vector<std::string> locked;
};

std::vector<Case> Cases() {
  return {
      {ModelKind::kCloth, {0.6, 0.35, 0.2, 0.8, 0.7, 0.5, 0.62, 0, 0, 0}, {}},
      {ModelKind::kStandard, {0.5, 0.3, 0.2, 0.45, 0.0}, {"metalness"}},
      {ModelKind::kPhysicalSheen, {0.5, 0.3, 0.2, 0.55, 0.0, 0.6, 0.5, 0.4, 0.45}, {"metalness"}},
      {ModelKind::kGltfSheen, {0.5, 0.3, 0.2, 0.5, 0.0, 0.6, 0.5, 0.4, 0.5}, {"metallic"}},
  };
}

FitOptions Options(const render::MaterialPreset& start, const std::vector<std::string>& locked) {
  FitOptions o;
  o.start = start;
  o.locked = locked;
  o.level = 0;
  o.loss = Loss::kNone;
  o.init_from_reference = false;
  o.start_roughness = {0.0};  // one start: the preset's own values
  o.function_tolerance = 1e-12;
  o.max_iterations = 200;
  return o;
}

TEST(Fit, SyntheticRecoveryFromRandomStartsForEveryModel) {
  const render::Scene s = TestScene(32);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  std::mt19937 rng(5);
  for (const Case& c : Cases()) {
    render::MaterialPreset truth = render::DefaultPreset(c.model);
    truth.values = c.truth;
    const Reference ref = PreviewReference(s, &env, truth);
    const auto table = render::ParameterTable(c.model);
    for (int trial = 0; trial < 5; ++trial) {
      render::MaterialPreset start = truth;
      int off = 0;
      for (const ParamInfo& p : table) {
        const bool locked = std::find(c.locked.begin(), c.locked.end(), std::string(p.name)) != c.locked.end();
        for (int k = 0; k < p.size; ++k) {
          if (!locked && !(c.model == ModelKind::kCloth && p.name == "subsurface_color")) {
            std::uniform_real_distribution<double> u(std::max(p.lower, 0.1), 0.9);
            start.values[size_t(off + k)] = u(rng);
          }
        }
        off += p.size;
      }
      const FitResult r = FitImages({{&s, &env, &ref, nullptr, "test"}}, Options(start, c.locked));
      ASSERT_TRUE(r.usable) << render::ToString(c.model) << ": " << r.message;
      for (size_t k = 0; k < c.truth.size(); ++k)
        EXPECT_NEAR(r.preset.values[k], c.truth[k], 1e-3)
            << render::ToString(c.model) << " parameter " << k << " trial " << trial << "\n"
            << r.solver_report;
    }
  }
}

// A strided fit compares the preview at a subset of each block's pixels with the reference's
// full-block mean: the subset must sit at the centres of the stride cells, or every block is
// sampled half a cell off and even the true parameters leave a residual on shaded gradients.
TEST(Fit, StridedBlocksAreSampledAtCellCentres) {
  const render::Scene s = TestScene(64);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  render::MaterialPreset truth = render::DefaultPreset(ModelKind::kStandard);
  truth.values = {0.5, 0.3, 0.2, 0.45, 0.0};
  const Reference ref = PreviewReference(s, &env, truth);
  FitOptions o = Options(truth, {"metalness"});
  o.level = 3;         // 8 x 8 blocks
  o.pixel_stride = 4;  // 2 x 2 samples per block
  const FitResult r = FitImages({{&s, &env, &ref, nullptr, "test"}}, o);
  ASSERT_TRUE(r.usable) << r.message;
  std::printf("[ measured ] display RMSE of a self-fit, 8 x 8 blocks, stride 4: %.5f\n",
              r.rmse);
  // Measured: 0.0047 with the cell centres (pixels 2, 6), 0.0134 with the first pixels (0, 4).
  EXPECT_LT(r.rmse, 0.008);
}

TEST(Fit, RobustLossRecoversThroughNoiseAndOutliers) {
  const render::Scene s = TestScene(64);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  render::MaterialPreset truth = render::DefaultPreset(ModelKind::kCloth);
  truth.values = Cases()[0].truth;
  Reference ref = PreviewReference(s, &env, truth);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 0.02);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (size_t p = 0; p < ref.fabric.size(); ++p) {
    const bool outlier = u(rng) < 0.01;
    for (size_t c = 0; c < 3; ++c) {
      float& v = ref.rgb[p * 3 + c];
      v = outlier ? float(5.0 * u(rng)) : float(double(v) * (1.0 + noise(rng)));
    }
  }
  render::MaterialPreset start = truth;
  for (double& v : start.values) v = std::clamp(v * 0.7 + 0.1, 0.0, 1.0);
  FitOptions o = Options(start, {});
  o.space = Space::kDisplay;  // the default space
  o.loss = Loss::kCauchy;     // outliers up to 5x the signal
  o.loss_scale = 3.0;         // residuals are in units of the 0.01 display floor
  const FitResult r = FitImages({{&s, &env, &ref, nullptr, "test"}}, o);
  ASSERT_TRUE(r.usable);
  for (size_t k = 0; k < 7; ++k)
    EXPECT_NEAR(r.preset.values[k], truth.values[k], 1e-2) << k << " " << r.solver_report;
}

TEST(Fit, NanPixelInReferenceIsAnExplicitError) {
  io::Image img;
  img.width = img.height = 4;
  img.channel_names = {"R", "G", "B"};
  img.pixels.assign(48, 0.5f);
  img.pixels[17] = std::nanf("");
  const std::string path = (fs::temp_directory_path() / "clothfit_nan_ref.exr").string();
  io::WriteExr(path, img);
  try {
    ReadReference(path);
    FAIL() << "NaN accepted";
  } catch (const FitError& e) {
    EXPECT_NE(std::string(e.what()).find("clothfit_nan_ref.exr"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos);
  }
  fs::remove(path);
}

TEST(Fit, InfeasibleStartAndMismatchedSizesAreExplicitErrors) {
  const render::Scene s = TestScene(16);
  render::MaterialPreset truth = render::DefaultPreset(ModelKind::kCloth);
  truth.values = Cases()[0].truth;
  const Reference ref = PreviewReference(s, nullptr, truth);
  render::MaterialPreset bad = truth;
  bad.values[6] = 1.5;  // roughness beyond its bound
  EXPECT_THROW(FitImages({{&s, nullptr, &ref, nullptr, "t"}}, Options(bad, {})), FitError);
  Reference small = ref;
  small.width = 8;
  EXPECT_THROW(FitImages({{&s, nullptr, &small, nullptr, "t"}}, Options(truth, {})), FitError);
  EXPECT_THROW(FitImages({{&s, nullptr, &ref, nullptr, "t"}}, Options(truth, {"sheen"})), FitError);
}

std::string Datasets() {
  if (const char* d = std::getenv("CLOTHFIT_SOURCE_DIR")) return std::string(d) + "/datasets";
  return (fs::path(__FILE__).parent_path().parent_path() / "datasets").string();
}

// Display RMSE of the cloth, MeshPhysicalMaterial (sheen) and MeshStandardMaterial fits to a
// path-traced reference of `fabric_name` on a canonical scene at size x size, procedural sky.
struct ModelErrors {
  double cloth, physical, standard;
};

ModelErrors FitThreeModels(const std::string& scene_name, const std::string& fabric_name, int size,
                           int spp, int level) {
  render::Scene s = render::LoadScene(Datasets() + "/scenes/" + scene_name + ".json");
  s.card.width = s.card.height = size;
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.0);
  const render::Fabric fabric = render::LoadFabric(Datasets() + "/fabrics/" + fabric_name + ".json");
  render::PathTracer pt(s, *fabric.bsdf, &env);
  render::RenderSettings st;
  st.spp = spp;
  const render::RenderResult rr = pt.Render(st);
  Reference ref;
  ref.path = fabric_name + "/" + scene_name;
  ref.width = ref.height = size;
  ref.rgb = rr.rgb;
  ref.std_error = rr.std_error;
  ref.fabric = rr.fabric;
  double err[3];
  const ModelKind models[3] = {ModelKind::kCloth, ModelKind::kPhysicalSheen, ModelKind::kStandard};
  for (int m = 0; m < 3; ++m) {
    FitOptions o;
    o.start = render::DefaultPreset(models[m]);
    if (models[m] != ModelKind::kCloth) o.locked = {"metalness"};
    o.level = level;
    const FitResult r = FitImages({{&s, &env, &ref, nullptr, scene_name}}, o);
    EXPECT_TRUE(r.usable) << ref.path << " " << render::ToString(models[m]) << ": " << r.message;
    EXPECT_TRUE(std::isfinite(r.rmse));
    err[m] = r.rmse;
  }
  std::printf("[ measured ] %-6s on %-6s display RMSE: cloth %.5f, physical-sheen %.5f, standard %.5f\n",
              fabric_name.c_str(), scene_name.c_str(), err[0], err[1], err[2]);
  return {err[0], err[1], err[2]};
}

// The issue asked that the cloth fit beat both baselines on canvas and twill. Measured, that
// holds only where the reference shows sheen (docs/fitting.md, "What the fits show"):
//  - velvet (Sadeghi: fibres standing out of the surface, back- and grazing scattering) on the
//    backlit swatch: cloth beats both baselines by a wide margin;
//  - canvas and twill (Irawan-Marschner: smooth yarns, no fuzz) front-lit on the sphere have no
//    sheen to fit: every model reduces to nearly Lambert and they tie;
//  - canvas and twill on the backlit swatch under the studio environment at 256 x 256 carry a
//    forward-scattered yarn highlight (n.h ~ 1) that GGX reproduces and Charlie sheen, zero at
//    n.h = 1, cannot: cloth loses 2-5x there (measured with `clothfit fit`, docs/fitting.md;
//    at this test's 64 x 64 with the procedural sky the three models tie on that scene).
// MeshPhysicalMaterial (GGX + Lambert + sheen) is a superset of MeshStandardMaterial, so it
// must never be worse beyond the solver's tolerance.
TEST(Fit, ClothBeatsBothBaselinesWhereTheReferenceHasSheen) {
  const ModelErrors v = FitThreeModels("swatch", "velvet", 64, 64, 1);
  EXPECT_LT(v.cloth, v.physical);
  EXPECT_LT(v.cloth, v.standard);
  EXPECT_LE(v.physical, v.standard * 1.02);
}

TEST(Fit, ClothTiesTheBaselinesOnFrontLitCanvasAndTwill) {
  for (const char* fabric : {"canvas", "twill"}) {
    const ModelErrors e = FitThreeModels("sphere", fabric, 64, 64, 1);
    EXPECT_LT(e.cloth, 1.15 * std::min(e.physical, e.standard)) << fabric;
    EXPECT_LE(e.physical, e.standard * 1.02) << fabric;
  }
}

// Mesostructure: the block level follows the weave scale (AutoLevel), so a canvas woven twice
// as fine or twice as coarse on the same sphere must give the same fitted parameters. The
// tile-averaged Irawan reflectance does not depend on the tile size, so any drift is the fit
// seeing yarn-scale structure it cannot reproduce. Tolerance 0.03 per parameter: the spread
// of the same fit over reference seeds at this resolution and spp is about 0.01.
TEST(Fit, FittedParametersDoNotDriftWithWeaveScale) {
  render::Scene s = render::LoadScene(Datasets() + "/scenes/sphere.json");
  s.card.width = s.card.height = 128;
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.0);
  const render::WeavePattern pattern = render::LoadWeave(Datasets() + "/weaves/cotton_canvas.weave");
  std::vector<std::vector<double>> fitted;
  std::vector<int> levels;
  for (double repeats : {30.0, 60.0, 120.0}) {
    const render::IrawanBsdf bsdf(pattern, repeats, repeats);
    render::PathTracer pt(s, bsdf, &env);
    render::RenderSettings st;
    st.spp = 32;
    const render::RenderResult rr = pt.Render(st);
    Reference ref;
    ref.path = "canvas x" + std::to_string(int(repeats));
    ref.width = ref.height = 128;
    ref.rgb = rr.rgb;
    ref.std_error = rr.std_error;
    ref.fabric = rr.fabric;
    const std::vector<SceneInput> in{{&s, &env, &ref, nullptr, "sphere"}};
    FitOptions o;
    o.start = render::DefaultPreset(ModelKind::kCloth);
    o.level = AutoLevel(in, 1.0 / repeats);
    levels.push_back(o.level);
    const FitResult r = FitImages(in, o);
    ASSERT_TRUE(r.usable) << ref.path << ": " << r.message;
    fitted.push_back(r.preset.values);
    std::printf("[ measured ] canvas x%g: level %d, base (%.4f %.4f %.4f) sheen (%.4f %.4f %.4f) roughness %.4f\n",
                repeats, o.level, r.preset.values[0], r.preset.values[1], r.preset.values[2],
                r.preset.values[3], r.preset.values[4], r.preset.values[5], r.preset.values[6]);
  }
  // The level must actually follow the scale (else this test would not test AutoLevel).
  EXPECT_LT(levels[2], levels[0]);
  const double sheen = *std::max_element(fitted[0].begin() + 3, fitted[0].begin() + 6);
  for (size_t k = 1; k < fitted.size(); ++k) {
    for (size_t p = 0; p < 6; ++p)  // base and sheen colours
      EXPECT_NEAR(fitted[k][p], fitted[0][p], 0.03) << "parameter " << p << ", scale " << k;
    // Roughness only shapes the sheen lobe: with (near) zero sheen it is unidentifiable and
    // its value is arbitrary, so it is compared only when the sheen is visible.
    if (sheen > 0.05) {
      EXPECT_NEAR(fitted[k][6], fitted[0][6], 0.03) << "roughness, scale " << k;
    }
  }
  // And what matters to users: the fitted presets look the same (display RMSE of their previews).
  auto display = [&](const std::vector<double>& v) {
    render::MaterialPreset m = render::DefaultPreset(ModelKind::kCloth);
    m.values = v;
    const auto frame = RenderPreviewFrame(s, &env, m);
    std::vector<double> d;
    for (size_t i = 0; i < frame.size(); i += 3) {
      const Rgb<double> c = render::ToDisplay(
          Rgb<double>(double(frame[i]), double(frame[i + 1]), double(frame[i + 2])),
          render::ToneMapping::kAcesFilmic, 1.0);
      d.insert(d.end(), {c[0], c[1], c[2]});
    }
    return d;
  };
  const auto d0 = display(fitted[0]);
  for (size_t k = 1; k < fitted.size(); ++k) {
    const auto dk = display(fitted[k]);
    double se = 0;
    for (size_t i = 0; i < d0.size(); ++i) se += (dk[i] - d0[i]) * (dk[i] - d0[i]);
    EXPECT_LT(std::sqrt(se / double(d0.size())), 0.01) << "scale " << k;
  }
}

}  // namespace
}  // namespace clothfit::fit

namespace clothfit::fit {
namespace {

// Colour packing (fit/image_fit.cpp, kJetWidths): a channel-separable colour block carried in
// one derivative slot gives the same Jacobian as three slots (up to rounding), so the same
// fit: same iterations, same parameters. Under ACES (per channel) and AgX (mixes channels:
// the display transform's 3 x 3 Jacobian is applied per block), for every model with a
// packed block (woven: both image stages' free sets).
TEST(Fit, ColourPackingGivesTheSameFitAsOneSlotPerScalar) {
  struct PackCase {
    ModelKind model;
    std::vector<double> truth, start;
    std::vector<std::string> locked;
  };
  const std::vector<PackCase> cases = {
      {ModelKind::kCloth, {0.6, 0.35, 0.2, 0.8, 0.7, 0.5, 0.62, 0, 0, 0},
       {0.4, 0.4, 0.4, 0.5, 0.5, 0.5, 0.8, 0, 0, 0}, {}},
      {ModelKind::kStandard, {0.5, 0.3, 0.2, 0.45, 0.0}, {0.3, 0.3, 0.3, 0.7, 0.0}, {"metalness"}},
      {ModelKind::kGltfSheen, {0.5, 0.3, 0.2, 0.5, 0.0, 0.6, 0.5, 0.4, 0.5},
       {0.3, 0.3, 0.3, 0.7, 0.0, 0.3, 0.3, 0.3, 0.7}, {"metallic"}},
      {ModelKind::kWoven,
       {0.5, 0.3, 0.2, 0.6, 0.5, 0.4, 0.5, 0.7, 0, 0.6, 0.1, 3.0, 0, 0, 0, 0.6, 0},
       {0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.7, 0.7, 0, 0.5, 0.05, 2.0, 0, 0, 0, 0.6, 0},
       {"anisotropy", "twist", "sheen_color", "sheen_roughness", "diffuse_roughness"}},
      {ModelKind::kWoven,
       {0.5, 0.3, 0.2, 0.6, 0.5, 0.4, 0.5, 0.7, 0, 0.6, 0.1, 3.0, 0.2, 0.15, 0.1, 0.5, 0.4},
       {0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.5, 0.7, 0, 0.6, 0.1, 3.0, 0.05, 0.05, 0.05, 0.7, 0.4},
       {"roughness", "anisotropy", "twist", "warp_share", "specular_f0", "forward_scattering",
        "diffuse_roughness"}},
  };
  for (const char* tone : {"ACESFilmic", "AgX"}) {
    render::Scene s = TestScene(32);
    s.card.tone_mapping = tone;
    const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
    for (const PackCase& c : cases) {
      render::MaterialPreset truth = render::DefaultPreset(c.model);
      truth.values = c.truth;
      const Reference ref = PreviewReference(s, &env, truth);
      render::MaterialPreset start = truth;
      start.values = c.start;
      FitOptions packed = Options(start, c.locked);
      packed.max_iterations = 30;
      FitOptions plain = packed;
      plain.pack_colours = false;
      const FitResult a = FitImages({{&s, &env, &ref, nullptr, "test"}}, packed);
      const FitResult b = FitImages({{&s, &env, &ref, nullptr, "test"}}, plain);
      const std::string what = std::string(tone) + " " + render::ToString(c.model);
      ASSERT_TRUE(a.usable && b.usable) << what;
      EXPECT_EQ(a.iterations, b.iterations) << what;
      EXPECT_NEAR(a.final_cost, b.final_cost, 1e-9 * (1.0 + b.final_cost)) << what;
      EXPECT_NEAR(a.initial_cost, b.initial_cost, 1e-12 * (1.0 + b.initial_cost)) << what;
      for (size_t k = 0; k < c.truth.size(); ++k)
        EXPECT_NEAR(a.preset.values[k], b.preset.values[k], 1e-7) << what << " parameter " << k;
      EXPECT_LT(a.final_cost, 0.5 * a.initial_cost) << what;  // the fit moved
    }
  }
}

// Prepared scenes are shared only by fits with the same cache-relevant options.
TEST(Fit, PreparedScenesMustMatchTheFitOptions) {
  const render::Scene s = TestScene(32);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  render::MaterialPreset truth = render::DefaultPreset(ModelKind::kStandard);
  truth.values = {0.5, 0.3, 0.2, 0.45, 0.0};
  const Reference ref = PreviewReference(s, &env, truth);
  const std::vector<SceneInput> in = {{&s, &env, &ref, nullptr, "test"}};
  FitOptions o = Options(truth, {"metalness"});
  const auto prepared = PrepareScenes(in, o);
  const FitResult shared = FitImages(in, o, prepared.get());
  const FitResult own = FitImages(in, o);
  ASSERT_TRUE(shared.usable && own.usable);
  EXPECT_EQ(shared.final_cost, own.final_cost);
  EXPECT_EQ(shared.preset.values, own.preset.values);
  FitOptions other = o;
  other.level = 1;
  EXPECT_THROW(FitImages(in, other, prepared.get()), FitError);
  other = o;
  other.start = render::DefaultPreset(ModelKind::kGltfSheen);
  other.locked = {"metallic"};
  EXPECT_THROW(FitImages(in, other, prepared.get()), FitError);
}

}  // namespace
}  // namespace clothfit::fit
