// BRDF-space fitting (fit/brdf_fit.h) and the MERL reader (fit/convert/merl.h): the direction set,
// self-conversion of every model, glTF sheen -> cloth within the stated error, recovery of an
// analytic BRDF from a synthetic MERL file, and reader errors naming file and field.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>

#include "brdf/lut.h"
#include "fit/brdf_fit.h"
#include "fit/convert/merl.h"
#include "render/reference/fabric.h"
#include "render/reference/irawan.h"
#include "render/scene/sampler.h"

namespace clothfit::fit {
namespace {
namespace fs = std::filesystem;
using render::ModelKind;

render::MaterialPreset Cloth(Rgb<double> base, Rgb<double> sheen, double r) {
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kCloth);
  for (int c = 0; c < 3; ++c) {
    p.values[size_t(c)] = base[c];
    p.values[size_t(3 + c)] = sheen[c];
  }
  p.values[6] = r;
  return p;
}

TEST(BrdfFit, DirectionSetIsFixedNormalisedAndCoversGrazing) {
  const auto& d = CanonicalDirections();
  ASSERT_LE(d.size(), size_t(kDirNodes * kHalfNodes * kHalfAzimuths));
  ASSERT_GT(d.size(), size_t(kDirNodes * kHalfNodes * kHalfAzimuths / 2));
  double sum = 0.0, min_mu = 1.0, min_theta_h = 1.0;
  std::map<double, double> per_view;  // mu_v -> summed weight
  for (const auto& p : d) {
    sum += p.weight;
    EXPECT_GT(p.weight, 0.0);
    min_mu = std::min({min_mu, p.v.z, p.l.z});
    EXPECT_GT(p.l.z, kMinLightCosine);
    EXPECT_NEAR(p.cos.NoV, p.v.z, 1e-12);
    min_theta_h = std::min(min_theta_h, std::acos(std::min(p.cos.NoH, 1.0)));
    per_view[p.v.z] += p.weight;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_LT(min_mu, 0.05);       // reaches ~88 degrees
  EXPECT_LT(min_theta_h, 1e-3);  // a node within 0.06 degrees of the mirror configuration
  // Each view's share is w_GL(mu_v) 2 mu_v (the light weights sum to pi per view): the most
  // normal view outweighs the most grazing one.
  ASSERT_EQ(per_view.size(), size_t(kDirNodes));
  EXPECT_GT(per_view.rbegin()->first, 0.95);
  EXPECT_LT(per_view.begin()->first, 0.05);
  EXPECT_GT(per_view.rbegin()->second, 10 * per_view.begin()->second);
  // The light quadrature integrates the hemisphere's cosine: int n.l d omega_l = pi over the
  // full hemisphere, pi / 2 over phi in [0, pi]; per view, sum(w n.l) / sum(w) = 1/2.
  std::map<double, double> cos_moment;
  for (const auto& p : d) cos_moment[p.v.z] += p.weight * p.l.z;
  for (const auto& [mu, m] : cos_moment) EXPECT_NEAR(m / per_view[mu], 0.5, 0.03) << mu;  // measured max 0.027
}

TEST(BrdfFit, ClothConvertsToItselfFromGenericStarts) {
  const render::MaterialPreset truth = Cloth({0.45, 0.3, 0.2}, {0.8, 0.7, 0.6}, 0.55);
  BrdfFitOptions o;  // no source start: the roughness starts must find it
  const BrdfFitResult r = FitBrdf(SampleAnalytic(truth), o);
  ASSERT_TRUE(r.usable) << r.message;
  for (size_t i = 0; i < 7; ++i) EXPECT_NEAR(r.preset.values[i], truth.values[i], 2e-3) << i;
  EXPECT_LT(r.error, 1e-5);
}

TEST(BrdfFit, EveryModelConvertsToItself) {
  for (ModelKind m : {ModelKind::kStandard, ModelKind::kPhysicalSheen, ModelKind::kGltfSheen}) {
    render::MaterialPreset p = render::DefaultPreset(m);
    p.values[0] = 0.5, p.values[1] = 0.35, p.values[2] = 0.2, p.values[3] = 0.6;
    if (m != ModelKind::kStandard) {
      p.values[5] = 0.7, p.values[6] = 0.6, p.values[7] = 0.5, p.values[8] = 0.45;
    }
    BrdfFitOptions o;
    o.model = m;
    const BrdfFitResult r = FitBrdf(SampleAnalytic(p), o);
    ASSERT_TRUE(r.usable) << render::ToString(m);
    EXPECT_LT(r.error, 2e-3) << render::ToString(m);
    EXPECT_NEAR(r.preset.values[3], 0.6, 0.03) << render::ToString(m);
  }
}

// The stated error of a glTF sheen -> cloth conversion (docs/convert.md): a dielectric
// glTF sheen fabric (GGX base with rough base roughness) converts to a cloth preset within
// 0.02 square-root units on the canonical set, and the cloth keeps the base colour's hue.
TEST(BrdfFit, GltfSheenConvertsToClothWithinStatedError) {
  render::MaterialPreset g = render::DefaultPreset(ModelKind::kGltfSheen);
  const double v[9] = {0.5, 0.25, 0.15, 0.85, 0.0, 0.6, 0.5, 0.45, 0.5};
  g.values.assign(v, v + 9);
  const BrdfSamples s = SampleAnalytic(g);
  const BrdfFitResult r = FitBrdf(s, {});
  ASSERT_TRUE(r.usable);
  std::printf("gltf-sheen -> cloth: error %.4f, roughness %.3f\n", r.error, r.preset.values[6]);
  EXPECT_LT(r.error, 0.02);
  EXPECT_GT(r.preset.values[0], r.preset.values[1]);
  EXPECT_GT(r.preset.values[1], r.preset.values[2]);
  // And the untouched default cloth is far worse: the fit did something.
  EXPECT_GT(BrdfError(s, render::DefaultPreset(ModelKind::kCloth)), 3 * r.error);
}

TEST(Merl, SyntheticTableOfAnAnalyticClothRecoversItsParameters) {
  const render::MaterialPreset truth = Cloth({0.3, 0.5, 0.25}, {0.6, 0.75, 0.9}, 0.7);
  const MerlTable t =
      TabulateMerl(90, 90, 180, [&](const Vec3<double>& wi, const Vec3<double>& wo) {
        const Cosines<double> c = CosinesFromDirections(wo, wi);
        return EvalDirectFlat(ModelKind::kCloth, truth.cloth, truth.values.data(), c) *
               (1.0 / wi.z);
      });
  const fs::path dir = fs::temp_directory_path() / "clothfit_test_merl";
  fs::create_directories(dir);
  const std::string path = (dir / "cloth.binary").string();
  WriteMerl(path, t);
  EXPECT_EQ(fs::file_size(path), size_t(12 + 3 * 90 * 90 * 180 * 8));
  const MerlTable back = ReadMerl(path);
  const BrdfFitResult r = FitBrdf(SampleMerl(back), {});
  ASSERT_TRUE(r.usable);
  std::printf("MERL cloth recovery: error %.4f\n", r.error);
  for (size_t i = 0; i < 7; ++i) EXPECT_NEAR(r.preset.values[i], truth.values[i], 0.03) << i;
  fs::remove_all(dir);
}

TEST(Merl, LookupFindsTheCellItWasTabulatedAt) {
  MerlTable t = TabulateMerl(16, 16, 32, [](const Vec3<double>& wi, const Vec3<double>& wo) {
    return Rgb<double>(wi.z, wo.z, 0.5);
  });
  for (int ih : {0, 7, 15})
    for (int id : {0, 5, 15})
      for (int ip : {0, 13, 31}) {
        Vec3<double> wi, wo;
        if (!MerlCellDirections(t, ih, id, ip, wi, wo)) continue;
        Rgb<double> f;
        ASSERT_TRUE(t.Lookup(wi, wo, f));
        EXPECT_NEAR(f[0], wi.z, 1e-9);
        EXPECT_NEAR(f[2], 0.5, 1e-9);
        ASSERT_TRUE(t.Lookup(wo, wi, f));  // reciprocity: the same cell
        EXPECT_NEAR(f[2], 0.5, 1e-9);
      }
}

TEST(Merl, BadFilesNameFileAndField) {
  const fs::path dir = fs::temp_directory_path() / "clothfit_test_merl_bad";
  fs::create_directories(dir);
  const std::string p = (dir / "short.binary").string();
  {
    std::ofstream f(p, std::ios::binary);
    const int32_t dims[3] = {90, 90, 180};
    f.write(reinterpret_cast<const char*>(dims), 12);
    f << "abc";
  }
  try {
    ReadMerl(p);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(p + ": data:"), std::string::npos) << e.what();
  }
  {
    std::ofstream f(p, std::ios::binary);
    const int32_t dims[3] = {90, -1, 180};
    f.write(reinterpret_cast<const char*>(dims), 12);
  }
  try {
    ReadMerl(p);
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("header.n_theta_d"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

TEST(BrdfFit, WovenFabricAveragedOverTheWeaveConverts) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const render::Fabric f = render::LoadFabric((fabrics / "canvas.json").string());
  const BrdfSamples s = SampleBsdf(*f.bsdf, f.weave_period_uv, 512);
  const BrdfFitResult r = FitBrdf(s, {});
  ASSERT_TRUE(r.usable);
  std::printf("canvas -> cloth: error %.4f\n", r.error);
  EXPECT_LT(r.error, BrdfError(s, render::DefaultPreset(ModelKind::kCloth)));
}

// Session 27 audit, item 1: matte cloth sources converted to the engines' GGX + sheen models
// came out mirror-smooth (three.js roughness 0.045, glTF 0.0) with a tiny reported error: the
// old (mu_l, phi) grid never sampled the narrow lobe, and the cube-root metric priced a lobe
// it did see at E^(2/3) A^(1/3), which vanishes as the lobe narrows (docs/convert.md section 2).
BrdfFitOptions EngineFit(ModelKind m) {  // as convert's FitOrThrow: dielectric, 15 iterations
  BrdfFitOptions o;
  o.model = m;
  o.locked = {m == ModelKind::kGltfSheen ? "metallic" : "metalness"};
  o.max_iterations = 15;
  return o;
}

TEST(BrdfFit, MatteClothSourcesConvertToRoughEngineMaterials) {
  // The demo's fitted velvet cloth preset (/tmp/ux2/in2/velvet_cloth.json of the audit: a
  // dark base under a strong sheen), a lighter cloth, and a near-black matte surface.
  struct Case {
    const char* name;
    render::MaterialPreset source;
  };
  render::MaterialPreset black = render::DefaultPreset(ModelKind::kStandard);
  black.values = {2e-4, 2e-4, 2e-4, 1.0, 0.0};  // the audit's tiny.binary: f = 6.7e-5 everywhere
  const Case cases[] = {
      {"velvet cloth", Cloth({0.0251, 0.0213, 0.0193}, {0.3032, 0.2679, 0.2392}, 0.314)},
      {"cloth 0.8", Cloth({0.2, 0.12, 0.08}, {0.5, 0.4, 0.35}, 0.8)},
  };
  for (const Case& c : cases)
    for (ModelKind m : {ModelKind::kPhysicalSheen, ModelKind::kGltfSheen}) {
      const BrdfFitResult r = FitBrdf(SampleAnalytic(c.source), EngineFit(m));
      ASSERT_TRUE(r.usable) << c.name;
      const double rough = r.preset.values[size_t(r.preset.Offset("roughness"))];
      std::printf("%s -> %s: roughness %.3f, error %.4f\n", c.name, render::ToString(m).c_str(),
                  rough, r.error);
      EXPECT_GT(rough, 0.8) << c.name << " -> " << render::ToString(m);
    }
  // A black matte source: the engine model's dielectric specular (F0 0.04) is all it can
  // show; spread out, not a mirror.
  BrdfSamples s = SampleAnalytic(black);
  const BrdfFitResult r = FitBrdf(s, EngineFit(ModelKind::kPhysicalSheen));
  ASSERT_TRUE(r.usable);
  EXPECT_GT(r.preset.values[3], 0.8) << "black matte -> physical-sheen";
}

TEST(BrdfFit, VelvetFabricConvertsToARoughEngineMaterial) {
  // datasets/fabrics/velvet.json (Sadeghi): before session 27, physical-sheen roughness 0.045.
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const render::Fabric f = render::LoadFabric((fabrics / "velvet.json").string());
  const BrdfSamples s = SampleBsdf(*f.bsdf, f.weave_period_uv, 512);
  for (ModelKind m : {ModelKind::kPhysicalSheen, ModelKind::kGltfSheen}) {
    const BrdfFitResult r = FitBrdf(s, EngineFit(m));
    ASSERT_TRUE(r.usable);
    const double rough = r.preset.values[size_t(r.preset.Offset("roughness"))];
    std::printf("velvet fabric -> %s: roughness %.3f, error %.4f\n", render::ToString(m).c_str(),
                rough, r.error);
    EXPECT_GT(rough, 0.8) << render::ToString(m);
  }
}

TEST(BrdfFit, GlossyGgxSourcesStayGlossy) {
  // A dielectric GGX at roughness 0.2 (standard, and glTF with a sheen) keeps its roughness
  // in physical-sheen and gltf-sheen.
  render::MaterialPreset std_src = render::DefaultPreset(ModelKind::kStandard);
  std_src.values = {0.5, 0.3, 0.2, 0.2, 0.0};
  render::MaterialPreset gltf_src = render::DefaultPreset(ModelKind::kGltfSheen);
  gltf_src.values = {0.5, 0.3, 0.2, 0.2, 0.0, 0.2, 0.2, 0.2, 0.5};
  for (const render::MaterialPreset* src : {&std_src, &gltf_src})
    for (ModelKind m : {ModelKind::kPhysicalSheen, ModelKind::kGltfSheen}) {
      BrdfFitOptions o = EngineFit(m);
      if (src->model == m) o.source_preset = src;
      const BrdfFitResult r = FitBrdf(SampleAnalytic(*src), o);
      ASSERT_TRUE(r.usable);
      const double rough = r.preset.values[size_t(r.preset.Offset("roughness"))];
      EXPECT_NEAR(rough, 0.2, 0.02) << render::ToString(src->model) << " -> "
                                    << render::ToString(m);
    }
}

TEST(BrdfFit, GltfRoughnessIsFlooredUnlessTheSourceIsSmoother) {
  // gltf-sheen's own range reaches 0; the fit stops at kMinFitRoughness (brdf_fit.h) except
  // when the source is a gltf-sheen material that is smoother: it converts to itself.
  render::MaterialPreset src = render::DefaultPreset(ModelKind::kGltfSheen);
  src.values = {0.5, 0.3, 0.2, 0.01, 0.0, 0.2, 0.2, 0.2, 0.5};
  BrdfFitOptions o = EngineFit(ModelKind::kGltfSheen);
  o.source_preset = &src;
  const BrdfFitResult self = FitBrdf(SampleAnalytic(src), o);
  ASSERT_TRUE(self.usable);
  EXPECT_NEAR(self.preset.values[3], 0.01, 1e-9);
  const BrdfFitResult other = FitBrdf(SampleAnalytic(src), EngineFit(ModelKind::kGltfSheen));
  ASSERT_TRUE(other.usable);
  EXPECT_GE(other.preset.values[3], kMinFitRoughness - 1e-12);
}

// The canonical set against a dense quadrature of the same integral (the same view weights;
// light directions through the half vector, 12 x 48 x 32 nodes, ~11 000 pairs): on a cloth
// source, a mirror-smooth physical-sheen candidate (what the old (mu_l, phi) grid fitted, error
// 0.0070 there) and a rough one (what the fit now gives). The canonical error must track the
// dense one for both (the set sees the narrow lobe) and rank them alike.
TEST(BrdfFit, CanonicalSetTracksADenseQuadratureOnNarrowLobes) {
  const render::MaterialPreset source =
      Cloth({0.0251, 0.0213, 0.0193}, {0.3032, 0.2679, 0.2392}, 0.314);
  render::MaterialPreset smooth = render::DefaultPreset(ModelKind::kPhysicalSheen);
  smooth.values = {0.0273, 0.0232, 0.0203, 0.045, 0.0, 0.3095, 0.2747, 0.2423, 0.312};
  render::MaterialPreset rough = smooth;
  rough.values = {0.0222, 0.0176, 0.0152, 1.0, 0.0, 0.2789, 0.2423, 0.2122, 0.287};
  const lut::GaussLegendre gv(12), gt(48);
  auto dense_error = [&](const render::MaterialPreset& t) {
    double se = 0.0, total = 0.0;
    for (int a = 0; a < 12; ++a) {
      const double mv = 0.5 * (gv.x[size_t(a)] + 1.0), sv = std::sqrt(1.0 - mv * mv);
      const Vec3<double> v(sv, 0.0, mv);
      for (int b = 0; b < 48; ++b) {
        const double u = 0.5 * (gt.x[size_t(b)] + 1.0), th = 0.5 * kPi * u * u;
        for (int k = 0; k < 32; ++k) {
          const double ph = (k + 0.5) * kPi / 32;
          const Vec3<double> h(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph),
                               std::cos(th));
          const double vh = Dot(v, h);
          const Vec3<double> l = h * (2.0 * vh) - v;
          if (!(vh > 0.0) || !(l.z > kMinLightCosine)) continue;
          const double w = 0.5 * gv.w[size_t(a)] * 2.0 * mv * 0.5 * gt.w[size_t(b)] * kPi * u *
                           std::sin(th) * (kPi / 32) * 4.0 * vh;
          const Cosines<double> c = CosinesFromDirections(v, l);
          const Rgb<double> fs = EvalDirectFlat(source.model, source.cloth, source.values.data(), c);
          const Rgb<double> ft = EvalDirectFlat(t.model, t.cloth, t.values.data(), c);
          for (int ch = 0; ch < 3; ++ch)
            se += w * Sq(std::sqrt(std::max(ft[ch], 0.0) + kCompressEps) -
                         std::sqrt(std::max(fs[ch], 0.0) + kCompressEps));
          total += w;
        }
      }
    }
    return std::sqrt(se / (3.0 * total));
  };
  const BrdfSamples s = SampleAnalytic(source);
  const double cs = BrdfError(s, smooth), cr = BrdfError(s, rough);
  const double ds = dense_error(smooth), dr = dense_error(rough);
  std::printf("smooth (r 0.045): canonical %.4f dense %.4f; rough (r 1): canonical %.4f dense %.4f\n",
              cs, ds, cr, dr);
  // Measured: smooth canonical 0.0789, dense 0.1142 (0.1143 at 24 x 96 x 64: converged): the
  // set's two nodes inside the lobe undercount it by 31 % (the old grid, in its cube-root metric,
  // scored this candidate 0.0070: it saw no lobe);
  // rough 0.0165 vs 0.0163.
  EXPECT_GT(cs, 0.6 * ds);
  EXPECT_LT(cs, 1.1 * ds);
  EXPECT_NEAR(cr, dr, 0.1 * dr);
  EXPECT_GT(ds, 3 * dr);
  EXPECT_GT(cs, 3 * cr);
}

// The direction set covers the light on one side of the plane of incidence only (phi_h in
// [0, pi]; brdf_fit.h), which is exact for a source symmetric under the mirror y -> -y. A
// twill is chiral: averaged over its period and over rotations, a pair and its mirror image
// still differ, so SampleBsdf averages each pair with its mirror image (session 28). Checked:
// the samples of the twill equal those of the twill seen in the mirror, and a pair and its
// mirror image really do differ (else the first check would pass without the averaging).
class MirroredBsdf final : public render::Bsdf {
 public:
  explicit MirroredBsdf(const render::Bsdf& inner) : inner_(inner) {}
  render::Rgbd Eval(const render::Vec3d& wo, const render::Vec3d& wi,
                    const render::ShadingPoint& sp) const override {
    return inner_.Eval({wo.x, -wo.y, wo.z}, {wi.x, -wi.y, wi.z}, sp);
  }
  double Pdf(const render::Vec3d& wo, const render::Vec3d& wi,
             const render::ShadingPoint& sp) const override {
    return inner_.Pdf({wo.x, -wo.y, wo.z}, {wi.x, -wi.y, wi.z}, sp);
  }
  bool Sample(const render::Vec3d&, const render::Point2d&, double, const render::ShadingPoint&,
              render::BsdfSample*) const override {
    return false;  // not used by SampleBsdf
  }
  std::string Name() const override { return "mirrored " + inner_.Name(); }

 private:
  const render::Bsdf& inner_;
};

TEST(BrdfFit, ChiralWeaveIsSampledSymmetrically) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const render::Fabric f = render::LoadFabric((fabrics / "twill-noglint.json").string());
  const MirroredBsdf mirrored(*f.bsdf);
  // The mirror of a rotated pair is the mirrored pair rotated the other way; SampleBsdf takes
  // the mirror image of each evaluated pair, so both sources sum the same terms.
  const BrdfSamples a = SampleBsdf(*f.bsdf, f.weave_period_uv, 64);
  const BrdfSamples b = SampleBsdf(mirrored, f.weave_period_uv, 64);
  ASSERT_EQ(a.value.size(), b.value.size());
  double max_rel = 0.0;
  for (size_t k = 0; k < a.value.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      const double x = a.value[k][c], y = b.value[k][c];
      max_rel = std::max(max_rel, std::abs(x - y) / std::max({std::abs(x), std::abs(y), 1e-3}));
    }
  std::printf("twill: samples against the mirrored twill's, max relative difference %.3g\n",
              max_rel);
  EXPECT_LT(max_rel, 1e-12);
  // The guard: without the mirror term the two would differ. Each pair averaged over 8 x 8
  // points of a period and 64 azimuths, for the twill and for the mirrored twill.
  const auto& dirs = CanonicalDirections();
  double num = 0.0, den = 0.0;
  for (size_t k = 0; k < dirs.size(); k += 3) {
    render::Rgbd s(0, 0, 0), t(0, 0, 0);
    for (int r = 0; r < 64; ++r) {
      const double phi = 2.0 * kPi * (r + 0.5) / 64, c = std::cos(phi), sn = std::sin(phi);
      const Vec3<double>& dv = dirs[k].v;
      const Vec3<double>& dl = dirs[k].l;
      const render::Vec3d v(c * dv.x - sn * dv.y, sn * dv.x + c * dv.y, dv.z);
      const render::Vec3d l(c * dl.x - sn * dl.y, sn * dl.x + c * dl.y, dl.z);
      for (int i = 0; i < 8; ++i)
        for (int j = 0; j < 8; ++j) {
          render::ShadingPoint sp;
          sp.uv = {(i + 0.5) / 8 * f.weave_period_uv, (j + 0.5) / 8 * f.weave_period_uv};
          s += f.bsdf->Eval(v, l, sp);
          t += mirrored.Eval(v, l, sp);
        }
    }
    num += dirs[k].weight * std::abs(s[1] - t[1]);
    den += dirs[k].weight * 0.5 * (s[1] + t[1]);
  }
  std::printf("twill, isotropic average: a pair against its mirror image, weighted mean "
              "relative difference %.3g\n",
              num / den);
  EXPECT_GT(num / den, 0.01);
}

// The source's point and azimuth draws against a plain Monte Carlo average of the same
// quantity: per canonical pair, uniformly random points over 64 x 64 periods and random
// azimuths (Pcg32, independent of the R3 draws), each with its mirror image. An Irawan fabric
// (its BSDF without the fineness glints, as SampleFabric draws it: a per-pair average of the
// glints needs far more draws than this test can afford; their mean is checked against the
// glinted BSDF by WovenSourceAlbedoMatchesAnIndependentEstimate) and a Sadeghi one (velvet: a
// tilted pile, which a rotation set over [0, pi) does not average). Not the denim: its narrow
// yarn highlights make the per-pair average converge slowly (measured against 131072 draws:
// 1.5 % at 4096, 1.4 % at 16384; the random average at 16384: 2.6 %).
TEST(BrdfFit, WovenSourceMatchesARandomAverage) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const auto& dirs = CanonicalDirections();
  for (const char* name : {"twill.json", "velvet.json"}) {
    const render::Fabric fabric = render::LoadFabric((fabrics / name).string());
    const BrdfSamples s = SampleFabric(fabric);
    std::unique_ptr<render::IrawanBsdf> plain;
    if (const auto* irawan = dynamic_cast<const render::IrawanBsdf*>(fabric.bsdf.get())) {
      render::WeavePattern pattern = irawan->pattern();
      pattern.fineness = 0.0;
      plain = std::make_unique<render::IrawanBsdf>(pattern, irawan->repeat_u(), irawan->repeat_v());
    }
    struct {
      const render::Bsdf* bsdf;
      double weave_period_uv;
      std::string model;
    } const f{plain ? plain.get() : fabric.bsdf.get(), fabric.weave_period_uv, fabric.model};
    render::Pcg32 rng(5, 9);
    const int n = f.model == "irawan" ? 16384 : 2048;
    std::vector<double> mc(dirs.size(), 0.0);
    for (int i = 0; i < n; ++i) {
      render::ShadingPoint sp;
      const double extent = 64.0 * f.weave_period_uv;
      sp.uv = {extent * rng.Uniform(), extent * rng.Uniform()};
      const double phi = 2.0 * kPi * rng.Uniform(), c = std::cos(phi), sn = std::sin(phi);
      for (size_t k = 0; k < dirs.size(); ++k) {
        const Vec3<double>& dv = dirs[k].v;
        const Vec3<double>& dl = dirs[k].l;
        const render::Vec3d v(c * dv.x - sn * dv.y, sn * dv.x + c * dv.y, dv.z);
        const render::Vec3d l(c * dl.x - sn * dl.y, sn * dl.x + c * dl.y, dl.z);
        const render::Vec3d vm(v.x, -v.y, v.z), lm(l.x, -l.y, l.z);
        mc[k] += 0.5 * l.z * (f.bsdf->Eval(v, l, sp)[1] + f.bsdf->Eval(vm, lm, sp)[1]);
      }
    }
    double num = 0.0, den = 0.0;
    for (size_t k = 0; k < dirs.size(); ++k) {
      num += dirs[k].weight * std::abs(s.value[k][1] - mc[k] / n);
      den += dirs[k].weight * mc[k] / n;
    }
    std::printf("%s: source against a random average, weighted mean relative difference %.4f\n",
                name, num / den);
    // Measured 0.5 % (twill), 1.2 % (velvet). The pre-session-28 source differs from this
    // one by 75 % (twill) and 34 % (velvet), weighted the same way.
    EXPECT_LT(num / den, 0.03) << name;
  }
}

