// render/preview/weave_maps.h: the woven model's weave maps (issue 12, deliverable 2) as the
// preview samples them. The maps are baked by fit/weave_maps.h (which may read the reference
// BSDF); this file only holds the data type, its file format and the GPU-style sampling, so
// the preview never depends on render/reference (docs/architecture.md).
//
// Content. One weave period, size x size texels (size a power of two), 5 channels, all LINEAR
// and all RATIOS with a tile mean of exactly 1 (so a uniform map of 1 is the uniform model,
// and the mapped and uniform models have the same block means under constant lighting):
//   warp   weight of the warp yarn lobe here / its tile mean   -> woven::WeaveSample::warp
//   weft   weight of the weft yarn lobe here / its tile mean   -> woven::WeaveSample::weft
//   kd.R, kd.G, kd.B  diffuse albedo here / its tile mean (linear sRGB, per channel)
//                                                              -> woven::WeaveSample::kd
// The "yarn direction" of the issue is carried by warp/weft: each texel's specular sits on
// the lobe aligned with its yarn (the woven model's two lobes, brdf/woven.h); a direction map
// (KHR anisotropyTexture) would not mip linearly (warp + weft average to a 45 degree lobe).
//
// Convention (stated; the same as a glTF texture with KHR_texture_transform scale (R, R) and
// REPEAT wrapping): texel (i, j), i = column from the left, j = row from the TOP of the image,
// covers uv in [i, i+1) / (size R) x [j, j+1) / (size R) of TEXCOORD_0 (glTF: v down from the
// top), R = uv_repeats (weave tiles per uv unit, the fabric's `uv_repeats`); texel centres at
// (i + 0.5, j + 0.5). This is the reference renderer's uv convention by construction (the bake
// locates each texel with the reference BSDF's own Locate).
//
// Sampling (as a GPU with isotropic filtering, texture.anisotropy = 1, does it): the LOD is
// lambda = log2(max(|d(uv)/dx|, |d(uv)/dy|) x size x R x footprint_scale) from the screen-
// space uv derivatives (OpenGL 4.6 section 8.14, rho = max of the two lengths), clamped to
// [0, levels - 1]; trilinear: bilinear (REPEAT, texel centres) in the two nearest levels,
// lerped by frac(lambda). Mips are 2 x 2 box averages down to 1 x 1 (the tile means, 1).
// Every channel enters the model linearly, so averaging the maps averages the shading.
//
// Anisotropic filtering (session 9; three.js `texture.anisotropy`, WeaveMaps::anisotropy > 1):
// EXT_texture_filter_anisotropic (Khronos OpenGL registry, "Texture Filter Anisotropic", the
// replacement of OpenGL section 3.8.5 / GL 4.6 section 8.14.1), with the footprint in texels
// of the map being sampled (derivatives times texels per uv unit times footprint_scale):
//   Px = |(du/dx, dv/dx)|, Py = |(du/dy, dv/dy)|, Pmax = max, Pmin = min,
//   N = min(ceil(Pmax / Pmin), anisotropy), lambda' = log2(Pmax / N) clamped to [0, top],
//   result = the mean of N trilinear samples at lambda' along the major axis (the derivative
//   vector d of the longer axis: x when Px > Py, y when Py >= Px, as the spec's two cases),
//   probe i = 1..N at uv + d ((i - 1/2) / N - 1/2).
// Probe placement (stated; the spec allows any N locations "within the footprint" and gives
// i / (N + 1) - 1/2 as its example): the CENTRES of N equal segments of the major axis
// [-1/2, 1/2] d. Each probe's trilinear footprint at lambda' is Pmax / N texels long, so the N
// segments tile the major axis exactly (the midpoint rule of the pixel's box integral along
// it); the spec's i / (N + 1) spacing leaves the two ends uncovered and overlaps the rest. It is
// also the placement of SwiftShader (the WebGL2 the browser test runs: Constants.cpp uvStart =
// -(N - 1) / (2N), uvWeight = 1 / N), which differs from the spec in N and lambda' only
// (docs/preview.md "Anisotropic filtering of the weave maps").
// Degenerate footprints: Pmax = 0 or not finite -> the isotropic rule (one sample); Pmin = 0
// -> N = anisotropy. anisotropy = 1 is the isotropic path above, bit for bit (same code).
// AnisoRule::kSwiftShader (opt-in, `render-preview --map-aniso-rule swiftshader`; the browser
// test compares with it): SwiftShader's own rule (src/Pipeline/SamplerCore.cpp computeLod2D,
// the WebGL2 of headless Chromium): the minor axis from the footprint's AREA, Pmin' = |det J| /
// Pmax (det J = du/dx dv/dy - du/dy dv/dx in texels; <= Pmin), a = min(Pmax^2 / |det J|,
// anisotropy) unrounded, N = round(a) probes, ties to even as its RoundInt (same placement),
// lambda' = log2(Pmax / a) taken
// with SwiftShader's piecewise-linear log2 (log2sqrt: the float's exponent plus its mantissa
// fraction, of (Pmax / a)^4, times 1/4); the major axis is x when Px >= Py. The spec's ceil
// makes a slightly anisotropic footprint (ratio 1.01) take 2 probes one LOD finer; SwiftShader
// takes 1 probe at about the same LOD: measured, that difference is up to 7.9 / 255 mean on the
// sphere (docs/preview.md "Anisotropic filtering of the weave maps").
//
// File: a 32-bit float EXR, channels warp, weft, kd.R, kd.G, kd.B [, N.X, N.Y, N.Z], metadata
// clothfit:weave_maps = 1, clothfit:uv_repeats, clothfit:convention. The preset lists it in
// its top-level "weave_maps" object (written by the fit; see PresetField below).
#pragma once

