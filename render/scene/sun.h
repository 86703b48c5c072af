// render/scene/sun.h: split a compact sun off an equirect environment into a directional light
// (docs/sun.md). The preview (render/preview) and web/clothfit.js (splitEnvironmentSun) run the
// same algorithm, so a split map + light is what both draw; the reference renderer never uses
// it (it renders the full map, where the sun is the same light).
//
// Conventions.
//   Map space and (u, v): the toolkit's equirect convention (render/scene/environment.h,
//   docs/environments.md): texel (i, j), j = 0 the top row, has its centre at
//   u = (i + 0.5) / W, v = 1 - (j + 0.5) / H, direction Environment::UvToDirection(u, v)
//   = (cos e cos phi, sin e, cos e sin phi), phi = (u - 0.5) 2 pi, e = (v - 0.5) pi.
//   Texel solid angle: the exact area of its (u, v) cell on the sphere,
//   dw_j = (2 pi / W) (sin e_top - sin e_bottom)   (so the texels sum to 4 pi).
//   Luminance: Rec.709 Y = 0.2126 R + 0.7152 G + 0.0722 B of the stored (linear) texels.
//   Median: the LOWER median (sorted element (n - 1) / 2), per channel, so the fill is one of
//   the map's own values (web/: exactly representable in the half-float texture three.js
//   loads).
//   The light: a glTF / three.js directional light as the cards' KHR_lights_punctual lights are
//   read (render/scene/scene.h "Light units"): `intensity` x `color` = irradiance E at normal
//   incidence (W/m^2, three.js DirectionalLight.intensity with physically based lights: a
//   white Lambertian surface facing it reflects E / pi), E_c = intensity_env x sum over the
//   sun texels of (L_c - fill_c) dw per channel; `direction` (the way the light travels) =
//   minus the world direction of the sun, i.e. the map-space luminance-excess-weighted mean
//   direction rotated by the card's rotation_y (Environment::MapToWorld). Not multiplied by the
//   card's light_scale (the sun is part of the environment: its intensity applies).
//
// Detection ("auto", SunDetectParams; the numbers and why in docs/sun.md "Detection"):
//   1. P = sum Y dw (the map's power); none if P = 0. The peak = the brightest texel (first in
//      row-major order on ties).
//      The window's centre: the luminance-weighted mean direction of the texels within
//      max_radius_deg of the peak with Y >= Y_peak / 2 (a clipped, flat-topped sun's first
//      peak texel is at its edge; this is its middle).
//   2. Window: texels whose centre is within max_radius_deg of that centre (angles,
//      not texels: the seam u = 0 / 1 and the poles need no special case). Annulus: centres
//      between max_radius_deg and 2 x max_radius_deg. None if the annulus has fewer than
//      min_annulus_texels texels (the map is too coarse to tell a sun from its sky).
//   3. Fill = per-channel lower median of the annulus; B = lower median of the annulus's Y.
//      Threshold T = contrast x B.
//   4. Sun texels = window texels with Y > T. Compactness: the excess above B of the annulus
//      texels with Y > T must be <= max_annulus_excess x the sun texels' excess (the source has
//      ended inside the window: a softbox or a bright window is not a sun). Power: the sun's
//      luminance excess sum (Y - Y(fill)) dw >= min_power_fraction x P.
//   5. The split: the sun texels get the fill; the light as above.
#pragma once

#include <array>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "render/scene/environment.h"
#include "render/scene/scene.h"

