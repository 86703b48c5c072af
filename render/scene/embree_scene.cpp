#include "render/scene/embree_scene.h"

#include <embree3/rtcore.h>

#include <atomic>
#include <cmath>
#include <stdexcept>
#include <string>

namespace clothfit::render {

struct EmbreeScene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  mutable std::atomic<long long> invalid_rays{0};
};

bool EmbreeScene::RayValid(const std::array<double, 3>& org, const std::array<double, 3>& dir,
                           double tnear, double tfar) {
  // Embree's RayK::valid(): |org| <= FLT_LARGE (1.844e18), finite direction, tnear >= 0 and
  // tnear <= tfar; checked here in double before any float conversion (which would be UB).
  constexpr double kMaxOrigin = 1e18;
  double d2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    if (!(std::abs(org[size_t(k)]) <= kMaxOrigin)) return false;
    if (!(std::abs(dir[size_t(k)]) <= 1e30)) return false;
    d2 += dir[size_t(k)] * dir[size_t(k)];
  }
  if (!(d2 > 0.0)) return false;
  if (!(tnear >= 0.0 && tnear <= 1e30)) return false;
  if (std::isnan(tfar) || tfar < tnear) return false;
  return true;
}

long long EmbreeScene::invalid_rays() const { return impl_->invalid_rays.load(); }

namespace {
void ErrorCallback(void*, RTCError code, const char* message) {
  throw std::runtime_error(std::string("Embree error ") + std::to_string(int(code)) + ": " +
                           (message ? message : ""));
}
}  // namespace

EmbreeScene::EmbreeScene(const Scene& scene) : impl_(std::make_unique<Impl>()), scene_(scene) {
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) throw std::runtime_error("Embree: cannot create a device");
  rtcSetDeviceErrorFunction(impl_->device, ErrorCallback, nullptr);
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
  double lo[3] = {1e30, 1e30, 1e30}, hi[3] = {-1e30, -1e30, -1e30};
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    const Mesh& mesh = scene.meshes[m];
    RTCGeometry g = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.positions.size()));
    for (size_t i = 0; i < mesh.positions.size(); ++i) {
      for (int k = 0; k < 3; ++k) {
        vb[3 * i + size_t(k)] = mesh.positions[i][size_t(k)];
        lo[k] = std::min(lo[k], double(mesh.positions[i][size_t(k)]));
        hi[k] = std::max(hi[k], double(mesh.positions[i][size_t(k)]));
      }
    }
    const size_t tris = mesh.indices.size() / 3;
    auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris));
    for (size_t i = 0; i < tris * 3; ++i) ib[i] = mesh.indices[i];
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(impl_->scene, g, unsigned(m));
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(impl_->scene);
  double d2 = 0.0;
  for (int k = 0; k < 3; ++k) d2 += (hi[k] - lo[k]) * (hi[k] - lo[k]);
  scale_ = scene.meshes.empty() ? 1.0 : std::max(1e-3, 0.5 * std::sqrt(d2));
}

EmbreeScene::~EmbreeScene() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

