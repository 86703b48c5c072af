// render/preview/threejs_ibl.h: three.js r187's image-based lighting, emulated on the CPU.
//
// What three.js r187 computes for MeshStandardMaterial / MeshPhysicalMaterial (and clothfit's
// MeshClothMaterial, web/clothfit.js) lit by scene.environment = PMREMGenerator
// .fromEquirectangular(equirect) (source: npm three@0.187.0, src/extras/PMREMGenerator.js and
// the envmap_* / lights_* shader chunks; summary with formulas in docs/preview-threejs.md):
//
//   PMREM: a cube map of face S = max(256, floorPow2(W / 4)), fp16 texels, mips 0..maxLod,
//     maxLod = log2(S) - 3 (smallest face 8 x 8). Level roughness r(lod) = 1 - sqrt(1 - lod/maxLod).
//     Built from a source cube (face S, full mip chain, 2x2 box mips):
//       source mip 0: per texel, the mean of 4 bilinear equirect reads at the texel-centre
//         direction offset by +-dFdx/4 +-dFdy/4 (derivatives over the 2x2 pixel quad);
//       lod 0: a copy of source mip 0;
//       1 <= lod <= maxLod - 3: GGX importance sampling for V = N, 256 Hammersley samples,
//         each read from the source at lod max(log2(alpha^2 / q) + bias, 0),
//         bias = log2(S) + log2(6 / (256 r^4)) / 2 + 1/2, weighted by n.l;
//       lod > maxLod - 3: a quadrature over the 16 x 16 source mip's texels in the hemisphere,
//         weight n.l dOmega / (1 + alpha^2 + (alpha^2 - 1) n.l)^2 (at r = 1: cos-weighted mean).
//   Lookups (textureLod on the cube, seamless trilinear, lod clamped to [0, maxLod]):
//     radiance(n, v, r)  at R = normalize(mix(reflect(-v, n), n, r^4)), mip = maxLod r (2 - r);
//     irradiance / pi    at n, mip = maxLod (the top level, bilinear on the 8 x 8 faces).
//   DFG: a 16 x 16 fp16 table of the GGX split-sum (A, B) at texel centres, bilinear
//     (ThreejsDfgTable, same layout as clothfit's DFG LUT: u = NoV, v = r).
//
// Conventions: directions are world space; the environment's rotation about +Y and its
// intensity apply at lookup, as three.js's envMapRotation / envMapIntensity do. Cube faces
// follow the OpenGL table (major axis, sc, tc); seamless filtering takes a tap beyond a face
// edge from the adjacent face (the texel across the edge), and a corner tap, where three faces
// meet, is the mean of the other three taps.
//
// Differentiability: the PMREM and the DFG table are data; a model's parameters enter through
// the lookup roughness (mip) and the table sample, as with the Filament chain
// (render/preview/prefilter.h).
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "brdf/math.h"
#include "brdf/table.h"
#include "render/scene/environment.h"
#include "render/scene/scene.h"

namespace clothfit::render {

class ThreejsPmrem {
 public:
  explicit ThreejsPmrem(const Environment& env);

  int face_size() const { return size_; }
  int max_lod() const { return max_lod_; }
  // three.js roughnessToMip: maxLod r (2 - r), r clamped to [0, 1].
  double MipForRoughness(double r) const;
  // textureLod(pmrem, world direction (unit or not), mip) x intensity.
  Rgb<double> Sample(const Vec3<double>& world_dir, double mip) const;
  // getIBLIrradiance / pi: the top level at n.
  Rgb<double> IrradianceOverPi(const Vec3<double>& n) const { return Sample(n, max_lod_); }

