// fit/convert/weave_textures.h: a physical-aniso preset's weave maps as glTF / three.js
// textures (issue 12, deliverable 4; docs/convert.md, "Weave maps in glTF and three.js").
//
// What the preview does with the maps (render/preview/preview.cpp, physical-aniso; docs/
// fitting.md, "The honest baseline"), per texel t of level 0 of the weave maps (ratios to the
// tile mean, render/preview/weave_maps.h):
//   base colour   b_c k_c(t)            b = preset base_color (linear), k = kd ratio channel c
//   direction     (1, 0) if warp(t) >= weft(t) else (0, 1)   in the mesh tangent frame (t, b),
//                 then rotated by the preset's anisotropy_rotation (three.js anisotropyMat)
//   strength      a s(t), s = |warp - weft| / (warp + weft)  (0 when both are 0), a = preset
//                 anisotropy_strength; three.js / KHR: saturate(anisotropyStrength x texel.b)
//
// Encodings (the glTF 2.0 spec, KHR_materials_anisotropy, three.js r187 lights_physical_fragment):
//   baseColorTexture: 8-bit sRGB. Per channel c, K_c = max_t k_c(t); the factor f_c is the
//     smallest 8-bit sRGB code value >= b_c K_c (so the three.js hex colour holds it exactly,
//     and f_c <= 1 whenever b_c K_c <= 1); texel = the 8-bit sRGB code whose decoded value is
//     nearest to b_c k_c(t) / f_c (nearest in LINEAR value, not in code). Product f_c x texel
//     = b_c k_c(t) within f_c x half the local code step. If b_c K_c > 1 (not expressible:
//     glTF factors and texels are <= 1) f_c = 1 and those texels clip at 1: counted in
//     `clipped_texels` and in the measured error.
//   anisotropyTexture: 8-bit, linear, no colour chunk. RG = direction d in [-1, 1] stored as
//     (d + 1) / 2; B = s(t) / S with S = max_t s(t); anisotropyStrength = a S. 0.5 has no 8-bit
//     code, so the warp direction is stored as (255, 127) -> (1, -1/255) and the weft as
//     (128, 255) -> (1/255, 1): both are the exact axis turned by -e, e = atan(1/255); the
//     writer adds e to anisotropyRotation (wrapped into [-pi, pi]), so the decoded direction
//     after the rotation is the preview's exactly (to double rounding). Strength error <= a S /
//     510.
//   Both: TEXCOORD_0 scaled by (R, R) (KHR_texture_transform / three.js texture.repeat),
//     R = the maps' uv_repeats; REPEAT wrapping; texel (i, j) = PNG column i, row j from the top
//     (glTF's uv origin is the image's top-left, three.js flipY = false).
// Not expressible, stated rather than approximated: the preview derives direction and
// strength from the FILTERED warp/weft weights (a mip or bilinear footprint), a GPU filters
// the encoded direction texels; they agree at texel centres at level 0 (what the test checks)
// and differ where warp and weft texels are averaged (docs/convert.md gives the measure).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "brdf/math.h"
#include "render/preview/weave_maps.h"
#include "render/scene/material.h"

namespace clothfit::fit {

struct WeaveTextures {
  int size = 0;             // texels per side (one weave period)
  double uv_repeats = 1.0;  // KHR_texture_transform scale / three.js repeat
  // The preset's weave_maps.anisotropy (1..16; 1 when missing): the maps' max anisotropy as
  // three.js texture.anisotropy (EXT_texture_filter_anisotropic). Written as the three.js
  // textures' "anisotropy"; glTF samplers have no such field, so the glTF output records it in
  // extras.clothfit_weave_textures.max_anisotropy (docs/convert.md).
  int max_anisotropy = 1;
  std::vector<unsigned char> base_color;  // size^2 x 3, sRGB codes, rows top first
  std::vector<unsigned char> anisotropy;  // size^2 x 3, linear codes (RG direction, B strength)
  Rgb<double> base_factor{0.0, 0.0, 0.0};  // linear baseColorFactor (an exact 8-bit sRGB value)
  double anisotropy_strength = 0.0;        // KHR anisotropyStrength / three.js anisotropy (= a S)
  double anisotropy_rotation = 0.0;        // radians, preset rotation + atan(1/255), wrapped
  Rgb<double> kd_max{0.0, 0.0, 0.0};       // K_c
  double strength_max = 0.0;               // S
  // Measured over all texels against the exact values above (linear units):
  double base_max_abs_error = 0.0;   // max |f texel - b k| over texels and channels
  double base_max_rel_error = 0.0;   // max of that / (b k) where b k > 1e-3
  double strength_max_abs_error = 0.0;  // max |anisotropyStrength texel.b - a s|
  double direction_max_angle_error = 0.0;  // radians, decoded + rotated vs the preview's
  int clipped_texels = 0;            // texel-channels where b k > 1 (clipped)
};

// Bakes the two textures. Throws std::invalid_argument if `p` is not physical-aniso.
WeaveTextures BakePhysicalAnisoTextures(const render::MaterialPreset& p,
                                        const render::WeaveMaps& maps);

// The 8-bit sRGB decode table (IEC 61966-2-1, the same curve as three.js
// SRGBToLinear and Color.setHex): code q -> linear value.
const std::array<double, 256>& SrgbDecodeTable();

}  // namespace clothfit::fit