Hit EmbreeScene::Intersect(const std::array<double, 3>& org, const std::array<double, 3>& dir,
                           double tnear, double tfar) const {
  if (!RayValid(org, dir, tnear, tfar)) {
    impl_->invalid_rays.fetch_add(1, std::memory_order_relaxed);
    return Hit{};
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh{};
  rh.ray.org_x = float(org[0]);
  rh.ray.org_y = float(org[1]);
  rh.ray.org_z = float(org[2]);
  rh.ray.dir_x = float(dir[0]);
  rh.ray.dir_y = float(dir[1]);
  rh.ray.dir_z = float(dir[2]);
  rh.ray.tnear = float(tnear);
  rh.ray.tfar = tfar > 1e30 ? std::numeric_limits<float>::infinity() : float(tfar);
  rh.ray.mask = 0xFFFFFFFFu;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  Hit h;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return h;
  h.valid = true;
  h.t = double(rh.ray.tfar);
  h.mesh = int(rh.hit.geomID);
  h.triangle = int(rh.hit.primID);
  h.b1 = double(rh.hit.u);
  h.b2 = double(rh.hit.v);
  const double nx = double(rh.hit.Ng_x), ny = double(rh.hit.Ng_y), nz = double(rh.hit.Ng_z);
  const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
  if (len > 0.0) h.ng = {nx / len, ny / len, nz / len};
  return h;
}

bool EmbreeScene::Occluded(const std::array<double, 3>& org, const std::array<double, 3>& dir,
                           double tnear, double tfar) const {
  if (!RayValid(org, dir, tnear, tfar)) {
    impl_->invalid_rays.fetch_add(1, std::memory_order_relaxed);
    return true;
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r{};
  r.org_x = float(org[0]);
  r.org_y = float(org[1]);
  r.org_z = float(org[2]);
  r.dir_x = float(dir[0]);
  r.dir_y = float(dir[1]);
  r.dir_z = float(dir[2]);
  r.tnear = float(tnear);
  r.tfar = tfar > 1e30 ? std::numeric_limits<float>::infinity() : float(tfar);
  r.mask = 0xFFFFFFFFu;
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar < 0.0f;  // Embree sets tfar = -inf on a hit
}

SurfaceAttributes EmbreeScene::Attributes(const Hit& hit) const {
  const Mesh& m = scene_.meshes[size_t(hit.mesh)];
  const size_t i0 = m.indices[3 * size_t(hit.triangle)];
  const size_t i1 = m.indices[3 * size_t(hit.triangle) + 1];
  const size_t i2 = m.indices[3 * size_t(hit.triangle) + 2];
  const double w0 = 1.0 - hit.b1 - hit.b2, w1 = hit.b1, w2 = hit.b2;
  SurfaceAttributes a;
  auto lerp3 = [&](const auto& arr, std::array<double, 3>& out) {
    for (int k = 0; k < 3; ++k)
      out[size_t(k)] = w0 * double(arr[i0][size_t(k)]) + w1 * double(arr[i1][size_t(k)]) +
                       w2 * double(arr[i2][size_t(k)]);
  };
  auto normalize = [](std::array<double, 3>& v) {
    const double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (l > 0) {
      for (double& x : v) x /= l;
    }
  };
  lerp3(m.positions, a.position);
  if (!m.normals.empty()) {
    lerp3(m.normals, a.normal);
    normalize(a.normal);
  } else {
    a.normal = hit.ng;
  }
  if (!m.uvs.empty()) {
    for (int k = 0; k < 2; ++k)
      a.uv[size_t(k)] = w0 * double(m.uvs[i0][size_t(k)]) + w1 * double(m.uvs[i1][size_t(k)]) +
                        w2 * double(m.uvs[i2][size_t(k)]);
  }
  if (!m.tangents.empty()) {
    for (int k = 0; k < 3; ++k)
      a.tangent[size_t(k)] =
          w0 * double(m.tangents[i0][size_t(k)]) + w1 * double(m.tangents[i1][size_t(k)]) +
          w2 * double(m.tangents[i2][size_t(k)]);
    a.tangent_sign = m.tangents[i0][3] < 0.0f ? -1.0 : 1.0;
  }
  // Gram-Schmidt against the normal; fall back to any perpendicular direction.
  double d = 0;
  for (int k = 0; k < 3; ++k) d += a.tangent[size_t(k)] * a.normal[size_t(k)];
  for (int k = 0; k < 3; ++k) a.tangent[size_t(k)] -= d * a.normal[size_t(k)];
  double tl = std::sqrt(a.tangent[0] * a.tangent[0] + a.tangent[1] * a.tangent[1] +
                        a.tangent[2] * a.tangent[2]);
  if (tl < 1e-8) {
    const auto& n = a.normal;
    a.tangent = std::abs(n[0]) < 0.9 ? std::array<double, 3>{0, -n[2], n[1]}
                                     : std::array<double, 3>{n[2], 0, -n[0]};
    // (any vector perpendicular to n: e_x x n or e_y x n)
    tl = std::sqrt(a.tangent[0] * a.tangent[0] + a.tangent[1] * a.tangent[1] +
                   a.tangent[2] * a.tangent[2]);
  }
  for (double& x : a.tangent) x /= tl;
  return a;
}

}  // namespace clothfit::render