  // A cube level: 6 faces of n x n RGB, face-major, row t, column s.
  struct Level {
    int n = 0;
    std::vector<float> rgb;
    const float* texel(int face, int i, int j) const {
      return &rgb[((size_t(face) * size_t(n) + size_t(j)) * size_t(n) + size_t(i)) * 3];
    }
    float* texel(int face, int i, int j) {
      return &rgb[((size_t(face) * size_t(n) + size_t(j)) * size_t(n) + size_t(i)) * 3];
    }
  };
  const std::vector<Level>& levels() const { return pmrem_; }
  const std::vector<Level>& source_levels() const { return source_; }

  // Building blocks (public for the tests).
  static Vec3<double> TexelDirection(int face, int i, int j, int n);  // not normalized
  static void Bilinear(const Level& level, const Vec3<double>& d, float out[3]);
  static void Trilinear(const std::vector<Level>& chain, const Vec3<double>& d, double lod,
                        float out[3]);

 private:
  ThreejsPmrem() = default;
  void SetLookup(const Environment& env);  // intensity and rotation (applied at lookup)
  friend std::shared_ptr<const ThreejsPmrem> SharedThreejsPmrem(const Environment& env);

  int size_ = 0, max_lod_ = 0;
  double intensity_ = 1.0, cos_rot_ = 1.0, sin_rot_ = 0.0;
  std::vector<Level> source_, pmrem_;
};

// The PMREM for an environment, cached per environment object for the process's lifetime
// (keyed by its pixel buffer, size and rotation): built once per scene. The PMREM levels are
// also cached on disk next to clothfit's tables ($CLOTHFIT_TABLE_CACHE, default
// ${XDG_CACHE_HOME:-~/.cache}/clothfit/tables; "off" disables), keyed by an FNV-1a hash of the
// map's texels and size and an algorithm version, and used only if the header and the
// checksum of the floats match; rotation and intensity apply at lookup, so they are not part
// of the key.
std::shared_ptr<const ThreejsPmrem> SharedThreejsPmrem(const Environment& env);

// three.js r187's DFG table (renderers/shaders/DFGLUTData.js): 16 x 16, fp16, regenerated by
// clothfit's integrator (lut::IntegrateGgx, the same split sum: alpha = r^2, height-correlated
// Smith, Schlick pow5) at the texel centres and rounded to fp16. Layout as clothfit's DFG LUT:
// u = NoV, v = perceptual r, channels 0 = A, 1 = B, 2 = 0; Table2D::Sample is GL bilinear with
// clamp to edge, which is how three.js reads it.
const Table2D& ThreejsDfgTable();

// The rasteriser's vertex snapping. A GPU rasterises a triangle from its window-space vertex
// positions rounded to a fixed-point grid of 1 / 2^bits pixel (GL_SUBPIXEL_BITS; Vulkan
// subPixelPrecisionBits), and SwiftShader also sets up the attribute plane equations
// (perspective-correct: a / w and 1 / w interpolated linearly in window space) from those
// snapped positions (src/Pipeline/SetupRoutine.cpp: X, Y are the fixed-point projected
// positions). Chromium's SwiftShader WebGL2 (the browser tests) reports GL_SUBPIXEL_BITS = 4.
constexpr int kSwiftShaderSubpixelBits = 4;

// Perspective-correct barycentrics b[0..2] (sum 1) of the sample at image point (sx, sy)
// (image coordinates: x right, y down, pixel (x, y)'s centre at (x + 0.5, y + 0.5)) on the
// world-space triangle P0 P1 P2, as a rasteriser with `subpixel_bits` of sub-pixel precision
// gives them: vertices projected by the scene's camera to window coordinates (window y counts
// up from the bottom row), each rounded to the nearest multiple of 2^-bits pixel; the sample's
// screen-space barycentrics in that snapped triangle (extrapolated outside it, as for helper
// lanes); each divided by its vertex's clip w (the view depth) and renormalised.
// subpixel_bits < 0: no snapping, which equals intersecting the camera ray through (sx, sy)
// with the triangle's plane. Returns false when a vertex is not in front of the camera or the
// (snapped) triangle has no area on screen.
bool RasterBarycentrics(const Scene& scene, const std::array<Vec3<double>, 3>& P, double sx,
                        double sy, int subpixel_bits, double b[3]);

// three.js's geometryRoughness at image pixel (x, y), whose primary hit is triangle `triangle`
// of mesh `mesh`: max over the view-space components of max(|dFdx n|, |dFdy n|), where n is
// the normalized interpolated vertex normal and the derivatives are COARSE, as SwiftShader
// computes them: one pair per 2 x 2 pixel quad, from the quad's lane 0 (even window x and y;
// window y counts up from the bottom row) to lanes 1 (x + 1) and 2 (window y + 1). Every lane
// evaluates the SAME triangle's attribute plane (as helper invocations do): the camera ray
// through the lane's pixel centre meets the triangle's plane and the normal is interpolated
// there, even outside the triangle. The sign of n (double-sided flips) does not change it.
// `subpixel_bits`: the rasteriser's sub-pixel precision (RasterBarycentrics); < 0: exact planes.
double ThreejsGeometryRoughness(const Scene& scene, int mesh, int triangle, int x, int y,
                                int subpixel_bits = kSwiftShaderSubpixelBits);


// Filtered importance sampling (FIS; Colbert & Krivanek 2007, "GPU-based importance sampling",
// GPU Gems 3 ch. 20) of the PMREM: the session-8 spec that web/clothfit.js implements too
// (docs/fitting.md "Filtered importance sampling for woven's IBL (session 8)"). World space;
// n the shading normal, v the view direction (unit).
//   Frame (Duff et al. 2017, JCGT 6(1)): s = sign(n.z) (+1 at 0), a = -1 / (s + n.z),
//     b = n.x n.y a, t1 = (1 + s n.x^2 a, s b, -s n.x), t2 = (b, s + n.y^2 a, -n.y).
//   Tap i of N: u1 = (i + 0.5) / N, u2 = radical inverse base 2 of i, phi = 2 pi u2.
//   Each tap is read with Sample(l, MipForRoughness(r_t)), where the tap's solid angle
//   Omega_s = 4 / (N pdf) is matched to the PMREM roughness whose GGX lobe (seen at v = n, peak
//   pdf 1 / (4 pi alpha'^2)) covers it: a_t = sqrt(Omega_s / (4 pi)), r_t = min(sqrt(a_t), 1).
//   The factor 4 (GPU Gems 3's +1 LOD bias) is a measured fix of the spec's 1 / (N pdf), which
//   under-filters (threejs_ibl.cpp kFisSolidAngleBias).
struct FisPattern {
  explicit FisPattern(int taps);  // 1 <= taps <= 2^20
  int n = 0;
  std::vector<double> u1, cos_phi, sin_phi;
};
void FisFrame(const Vec3<double>& n, Vec3<double>* t1, Vec3<double>* t2);
// GGX lobe radiance at perceptual roughness r (alpha = max(r^2, 1e-3)): half vectors from D,
// l = reflect(-v, h), taps with n.l <= 0 or v.h <= 0 skipped, pdf(l) = D cos_h / (4 v.h);
// returns sum (n.l) L(l) / sum (n.l). *taps_used: the taps kept (0: the result is 0 and the
// caller falls back to the split-sum read).
Rgb<double> FisGgxRadiance(const ThreejsPmrem& pmrem, const FisPattern& taps,
                           const Vec3<double>& n, const Vec3<double>& v, double r,
                           int* taps_used);
// Diffuse irradiance / pi: cosine-weighted taps (cos_t = sqrt(1 - u1)), pdf = cos_t / pi,
// E / pi = (1 / N) sum L(l).
Rgb<double> FisIrradianceOverPi(const ThreejsPmrem& pmrem, const FisPattern& taps,
                                const Vec3<double>& n);

// Rounds to the nearest IEEE half (ties to even), as a GPU does when it writes RGBA16F.
float RoundToHalf(float x);

}  // namespace clothfit::render
