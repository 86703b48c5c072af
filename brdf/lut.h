// brdf/lut.h: the tables the real-time models read, computed by our own integrator.
//
// DFG LUT (clothfit lut --out dfg.exr), size N x N, 3 channels, u = NoV, v = perceptual r,
// texel (i, j) at u = (i + 0.5)/N, v = (j + 0.5)/N:
//   R = A, G = B: GGX split-sum scale and bias (Karis 2013), alpha = r^2, height-correlated
//       Smith visibility, Schlick pow5 weight:  int f_GGX / F * ((1 - Fc) | Fc) cos = A | B,
//       so the directional albedo for F0 is F0 A + B (Filament's multiscatter layout stores
//       (B, A + B) instead: Er = mix(x, y, F0)).
//   B = DG: cloth sheen directional albedo int D_Charlie(alpha = r^2) V_Neubelt cos dl
//       (unclamped V, unclamped sin2h as in Filament's generator; no sheen colour).
// Sheen albedo table (clothfit lut --sheen-out), size M x M, 1 channel, u = NoV, v = r_s:
//   E = int D_Charlie(alpha = r_s^2) V_Charlie(alpha) cos dl (glTF KHR_materials_sheen).
//
// Integrator: deterministic stratified importance sampling of the half vector (GGX: its
// D cos; Charlie: sin(theta_h) = u^(alpha/(2 alpha + 1))), `samples` = S x S midpoint
// strata per texel, l = reflect(v, h), estimator f cos / pdf(l) = V cos_l 4 (v.h) / (n.h).
#pragma once

#include <functional>

#include "brdf/table.h"

namespace clothfit::lut {

struct Settings {
  int size = 128;              // texels per axis
  int samples_per_axis = 64;   // S: S x S importance samples per texel (4096 by default)
};

// Progress callback: called with (rows done, rows total); may be empty.
using Progress = std::function<void(int, int)>;

Table2D ComputeDfg(const Settings& s, const Progress& progress = {});
Table2D ComputeSheenAlbedo(const Settings& s, const Progress& progress = {});

// Single-texel integrals (the same estimators; used by tests and tools).
void IntegrateGgx(double NoV, double r, int samples_per_axis, double& A, double& B);
double IntegrateClothDg(double NoV, double r, int samples_per_axis);
double IntegrateSheenAlbedo(double NoV, double r, int samples_per_axis);

// Process-wide default tables (DFG 128 x 128, sheen albedo 32 x 32, 64 x 64 samples),
// computed on first use (thread-safe) and kept.
const Table2D& DefaultDfg();
const Table2D& DefaultSheenAlbedo();

}  // namespace clothfit::lut
