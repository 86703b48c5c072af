// fit/weave_maps.h: baking the woven model's weave maps (issue 12, deliverable 2) from a
// fabric's Irawan weave and its reference BSDF. Lives in fit/ because it reads
// render/reference (the preview may not; the data type and the sampling are in
// render/preview/weave_maps.h, which states the channels, the colour space and the uv
// convention).
//
// Per texel (i, j) of one weave period (size x size texels, texel centre uv =
// ((i + 0.5), (j + 0.5)) / (size R)), the reference BSDF (fineness glints off: E[I] = 1, the
// maps are periodic and the glint hash is not) is evaluated on a small ANISOTROPIC direction
// set in the shading frame (t = +x = warp, b = +y = weft, n = +z):
//   mu_v, mu_l at `mu_nodes` Gauss-Legendre nodes of [0, 1]; phi_v at `phi_v` values
//   (k + 0.5) pi / phi_v over a half turn (the model's lobes are lines: a half turn of the
//   view sees every orientation once); phi_l at `phi_l` values (k + 0.5) 2 pi / phi_l;
//   weight w = w_GL(mu_v) w_GL(mu_l) 2 mu_v (as fit/brdf_fit.h's canonical set: projected-
//   area view weighting, uniform lights), normalised to sum 1.
// The per-texel model is the woven model (brdf/woven.h) with its GLOBAL lobes (the preset's
// roughness, anisotropy, twist, warp share, f0, beta, specular and sheen colours) and the
// texel's WeaveSample as unknowns:
//   f(k) = B_sheen(k) + a_w B_warp(k) + a_f B_weft(k) + kd_c B_kd,c(k)     (per channel c)
// which is LINEAR in x = (a_w, a_f, kd_R, kd_G, kd_B). It is solved per texel in closed form
// (5 x 5 normal equations; no Ceres, no start needed) for a cube-root metric (fit/brdf_fit.h's
// until session 27, which moved to a square root; the bake keeps the cube root) linearised at
// the target (weight w (target + eps)^(-4/3) / 9 per squared
// linear residual), with non-negativity by an active set (a negative unknown is fixed at 0 and
// the rest re-solved), and a small ridge towards the tile's uniform value (1) that keeps
// texels with no specular information (e.g. a lobe that is dark on every direction) finite.
// The maps store x / mean(x) (render/preview/weave_maps.h): the tile means of the mapped and
// the uniform model are equal, and the global parameters keep their meaning.
#pragma once

#include <string>

#include "render/preview/weave_maps.h"
#include "render/reference/irawan.h"
#include "render/scene/material.h"

namespace clothfit::fit {

struct WeaveBakeOptions {
  int size = 64;      // texels per period (power of two)
  int mu_nodes = 3;   // Gauss-Legendre nodes per cosine
  int phi_v = 4;      // view azimuths over [0, pi)
  int phi_l = 8;      // light azimuths over [0, 2 pi)
  double ridge = 1e-3;  // relative ridge towards x = 1 (see the header comment)
  // true: no per-texel fit; the analytic maps of the design notes instead: warp = 1 where
  // the reference's Locate puts a warp yarn on top (else 0), weft likewise, kd = that yarn's
  // kd, each averaged over 4 x 4 sub-positions of the texel (a box prefilter).
  bool indicator = false;
  // true: also a relief normal map from the reference's yarn geometry (render/preview/
  // weave_maps.h), and the per-texel fit evaluates the model in each texel's normal-mapped
  // frame (what the preview then shades).
  bool relief = false;
  // true: also the glint map (render/preview/weave_maps.h): the reference's fineness
  // intensity I = min(-log xi, 10) of its own hash (IrawanBsdf::Locate), over the whole uv
  // square at the smallest power of two >= the fineness cells per uv unit (<= 2048), 2 x 2
  // sub-positions per texel (box prefilter). Not normalised (the reference's E[I] is 1).
  bool glint = false;
  // Measurement (session 14, docs/flip.md "View-dependent weave maps"): >= 0 fits the texels on
  // the pairs whose view cosine is the view_band-th Gauss-Legendre node only (0 .. mu_nodes-1,
  // in the order of lut::GaussLegendre); -1 (default) on every pair.
  int view_band = -1;
  // true (session 14, `clothfit fit --weave-map-views`): also bake one map per view cosine
  // (view_band = 0 .. mu_nodes - 1) into the result's view bands (render/preview/weave_maps.h
  // SetViews; cosines = the Gauss-Legendre nodes, decreasing). Not with indicator, relief,
  // glint or view_band >= 0.
  bool view_bands = false;
};
// The view cosine of view band k (the k-th Gauss-Legendre node of [0, 1] with `mu_nodes` nodes).
double WeaveViewBandCosine(int k, int mu_nodes);

struct WeaveBakeResult {
  render::WeaveMaps maps;
  // Fit error over all texels and pairs (the cube-root metric above, cube-root units): the tile
  // with one uniform x (the texel-mean solution, what the uniform model can do with these
  // global lobes) and with the per-texel x (what the maps can do).
  double error_uniform = 0.0, error_mapped = 0.0;
  double mean_warp = 0.0, mean_weft = 0.0;  // tile means of a_w, a_f before normalisation
  Rgb<double> mean_kd{0, 0, 0};             // tile mean of kd_c (x the preset's base colour)
  int pairs = 0;
  double seconds = 0.0;
};

// Throws std::invalid_argument when the preset is not woven or the BSDF's repeats differ.
WeaveBakeResult BakeWeaveMaps(const render::IrawanBsdf& bsdf, const render::MaterialPreset& preset,
                              const WeaveBakeOptions& options = {});

}  // namespace clothfit::fit
