// The preview's visibility prototype (render/preview/visibility.h, PreviewOptions::visibility;
// docs/visibility.md): a ray-traced AO map and one-bounce light map applied as three.js r187
// applies aoMap / lightMap. Checks: three.js's computeSpecularOcclusion by hand; a convex
// object is unoccluded (AO exactly 1, the frame bit-identical to the option-off frame); a floor
// point next to a wall matches the configuration factor of an infinitely long strip; the
// light map's bounce off a lit wall matches its closed form; the fit's sampled cache equals the
// full frame at its pixels; options off (whatever the other fields) leave the frame unchanged.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <vector>

#include "render/preview/preview.h"
#include "render/preview/visibility.h"
#include "render/scene/embree_scene.h"
#include "render/scene/environment.h"
#include "tests/preview_fixtures.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

using Vec3d = Vec3<double>;

// An axis-aligned quad mesh with the given corners (counter-clockwise seen from `normal`).
Mesh Quad(const std::array<Vec3d, 4>& c, const Vec3d& normal, bool fabric, float albedo) {
  Mesh m;
  m.name = "quad";
  m.is_fabric = fabric;
  m.base_color = {albedo, albedo, albedo};
  for (int k = 0; k < 4; ++k) {
    m.positions.push_back({float(c[size_t(k)].x), float(c[size_t(k)].y), float(c[size_t(k)].z)});
    m.normals.push_back({float(normal.x), float(normal.y), float(normal.z)});
    m.uvs.push_back({float(k == 1 || k == 2), float(k >= 2)});
    m.tangents.push_back({1.f, 0.f, 0.f, 1.f});
  }
  m.indices = {0, 1, 2, 0, 2, 3};
  return m;
}

// standard flat parameters: base colour, roughness, metalness.
std::vector<double> StandardFlat(double r) { return {0.5, 0.4, 0.3, r, 0.0}; }

// A fabric sphere resting on a grey floor (non-fabric), a directional key light: the lower
// part of the sphere and the floor around it are occluded.
Scene SphereOnFloor(int size) {
  Scene s = CameraScene(size, size, {0, 0.3, 3}, {0, -0.1, -1}, 0.5);
  s.meshes.push_back(SphereMesh(0.5, 96, 48, true, 0.f));
  s.meshes.push_back(Quad({Vec3d(-5, -0.5, 5), Vec3d(5, -0.5, 5), Vec3d(5, -0.5, -5),
                           Vec3d(-5, -0.5, -5)},
                          Vec3d(0, 1, 0), false, 0.5f));
  Light key;
  key.type = Light::Type::kDirectional;
  key.intensity = 2.0;
  key.direction = {0.3, -0.8, -0.5};
  s.lights = {key};
  return s;
}

// The cache pixels the AO map occludes (ao < 0.99), with ao recovered from the diffuse
// irradiance: `on` built with the AO map alone, `off` without (E_d x ao).
std::vector<std::pair<size_t, double>> OccludedPixels(const PreviewCache& on, const PreviewCache& off) {
  std::vector<std::pair<size_t, double>> out;
  for (size_t i = 0; i < on.pixels.size(); ++i) {
    if (!(off.irradiance[i * 3 + 1] > 1e-3f)) continue;
    const double ao = double(on.irradiance[i * 3 + 1]) / double(off.irradiance[i * 3 + 1]);
    if (ao <= 0.99) out.emplace_back(i, ao);
  }
  return out;
}

// three.js r187 lights_physical_pars_fragment:
// saturate(pow(dotNV + ao, exp2(-16 roughness - 1)) - 1 + ao), evaluated by hand.
TEST(S9Visibility, SpecularOcclusionIsThreejsFormula) {
  EXPECT_DOUBLE_EQ(SpecularOcclusion(0.5, 0.5, 0.0), 0.5);           // pow(1, 0.5) - 0.5
  EXPECT_NEAR(SpecularOcclusion(0.5, 0.3, 0.0), std::sqrt(0.8) - 0.7, 1e-15);
  EXPECT_NEAR(SpecularOcclusion(0.2, 0.6, 0.25), std::pow(0.8, 1.0 / 32.0) - 0.4, 1e-15);
  EXPECT_DOUBLE_EQ(SpecularOcclusion(0.7, 1.0, 0.4), 1.0);           // saturate: no occlusion
  EXPECT_DOUBLE_EQ(SpecularOcclusion(0.1, 0.0, 0.0), 0.0);           // saturate(pow(0.1, .5) - 1)
  // At r = 1 it is ao up to (n.v + ao)^(2^-17) - 1 ~ 7.6e-6 ln(n.v + ao).
  EXPECT_NEAR(SpecularOcclusion(0.5, 0.4, 1.0), 0.4, 1e-5);
}

