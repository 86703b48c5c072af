// fit/image_fit.h: fit a material's parameters so the preview matches path-traced references.
//
// Problem. For each (scene, reference) pair the preview cache of the scene (render/preview/preview.h)
// is built once. Residuals are taken per block of B x B pixels, B = 2^level (the
// mesostructure footprint: a woven reference shows yarn-scale structure a uniform material
// cannot reproduce, so both images are averaged over blocks larger than the weave period
// before they are compared). Only blocks whose pixels are all fabric in the reference (its
// "fabric" coverage channel = 1) and in the preview are used: background and silhouette
// pixels are masked out. Averaging happens in linear radiance (what a pixel footprint does);
// the residual space is applied to the block means:
//   display (default): the scene card's tone mapping + exposure, then the sRGB transfer
//   linear           : radiance as is
//   log              : log(radiance + 1e-3)
// residual = (T(preview block) - T(reference block)) / sqrt(sigma^2 + floor^2), with sigma the
// reference block's standard error propagated through T (first order) and floor = 0.01 in
// display units (0.01 x mean reference radiance in linear, 0.01 in log), so a converged
// reference does not give a few blocks unbounded weight. A robust loss (Huber by default,
// scale 1 in these units: residuals beyond one floor-unit grow linearly) tempers outliers.
//
// Solver. Ceres trust region (Levenberg-Marquardt) with the parameter table's bounds; the
// Jacobian comes from one ceres::Jet<double, N> evaluation of the preview per scene (all free
// parameters at once; N = 4, 6, 8 or 10, the narrowest width holding the free derivative
// slots: a channel-separable colour block takes one slot, FitOptions::pack_colours). The
// preview cache of a scene is built only for the pixels the blocks sample
// (PreviewOptions::sample_mask), with every pixel's fabric flag (docs/fitting.md, "Fit speed"). Multi-start over roughness (the colours are started from the
// reference's mean colour); the best usable start wins. A fit whose Summary is not usable, or
// whose parameters are not finite, is reported as failed and never written as a preset.
#pragma once

#include <ceres/ceres.h>

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "fit/convergence.h"
#include "render/scene/environment.h"
#include "render/scene/material.h"
#include "render/preview/preview.h"
#include "render/scene/scene.h"
#include "render/scene/tonemap.h"

