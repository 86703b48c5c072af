// fit/brdf_fit.h: conversion by fitting in BRDF space (docs/convert.md, "The BRDF-space fit").
//
// Directions. A fixed, deterministic set of (view, light) pairs in the shading frame (n = +z),
// a product rule over the view cosine and the half vector (session 27; before, the light was
// gridded in (mu_l, phi), whose nodes never came within ~1.5 degrees of a mirror
// configuration, so a GGX lobe narrower than that was invisible to the fit and a cloth source
// converted to a mirror-smooth engine material with a tiny error; docs/convert.md section 2):
//   mu_v = cos(theta_v) at the kDirNodes Gauss-Legendre nodes of [0, 1] (no node at exactly 0
//   or 1: grazing down to ~88 degrees), v = (sqrt(1 - mu_v^2), 0, mu_v);
//   h at theta_h = (pi/2) t^2 (the MERL tables' mapping), t at the kHalfNodes Gauss-Legendre
//   nodes of [0, 1] (the first nodes at theta_h = 2.7e-4 and 7.2e-3 rad, the light about twice
//   that from the mirror direction: a
//   GGX lobe down to roughness ~0.02, alpha = r^2 ~ 4e-4, is seen), phi_h = (k + 0.5) pi / kHalfAzimuths relative to v's azimuth (isotropic sources:
//   [0, pi] suffices by symmetry); l = 2 (v.h) h - v, kept when l.z > kMinLightCosine.
// Weights (normalised to sum 1):
//   w = w_GL(mu_v) * 2 mu_v                            how often a view cosine occurs in the
//                                                      canonical scenes: the fabric pixels of
//                                                      a convex object under the camera have
//                                                      n.v distributed as 2 mu dmu (projected
//                                                      area; sphere, drape)
//     * w_GL(t) pi t sin(theta_h) (pi / kHalfAzimuths) 4 (v.h)
//                                                      solid angle of l: d omega_l =
//                                                      4 (v.h) d omega_h (Walter et al. 2007,
//                                                      eq. 14), d omega_h = sin theta_h
//                                                      d theta_h d phi_h
//   the light weights of each view rescaled to sum to pi exactly (the horizon truncates the
//   grid). Light directions are uniform over the hemisphere (environment light arrives from all
//   directions; the canonical scenes' key/rim lights sit at a range of elevations): the cosine
//   of the light is in the compared value itself, not in the weight.
// Value compared: the cosine-weighted BRDF f(v, l) * n.l (what EvalDirect returns), per RGB
// channel, compressed by a square root (session 27; a cube root before):
//   residual = sqrt(w) * (sqrt(max(f_target n.l, 0) + eps) - sqrt(max(f_source n.l, 0) + eps)),
//   eps = 1e-4 (keeps the derivative finite at 0: at most 1 / (2 sqrt(eps)) = 50).
// Summed over the light hemisphere, sum_c residual^2 is the squared Hellinger distance
// int (sqrt(f_t) - sqrt(f_s))^2 d omega_l between the two reflected-light distributions.
// Why the square root: a lobe of energy E over a solid angle A that the source does not have
// costs A (E / A)^(2p) = E^(2p) A^(1 - 2p) under a compression x^p. For the cube root (p = 1/3)
// that vanishes as A -> 0, so the fit hid a target's unwanted specular energy (the F0 = 0.04 of
// the engines' dielectric base) in a mirror-sharp lobe; for p = 1/2 it costs E whatever its
// width (and less where the source has light to mask it, ~ f^2 / (4 f_source)), so the energy
// goes where it shows least. Larger p would weight the bright peaks ever more.
// Fit error: sqrt(sum_k w_k sum_c residual^2 / (3 sum_k w_k)), in square-root units (a value
// of 0.01 is ~6 % relative error at f n.l = 0.1: d sqrt(y) / sqrt(y) = dy / (2 y)). Missing
// source samples (MERL cells marked negative) are dropped and the weights renormalised.
//
// Solver: Ceres Levenberg-Marquardt, one parameter block in the model's flat layout
// (fit/parameter_layout.h bounds; cloth roughness floored at the variant's clamp), dynamic
// autodiff with ceres::Jet<double, 10>; parameters a model ignores (cloth sheen_color under a
// non-explicit sheen default, subsurface_color without subsurface) and locked ones are held by
// a SubsetManifold. Multi-start: roughness starts (sheen roughness too) with colours started
// from the source's mean albedo, plus the source's own parameters when the source is the same
// model; the start with the lowest fit error wins.
#pragma once

