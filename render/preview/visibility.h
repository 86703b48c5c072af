// render/preview/visibility.h: what a real-time engine can add to the preview for light
// visibility beyond shadow maps (PreviewOptions::shadows): an ambient-occlusion map and a light
// map, both "perfect" (ray-traced per pixel with the preview's own EmbreeScene), applied the way
// three.js r187 applies material.aoMap and material.lightMap. A measurement prototype, opt-in
// (PreviewOptions::visibility, default off: the cache and every frame are bit-identical to a
// preview without it). docs/visibility.md has the conventions, formulas and measurements.
//
// Conventions:
// - Directions: N cosine-weighted directions around the pixel's shading normal n (the viewer
//   side, as the preview shades it), stratified (j + 0.5) / N x the base-2 radical inverse,
//   under a per-pixel Cranley-Patterson shift drawn from Pcg32(seed, pixel index): deterministic
//   per pixel, so a fit's sampled cache holds exactly the full frame's values at its pixels.
// - ao = (1 / N) sum_j V(l_j), V = 1 when the ray from the pixel's (offset) position leaves the
//   scene or hits geometry farther than max_distance: the Monte Carlo estimate of the
//   cosine-weighted visibility (1 / pi) int V(l) (n.l) dl in [0, 1] (1 = open hemisphere).
// - indirect_over_pi = (1 / N) sum_j [hit within max_distance] L_o(q_j -> p): the estimate of
//   E_ind / pi = (1 / pi) int L_ind(l) (n.l) dl, the one-bounce indirect irradiance over pi (the
//   unit of PreviewCache::irradiance). L_o at a hit point q: Lambert with albedo kd (the mesh's
//   glTF base colour; VisibilityOptions::fabric_albedo for fabric meshes when set):
//     L_o = kd / pi * sum_lights E_l V_l max(0, n_q.l) + kd * ao_q * E_env(n_q) / pi
//   with ray-traced light visibility V_l (always, whatever PreviewOptions::shadows says) and the
//   environment's unoccluded irradiance (the preview's own: SH9 or three.js's PMREM, passed in)
//   times an ao_q of hit_samples directions at q. n_q faces the ray's origin.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <vector>

#include "brdf/math.h"
#include "render/scene/scene.h"

