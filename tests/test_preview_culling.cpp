// The preview draws faces as the glTF material's doubleSided says (issue 13): a single-sided
// mesh seen from behind is culled (three.js FrontSide, Filament's culling), so the ray goes on
// to what lies behind it; a double-sided one is drawn. The canonical glTFs: datasets/scenes
// drape (fabric doubleSided true; support, floor false), swatch (true), sphere (false).
#include <gtest/gtest.h>

#include "render/preview/preview.h"
#include "render/scene/scene.h"
#include "tests/scene_fixtures.h"

namespace clothfit::render {
namespace {

// A 2 x 2 quad in the plane z = z0; `front_to_camera`: counter-clockwise seen from +z (the
// camera's side), i.e. a glTF front face there.
Mesh Quad(double z0, bool front_to_camera, bool fabric, bool double_sided) {
  Mesh m;
  m.name = fabric ? "fabric" : "wall";
  m.is_fabric = fabric;
  m.double_sided = double_sided;
  m.base_color = {0.5f, 0.5f, 0.5f};
  const float z = float(z0);
  m.positions = {{-1, -1, z}, {1, -1, z}, {1, 1, z}, {-1, 1, z}};
  const float nz = front_to_camera ? 1.f : -1.f;
  m.normals.assign(4, {0.f, 0.f, nz});
  m.uvs = {{0, 1}, {1, 1}, {1, 0}, {0, 0}};
  m.tangents.assign(4, {1.f, 0.f, 0.f, 1.f});
  if (front_to_camera) m.indices = {0, 1, 2, 0, 2, 3};
  else m.indices = {0, 2, 1, 0, 3, 2};
  return m;
}

struct Frame {
  size_t fabric_pixels;
  float centre[3];  // linear RGB at the image centre (background layer if not fabric)
};

Frame Render(const std::vector<Mesh>& meshes, IblEngine engine) {
  Scene s = CameraScene(16, 16, {0, 0, 3}, {0, 0, -1}, 0.5);
  s.card.background = {0.0, 0.0, 1.0};
  Light sun;
  sun.type = Light::Type::kDirectional;
  sun.direction = {0, 0, -1};  // towards -z: lights the faces seen by the camera
  sun.intensity = 3.0;
  s.lights.push_back(sun);
  s.meshes = meshes;
  PreviewOptions o;
  o.model = ModelKind::kStandard;
  o.ibl_engine = engine;
  const auto c = PreviewCache::Build(s, nullptr, o);
  Frame f{c->pixels.size(), {}};
  const size_t centre = size_t(8 * 16 + 8);
  for (int k = 0; k < 3; ++k) f.centre[k] = c->background[centre * 3 + size_t(k)];
  return f;
}

TEST(PreviewCulling, SingleSidedBackFaceIsCulledAndTheRayGoesOn) {
  for (const IblEngine e : {IblEngine::kFilament, IblEngine::kThreejs}) {
    // Front face, single-sided: drawn.
    EXPECT_GT(Render({Quad(0, true, true, false)}, e).fabric_pixels, 100u);
    // Back face, double-sided: drawn.
    EXPECT_GT(Render({Quad(0, false, true, true)}, e).fabric_pixels, 100u);
    // Back face, single-sided: culled; the pixel is the background colour.
    const Frame culled = Render({Quad(0, false, true, false)}, e);
    EXPECT_EQ(culled.fabric_pixels, 0u);
    EXPECT_EQ(culled.centre[2], 1.f);
    // ... or the wall behind it, lit (not the background's blue only).
    const Frame wall = Render({Quad(0, false, true, false), Quad(-1, true, false, false)}, e);
    EXPECT_EQ(wall.fabric_pixels, 0u);
    EXPECT_GT(wall.centre[0], 0.01f);
    // The same back-facing fabric, double-sided, hides the wall.
    EXPECT_GT(Render({Quad(0, false, true, true), Quad(-1, true, false, false)}, e).fabric_pixels,
              100u);
  }
}

}  // namespace
}  // namespace clothfit::render
