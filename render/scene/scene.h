// render/scene/scene.h: a scene = a glTF 2.0 file + a JSON scene card (docs/scene-card.md).
//
// Both renderers (reference path tracer, real-time preview) read the same Scene, so pixel
// centres, camera and lights agree by construction.
//
// Coordinate conventions (glTF): right-handed, +Y up, metres; node transforms are flattened
// into world space at load time. The camera looks down its local -Z with +Y up; pixel (x, y)
// has its centre at ((x + 0.5) / W, (y + 0.5) / H), y = 0 the TOP row of the image.
//
// Light units (KHR_lights_punctual, mapped as three.js does with physically based lights):
//   directional: `intensity` in lux is taken as irradiance E (W/m^2 radiometric, 1:1);
//                a surface receives E * color * max(n.l, 0), so a white Lambertian surface
//                reflects radiance E / pi.
//   point/spot : `intensity` in candela is taken as radiant intensity I; irradiance at
//                distance d is I * color / d^2 * max(n.l, 0), times the glTF range window
//                (1 - (d / range)^4)^2 clamped to [0, 1] when range > 0, and for spots
//                smoothstep(cos(outer), cos(inner), cos(angle to the spot axis)).
//   The scene card's light_scale and environment intensity multiply these (exporters
//   differ: Blender writes sun strength in W/m^2 x 683).
#pragma once

#include <array>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "brdf/math.h"

namespace clothfit::render {

// An error in a scene card or glTF file; the message names the file and the field.
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Mesh {
  std::string name;
  std::vector<std::array<float, 3>> positions;        // world space
  std::vector<std::array<float, 3>> normals;          // world space, unit length
  std::vector<std::array<float, 2>> uvs;              // TEXCOORD_0 (glTF: v down from the top)
  std::vector<std::array<float, 4>> tangents;         // world space xyz + handedness w (+-1);
                                                      // generated from uvs when the file has none
  std::vector<uint32_t> indices;                      // triangles
  int material = -1;                                  // glTF material index (-1: default)
  bool is_fabric = false;                             // material == card.fabric_material
  std::array<float, 3> base_color{0.8f, 0.8f, 0.8f};  // linear; pbrMetallicRoughness factor
  // Back faces are drawn (true) or culled (false) by the preview (render/preview), as an engine
  // does. glTF meshes: the material's doubleSided (glTF default false, the default material
  // too); meshes built in code default to two-sided.
  bool double_sided = true;
};

struct Camera {
  std::array<double, 3> position{0, 0, 0};
  std::array<double, 3> forward{0, 0, -1};  // unit, world
  std::array<double, 3> up{0, 1, 0};        // unit, world, orthogonal to forward
  std::array<double, 3> right{1, 0, 0};     // unit, world = forward x up
  double yfov = 0.8;                        // radians, full vertical field of view
};

struct Light {
  enum class Type { kDirectional, kPoint, kSpot };
  Type type = Type::kDirectional;
  std::string name;
  std::array<double, 3> color{1, 1, 1};             // linear
  double intensity = 1.0;                           // after the card's light_scale
  std::array<double, 3> position{0, 0, 0};          // world (point, spot)
  std::array<double, 3> direction{0, 0, -1};        // world, direction the light TRAVELS
  double range = 0.0;                               // 0 = infinite
  double inner_cone = 0.0, outer_cone = kPi / 4.0;  // radians (spot)
  // Directional lights split off an environment map (render/scene/sun.h: the sun, the panels):
  // sin of the angular radius of the spherical cap with the source's solid angle; 0 = a delta
  // light (every card light). Only woven's preview shading reads it, for the horizon fade
  // (render/scene/lights.h ClipDiscAtHorizon); the reference renderer renders the map itself.
  double sin_angular_radius = 0.0;
};

// Whether the preview draws a compact sun of the environment as a directional light
// (render/scene/sun.h, docs/sun.md): kOff = the map as is; kAuto = detect one and, if found,
// split it off the map (the IBL gets the sun-free map, the sun becomes one more light);
// kPanels = kAuto, then up to kMaxPanelLights broad bright sources (softboxes, lit windows)
// split off the same way, each one more directional light (docs/sun.md "Panels").
// The reference renderer ignores it (it renders the full map; the sun is the same light).
enum class SunMode { kOff, kAuto, kPanels };

struct EnvironmentSpec {
  std::string name;         // as written in the card ("studio", "maps/x.exr", ...)
  std::string path;         // resolved absolute path, or "procedural-sky"
  bool found = true;        // false: the map is not installed (yet); loading does not fail,
                            // the renderer falls back to the procedural sky and warns
  bool is_file = false;     // `name` is a file path ('/' or an extension), not a cache name: the
                            // renderers refuse it when it is missing (session 28)
  double intensity = 1.0;   // multiplies the map's radiance
  double rotation_y = 0.0;  // radians, rotation of the map about +Y (three.js environmentRotation)
  // "sun": "auto" | "off" | "panels" (docs/scene-card.md); unset = not in the card (the preview's default).
  std::optional<SunMode> sun;
};

// How the engine lights the scene beyond its lights and environment (session 13,
// docs/scene-card.md "visibility"; the preview follows it unless PreviewOptions::card_visibility
// is false, the reference renderer ignores it): shadow maps for the punctual lights, and a light
// map baked over the fabric mesh's uv (render/preview/visibility.h, one bounce by default).
struct CardVisibility {
  bool shadows = false;
  bool light_map = false;
  int size = 128;        // light map texels per side
  int samples = 64;      // directions per texel
  int hit_samples = 8;   // AO directions at each bounce point
  int bounces = 1;
};

struct SceneCard {
  std::string path;               // the card file itself
  std::string gltf;               // resolved path of the glTF
  int width = 256, height = 256;  // image size in pixels
  std::optional<EnvironmentSpec> environment;
  std::string tone_mapping = "ACESFilmic";  // Linear|Reinhard|Cineon|ACESFilmic|AgX|Neutral
  double exposure = 1.0;
  int fabric_material = 0;                    // glTF material index that is the fabric
  double light_scale = 1.0;                   // multiplies every punctual light's intensity
  int camera = 0;                             // index into the glTF cameras
  std::array<double, 3> background{0, 0, 0};  // linear radiance seen where rays escape and
                                              // there is no environment
  double uv_metres_per_unit = 0.0;            // surface length of one UV unit on the fabric (0: not
                                              // stated), so a weave period in metres maps to UVs
  std::string description;                    // free text, for reports
  std::optional<CardVisibility> visibility;   // absent: no shadows, no light map
};

struct Scene {
  SceneCard card;
  std::vector<Mesh> meshes;
  Camera camera;
  std::vector<Light> lights;
  // Repairs made while loading (computed normals, ...) and non-fatal problems (environment
  // map not installed), one line each, naming the file; the caller decides how to show them.
  std::vector<std::string> warnings;

  // Primary ray through the pixel-space position (px, py), px in [0, W), py in [0, H)
  // (pixel centres at +0.5): origin and unit direction in world space.
  void CameraRay(double px, double py, std::array<double, 3>& origin,
                 std::array<double, 3>& dir) const;
};

// Loads the card and the glTF it names. Throws SceneError naming the file and field.
Scene LoadScene(const std::string& card_path);

// Parses only the card (used by tools that do not need geometry). Throws SceneError.
SceneCard LoadSceneCard(const std::string& card_path);

}  // namespace clothfit::render