#include <array>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "render/scene/material.h"

namespace clothfit::render {

struct Scene;
struct Hit;

struct WeaveMaps {
  static constexpr int kChannels = 5;  // warp, weft, kd.R, kd.G, kd.B
  static constexpr int kMaxAnisotropy = 16;  // the preset's limit (GPUs: 16)
  int size = 0;                        // texels per period along u and v (power of two)
  double uv_repeats = 1.0;             // weave tiles per uv unit
  // Max anisotropy of every map here (weave, relief normal, glint, physical-aniso anisotropy
  // map), as three.js's texture.anisotropy: 1 = isotropic (GL's default), up to 16. From the
  // preset's weave_maps.anisotropy (missing: 1).
  int anisotropy = 1;
  // How N and lambda' are chosen for anisotropy > 1 (above): the EXT specification (default)
  // or SwiftShader's rule. Not a preset key: an engine property, set by the caller.
  enum class AnisoRule { kSpec, kSwiftShader };
  AnisoRule aniso_rule = AnisoRule::kSpec;
  std::vector<std::vector<float>> levels;  // mip chain; level l: (size >> l)^2 x 5, row-major
  // Optional relief normal map (empty: none): tangent-space unit normals (x along the mesh
  // tangent t = +u = warp, y along b = tangent_sign n x t = +v = weft, z along n), 3 per
  // texel, mips = 2 x 2 averages of the vectors (not renormalised: a GPU averages the texels
  // and the shader normalises, which flattens the relief at coarse mips).
  std::vector<std::vector<float>> normal_levels;
  // Optional glint map (empty: none): the reference's fineness intensity I (Irawan: a hash
  // per fineness cell, NOT periodic) over the whole uv square [0, 1)^2, glint_size^2 texels,
  // REPEAT with repeat 1 (not uv_repeats), texel (i, j) covering uv [i, i+1) / glint_size x
  // [j, j+1) / glint_size; 1 channel, linear, box mips. It multiplies the yarn specular (both
  // lobes), so the preview folds it into the warp and weft weights.
  int glint_size = 0;
  std::vector<std::vector<float>> glint_levels;
  // The three.js anisotropyMap a physical-aniso preset with these maps draws with (web/clothfit.js
  // anisotropyFromWeave; KHR_materials_anisotropy encoding), built by FromLevel0: per level-0
  // texel RG = d * 0.5 + 0.5 with d = (1, 0) (+u, warp) where warp >= weft, else (0, 1) (+v,
  // weft), B = |warp - weft| / (warp + weft); 3 channels, box mips. It is filtered as a GPU
  // filters that texture (the encoded values, not warp/weft), see SampleAnisotropy.
  std::vector<std::vector<float>> aniso_levels;
  // Optional view bands (session 14, docs/preview.md "View-dependent weave maps"): the 5
  // channels baked again from the pairs of one view cosine each (fit/weave_maps.h view_bands),
  // view_cosines strictly decreasing in (0, 1] (the bake's Gauss-Legendre nodes: 0.887, 0.5,
  // 0.113), each band a ratio map with tile mean 1 of this object's size and uv_repeats, box
  // mips. SampleView blends them by the view cosine: piecewise linear in NoV between the
  // cosines (hat weights over the ascending nodes), clamped to the end bands outside them.
  // The five main channels stay the all-views maps (what physical-aniso and a reader without
  // bands draw). File: channels view{k}.warp ... view{k}.kd.B and metadata
  // clothfit:view_cosines; preset: weave_maps.view_cosines (the bands are drawn only when the
  // preset names them, and the two must agree).
  std::vector<double> view_cosines;
  std::vector<std::vector<std::vector<float>>> view_levels;  // per band: its mip chain