#include <string>
#include <vector>

#include "brdf/math.h"
#include "brdf/models.h"
#include "brdf/params.h"
#include "render/reference/bsdf.h"
#include "render/reference/fabric.h"
#include "render/scene/material.h"

namespace clothfit::fit {

inline constexpr int kDirNodes = 6;      // Gauss-Legendre nodes of the view cosine
inline constexpr int kHalfNodes = 10;    // Gauss-Legendre nodes of t, theta_h = (pi/2) t^2
inline constexpr int kHalfAzimuths = 8;  // half-vector azimuths over [0, pi]
inline constexpr double kMinLightCosine = 1e-3;  // pairs with l.z at or below are dropped
inline constexpr double kCompressEps = 1e-4;
// Names the direction set and metric; part of convert's resume hash (fit/convert/convert.h), so
// outputs fitted under an earlier revision are converted again.
inline constexpr const char* kFitRevision =
    "s28: woven sources by (point, azimuth) draws, mirror-averaged; "
    "s27: half-vector directions, square-root metric";
// Lowest roughness a fit may reach in a model whose range goes to 0 (gltf-sheen): below it
// the lobe falls between the half-vector nodes (the first sits 2.7e-4 rad from the mirror
// direction) and the fit would see a specular lobe of roughness -> 0 as no lobe at all
// (measured, docs/convert.md section 2). 0.045 is Filament's MIN_PERCEPTUAL_ROUGHNESS and the
// floor of this repository's cloth, standard and physical-sheen models; engines draw glTF
// roughness 0 at their own floor (three.js r187: 0.0525), never as an invisible lobe.
inline constexpr double kMinFitRoughness = 0.045;

struct DirectionPair {
  Vec3<double> v, l;
  Cosines<double> cos;
  double weight = 0.0;  // normalised over the whole set
};

// The canonical set (at most kDirNodes * kHalfNodes * kHalfAzimuths pairs), built once.
const std::vector<DirectionPair>& CanonicalDirections();

// A source BRDF sampled on the canonical set: value[k] = f * n.l (linear RGB), valid[k] false
// where the source has no data.
struct BrdfSamples {
  std::vector<Rgb<double>> value;
  std::vector<char> valid;
};

// Direct reflectance (cosine included, per unit light) of any preset model, flat parameters in
// parameter-table order; Jet-safe.
template <typename T>
Rgb<T> EvalDirectFlat(render::ModelKind m, const cloth::Options& co, const T* x,
                      const Cosines<T>& c) {
  auto rgb = [&](int k) { return Rgb<T>(x[k], x[k + 1], x[k + 2]); };
  switch (m) {
    case render::ModelKind::kCloth:
      return cloth::EvalDirect(cloth::Params<T>{rgb(0), rgb(3), x[6], rgb(7)}, co, c);
    case render::ModelKind::kStandard:
      return standard::EvalDirect(standard::Params<T>{rgb(0), x[3], x[4]}, {}, c,
                                  lut::DefaultDfg());
    case render::ModelKind::kPhysicalSheen:
      return physical_sheen::EvalDirect(physical_sheen::Params<T>{rgb(0), x[3], x[4], rgb(5), x[8]},
                                        {}, c, lut::DefaultDfg());
    case render::ModelKind::kGltfSheen:
      return gltf_sheen::EvalDirect(gltf_sheen::Params<T>{rgb(0), x[3], x[4], rgb(5), x[8]}, {}, c,
                                    lut::DefaultSheenAlbedo());
    case render::ModelKind::kWoven:
      // The canonical set is isotropic (relative azimuth only): the woven lobes are evaluated
      // with v in the tangent-normal plane (woven::TangentCosinesInPlane), one azimuth of an
      // anisotropic model, not its azimuthal average.
      return woven::EvalDirect(woven::FromFlat(x), {}, c, woven::TangentCosinesInPlane(c),
                               woven::WeaveSample<T>{}, lut::DefaultDfg(),
                               lut::DefaultWovenPhase());
    case render::ModelKind::kPhysicalAniso:  // in-plane v, as woven; no map
      return physical_aniso::EvalDirect(physical_aniso::FromFlat(x), {}, c,
                                        woven::TangentCosinesInPlane(c),
                                        physical_aniso::AnisoSample<T>{}, lut::DefaultDfg());
  }
  return Rgb<T>(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
}

// An analytic preset sampled on the canonical set.
BrdfSamples SampleAnalytic(const render::MaterialPreset& preset);
// A woven (spatially varying, possibly anisotropic) BSDF: the mean of Eval * cos over
// `samples` draws of a surface point (low-discrepancy within the weave period, period_uv wide,
// over kSourcePeriods^2 periods in turn) and an azimuthal rotation of the pair about n (over
// [0, 2 pi): an isotropic average), each pair also taken as its mirror image (y -> -y; the
// direction set holds one side of the plane of incidence). Session 28; before, a 4 x 4 grid
// of one period at 4 rotations over [0, pi), no mirror: the twill's tile is 4 x 8 yarn cells,
// so every other cell row was never sampled (its albedo came out 1.6-1.9x too high), and the
// satin's sharp anisotropic lobe was hit at 4 angles (its summed samples 3.3x a converged
// average's). docs/convert.md "Woven fabrics" has the measurements. Not averaged: variation
// slower than kSourcePeriods periods, e.g. a .weave's `period` > 0 (umax noise over 50-500
// cells: polyester, silk_shantung; no shipped fabric uses them).
inline constexpr double kSourcePeriods = 16.0;
// Defaults, measured against 65536 draws and against an independent Monte Carlo average
// (docs/convert.md "Woven fabrics"): Irawan fabrics (point-dependent, glints) 4096; a BSDF that
// is the same at every point (Sadeghi, lambert, ggx_conductor) needs azimuths only: 1024.
inline constexpr int kSourceSamples = 4096;
inline constexpr int kSourceSamplesUniform = 1024;
BrdfSamples SampleBsdf(const render::Bsdf& bsdf, double period_uv, int samples = kSourceSamples);
// The number of draws convert uses for a fabric (kSourceSamples for irawan, else
// kSourceSamplesUniform).
int SourceSampleCount(const render::Fabric& fabric);
// A fabric's BRDF-space source, as convert takes it: SampleBsdf with SourceSampleCount draws,
// of the fabric's BSDF or, for an Irawan fabric with fineness glints, of the same BSDF without
// them and its specular scaled by their mean (1 - e^-10): the same average, without the
// glints' variance.
BrdfSamples SampleFabric(const render::Fabric& fabric);

struct BrdfFitOptions {
  render::ModelKind model = render::ModelKind::kCloth;
  cloth::Options cloth;             // target options when model == kCloth
  std::vector<std::string> locked;  // held at the start preset's values
  // Candidate starts (roughness and sheen roughness; cloth colours in closed form, other
  // models' colours from the source's albedo), scored by their error; the best
  // `solved_starts` are solved.
  std::vector<double> start_roughness = {0.3, 0.45, 0.6, 0.75, 0.9};
  int solved_starts = 1;
  int max_iterations = 30;
  // The source itself when it is of the target model: added as a start.
  const render::MaterialPreset* source_preset = nullptr;
};

struct BrdfFitResult {
  bool usable = false;
  std::string message;
  render::MaterialPreset preset;
  double error = 0.0;  // weighted RMS in square-root units (see above)
  int starts = 0, iterations = 0;
};

// Throws std::invalid_argument when fewer than 16 samples are valid.
BrdfFitResult FitBrdf(const BrdfSamples& source, const BrdfFitOptions& options);

// The fit error of a preset against samples (same metric as BrdfFitResult::error).
double BrdfError(const BrdfSamples& source, const render::MaterialPreset& preset);

}  // namespace clothfit::fit
