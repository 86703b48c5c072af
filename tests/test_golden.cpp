// Golden values: every term and the table-free part of every model at fixed angles, against
// an independent Python implementation (tests/golden/gen_golden.py), atol 1e-6 (double).
// A failure here means a model changed: regenerate only on purpose, and review the diff.
#include <gtest/gtest.h>

#include <array>
#include <functional>
#include <map>
#include <string>

#include "brdf/cloth.h"
#include "brdf/gltf_sheen.h"
#include "brdf/physical_sheen.h"
#include "brdf/terms.h"

namespace clothfit {
namespace {

struct GoldenEntry {
  const char* name;
  std::array<double, 3> value;
};
#include "tests/golden/golden_values.inc"

const Cosines<double> kC{kGoldenNoV, kGoldenNoL, kGoldenNoH, kGoldenLoH};

std::array<double, 3> A(const Rgb<double>& c) { return {c.r, c.g, c.b}; }
std::array<double, 3> S(double v) { return {v, 0.0, 0.0}; }

// An 8-wide step table (texel centres 0.0625 ... 0.9375): 0.3 up to texel 5 (u = 0.6875),
// 0.4 from texel 6 (u = 0.8125) on, so E(NoL = 0.643) = 0.3 and E(NoV = 0.866) = 0.4 exactly.
Table2D StepTable() {
  Table2D t(8, 8, 1);
  for (int j = 0; j < 8; ++j)
    for (int i = 0; i < 8; ++i) t.at(i, j, 0) = i <= 5 ? 0.3f : 0.4f;
  return t;
}

std::map<std::string, std::function<std::array<double, 3>()>> Computations() {
  std::map<std::string, std::function<std::array<double, 3>()>> m;
  for (double r : {0.3, 0.7, 1.0}) {
    const double a = r * r;
    char buf[64];
    auto key = [&](const char* f) {
      std::snprintf(buf, sizeof buf, f, r);
      return std::string(buf);
    };
    m[key("D_Charlie r=%g")] = [a] { return S(D_Charlie(a, kC.NoH)); };
    m[key("D_GGX r=%g")] = [a] { return S(D_GGX(a, kC.NoH)); };
    m[key("V_Smith r=%g")] = [a] { return S(V_SmithGGXCorrelated(a, kC.NoV, kC.NoL)); };
    m[key("V_Charlie r=%g")] = [a] { return S(V_Charlie(kC.NoV, kC.NoL, a)); };
    m[key("Lambda_Charlie(NoV) r=%g")] = [a] { return S(Lambda_Charlie(kC.NoV, a)); };
    m[key("Lambda_Charlie(0.3) r=%g")] = [a] { return S(Lambda_Charlie(0.3, a)); };
    m[key("SheenAlbedoFit(NoV) r=%g")] = [r] {
      return S(physical_sheen::SheenAlbedoFit(kC.NoV, r));
    };
  }
  m["D_Charlie grazing r=0.5"] = [] { return S(D_Charlie(0.25, 0.999)); };
  m["V_Neubelt"] = [] { return S(V_Neubelt(kC.NoV, kC.NoL)); };
  m["V_Neubelt clamped grazing"] = [] { return S(V_Neubelt(0.05, 0.1, NeubeltClamp::kOne)); };
  m["F_SG"] = [] { return S(F_SchlickWeight(kC.LoH, FresnelForm::kSphericalGaussian)); };
  m["F_pow5"] = [] { return S(F_SchlickWeight(kC.LoH, FresnelForm::kPow5)); };
  m["Fd_Wrap(NoL, 0.5)"] = [] { return S(Fd_Wrap(kC.NoL, 0.5)); };
  m["Fd_Wrap(-0.2, 0.5)"] = [] { return S(Fd_Wrap(-0.2, 0.5)); };

  cloth::Params<double> p;
  p.base_color = {0.6, 0.35, 0.2};
  p.sheen_color = {0.8, 0.7, 0.5};
  p.roughness = 0.6;
  p.subsurface_color = {0.4, 0.1, 0.05};
  m["cloth/filament r=0.6"] = [p] { return A(cloth::EvalDirect(p, {}, kC)); };
  m["cloth/filament+subsurface r=0.6"] = [p] {
    cloth::Options o;
    o.subsurface = true;
    return A(cloth::EvalDirect(p, o, kC));
  };
  m["cloth/filament+subsurface NoL=-0.2 r=0.6"] = [p] {
    cloth::Options o;
    o.subsurface = true;
    return A(cloth::EvalDirect(p, o, Cosines<double>{kC.NoV, -0.2, kC.NoH, kC.LoH}));
  };
  m["cloth/seed r=0.6"] = [p] {
    cloth::Options o;
    o.variant = cloth::Variant::kSeedThreejs;
    o.sheen_default = cloth::SheenDefault::kSqrtBaseColor;
    return A(cloth::EvalDirect(p, o, kC));
  };
  m["cloth/seed+subsurface r=0.6"] = [p] {
    cloth::Options o;
    o.variant = cloth::Variant::kSeedThreejs;
    o.sheen_default = cloth::SheenDefault::kSqrtBaseColor;
    o.subsurface = true;
    return A(cloth::EvalDirect(p, o, kC));
  };
  m["gltf-sheen direct (E=0.4,0.3) r=0.5 rs=0.6"] = [] {
    const Table2D t = StepTable();
    gltf_sheen::Params<double> g;
    g.base_color = {0.6, 0.35, 0.2};
    g.roughness = 0.5;
    g.sheen_color = {0.5, 0.4, 0.3};
    g.sheen_roughness = 0.6;
    return A(gltf_sheen::EvalDirect(g, {}, kC, t));
  };
  return m;
}

TEST(Golden, EveryStoredValueIsReproduced) {
  const auto computations = Computations();
  int checked = 0;
  for (const GoldenEntry& e : kGolden) {
    auto it = computations.find(e.name);
    ASSERT_NE(it, computations.end()) << "no computation for golden entry '" << e.name << "'";
    const std::array<double, 3> got = it->second();
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(got[size_t(k)], e.value[size_t(k)], 1e-6) << e.name << " channel " << k;
    }
    ++checked;
  }
  EXPECT_EQ(checked, int(computations.size())) << "a computation has no golden entry";
}

TEST(Golden, TableLookupOfTheGltfFixtureIsWhatTheGeneratorAssumed) {
  // Guard the fixture: if this fails, the golden glTF entry tests the wrong thing.
  const Table2D t = StepTable();
  EXPECT_NEAR(t.Sample(kGoldenNoL, 0.6, 0), 0.3, 1e-7);
  EXPECT_NEAR(t.Sample(kGoldenNoV, 0.6, 0), 0.4, 1e-7);
}

}  // namespace
}  // namespace clothfit
