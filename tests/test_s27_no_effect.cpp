// Session 27: woven's degenerate solution (fit/image_fit.h ParametersWithoutEffect,
// ApplyNoEffect). At anisotropy 0, with woven's own GGX yarn lobes, both lobes are one
// isotropic lobe: `twist` has no effect on the image, nor has `warp_share` without weave maps
// or tints. A bound on them, or on the anisotropy at 0, is reported unflagged (before, a woven
// fit of a smooth reference exited 3 with "warp_share at its lower bound"); a bound on a
// parameter that matters is still flagged.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "fit/image_fit.h"
#include "render/preview/preview.h"
#include "tests/fit_fixtures.h"

namespace clothfit::fit {
namespace {
using render::ModelKind;

render::MaterialPreset Woven(std::initializer_list<std::pair<const char*, double>> values) {
  render::MaterialPreset p = render::DefaultPreset(ModelKind::kWoven);
  for (const auto& [name, v] : values) p.values[size_t(p.Offset(name))] = v;
  return p;
}

FitOptions WovenOptions(const render::MaterialPreset& start) {
  FitOptions o;
  o.start = start;
  return o;
}

std::vector<std::string> NoEffect(const render::MaterialPreset& p, const FitOptions& o) {
  std::string why;
  std::vector<std::string> names = ParametersWithoutEffect(p, o, &why);
  if (!names.empty()) {
    EXPECT_EQ(why, "at anisotropy 0");
  }
  return names;
}

// Max |a - b| over two frames.
double MaxDifference(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0.0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    d = std::max(d, std::abs(double(a[i]) - double(b[i])));
  return d;
}

// The claim itself, on the preview (lights and environment): at anisotropy 0 the frame does
// not change with warp_share and twist; at anisotropy 0.5 it does.
TEST(S27NoEffect, WarpShareAndTwistDoNotChangeTheImageAtAnisotropyZero) {
  const render::Scene s = KeyRimSphereScene(32, 3.0);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  for (const double s_aniso : {0.0, 0.5}) {
    const Reference a = PreviewReference(
        s, &env, Woven({{"anisotropy", s_aniso}, {"warp_share", 0.0}, {"twist", -90.0}}));
    const Reference b = PreviewReference(
        s, &env, Woven({{"anisotropy", s_aniso}, {"warp_share", 1.0}, {"twist", 37.0}}));
    double peak = 0.0;
    for (float v : a.rgb) peak = std::max(peak, double(v));
    const double d = MaxDifference(a.rgb, b.rgb);
    if (s_aniso == 0.0)
      EXPECT_LE(d, 1e-6 * peak) << "anisotropy 0: warp_share / twist changed the frame";
    else
      EXPECT_GT(d, 1e-3 * peak) << "anisotropy 0.5: warp_share / twist did not change the frame";
  }
}

TEST(S27NoEffect, WarpShareAndTwistAreListedOnlyWhereTheyHaveNoEffect) {
  const render::MaterialPreset iso = Woven({{"anisotropy", 0.0}});
  EXPECT_EQ(NoEffect(iso, WovenOptions(iso)), (std::vector<std::string>{"warp_share", "twist"}));
  // within the bound tolerance of ParametersAtBounds, not beyond it
  const render::MaterialPreset tiny = Woven({{"anisotropy", 0.5 * kIsotropicAnisotropy}});
  EXPECT_EQ(NoEffect(tiny, WovenOptions(tiny)).size(), 2u);
  for (const double s : {1e-3, 0.5, 1.0}) {
    const render::MaterialPreset p = Woven({{"anisotropy", s}});
    EXPECT_TRUE(NoEffect(p, WovenOptions(p)).empty()) << "anisotropy " << s;
  }
  // locked parameters are not listed
  FitOptions o = WovenOptions(iso);
  o.locked = {"twist"};
  EXPECT_EQ(NoEffect(iso, o), std::vector<std::string>{"warp_share"});
  // the two lobes weighted differently per pixel (weave maps) or per colour (tints): warp_share
  // matters, twist still does not
  render::MaterialPreset maps = iso;
  maps.extra["weave_maps"] = {{"file", "x.weave.exr"}};
  EXPECT_EQ(NoEffect(maps, WovenOptions(maps)), std::vector<std::string>{"twist"});
  render::MaterialPreset tint = iso;
  tint.woven.tint_weft = Rgb<double>(0.8, 0.9, 1.0);
  EXPECT_EQ(NoEffect(tint, WovenOptions(tint)), std::vector<std::string>{"twist"});
  // not the GGX lobes (the bent-normal IBL's tables) or another model: nothing is claimed
  render::MaterialPreset bent = iso;
  bent.woven.ibl = woven::IblMode::kBent;
  EXPECT_TRUE(NoEffect(bent, WovenOptions(bent)).empty());
  const render::MaterialPreset aniso = [] {
    render::MaterialPreset p = render::DefaultPreset(ModelKind::kPhysicalAniso);
    p.values[size_t(p.Offset("anisotropy_strength"))] = 0.0;
    return p;
  }();
  EXPECT_TRUE(NoEffect(aniso, WovenOptions(aniso)).empty());
}

// FitImages' bounds: the parameters without effect and the anisotropy at 0 unflagged, a bound
// that matters flagged, and every bound flagged when the anisotropy is not 0.
TEST(S27NoEffect, BoundsWithoutEffectAreNotFlagged) {
  const auto result = [](double anisotropy) {
    FitResult r;
    r.preset = Woven({{"anisotropy", anisotropy}, {"warp_share", 0.0}, {"twist", 90.0},
                      {"specular_f0", 1.0}});
    r.at_bound = ParametersAtBounds(r.preset, {"sheen_color"});  // (a colour at 0: unflagged)
    return r;
  };
  FitResult r = result(0.0);
  ApplyNoEffect(WovenOptions(r.preset), &r);
  std::vector<std::string> flagged, unflagged;
  for (const AtBound& b : r.at_bound) (b.flagged ? flagged : unflagged).push_back(b.name);
  std::sort(unflagged.begin(), unflagged.end());
  EXPECT_EQ(unflagged, (std::vector<std::string>{"anisotropy", "twist", "warp_share"}));
  EXPECT_NE(std::find(flagged.begin(), flagged.end(), "specular_f0"), flagged.end());

  r = result(0.4);
  ApplyNoEffect(WovenOptions(r.preset), &r);
  for (const AtBound& b : r.at_bound) {
    if (b.name == "warp_share" || b.name == "twist" || b.name == "specular_f0") {
      EXPECT_TRUE(b.flagged) << b.name << " at anisotropy 0.4";
    }
  }
}

// The whole fit: anisotropy held at 0, warp_share and twist started on their bounds stay
// there (their derivative is 0) and are reported at the bound, unflagged.
TEST(S27NoEffect, SyntheticFitAtAnisotropyZeroLeavesWarpShareAndTwistUnflagged) {
  const render::Scene s = KeyRimSphereScene(32, 3.0);
  const render::Environment env = render::Environment::ProceduralSky(1.0, 0.7);
  const Reference ref = PreviewReference(s, &env, Woven({{"anisotropy", 0.0}}));
  FitOptions o = WovenOptions(Woven({{"anisotropy", 0.0}, {"warp_share", 0.0}, {"twist", 90.0}}));
  o.level = 0;
  o.loss = Loss::kNone;
  o.init_from_reference = false;
  o.start_roughness = {0.0};
  o.locked = {"anisotropy", "sheen_color", "sheen_roughness", "diffuse_roughness",
              "specular_f0", "forward_scattering"};
  const FitResult r = FitImages({{&s, &env, &ref, nullptr, "test"}}, o);
  ASSERT_TRUE(r.usable) << r.message;
  int seen = 0;
  for (const AtBound& b : r.at_bound)
    if (b.name == "warp_share" || b.name == "twist") {
      ++seen;
      EXPECT_FALSE(b.flagged) << b.name;
    }
  EXPECT_EQ(seen, 2);
}

}  // namespace
}  // namespace clothfit::fit