namespace clothfit::render {

// "auto" -> kAuto, "off" -> kOff, "panels" -> kPanels; anything else throws
// std::invalid_argument naming `field`.
SunMode ParseSunMode(const std::string& value, const std::string& field);
const char* SunModeName(SunMode m);

struct SunDetectParams {
  double max_radius_deg = 3.0;        // angular radius of the window a sun must fit in
  double contrast = 10.0;             // T = contrast x the annulus's median luminance
  double min_power_fraction = 0.05;   // the sun's share of the map's luminance power
  double max_annulus_excess = 0.1;    // annulus excess above T / sun excess
  int min_annulus_texels = 8;
};

// Panels (SunMode::kPanels, docs/sun.md "Panels"): after the auto sun, DetectSun runs again on
// the map with every source found so far filled, up to kMaxPanelLights times, with these
// parameters: a window of 8 degrees (a studio softbox is 5-15 degrees across), a contrast of 5,
// no compactness test (a softbox does not end inside its window: its glow stays in the IBL,
// what the window holds above 5 x the annulus becomes the light), 2 % of the (remaining) map's
// power. Chosen from what a softbox is and checked on the 26 installed maps (17 have panels;
// radius 6 or 12 and contrast 3 or 10 move the fitted errors by < 25 %, docs/fitting.md).
inline constexpr SunDetectParams kPanelDetectParams{
    8.0, 5.0, 0.02, std::numeric_limits<double>::infinity(), 8};
inline constexpr int kMaxPanelLights = 8;

struct SunSplit {
  bool found = false;
  std::string summary;                   // one line: what was found, or why nothing
  // Filled in whenever the map has a peak (also when not found, for reports):
  double power_fraction = 0.0;           // luminance excess of the candidate / P
  double annulus_excess_ratio = 0.0;     // compactness figure of step 4
  int texels = 0;                        // candidate sun texels
  double solid_angle = 0.0;              // their solid angle (sr)
  std::array<double, 3> map_direction{0, 1, 0};    // unit, map space, towards the sun
  std::array<double, 3> world_direction{0, 1, 0};  // unit, world (rotation applied)
  std::array<double, 3> irradiance{0, 0, 0};       // E per channel, x the env intensity
  std::array<float, 3> fill{0, 0, 0};              // stored radiance (no intensity)
  double map_power = 0.0;                // P (stored luminance x sr, no intensity)
  std::vector<int> sun_texels;           // texel indices j W + i (when found)
  Light light;                           // the directional light (when found)
};

// Detection on stored texels (RGB, top row first; negative / non-finite read as 0). `intensity`
// and `rotation_y` as the Environment's (they only scale / rotate the light). When found and
// `sun_free` is non-null it receives the texels with the sun replaced by the fill.
SunSplit DetectSun(int width, int height, const float* rgb, double intensity, double rotation_y,
                   const SunDetectParams& params = {}, std::vector<float>* sun_free = nullptr);

// The split of an Environment: `environment` is the sun-free map (source "<source>#sun-free";
// the input itself, shared, when nothing was found or mode is kOff).
struct SunSplitEnvironment {
  SunSplit split;                 // the auto detection (the sun)
  std::vector<SunSplit> panels;   // kPanels: each panel found, in order (detected on the map
                                  // with the sun and the earlier panels filled)
  std::vector<Light> lights;      // every light split off: the sun (when found), the panels
  std::string summary;            // one line: the sun's summary, then the panels' (kPanels)
  std::shared_ptr<const Environment> environment;
  bool found() const { return !lights.empty(); }
};
// Memoised per map content (hash of the texels, size, intensity, rotation), so every preview
// cache of a process shares one sun-free map (and so its prefiltered chains / PMREM).
std::shared_ptr<const SunSplitEnvironment> SplitEnvironmentSun(const Environment& env,
                                                                SunMode mode);

// The sun mode a scene's preview uses: `forced` when set (a CLI flag, a preset's fit.env_sun),
// else the card's environment.sun, else `fallback` (docs/sun.md "Where the option lives").
SunMode EffectiveSunMode(const Scene& scene, const std::optional<SunMode>& forced,
                         SunMode fallback = SunMode::kOff);
// The clothfit commands' default (render-preview, fit, evaluate; web/ too): auto.
inline constexpr SunMode kCliDefaultSunMode = SunMode::kAuto;

}  // namespace clothfit::render