// A convex object alone: every direction of the shading normal's hemisphere that is above the
// flat triangle leaves the scene, so ao = 1 exactly, the bounce is 0, and the frame equals
// the option-off frame bit for bit (also the non-fabric shading path, which has none here).
TEST(S9Visibility, ConvexSphereIsUnoccludedAndBitIdentical) {
  const Scene s = SphereWithLight(48);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions off;
  off.model = ModelKind::kStandard;
  PreviewOptions on = off;
  on.visibility.ao = true;
  on.visibility.indirect = true;
  on.visibility.samples = 256;
  std::unique_ptr<PreviewCache> c0, c1;
  const auto a = PreviewFrame(s, env, off, StandardFlat(0.4), &c0);
  const auto b = PreviewFrame(s, env, on, StandardFlat(0.4), &c1);
  ASSERT_GT(a.size(), 800u);
  ASSERT_EQ(c0->irradiance.size(), c1->irradiance.size());
  for (size_t i = 0; i < c0->irradiance.size(); ++i)
    ASSERT_EQ(c0->irradiance[i], c1->irradiance[i]);
  for (size_t i = 0; i < c0->radiance.size(); ++i) ASSERT_EQ(c0->radiance[i], c1->radiance[i]);
  for (size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].r, b[i].r) << "pixel " << i;
    ASSERT_EQ(a[i].g, b[i].g);
    ASSERT_EQ(a[i].b, b[i].b);
  }
  EXPECT_EQ(c0->background, c1->background);
}

// A point on a floor (normal +z) at distance d from a wall x = 0 of height h, infinitely long
// in y. In the cross-section the configuration factor from a differential planar element to
// an infinitely long strip is F = (sin t2 - sin t1) / 2, t measured from the element's normal
// (Howell, "A Catalog of Radiation Heat Transfer Configuration Factors", case B-2; Siegel &
// Howell, Thermal Radiation Heat Transfer, the "crossed-strings" 2D form). The wall spans
// t1 = atan(d / h) (its top) to t2 = pi / 2 (its foot), so the wall takes
// F = (1 - d / sqrt(d^2 + h^2)) / 2 of the cosine-weighted hemisphere and
//   ao = 1 - F = 1/2 + d / (2 sqrt(d^2 + h^2)),
// 1/2 at the foot of the wall (a concave right-angle corner hides exactly half) and -> 1 far
// away. The wall here is 2000 h long, so the finite length leaves it < 1e-6 more open.
TEST(S9Visibility, FloorPointNextToWallMatchesStripConfigurationFactor) {
  const double h = 1.0;
  Scene s = CameraScene(8, 8, {5, 0, 5}, {0, 0, -1}, 0.5);
  s.meshes.push_back(Quad({Vec3d(0, -1000, 0), Vec3d(0, 1000, 0), Vec3d(0, 1000, h),
                           Vec3d(0, -1000, h)},
                          Vec3d(1, 0, 0), false, 0.5f));
  const EmbreeScene bvh(s);
  VisibilityOptions o;
  o.ao = true;
  o.samples = 8192;
  for (double d : {1e-4, 0.25, 1.0, 3.0}) {
    const double expect = 0.5 + d / (2.0 * std::sqrt(d * d + h * h));
    double mean = 0.0;
    const int pixels = 8;  // different per-pixel shifts: the mean's noise shrinks
    for (int px = 0; px < pixels; ++px) {
      const VisibilityTerms t = ComputeVisibility(s, bvh, o, {}, Vec3d(d, 0.1 * px, 1e-6),
                                                  Vec3d(0, 0, 1), Vec3d(0, 0, 1), size_t(px), 1e-6);
      EXPECT_GE(t.ao, 0.0);
      EXPECT_LE(t.ao, 1.0);
      EXPECT_NEAR(t.ao, expect, 0.01) << "d " << d << " pixel " << px;
      mean += t.ao / pixels;
    }
    EXPECT_NEAR(mean, expect, 0.003) << "d " << d;
  }
  // max_distance: an occluder beyond it does not count.
  o.max_distance = 0.5;
  const VisibilityTerms far = ComputeVisibility(s, bvh, o, {}, Vec3d(1.0, 0, 1e-6),
                                                Vec3d(0, 0, 1), Vec3d(0, 0, 1), 0, 1e-6);
  EXPECT_EQ(far.ao, 1.0);
}