namespace clothfit::render {

class EmbreeScene;

struct VisibilityOptions {
  // IBL occlusion, three.js material.aoMap (aomap_fragment, r187): indirectDiffuse *= ao,
  // sheenSpecularIndirect *= ao, indirectSpecular *= computeSpecularOcclusion(n.v, ao, r).
  bool ao = false;
  // How the AO map is baked. kCosine: ao = the cosine-weighted visible fraction (the classic
  // AO map: right under a uniform sky). kEnvironment: the same directions weighted by the
  // environment's luminance Y(L_env(l)), ao = sum_open Y / sum_all Y (an environment-specific
  // bake: a floor hiding a dark lower hemisphere occludes little, a fold hiding a softbox a
  // lot). Both are one scalar per pixel, drawn by three.js's aoMap alike. Also the weighting
  // of ao_q at the bounce hit points.
  enum class Weighting { kCosine, kEnvironment };
  Weighting weighting = Weighting::kCosine;
  // One-bounce indirect irradiance, three.js material.lightMap (lights_fragment_maps, r187:
  // irradiance += lightMapTexel.rgb * lightMapIntensity, then RE_IndirectDiffuse). Baked as
  // E_ind / ao where ao is on too (three.js multiplies the whole indirectDiffuse by the aoMap),
  // so the preview gets ao * E_env + E_ind.
  bool indirect = false;
  int samples = 64;           // N directions per pixel, in [1, 65536]
  int hit_samples = 8;  // ao_q directions at each bounce hit point, in [0, 4096] (0: ao_q = 1)
  // Light-map bounces in [1, 4]: 1 = one bounce (L_o at the hit points is their direct and
  // environment light); b > 1 adds, at each hit point, the (b - 1)-bounce light gathered over
  // its hit_samples directions (the same Lambert shading one level deeper).
  int bounces = 1;
  // > 0: rays hitting farther than this count as open (and bring no bounce); 0: infinite.
  double max_distance = 0.0;
  unsigned seed = 1;
  // Albedo of fabric hit points for the bounce (linear RGB); any component < 0: the fabric
  // mesh's glTF base colour. A scene property here (the same for every model fitted).
  std::array<double, 3> fabric_albedo{-1.0, -1.0, -1.0};
  // Where the terms are baked (session 13). 0 (default): per shaded pixel, as above. N > 0: for
  // the fabric meshes, once per texel of an N x N texture over the mesh's TEXCOORD_0 bounding
  // box (UvVisibilityMap; the side the mesh's vertex normals face), then sampled bilinearly at
  // each fabric pixel's uv: the AO map / light map a real-time engine draws (three.js aoMap,
  // lightMap on uv channel 0 with the box as the texture's offset and repeat). Non-fabric
  // pixels keep the per-pixel terms (full frames only). In [0, 2048].
  int uv_size = 0;
  bool enabled() const { return ao || indirect; }
};

struct VisibilityTerms {
  double ao = 1.0;
  Rgb<double> indirect_over_pi{0.0, 0.0, 0.0};
  // The part of indirect_over_pi that bounced off fabric points, per unit fabric albedo: with
  // one bounce L_o at a fabric point is linear in its albedo kd, so indirect_over_pi =
  // (the rest) + kd x fabric_unit exactly. Zero when bounces > 1 (not linear).
  Rgb<double> fabric_unit{0.0, 0.0, 0.0};
};

// The visibility terms of one fabric mesh baked over its TEXCOORD_0 (VisibilityOptions::uv_size):
// texel (i, j), i along u and j along v (row j of the image is v = uv_min[1] + (j + 0.5) / size
// x extent: glTF's v, which three.js samples with flipY false), holds the terms at the surface
// point whose uv is the texel centre, on the side the interpolated vertex normal faces, with the
// texel index seeding its directions. Texels whose centre no triangle covers take the mean of
// their covered neighbours (repeated outwards), so bilinear reads at a chart's edge see no zeros.
struct UvVisibilityMap {
  int mesh = -1;
  int size = 0;
  std::array<double, 2> uv_min{0.0, 0.0}, uv_max{1.0, 1.0};
  std::vector<float> ao;        // size x size, row-major (j * size + i)
  std::vector<float> indirect;  // size x size x 3: E_ind / pi, linear RGB
  std::vector<float> indirect_unit;  // size x size x 3: VisibilityTerms::fabric_unit (bounces 1)
  size_t covered = 0;           // texels a triangle covers
  // Bilinear, clamped to the edge texels, as a GPU samples it with LinearFilter and
  // ClampToEdgeWrapping (texel centres at (i + 0.5) / size).
  VisibilityTerms Sample(double u, double v) const;
};

// three.js r187 computeSpecularOcclusion (lights_physical_pars_fragment):
//   saturate(pow(dotNV + ao, exp2(-16 roughness - 1)) - 1 + ao)
double SpecularOcclusion(double dotNV, double ao, double roughness);

// The environment's unoccluded irradiance over pi at a normal (the preview's engine), and its
// radiance in a direction (kEnvironment weighting).
using IrradianceOverPiFn = std::function<Rgb<double>(const Vec3<double>& n)>;
using RadianceFn = std::function<Rgb<double>(const Vec3<double>& l)>;

// Multiplies K-node radiance tables (n_tables consecutive tables of K x 3 floats, node k at
// roughness r_k = k / (K - 1), the layout of PreviewCache::radiance) by
// SpecularOcclusion(saturate(NoV), ao, r_k): the preview interpolates the product in r
// (Catmull-Rom), exact at the nodes.
void ApplySpecularOcclusion(float* tables, size_t n_tables, int K, double NoV, double ao);

// Throws std::invalid_argument naming the field when an option is out of range.
void ValidateVisibilityOptions(const VisibilityOptions& o);

// The visibility terms of one surface point p (already offset off the surface) with shading
// normal n (unit, viewer side) and geometric normal ng (unit, the same side), for image pixel
// `pixel` (seeds its directions). A direction of n's hemisphere below the geometric surface
// (l.ng <= 0, where an interpolated normal tilts off the flat triangle) counts as open and
// brings no bounce: the smooth surface the shading normal stands for does not occlude itself
// (without this, a tessellated convex sphere would occlude itself near every vertex). `env`
// may be empty (no environment). eps: the ray offset of the bounce hit points. env_radiance:
// needed for Weighting::kEnvironment (empty: cosine weighting).
VisibilityTerms ComputeVisibility(const Scene& scene, const EmbreeScene& bvh,
                                  const VisibilityOptions& o, const IrradianceOverPiFn& env,
                                  const Vec3<double>& p, const Vec3<double>& n,
                                  const Vec3<double>& ng, size_t pixel, double eps,
                                  const RadianceFn& env_radiance = {},
                                  const std::vector<Light>* lights = nullptr);
// The terms of fabric mesh `mesh` baked over its TEXCOORD_0 at o.uv_size x o.uv_size texels (see
// UvVisibilityMap); the same arguments as ComputeVisibility. Throws std::invalid_argument when
// the mesh has no uvs or a degenerate uv box.
UvVisibilityMap BakeUvVisibility(const Scene& scene, const EmbreeScene& bvh,
                                 const VisibilityOptions& o, const IrradianceOverPiFn& env,
                                 int mesh, double eps, const RadianceFn& env_radiance = {},
                                 const std::vector<Light>* lights = nullptr);
// lights: the punctual lights the bounce points see (null: scene.lights); the preview passes
// the scene's lights plus an environment sun split off as a light (render/scene/sun.h), since
// `env` / `env_radiance` are then the sun-free map's (review s10).

}  // namespace clothfit::render