// The woven source against an independent estimate of the same average. For each view cosine
// of the direction set, the source's directional albedo (its half-hemisphere sum times 2:
// valid because the samples are mirror-averaged) must match a Monte Carlo estimate from the
// BSDF's own importance sampling at uniformly random surface points over 64 x 64 periods and
// random azimuths. Before session 28 the source was a 4 x 4 grid of one period: the twill's
// 4 x 8 yarn-cell tile was sampled on every other cell row only and its albedo came out
// 1.6-1.9x too high (convert's cloth base colour: green 0.342 against 0.208 now).
TEST(BrdfFit, WovenSourceAlbedoMatchesAnIndependentEstimate) {
  const fs::path fabrics = fs::path(CLOTHFIT_TEST_SOURCE_DIR) / "datasets" / "fabrics";
  const auto& dirs = CanonicalDirections();
  // Directional albedo from the samples: the sum over the half hemisphere (pi sr) times 2.
  const auto albedo = [&](const BrdfSamples& s) {
    std::map<double, std::pair<double, double>> per_view;  // mu_v -> (sum w f cos, sum w)
    for (size_t k = 0; k < dirs.size(); ++k) {
      auto& a = per_view[dirs[k].v.z];
      a.first += dirs[k].weight * s.value[k][1];
      a.second += dirs[k].weight;
    }
    std::map<double, double> out;
    for (const auto& [mu, a] : per_view) out[mu] = 2.0 * kPi * a.first / a.second;
    return out;
  };
  // The direction set is a rule for lobes, not for a cosine: a Lambert surface of albedo 0.5
  // comes out 0.47-0.53 per view. The fabrics are mostly diffuse, so their albedo is compared
  // relative to that.
  const render::LambertBsdf lambert({0.5, 0.5, 0.5});
  const std::map<double, double> rule = albedo(SampleBsdf(lambert, 1.0, 1));
  // (Not the satin: its source converges to 0.3 % at 1024 azimuths, but its sharp lobe is
  // integrated by the direction set 5-9 % below the Monte Carlo albedo, a property of the
  // rule, not of the source average tested here.)
  for (const char* name : {"twill.json", "denim.json", "canvas.json"}) {
    const render::Fabric f = render::LoadFabric((fabrics / name).string());
    const std::map<double, double> source = albedo(SampleFabric(f));
    render::Pcg32 rng(7, 11);
    for (const auto& [mu, a] : source) {
      double sum = 0.0;
      const int n = 200000;
      for (int i = 0; i < n; ++i) {
        const double phi = 2.0 * kPi * rng.Uniform(), st = std::sqrt(1.0 - mu * mu);
        const render::Vec3d wo(st * std::cos(phi), st * std::sin(phi), mu);
        render::ShadingPoint sp;
        const double extent = 64.0 * f.weave_period_uv;
        sp.uv = {extent * rng.Uniform(), extent * rng.Uniform()};
        render::BsdfSample bs;
        if (!f.bsdf->Sample(wo, {rng.Uniform(), rng.Uniform()}, rng.Uniform(), sp, &bs)) continue;
        if (bs.pdf > 0.0 && bs.wi.z > kMinLightCosine) sum += bs.f[1] * bs.wi.z / bs.pdf;
      }
      const double mc = sum / n, src = a * 0.5 / rule.at(mu);
      std::printf("%s mu_v %.3f: albedo source %.4f (rule-corrected %.4f), Monte Carlo %.4f\n",
                  name, mu, a, src, mc);
      // Measured 0.98-1.02 (the pre-session-28 source: 1.6-1.9x on the twill, 0.64-0.92x
      // on the denim).
      EXPECT_NEAR(src / mc, 1.0, 0.03) << name << " mu_v " << mu;
    }
  }
}

}  // namespace
}  // namespace clothfit::fit