// The light map's bounce: a floor point at the foot of the same wall, the wall (albedo rho)
// lit head-on by a directional light of irradiance E (no environment, nothing shadows the
// wall's front). The wall is Lambertian with radiance rho E / pi everywhere, so
//   E_ind / pi = (rho E / pi) F,  F = (1 - d / sqrt(d^2 + h^2)) / 2 (the strip factor above).
TEST(S9Visibility, BounceOffLitWallMatchesClosedForm) {
  const double h = 1.0, rho = 0.6, E = 2.0;
  Scene s = CameraScene(8, 8, {5, 0, 5}, {0, 0, -1}, 0.5);
  s.meshes.push_back(Quad({Vec3d(0, -1000, 0), Vec3d(0, 1000, 0), Vec3d(0, 1000, h),
                           Vec3d(0, -1000, h)},
                          Vec3d(1, 0, 0), false, float(rho)));
  Light l;
  l.type = Light::Type::kDirectional;
  l.intensity = E;
  l.direction = {-1.0, 0.0, 0.0};  // travelling towards -x: hits the wall's +x face head-on
  s.lights = {l};
  const EmbreeScene bvh(s);
  VisibilityOptions o;
  o.indirect = true;
  o.samples = 8192;
  for (double d : {0.25, 1.0}) {
    const double F = (1.0 - d / std::sqrt(d * d + h * h)) / 2.0;
    const double expect = rho * E / kPi * F;
    const VisibilityTerms t = ComputeVisibility(s, bvh, o, {}, Vec3d(d, 0, 1e-6), Vec3d(0, 0, 1),
                                                Vec3d(0, 0, 1), 3, 1e-6);
    EXPECT_NEAR(t.indirect_over_pi.r, expect, 0.01 * expect + 1e-4) << "d " << d;
    EXPECT_NEAR(t.ao, 1.0 - F, 0.01);
  }
}

// The fit keeps one pixel per stride cell (PreviewOptions::sample_mask): those pixels must
// carry exactly the full frame's visibility terms (directions seeded by the pixel index).
// The scene is occluded (a sphere on a floor), so the terms are not trivially 1 / 0.
TEST(S9Visibility, SampledCacheEqualsFullFrame) {
  const Scene s = SphereOnFloor(48);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions o;
  o.model = ModelKind::kStandard;
  o.shadows = true;
  o.visibility.ao = true;
  o.visibility.indirect = true;
  o.visibility.samples = 32;
  o.visibility.hit_samples = 4;
  std::unique_ptr<PreviewCache> full, part, plain;
  PreviewOptions off = o;
  off.visibility = VisibilityOptions{};
  const auto x = StandardFlat(0.5);
  const auto a = PreviewFrame(s, env, o, x, &full);
  const auto z = PreviewFrame(s, env, off, x, &plain);
  PreviewOptions om = o;
  om.sample_mask.assign(size_t(s.card.width) * size_t(s.card.height), 0);
  for (size_t p = 0; p < om.sample_mask.size(); p += 3) om.sample_mask[p] = 1;
  const auto m = PreviewFrame(s, env, om, x, &part);
  ASSERT_GT(part->pixels.size(), 100u);
  std::map<int, size_t> full_index;
  for (size_t i = 0; i < full->pixels.size(); ++i) full_index[full->pixels[i]] = i;
  for (size_t i = 0; i < part->pixels.size(); ++i) {
    const size_t j = full_index.at(part->pixels[i]);
    ASSERT_EQ(m[i].r, a[j].r) << "pixel " << part->pixels[i];
    ASSERT_EQ(m[i].g, a[j].g);
    ASSERT_EQ(m[i].b, a[j].b);
  }
  // Non-trivial: the terms changed many pixels, and with the AO map alone (no bounce) the
  // lower quarter of the sphere, which the floor hides from the sky, got darker.
  PreviewOptions oa = off;
  oa.visibility.ao = true;
  oa.visibility.samples = 32;
  const auto ao_only = PreviewFrame(s, env, oa, x);
  int changed = 0;
  double lower_ao = 0.0, lower_off = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    changed += a[i].g != z[i].g;
    if (full->pixels[i] / s.card.width > s.card.height * 3 / 4) {
      lower_ao += ao_only[i].g;
      lower_off += z[i].g;
    }
  }
  EXPECT_GT(changed, int(a.size()) / 2);
  EXPECT_GT(lower_off, 0.0);
  EXPECT_LT(lower_ao, 0.95 * lower_off);
  // The floor (non-fabric, full frame only) gets the terms too.
  EXPECT_NE(full->background, plain->background);
}

