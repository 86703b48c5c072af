// fit/woven_fit.h: the image-space fit of the woven model (brdf/woven.h).
//
// The woven model has 16 parameters and the image fit differentiates at most 10 at once
// (ceres::Jet<double, 10>), so it is fitted in two stages over the same references, blocks and
// weights as every other model (fit/image_fit.h):
//   1. yarn stage: free = base_color, specular_color, roughness, specular_f0,
//      forward_scattering, warp_share (10); held = anisotropy, twist (at the start preset's
//      values: the defaults, which come from the BRDF-space fits of docs/fitting.md), sheen
//      off. Colours start from the reference's mean colour, roughness from start_roughness.
//   2. sheen stage, from stage 1's result: free = base_color, specular_color, sheen_color,
//      sheen_roughness (10); the lobe shape is held. Kept only if it lowers the unweighted
//      RMSE in the fit space (it cannot raise the cost it minimises: it starts at stage 1's
//      optimum with the sheen at a small value).
// Parameters the caller locks stay locked in both stages. Each stage carries 6 derivative
// slots with colour packing (fit/image_fit.h); both use one PrepareScenes (caches, blocks);
// stage 1 multi-starts over options.start_roughness when the roughness is locked or the start
// is explicit (then the starts are one start). Then the cloth-basin start below (session 13)
// runs the stages again from cloth's basin, and the rough-diffuse and lobe-shape stages run
// from the best. With several free start values (clothfit fit: 0.6 and 0.3; session 26) each
// start, and the cloth basin, runs that pipeline on its own without the rough-diffuse stage,
// the best is kept, and the whole pipeline runs once more from it ("second round");
// docs/fitting.md "A start for glossy references".
//
// Weave maps (fit/weave_maps.h): AttachWeaveMaps bakes them for an Irawan fabric BEFORE the
// stages, writes the EXR and names it in the start preset's "weave_maps" field; FitImages
// then builds every preview cache with the maps fixed (render/preview/weave_maps.h), so both
// stages fit the global parameters with the maps in place.
#pragma once

#include <string>
#include <vector>

#include "fit/image_fit.h"
#include "fit/weave_maps.h"