  bool has_views() const { return !view_levels.empty(); }
  // The hat weights of the bands at view cosine nov (sum 1; index = band).
  std::vector<double> ViewWeights(double nov) const;
  // Sets the bands from their level 0 (size^2 x 5 each; renormalised to tile mean 1, as
  // FromLevel0). Throws std::invalid_argument on 2..8 bands not given, cosines not strictly
  // decreasing in (0, 1], or a bad level.
  void SetViews(std::vector<double> cosines, std::vector<std::vector<float>> level0s);

  // The filter footprint of one sample (see "Anisotropic filtering" above): the LOD, the
  // number of probes and the uv step between them (the first probe at uv - (n - 1)/2 step).
  // n = 1, step 0: one trilinear sample at uv (the isotropic path when anisotropy = 1).
  struct Footprint {
    double lambda = 0.0;
    int n = 1;
    double step_u = 0.0, step_v = 0.0;
  };
  // The footprint for a map with `texels` texels per uv unit and `levels` mip levels, from the
  // uv derivatives (du/dx, dv/dx, du/dy, dv/dy) times footprint_scale, max anisotropy `aniso`.
  static Footprint FootprintFor(const std::array<double, 4>& duv, double texels, int levels,
                                int aniso, double footprint_scale = 1.0,
                                AnisoRule rule = AnisoRule::kSpec);
  // The footprint of the weave, normal and anisotropy maps (texels = size x uv_repeats) with
  // this object's anisotropy; anisotropy = 1: {Lod(duv, footprint_scale), 1, 0, 0}.
  Footprint FootprintAt(const std::array<double, 4>& duv, double footprint_scale = 1.0) const;
  // The samples below at a footprint: the mean of fp.n trilinear probes at fp.lambda.
  std::array<double, kChannels> Sample(double u, double v, const Footprint& fp) const;
  // Sample at a footprint with the view bands blended by nov in [0, 1] (above); Sample(u, v,
  // fp) without bands.
  std::array<double, kChannels> SampleView(double u, double v, const Footprint& fp, double nov) const;
  std::array<double, 2> SampleAnisotropy(double u, double v, const Footprint& fp) const;
  std::array<double, 3> SampleNormal(double u, double v, const Footprint& fp) const;