// The AO map darkens the prefiltered specular tables by three.js's computeSpecularOcclusion at
// each roughness node (session 9 review: the darkening check above is met by the diffuse alone).
// ao per pixel is recovered from the diffuse irradiance (E_d x ao with the light map off).
TEST(S9Visibility, AoAppliesSpecularOcclusionToTheRadianceTables) {
  const Scene s = SphereOnFloor(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions off;
  off.model = ModelKind::kStandard;
  PreviewOptions on = off;
  on.visibility.ao = true;
  on.visibility.samples = 32;
  const auto a = PreviewCache::Build(s, &env, on), b = PreviewCache::Build(s, &env, off);
  ASSERT_EQ(a->pixels, b->pixels);
  const int K = on.roughness_nodes;
  ASSERT_EQ(a->radiance.size(), a->pixels.size() * size_t(K) * 3);
  int occluded = 0;
  for (const auto& [i, ao] : OccludedPixels(*a, *b)) {
    ++occluded;
    for (int k = 0; k < K; k += 4) {
      const double so = SpecularOcclusion(std::clamp(double(a->NoV[i]), 0.0, 1.0), ao,
                                          double(k) / double(K - 1));
      for (int c = 0; c < 3; ++c) {
        const size_t j = (i * size_t(K) + size_t(k)) * 3 + size_t(c);
        EXPECT_NEAR(a->radiance[j], double(b->radiance[j]) * so, 1e-4 * double(b->radiance[j]) + 1e-7)
            << "pixel " << a->pixels[i] << " node " << k << " ao " << ao;
      }
    }
  }
  EXPECT_GT(occluded, 10);
}

// Session 13: the far-field yarn lobe with the visibility terms. The AO map's specular occlusion
// applies to each yarn lobe's environment read at that lobe's roughness (three.js
// computeSpecularOcclusion at the read's roughness); shadows and the light map touch only the
// lights' visibility and E_d, so the lobe's per-light values are the option-off ones. ao per pixel
// is recovered from the diffuse irradiance, as above.
TEST(S9Visibility, YarnLobeReadsGetTheSpecularOcclusionOfTheirRoughness) {
  const Scene s = SphereOnFloor(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions off;
  off.model = ModelKind::kWoven;
  // A smooth hand-made lobe (no fabric file): the values do not matter, only where they go.
  off.yarn_lobe = [](const Vec3d& wo, const Vec3d& wi, double out[2]) {
    out[0] = 0.2 + 0.1 * wo.x * wi.x;
    out[1] = 0.3 + 0.1 * wo.y * wi.y;
  };
  const double rough[2] = {0.2, 0.75};
  off.yarn_ibl = [rough](const Vec3d&, yarn_table::IblLobe out[2]) {
    for (int k = 0; k < 2; ++k) {
      out[k].albedo = 0.5 + 0.25 * k;
      out[k].dir = Vec3d(0.3 * (k ? -1 : 1), 0.0, 0.95);
      out[k].roughness = rough[k];
    }
  };
  PreviewOptions on = off;
  on.visibility.ao = true;
  on.visibility.samples = 32;
  const auto a = PreviewCache::Build(s, &env, on), b = PreviewCache::Build(s, &env, off);
  ASSERT_EQ(a->pixels, b->pixels);
  ASSERT_EQ(a->yarn_ibl.size(), a->pixels.size() * 6);
  ASSERT_EQ(a->yarn_lobe, b->yarn_lobe);  // the lights' lobe values are not visibility's
  int occluded = 0;
  for (const auto& [i, ao] : OccludedPixels(*a, *b)) {
    ++occluded;
    for (int k = 0; k < 2; ++k) {
      const double so = SpecularOcclusion(std::clamp(double(a->NoV[i]), 0.0, 1.0), ao, rough[k]);
      for (int c = 0; c < 3; ++c) {
        const size_t j = i * 6 + size_t(k) * 3 + size_t(c);
        EXPECT_NEAR(a->yarn_ibl[j], double(b->yarn_ibl[j]) * so, 1e-5 * double(b->yarn_ibl[j]) + 1e-8)
            << "pixel " << a->pixels[i] << " lobe " << k << " ao " << ao;
      }
    }
  }
  EXPECT_GT(occluded, 10);
  // Shadows and the light map with the lobe: a frame is drawn and changes; the light map alone
  // leaves the lobe's per-light values as they are; shadows drop the occluded light samples.
  PreviewOptions sh = off;
  sh.shadows = true;
  sh.visibility.indirect = true;
  sh.visibility.samples = 32;
  sh.visibility.hit_samples = 4;
  const std::vector<double> x = WovenFlat({0.4, 0.35, 0.3}, {0.1, 0.1, 0.1}, 0.5, 0.5, 0.5, 0.04, 0.5);
  std::unique_ptr<PreviewCache> cs, co, ci;
  const auto fs = PreviewFrame(s, env, sh, x, &cs);
  const auto fo = PreviewFrame(s, env, off, x, &co);
  PreviewOptions ind = sh;  // the light map alone keeps every light sample
  ind.shadows = false;
  PreviewFrame(s, env, ind, x, &ci);
  ASSERT_EQ(ci->yarn_lobe, co->yarn_lobe);
  EXPECT_LT(cs->yarn_lobe.size(), co->yarn_lobe.size());  // shadowed samples are dropped
  ASSERT_EQ(fs.size(), fo.size());
  int changed = 0;
  for (size_t i = 0; i < fs.size(); ++i) changed += fs[i].g != fo[i].g;
  EXPECT_GT(changed, int(fs.size()) / 4);
}

// Session 13: the terms baked over the fabric's uv (VisibilityOptions::uv_size), the texture an
// engine draws as aoMap / lightMap. (1) A texel holds ComputeVisibility at the surface point of
// its centre (the sphere's uv -> position by hand: u = longitude, v = latitude as SphereMesh
// lays them out), seeded by the texel index. (2) Sampling reproduces a texel exactly at its
// centre and interpolates bilinearly between centres. (3) A cache built with the texture is close
// to the per-pixel one on average (the terms are smooth; texture resolution and the seed pattern
// differ) and still darkens the floor-facing lower sphere.
TEST(S9Visibility, UvBakedMapIsThePerPointTermsAtTexelCentres) {
  const Scene s = SphereOnFloor(48);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  VisibilityOptions o;
  o.ao = true;
  o.indirect = true;
  o.samples = 32;
  o.hit_samples = 4;
  o.uv_size = 32;
  const EmbreeScene bvh(s);
  const double eps = 1e-5 * bvh.scale();
  const IrradianceOverPiFn sky = [](const Vec3d& n) {
    return Rgb<double>(0.5 + 0.2 * n.y, 0.5 + 0.2 * n.y, 0.5 + 0.2 * n.y);
  };
  const UvVisibilityMap map = BakeUvVisibility(s, bvh, o, sky, 0, eps);
  ASSERT_EQ(map.size, 32);
  EXPECT_EQ(map.covered, size_t(32 * 32));  // a UV sphere's charts cover the unit square
  EXPECT_THROW(BakeUvVisibility(s, bvh, o, sky, 5, eps), std::invalid_argument);
  // (1) texel (i, j) against the point of its uv, by the mesh's own interpolation: find the
  // surface point with a ray from the centre outwards along the sphere direction of that uv.
  const Mesh& m = s.meshes[0];
  int checked = 0, floor_facing = 0;
  for (int j = 1; j < 31; j += 5)
    for (int i = 0; i < 32; i += 7) {
      const size_t t = size_t(j) * 32 + size_t(i);
      const double u = map.uv_min[0] + (i + 0.5) / 32.0 * (map.uv_max[0] - map.uv_min[0]);
      const double v = map.uv_min[1] + (j + 0.5) / 32.0 * (map.uv_max[1] - map.uv_min[1]);
      // the triangle holding (u, v) and its barycentrics, searched over the mesh
      for (size_t f = 0; f + 2 < m.indices.size(); f += 3) {
        const auto& a = m.uvs[m.indices[f]];
        const auto& b = m.uvs[m.indices[f + 1]];
        const auto& c = m.uvs[m.indices[f + 2]];
        const double area = double((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]));
        if (!(std::abs(area) > 0.0)) continue;
        const double b0 =
            ((double(b[0]) - u) * (double(c[1]) - v) - (double(c[0]) - u) * (double(b[1]) - v)) /
            area;
        const double b1 =
            ((double(c[0]) - u) * (double(a[1]) - v) - (double(a[0]) - u) * (double(c[1]) - v)) /
            area;
        const double b2 = 1.0 - b0 - b1;
        if (b0 < -1e-9 || b1 < -1e-9 || b2 < -1e-9) continue;
        auto P = [&](int k) {
          const auto& q = m.positions[m.indices[f + size_t(k)]];
          return Vec3d(double(q[0]), double(q[1]), double(q[2]));
        };
        auto Nn = [&](int k) {
          const auto& q = m.normals[m.indices[f + size_t(k)]];
          return Vec3d(double(q[0]), double(q[1]), double(q[2]));
        };
        const Vec3d p = P(0) * b0 + P(1) * b1 + P(2) * b2;
        const Vec3d n = Normalize(Nn(0) * b0 + Nn(1) * b1 + Nn(2) * b2);
        Vec3d ng = Normalize(Cross(P(1) - P(0), P(2) - P(0)));
        if (Dot(ng, n) < 0.0) ng = ng * -1.0;
        const VisibilityTerms want = ComputeVisibility(s, bvh, o, sky, p + ng * eps, n, ng, t, eps);
        EXPECT_NEAR(map.ao[t], want.ao, 1e-6) << "texel " << i << "," << j;
        EXPECT_NEAR(map.indirect[t * 3 + 1], want.indirect_over_pi.g, 1e-6) << "texel " << i << "," << j;
        floor_facing += n.y < -0.5 && want.ao < 0.9;
        ++checked;
        break;
      }
    }
  EXPECT_GT(checked, 25);
  EXPECT_GT(floor_facing, 0);  // some checked texels are occluded (the test sees the floor)
  // (2) centre and midpoint reads.
  const auto centre = [&](int i, int j) {
    return std::array<double, 2>{map.uv_min[0] + (i + 0.5) / 32.0 * (map.uv_max[0] - map.uv_min[0]),
                                 map.uv_min[1] + (j + 0.5) / 32.0 * (map.uv_max[1] - map.uv_min[1])};
  };
  const auto c0 = centre(10, 27), c1 = centre(11, 27);
  EXPECT_NEAR(map.Sample(c0[0], c0[1]).ao, map.ao[27 * 32 + 10], 1e-6);
  EXPECT_NEAR(map.Sample(0.5 * (c0[0] + c1[0]), c0[1]).indirect_over_pi.r,
              0.5 * double(map.indirect[(27 * 32 + 10) * 3] + map.indirect[(27 * 32 + 11) * 3]),
              1e-6);
  // (3) the cache with the texture against the per-pixel cache.
  PreviewOptions px;
  px.model = ModelKind::kStandard;
  px.visibility = o;
  px.visibility.uv_size = 0;
  px.visibility.samples = 64;
  PreviewOptions tx = px;
  tx.visibility.uv_size = 64;
  PreviewOptions off;
  off.model = ModelKind::kStandard;
  const auto a = PreviewCache::Build(s, &env, px), b = PreviewCache::Build(s, &env, tx),
             z = PreviewCache::Build(s, &env, off);
  ASSERT_EQ(a->pixels, b->pixels);
  ASSERT_EQ(b->uv_visibility.size(), s.meshes.size());
  EXPECT_EQ(b->uv_visibility[0].size, 64);
  EXPECT_EQ(b->uv_visibility[1].size, 0);  // the floor is not fabric: no texture
  double sa = 0.0, sb = 0.0, sz = 0.0, lower_a = 0.0, lower_b = 0.0, lower_z = 0.0;
  for (size_t i = 0; i < a->pixels.size(); ++i) {
    sa += double(a->irradiance[i * 3 + 1]);
    sb += double(b->irradiance[i * 3 + 1]);
    sz += double(z->irradiance[i * 3 + 1]);
    if (a->pixels[i] / s.card.width > s.card.height * 3 / 4) {
      lower_a += double(a->irradiance[i * 3 + 1]);
      lower_b += double(b->irradiance[i * 3 + 1]);
      lower_z += double(z->irradiance[i * 3 + 1]);
    }
  }
  EXPECT_NEAR(sb / sa, 1.0, 0.02);
  // where the floor matters (occlusion of the sky, bounce off the lit floor) the texture's terms
  // change E_d as much as the per-pixel ones do
  EXPECT_GT(std::abs(lower_a - lower_z), 0.1 * lower_z);
  EXPECT_NEAR(lower_b / lower_a, 1.0, 0.03);
  EXPECT_NE(sb, sz);
}

// Session 13: a scene card's "visibility" block is the options it names (shadows, the uv light
// map with its size, samples, hit samples and bounces), bit for bit; card_visibility = false
// ignores it; the caller's own terms and exact IBL keep the card's light map out.
TEST(S9Visibility, CardBlockIsTheOptionsItNames) {
  Scene s = SphereOnFloor(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions base;
  base.model = ModelKind::kStandard;
  base.visibility.fabric_albedo = {0.3, 0.25, 0.2};
  PreviewOptions hand = base;
  hand.shadows = true;
  hand.visibility.indirect = true;
  hand.visibility.uv_size = 32;
  hand.visibility.samples = 16;
  hand.visibility.hit_samples = 2;
  hand.visibility.bounces = 2;
  const auto x = StandardFlat(0.5);
  const auto by_hand = PreviewFrame(s, env, hand, x);
  const auto plain = PreviewFrame(s, env, base, x);
  CardVisibility v;
  v.shadows = true;
  v.light_map = true;
  v.size = 32;
  v.samples = 16;
  v.hit_samples = 2;
  v.bounces = 2;
  s.card.visibility = v;
  std::unique_ptr<PreviewCache> cc;
  const auto by_card = PreviewFrame(s, env, base, x, &cc);
  ASSERT_EQ(by_card.size(), by_hand.size());
  int differs = 0;
  for (size_t i = 0; i < by_card.size(); ++i) {
    ASSERT_EQ(by_card[i].g, by_hand[i].g) << "pixel " << i;
    differs += by_card[i].g != plain[i].g;
  }
  EXPECT_GT(differs, int(by_card.size()) / 4);
  EXPECT_TRUE(cc->options.shadows);
  EXPECT_EQ(cc->options.visibility.uv_size, 32);
  ASSERT_EQ(cc->uv_visibility.size(), s.meshes.size());
  EXPECT_EQ(cc->uv_visibility[0].size, 32);
  PreviewOptions ignore = base;
  ignore.card_visibility = false;
  const auto ignored = PreviewFrame(s, env, ignore, x);
  for (size_t i = 0; i < ignored.size(); ++i) ASSERT_EQ(ignored[i].g, plain[i].g);
  // The caller's own terms win over the card's light map; exact IBL drops it (shadows stay).
  PreviewOptions own = base;
  own.visibility.ao = true;
  const PreviewOptions e1 = WithCardVisibility(own, s.card);
  EXPECT_TRUE(e1.visibility.ao);
  EXPECT_FALSE(e1.visibility.indirect);
  EXPECT_EQ(e1.visibility.uv_size, 0);
  EXPECT_TRUE(e1.shadows);
  PreviewOptions exact = base;
  exact.exact_ibl_samples = 16;
  const PreviewOptions e2 = WithCardVisibility(exact, s.card);
  EXPECT_FALSE(e2.visibility.enabled());
  EXPECT_TRUE(e2.shadows);
}

// render::DiffuseAlbedo: base colour x (1 - metalness), clamped; a model without a base colour
// gives -1 (the glTF's colour).
TEST(S9Visibility, DiffuseAlbedoOfPresets) {
  MaterialPreset st = DefaultPreset(ModelKind::kStandard);
  st.values[size_t(st.Offset("base_color"))] = 0.8;
  st.values[size_t(st.Offset("base_color")) + 1] = 0.4;
  st.values[size_t(st.Offset("base_color")) + 2] = 0.2;
  st.values[size_t(st.Offset("metalness"))] = 0.25;
  const auto a = DiffuseAlbedo(st);
  EXPECT_DOUBLE_EQ(a[0], 0.6);
  EXPECT_DOUBLE_EQ(a[1], 0.30000000000000004);
  EXPECT_DOUBLE_EQ(a[2], 0.15000000000000002);
  MaterialPreset w = DefaultPreset(ModelKind::kWoven);
  for (int c = 0; c < 3; ++c) w.values[size_t(w.Offset("base_color") + c)] = 0.1 * (c + 1);
  const auto b = DiffuseAlbedo(w);
  for (int c = 0; c < 3; ++c) EXPECT_DOUBLE_EQ(b[size_t(c)], 0.1 * (c + 1));
}

// Session 13: with one bounce the light map is linear in the fabric's albedo, so a cache baked
// with kd0 plus (kd1 - kd0) x irradiance_unit is the cache baked with kd1 (what a fit's second
// pass uses instead of baking again). A fabric wall beside the fabric sphere makes fabric
// bounce points; with two bounces there is no unit part.
TEST(S9Visibility, LightMapIsLinearInTheFabricAlbedo) {
  Scene s = SphereOnFloor(32);
  s.meshes.push_back(Quad({Vec3d(0.7, -0.5, 1), Vec3d(0.7, -0.5, -1), Vec3d(0.7, 1.5, -1),
                           Vec3d(0.7, 1.5, 1)},
                          Vec3d(-1, 0, 0), true, 0.8f));
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions o;
  o.model = ModelKind::kStandard;
  o.visibility.indirect = true;
  o.visibility.samples = 32;
  o.visibility.hit_samples = 4;
  o.visibility.uv_size = 32;
  o.visibility.fabric_albedo = {0.2, 0.5, 0.7};
  PreviewOptions o1 = o;
  o1.visibility.fabric_albedo = {0.9, 0.1, 0.4};
  const auto a = PreviewCache::Build(s, &env, o), b = PreviewCache::Build(s, &env, o1);
  ASSERT_EQ(a->pixels, b->pixels);
  ASSERT_EQ(a->irradiance_unit.size(), a->irradiance.size());
  double unit_max = 0.0;
  for (size_t i = 0; i < a->irradiance.size(); ++i) {
    const double kd0 = o.visibility.fabric_albedo[i % 3], kd1 = o1.visibility.fabric_albedo[i % 3];
    const double want = double(b->irradiance[i]);
    const double got = double(a->irradiance[i]) + (kd1 - kd0) * double(a->irradiance_unit[i]);
    EXPECT_NEAR(got, want, 1e-5 * std::abs(want) + 1e-7) << "value " << i;
    unit_max = std::max(unit_max, double(a->irradiance_unit[i]));
  }
  EXPECT_GT(unit_max, 1e-3);  // the wall bounces light onto the sphere
  PreviewOptions two = o;
  two.visibility.bounces = 2;
  EXPECT_TRUE(PreviewCache::Build(s, &env, two)->irradiance_unit.empty());
}

// Options off (ao and indirect false) with every other visibility field changed: bit-identical.
TEST(S9Visibility, OptionsOffAreBitIdentical) {
  const Scene s = SphereOnFloor(32);
  const Environment env = Environment::ProceduralSky(1.0, 0.3, 128);
  PreviewOptions a;
  a.model = ModelKind::kStandard;
  PreviewOptions b = a;
  b.visibility.samples = 3;
  b.visibility.hit_samples = 0;
  b.visibility.max_distance = 0.1;
  b.visibility.seed = 9;
  b.visibility.fabric_albedo = {0.2, 0.2, 0.2};
  std::unique_ptr<PreviewCache> ca, cb;
  const auto fa = PreviewFrame(s, env, a, StandardFlat(0.5), &ca);
  const auto fb = PreviewFrame(s, env, b, StandardFlat(0.5), &cb);
  ASSERT_EQ(fa.size(), fb.size());
  for (size_t i = 0; i < fa.size(); ++i) ASSERT_EQ(fa[i].g, fb[i].g);
  EXPECT_EQ(ComposeFrame(*ca, fa), ComposeFrame(*cb, fb));
}

TEST(S9Visibility, RejectsBadOptions) {
  const Scene s = SphereOnFloor(16);
  const Environment env = Environment::Constant({1.0, 1.0, 1.0});
  PreviewOptions o;
  o.model = ModelKind::kStandard;
  o.visibility.ao = true;
  o.visibility.samples = 0;
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
  o.visibility.samples = 16;
  o.visibility.max_distance = -1.0;
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
  o.visibility.max_distance = 0.0;
  o.exact_ibl_samples = 16;  // the terms apply to the split sum only
  EXPECT_THROW(PreviewCache::Build(s, &env, o), std::invalid_argument);
}

}  // namespace
}  // namespace clothfit::render