namespace clothfit::fit {

// Bakes the maps of `fabric_path` (an Irawan fabric) with the lobes of options->start, writes
// them to `maps_path` and sets options->start.extra["weave_maps"]. Returns a one-line summary
// for the log, or "" (nothing attached) when the fabric is not an Irawan fabric. Throws on
// unreadable files and bad fabrics.
std::string AttachWeaveMaps(const std::string& fabric_path, const std::string& maps_path,
                            FitOptions* options, const WeaveBakeOptions& bake = {});

FitResult FitWovenImages(const std::vector<SceneInput>& inputs, const FitOptions& options,
                         const PreparedScenes* prepared = nullptr);

// The cloth-basin start (session 13; docs/fitting.md "Woven's starts (session 13)"). Woven
// with specular_color = 0 has the cloth model's form (Lambert + Charlie sheen; woven scales
// the diffuse by the sheen albedo and Filament cloth does not, so the two agree exactly when
// the base colour is 0; the previews' IBL engines may differ too), and the yarn-first stages
// above start with the sheen off, so they can miss the sheen-dominated basin cloth finds.
// So, besides the two stages, FitWovenImages
//   (a) fits that sub-model: yarn lobes off and locked; free = base_color, sheen_color,
//       sheen_roughness; started as a cloth fit starts (base colour from the reference, sheen
//       colour 0.5) with the sheen broad, sheen_roughness = kClothBasinSheenRoughness (the
//       cloth preset's default roughness, the Filament cloth default);
//   (b) when (a)'s RMSE is within kClothBasinContinueRatio of the two stages' (the sheen-only
//       form explains the images about as well as the yarn-first fit; where it is several
//       times worse the images are yarn-dominated), runs the two stages again from (a)'s
//       result: the yarn stage with (a)'s sheen held and the yarn lobes back at the start
//       preset's values, then the sheen stage,
// and returns the candidate with the lowest fit-space RMSE ((a) included). Runs when
// UsesClothBasinStart: FitOptions::cloth_basin_start, the start comes from the reference (not
// explicit --start values), and no colour or sheen parameter is locked.
inline constexpr double kClothBasinSheenRoughness = 1.0;
inline constexpr double kClothBasinContinueRatio = 2.0;
bool UsesClothBasinStart(const FitOptions& options);
// The options of step (a) for a woven fit's `options`.
FitOptions ClothBasinOptions(const FitOptions& options);
// The options of step (b): `options` started from (a)'s fitted preset `basin`.
FitOptions FromClothBasin(const FitOptions& options, const render::MaterialPreset& basin);

// The rough-diffuse stage (session 18; docs/fitting.md "A rough diffuse for woven"). The
// stages above hold diffuse_roughness (sigma of brdf/woven.h's On; each stage already frees the
// ten scalars the Jacobian carries). After them FitWovenImages fits once more from the best
// result with sigma free together with base_color, sheen_color and sheen_roughness (8 free;
// the yarn parameters held), sigma started where the best result has it (0 = Lambert, unless
// --start sets it: the images must pull it off the bound), and keeps it when its RMSE is lower.
// Skipped when diffuse_roughness is locked (`--lock diffuse_roughness`: the Lambert model of
// sessions 7-18).
FitOptions DiffuseStageOptions(const FitOptions& options, const render::MaterialPreset& from);

// The lobe-shape stage (session 25; docs/fitting.md "Woven's lobe shape on another renderer's
// yarns"). The stages above hold the GGX yarn lobes' anisotropy at the start preset's value
// (the woven default 0.7, from the BRDF-space fits to our Irawan fabrics). On references whose
// yarns scatter otherwise (measured: real-yarn Blender Cycles renders with a Principled BSDF)
// that value is wrong and three.js's physical-aniso, whose anisotropy is free, fits them 1.6x
// better. So after them FitWovenImages fits twice more, each time from the best result so far,
// keeping a result when its RMSE is lower: (a) "lobe-shape", anisotropy free with roughness,
// base_color and specular_color (8 free); (b) "lobe-shape+share", the same with warp_share and
// specular_f0 (10, the Jacobian's width). Sheen, diffuse roughness, twist and forward
// scattering are held. (Measured on real-yarn Cycles references: (b) alone stops at a worse
// point, block RMSE 0.0130 against (a)'s 0.0086.) Skipped when anisotropy is locked: by the caller, or by a fabric's yarn lobe
// (--yarn-lobe preset, which replaces the GGX lobes).
// with_share: stage (b), else (a).
FitOptions LobeShapeStageOptions(const FitOptions& options, const render::MaterialPreset& from,
                                 bool with_share);

// The per-model defaults every image fit shares (clothfit fit, bench fit): metalness /
// metallic locked for the three.js and glTF baselines (fabrics are dielectric); physical-aniso
// (docs/fitting.md, "The honest baseline"): metalness, anisotropy_rotation (the maps carry the
// direction) and specular_color locked, and the strength started at 0.5, off 0 where
// d alpha_t / d strength = 2 strength (1 - alpha) = 0 would hold it (measured: every fit from 0
// stayed at 0). Appends to options->locked; changes options->start only for physical-aniso.
void ApplyModelDefaults(FitOptions* options);

// physical-aniso: bakes the SAME maps a woven fit of `fabric_path` bakes (woven defaults as the
// start lobes), writes them to `maps_path` and names them in options->start.extra
// ["weave_maps"] (the preview uses them as a colour map and an anisotropy map). Returns the
// log line, or "" when the fabric is not an Irawan fabric.
std::string AttachWeaveMapsToPhysicalAniso(const std::string& fabric_path,
                                           const std::string& maps_path, FitOptions* options);

// The weave maps' max anisotropy a fit uses by default (three.js texture.anisotropy; clothfit
// fit --map-anisotropy, bench fit; docs/flip.md "Anisotropic filtering of the maps", session 9).
inline constexpr int kDefaultMapAnisotropy = 16;

// Sets options->start.extra["weave_maps"]["anisotropy"] = n when the start preset names weave
// maps (after AttachWeaveMaps / AttachWeaveMapsToPhysicalAniso); returns false (nothing set)
// when it names none.
bool SetMapAnisotropy(int n, FitOptions* options);

}  // namespace clothfit::fit