  // From level 0 (size^2 x 5 values): checks the size, renormalises every channel to a tile
  // mean of 1 (throws std::invalid_argument on a non-positive or non-finite mean), builds mips.
  static WeaveMaps FromLevel0(int size, double uv_repeats, std::vector<float> level0);
  int level_count() const { return int(levels.size()); }
  // GPU LOD from the uv derivatives (du/dx, dv/dx, du/dy, dv/dy) times footprint_scale.
  double Lod(const std::array<double, 4>& duv, double footprint_scale = 1.0) const;
  // Trilinear sample (REPEAT) at uv (TEXCOORD_0) and LOD lambda.
  std::array<double, kChannels> Sample(double u, double v, double lambda) const;
  // Bilinear sample of one level.
  std::array<double, kChannels> SampleLevel(double u, double v, int level) const;
  // Trilinear sample of the anisotropy map at the same uv and LOD as Sample, decoded as three.js
  // r187 does (lights_physical_fragment): normalize(2 rg - 1) * b -> (vx, vy) in the (t, b)
  // frame (before the preset's rotation and strength); (0, 0) where rg = (0.5, 0.5) or b = 0.
  std::array<double, 2> SampleAnisotropy(double u, double v, double lambda) const;
  // Sets the relief normal map from level 0 (size^2 x 3, unit vectors with z > 0) and builds
  // its mips. Throws std::invalid_argument on a bad size or a non-finite value.
  void SetNormals(std::vector<float> level0);
  bool has_normals() const { return !normal_levels.empty(); }
  // Trilinear sample of the normal map, normalised (the shader's normalize); (0, 0, 1) without one.
  std::array<double, 3> SampleNormal(double u, double v, double lambda) const;
  // Glint map (see above). SetGlint throws std::invalid_argument on a bad size or value.
  void SetGlint(int size, std::vector<float> level0);
  bool has_glint() const { return !glint_levels.empty(); }
  // Trilinear sample of I with the GPU LOD of this map's own texel density (anisotropic with
  // this object's anisotropy > 1, the footprint in glint texels); 1 without one.
  double SampleGlint(double u, double v, const std::array<double, 4>& duv,
                     double footprint_scale = 1.0) const;
};

// EXR I/O (io::IoError naming the file; std::invalid_argument on bad content, naming the file).
// The glint map, if any, goes to its own file (channel I; another resolution).
void WriteGlintMap(const std::string& path, const WeaveMaps& maps);
void ReadGlintMap(const std::string& path, WeaveMaps* maps);
void WriteWeaveMaps(const std::string& path, const WeaveMaps& maps,
                    const std::map<std::string, std::string>& metadata = {});
WeaveMaps ReadWeaveMaps(const std::string& path);

// The preset's top-level field (MaterialPreset::extra["weave_maps"]):
//   {"file": "<absolute path of the EXR>", "uri": "<path relative to the preset's directory>",
//    "size": 64, "uv_repeats": 40,
//    "channels": ["warp", "weft", "kd.R", "kd.G", "kd.B"],
//    "colour_space": "linear ratios to the tile mean (kd: linear sRGB)",
//    "convention": "texel (i, j) covers uv [i, i+1) / (size uv_repeats) x [j, j+1) / ..., row j from the top; REPEAT",
//    "source": {...}   (what the bake was made from; informative),
//    "glint_file": "<absolute path>", "glint_uri": "<relative>"   (optional: the glint map),
//    "anisotropy": 16   (optional: WeaveMaps::anisotropy, an integer in [1, 16]; missing = 1)}
// Which path is read (docs/preset-format.md, "Weave maps"): "uri" ("glint_uri") resolved
// against the directory of the preset FILE when present -- it must be relative, stay inside
// that directory (after ".." and symlinks) and name an existing regular file, or the read fails
// naming the preset file and the field; "file" ("glint_file") only when there is no "uri".
// So a preset directory moved or copied elsewhere still loads its own copies of the maps.
nlohmann::json WeaveMapsPresetField(const std::string& file, const WeaveMaps& maps,
                                    const nlohmann::json& source = nlohmann::json::object());
// Adds "uri" (and "glint_uri") to a preset's weave_maps field, relative to the directory of
// `preset_path`, when the map files lie inside that directory (as `clothfit fit` writes them:
// <stem>.weave.exr next to <stem>.json); leaves the field alone otherwise. No-op without a field.
void AddPresetWeaveMapUris(MaterialPreset* preset, const std::string& preset_path);
// Resolves the field of a preset read from `preset_path` (above): afterwards "file" and
// "glint_file" hold the paths to read (absolute) and "uri"/"glint_uri" are gone, so the
// one-argument LoadPresetWeaveMaps reads them. Throws MaterialError naming `preset_path` and
// the field (untrusted text escaped) on an absolute, escaping, scheme-bearing or missing uri.
void ResolvePresetWeaveMapPaths(MaterialPreset* preset, const std::string& preset_path);
// Validates weave_maps.anisotropy (if present: a JSON integer in [1, 16]; 0, 17, 2.5, 16.0
// and "x" are refused, as the woven fis_taps are) and returns it (1 when missing). Throws
// MaterialError "<where>: field weave_maps.anisotropy: ..." (`where` the preset file, or
// "preset" when unknown). Called by ResolvePresetWeaveMapPaths and LoadPresetWeaveMaps.
int PresetMapAnisotropy(const nlohmann::json& weave_maps_field, const std::string& where);
// The maps a woven preset names, or null (no field, or not a woven preset). Throws
// MaterialError naming the field on a malformed field, io::IoError on an unreadable file.
// The one-argument form reads "file" and refuses a field that still has a "uri" (a preset
// read from a file must be resolved first: the "file" beside it may be another machine's path).
std::shared_ptr<const WeaveMaps> LoadPresetWeaveMaps(const MaterialPreset& preset);
// ResolvePresetWeaveMapPaths on a copy, then the above.
std::shared_ptr<const WeaveMaps> LoadPresetWeaveMaps(const MaterialPreset& preset,
                                                     const std::string& preset_path);

// Screen-space uv derivatives of the hit's triangle at pixel (px, py) (pixel centres at +0.5):
// the triangle's uv plane evaluated where the rays through (px + 1, py) and (px, py + 1) meet
// the triangle's plane, minus its value at (px, py) (what a GPU's quad derivatives of an
// interpolated varying give on one triangle). Returns {du/dx, dv/dx, du/dy, dv/dy}; a ray
// parallel to the plane gives +inf derivatives (the coarsest mip).
std::array<double, 4> UvDerivatives(const Scene& scene, const Hit& hit, double px, double py);

}  // namespace clothfit::render