namespace clothfit::fit {

class YarnFarField;  // fit/yarn_farfield.h

enum class Space { kDisplay, kLinear, kLog };
std::string ToString(Space s);
Space ParseSpace(const std::string& s);  // throws std::invalid_argument

enum class Loss { kHuber, kCauchy, kNone };

// One reference image for one scene (linear RGB + per-channel standard error + coverage).
struct Reference {
  std::string path;
  int width = 0, height = 0;
  std::vector<float> rgb, std_error, fabric;  // 3, 3, 1 per pixel
  // Coverage weight per pixel (fit/reference.h): the block means are sum(w x) / sum(w) on
  // both sides. ReadReference(path) fills it as 1 where fabric >= 0.999, else 0.
  std::vector<float> weight;
  std::string layout, noise;  // how coverage and noise were read (printed by clothfit fit)
  // The two independent half-sample images (fit/metrics/reference_halves.h): linear RGB per
  // pixel like `rgb` (same coverage handling), from the first `half_batches` of `batches`
  // batch means and from the others. Empty when the file has no half.R/G/B channels.
  std::vector<float> half_a, half_b;
  int half_batches = 0, batches = 0;
};

// Reads a reference with the default ReferenceOptions (fit/reference.h): channels R, G, B;
// optional stderr.R/G/B, fabric or A. Throws io::IoError naming the file on missing/corrupt
// files, and FitError on NaN/Inf pixels.
Reference ReadReference(const std::string& path);

class FitError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FitOptions {
  render::MaterialPreset start;   // model, cloth options, and values of locked parameters
  std::vector<std::string> locked;  // parameter names held fixed at `start`'s values
  Space space = Space::kDisplay;
  Loss loss = Loss::kHuber;
  double loss_scale = 1.0;
  int level = 2;                  // block size 2^level (see AutoLevel)
  int pixel_stride = 0;           // evaluate every stride-th pixel per block axis (speed);
                                  // 0 = auto: max(1, block / 4), i.e. at most 4 x 4 per block
  // Multi-start values (roughness; sheen_roughness too where the model has one). 0.3 since
  // session 26: from 0.6 and 0.9 every baseline missed the basin of a glossy reference
  // (Cycles Principled at roughness 0.1 and 0.25: block RMSE 6-9x the 0.3 start's;
  // docs/fitting.md "A start for glossy references"). Starts that give the same parameter
  // blocks run once: no init_from_reference, or every parameter r0 sets (roughness, and
  // sheen_roughness where the model has one) locked. physical-aniso adds one start: the
  // lowest of these values with its anisotropy strength at 0.05 (FitImages).
  std::vector<double> start_roughness = {0.6, 0.9, 0.3};
  int max_iterations = 50;        // per start
  double min_coverage = 0.5;      // a block is kept when sum(w) / B^2 >= this (docs/references.md)
  double function_tolerance = 1e-7;
  bool verbose = false;
  bool init_from_reference = true;  // start colours from the reference's mean colour
  // woven only (fit/woven_fit.h FitWovenImages): also fit from the cloth basin (yarn lobes off,
  // broad sheen) and keep the better result; false = the session-5 stages alone.
  bool cloth_basin_start = true;
  // Jacobian: a channel-separable colour block takes one derivative slot instead of three
  // (fit/image_fit.cpp, kJetWidths; docs/fitting.md "Fit speed"). Same Jacobian up to
  // rounding; false only to compare.
  bool pack_colours = true;
  // Exact image-based light in the preview (render/preview/preview.h PreviewOptions::
  // exact_ibl_samples / exact_ibl_seed): a measurement tool (docs/fitting.md, "The sphere's
  // error decomposed"); 0 = the engine's split sum (default).
  int exact_ibl_samples = 0;
  unsigned exact_ibl_seed = 1;
  int exact_irradiance_samples = 0;  // PreviewOptions::exact_irradiance_samples (measurement)
  // Sheen nap prototype (PreviewOptions::sheen_tilt_degrees, docs/velvet.md; measurement,
  // cloth and woven): 0 = untouched.
  double sheen_tilt_degrees = 0.0;
  // Light visibility in the preview (measurement, docs/visibility.md): PreviewOptions::shadows
  // and ::visibility (AO map, light map); every model of a comparison gets the same.
  bool shadows = false;
  render::VisibilityOptions visibility;
  // The scene cards' "visibility" blocks (shadows, a light map baked over the fabric's uv;
  // PreviewOptions::card_visibility, session 13). When a light map bounces off the fabric and
  // visibility.fabric_albedo is not set, the fit runs twice: the second pass bakes the light map
  // with the first pass's fitted diffuse albedo (render::DiffuseAlbedo) and restarts from its
  // solution, so the light map is the one an engine bakes for the fitted material.
  bool card_visibility = true;
  // Whose image-based lighting the previews reproduce (render/preview/preview.h IblEngine).
  // kFilament here keeps library callers unchanged; `clothfit fit` defaults to kAuto (the
  // engine web/ draws the model with). The woven IBL mode (split / FIS) is start.woven's.
  render::IblEngine ibl_engine = render::IblEngine::kFilament;
  // The environment's sun as a directional light in the previews (render/scene/sun.h,
  // PreviewOptions::env_sun / env_sun_default; docs/sun.md): unset = each card's
  // environment.sun, else env_sun_default (off here; `clothfit fit` and `evaluate` set auto).
  std::optional<render::SunMode> env_sun;
  render::SunMode env_sun_default = render::SunMode::kOff;
  // Far-field yarn lobe (measurement, fit/yarn_farfield.h; woven): the previews' yarn lobes are
  // the fabric's period-averaged Irawan specular (PreviewOptions::yarn_lobe; with an
  // environment it needs exact_ibl_samples > 0 unless yarn_table gives its split sum). Null:
  // the model's own lobes.
  std::shared_ptr<const YarnFarField> yarn_far_field;
  // Tabulated yarn lobe (session 11; brdf/yarn_table.h, woven): the previews' yarn lobes from
  // the table, direct lights by lookup and the environment by its per-wo split sum
  // (PreviewOptions::yarn_lobe and yarn_ibl), so no exact IBL is needed. Takes precedence over
  // yarn_far_field. Null: the model's own lobes.
  std::shared_ptr<const yarn_table::Table> yarn_table;
  // With yarn_table and yarn_far_field: the table gives the environment's split sum only, the
  // far-field lobe the lights (and exact-IBL samples): separates the two approximations.
  bool yarn_table_ibl_only = false;
  // > 0: the far-field lobe by YarnFarField::EvalQuadrature with this many nodes (the
  // deterministic, shader-shaped evaluation) instead of the Monte Carlo Eval.
  int yarn_quadrature_nodes = 0;
  // With yarn_table: the environment by one read per wi bin of the table (Table::BinTaps, a
  // filtered quadrature of the lobe; PreviewOptions::yarn_ibl_taps) instead of the one-read
  // summary per lobe. Measurement.
  bool yarn_ibl_bins = false;
};

struct SceneInput {
  const render::Scene* scene = nullptr;
  const render::Environment* environment = nullptr;  // may be null
  const Reference* reference = nullptr;
  const Reference* second = nullptr;  // same scene, another seed: the noise floor (optional)
  std::string scene_path;
};

struct SceneError {
  std::string scene, reference;
  int blocks = 0;
  int dropped_preview = 0;   // blocks with a pixel that is not fabric in the preview
  int dropped_coverage = 0;  // blocks whose reference coverage fraction < min_coverage
  double rmse = 0.0;         // unweighted RMSE in the fit space over the blocks
  double noise_floor = -1.0; // one reference's own noise over the same blocks and space,
                             // which no fit can beat (-1: neither a second reference nor
                             // half channels): with a second reference (another seed)
                             // RMSE(reference, second) / sqrt(2); else, from the reference's
                             // halves A and B, RMSE(A, B) x sqrt(kA (K - kA)) / K
                             // (= RMSE(A, B) / 2 for equal halves; reference_halves.h)
  std::string noise_floor_source;  // "second reference", "reference halves" or ""
};

struct FitResult {
  bool usable = false;
  std::string message;        // why it failed, if it did
  render::MaterialPreset preset;
  double final_cost = 0.0, initial_cost = 0.0;
  int iterations = 0, starts = 0, residuals = 0;
  double seconds = 0.0, setup_seconds = 0.0;
  // The fit ran the light map's second pass (FitOptions::card_visibility); the preset's
  // fit.visibility records the albedo it baked with.
  bool albedo_pass = false;
  std::string termination;
  bool converged = false;             // the winning start's termination was CONVERGENCE
  std::vector<AtBound> at_bound;      // free parameters at a bound (fit/convergence.h;
                                      // ApplyNoEffect)
  std::vector<SceneError> scenes;
  double rmse = 0.0;          // over all blocks of all scenes, fit space, unweighted
  std::string solver_report;  // Ceres BriefReport of the winning start
  // woven (fit/woven_fit.h FitWovenImages): each path's RMSE, iterations and fit seconds (setup
  // excluded), in the order run: "two-stage", "cloth-basin", "cloth-basin+two-stage", then
  // "rough-diffuse", "lobe-shape", "lobe-shape+share"; with several free start roughness
  // values (session 26) each branch's paths prefixed "start R: " (R = 0.6, 0.3) and "cloth
  // basin: ", then the second round's "second round: ". With a
  // card's light map (FitWithLightMapAlbedo's two passes) the first pass's paths are prefixed
  // "first pass: " and the second's "albedo pass: " (session 15).
  struct Candidate {
    std::string name;
    double rmse = 0.0, seconds = 0.0;
    int iterations = 0;
  };
  std::vector<Candidate> candidates;
};

// Block size from the weave scale: the smallest level whose block spans at least two weave
// periods in pixels at the median fabric pixel (uv footprint measured from the G-buffer).
int AutoLevel(const render::Scene& scene, double weave_period_uv, int max_level = 5);
// The level for a joint fit: the largest AutoLevel over the scenes (every scene's blocks must
// average the weave out). weave_period_uv <= 0 (no weave known): level 2.
int AutoLevel(const std::vector<SceneInput>& inputs, double weave_period_uv, int max_level = 5);

// The fit. Throws FitError on bad input (mismatched sizes, no usable blocks, infeasible
// start); returns usable = false when the solver fails.
FitResult FitImages(const std::vector<SceneInput>& inputs, const FitOptions& options);

// Free scalars of the fit: the parameters neither locked nor ignored by the model's options
// (cloth's sheen_color unless explicit, subsurface_color without subsurface). 0: nothing to fit
// (every start returns at once; `clothfit fit` warns).
int FreeParameterCount(const FitOptions& options);

// The woven model's degenerate solution (brdf/woven.h), with its own GGX yarn lobes: not with a
// far-field yarn lobe, which replaces them (the preset's "yarn_lobe", FitOptions::
// yarn_far_field / yarn_table), nor with "ibl": "bent", whose tables are built for the held
// anisotropy and twist. At `anisotropy` s <= kIsotropicAnisotropy (the bound tolerance of
// ParametersAtBounds: alpha_across - alpha_along = (1 - r^2) s^2 <= 1e-12) both yarn lobes are
// the same isotropic GGX lobe L:
//  - `twist`, which only turns the lobes' axes in the tangent plane, has no effect;
//  - `warp_share` m has none either when the two lobes' weights agree in every pixel (no weave
//    maps, tint_warp == tint_weft): m L + (1 - m) L = L, direct and IBL alike.
// Returns those of the two that are free (not in options.locked; a caller whose fit ran in
// stages passes its own options, not a stage's), and the reason ("at anisotropy 0"); empty for
// every other model and solution. `clothfit fit` prints them and records fit.no_effect.
inline constexpr double kIsotropicAnisotropy = 1e-6;
std::vector<std::string> ParametersWithoutEffect(const render::MaterialPreset& preset,
                                                 const FitOptions& options, std::string* reason);
// What FitImages does with a solution's bounds (FitResult::at_bound): the parameters without
// effect are reported at a bound but not flagged (a bound on a parameter that does not change
// the image says nothing about the fit). So is woven's `anisotropy` at 0 under the same
// conditions: s enters its lobes only as s^2, so its derivative vanishes at 0 and the isotropic
// lobe is a stationary point the bound did not stop (every lobe shape is reachable from it by
// roughness and twist): "none of this term", as a colour at 0 (fit/convergence.h).
void ApplyNoEffect(const FitOptions& options, FitResult* result);

// The per-scene fit data (preview caches of the sampled pixels, blocks, targets, weights),
// built once and shared by several fits of the same inputs (the woven stages): they must use
// the same level, pixel stride, space, min_coverage, model and weave maps (FitError if not;
// cloth, whose cache depends on its options, is not shared). `setup_seconds` of such a fit
// does not include the preparation (PreparedScenes::seconds, see PreparedSeconds).
struct PreparedScenes;
// A fit (`fit`: FitImages or FitWovenImages over the given prepared scenes, null = its own)
// with the light map's second pass (FitOptions::card_visibility): when some scene bakes a light
// map that bounces off the fabric and no fabric albedo is set, the fit runs again from its
// solution with the map baked for the fitted diffuse albedo (the first pass's caches re-weighted,
// PreviewCache::irradiance_unit, when the light map has one bounce; rebuilt otherwise).
FitResult FitWithLightMapAlbedo(
    const std::vector<SceneInput>& inputs, const FitOptions& options,
    const std::function<FitResult(const FitOptions&, const PreparedScenes*)>& fit);

std::shared_ptr<const PreparedScenes> PrepareScenes(const std::vector<SceneInput>& inputs,
                                                    const FitOptions& options);
double PreparedSeconds(const PreparedScenes& prepared);
FitResult FitImages(const std::vector<SceneInput>& inputs, const FitOptions& options,
                    const PreparedScenes* prepared);

// The preview (linear, full frame) of a preset on a scene: for residual images and reports.
// `engine`: the IBL engine of the fit (FitOptions::ibl_engine); the preset's woven options
// (IBL mode and taps) apply.
std::vector<float> RenderPreviewFrame(const render::Scene& scene, const render::Environment* env,
                                      const render::MaterialPreset& preset,
                                      render::IblEngine engine = render::IblEngine::kFilament,
                                      std::optional<render::SunMode> env_sun = std::nullopt,
                                      render::SunMode env_sun_default = render::SunMode::kOff);
// The same with the fit's own preview settings (IBL engine, sun, and the measurement settings:
// exact IBL, sheen tilt, visibility, far-field yarn lobe), so that a measurement fit's images
// show what its residuals were computed on; the full frame (no sample mask).
std::vector<float> RenderPreviewFrame(const render::Scene& scene, const render::Environment* env,
                                      const render::MaterialPreset& preset, const FitOptions& fit);

}  // namespace clothfit::fit
