// render/preview/visibility.cpp: ray-traced AO and one-bounce light map for the preview
// (conventions in visibility.h, formulas and measurements in docs/visibility.md).
#include "render/preview/visibility.h"

#include <algorithm>
#include <cmath>
#include <tbb/parallel_for.h>
#include <stdexcept>
#include <string>

#include "render/scene/embree_scene.h"
#include "render/scene/lights.h"
#include "render/scene/sampler.h"

namespace clothfit::render {
namespace {

using Vec3d = Vec3<double>;

std::array<double, 3> A(const Vec3d& v) { return {v.x, v.y, v.z}; }
Vec3d V(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }
double Frac(double u) { return u - std::floor(u); }

// N stratified cosine-weighted directions around n under the shift (s0, s1): direction j has
// u1 = frac((j + 0.5) / N + s0), u2 = frac(radical_inverse_2(j) + s1), r = sqrt(u1),
// phi = 2 pi u2, z = sqrt(1 - u1) (Malley's method: a uniform disc point lifted to the
// hemisphere has pdf (n.l) / pi).
struct CosineSet {
  Vec3d n, e1, e2;
  int count;
  double s0, s1;
  CosineSet(const Vec3d& normal, int N, Pcg32& rng) : n(normal), count(N) {
    const Vec3d a = std::abs(n.x) < 0.9 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0);
    e1 = Normalize(Cross(a, n));
    e2 = Cross(n, e1);
    s0 = rng.Uniform();
    s1 = rng.Uniform();
  }
  Vec3d operator[](int j) const {
    const double u1 = Frac((j + 0.5) / count + s0);
    const double u2 = Frac(RadicalInverse2(uint32_t(j)) + s1);
    const double r = std::sqrt(u1), phi = 2.0 * kPi * u2;
    const double z = std::sqrt(std::max(0.0, 1.0 - u1));
    return Normalize(e1 * (r * std::cos(phi)) + e2 * (r * std::sin(phi)) + n * z);
  }
};

// Weight of direction l in the AO estimate: 1 (cosine weighting: the directions are already
// cosine-distributed) or the environment's luminance there (Rec. 709).
double AoWeight(const VisibilityOptions& o, const RadianceFn& env_radiance, const Vec3d& l) {
  if (o.weighting != VisibilityOptions::Weighting::kEnvironment || !env_radiance) return 1.0;
  const Rgb<double> L = env_radiance(l);
  return 0.2126 * L.r + 0.7152 * L.g + 0.0722 * L.b;
}

// sum_open w / sum_all w (1 when every weight is 0).
double Ratio(double open, double all) { return all > 0.0 ? open / all : 1.0; }

double TFar(const VisibilityOptions& o) {
  return o.max_distance > 0.0 ? o.max_distance : std::numeric_limits<double>::infinity();
}

// Lambert radiance leaving a bounce hit point q (normal nq facing the ray's origin).
Rgb<double> BounceRadiance(const Scene& scene, const std::vector<Light>& lights,
                           const EmbreeScene& bvh, const VisibilityOptions& o,
                           const IrradianceOverPiFn& env, const RadianceFn& env_radiance,
                           const Mesh& mesh, const Vec3d& q, const Vec3d& nq, Pcg32& rng,
                           int depth, double eps, Rgb<double>* unit = nullptr) {
  Rgb<double> kd(double(mesh.base_color[0]), double(mesh.base_color[1]),
                 double(mesh.base_color[2]));
  if (mesh.is_fabric && o.fabric_albedo[0] >= 0.0 && o.fabric_albedo[1] >= 0.0 &&
      o.fabric_albedo[2] >= 0.0)
    kd = Rgb<double>(o.fabric_albedo[0], o.fabric_albedo[1], o.fabric_albedo[2]);
  Rgb<double> e(0.0, 0.0, 0.0);  // direct irradiance over pi
  for (const Light& light : lights) {
    const LightSample s = EvaluateLight(light, q);
    if (s.scale <= 0.0) continue;
    const double c = Dot(nq, s.wi);
    if (c <= 0.0) continue;
    if (bvh.Occluded(A(q), A(s.wi), 0.0,
                     std::isinf(s.distance) ? s.distance : s.distance * (1 - 1e-6)))
      continue;
    for (int k = 0; k < 3; ++k) e[k] += s.scale * light.color[size_t(k)] * c * kInvPi;
  }
  // The hit_samples directions at q: the environment's occlusion there (ao_q) and, below the
  // bounce limit, the next bounce's radiance (a path q -> q' of the same Lambert shading).
  const bool deeper = depth + 1 < o.bounces;
  double ao_q = 1.0;
  Rgb<double> next(0.0, 0.0, 0.0);
  if (o.hit_samples > 0 && (env || deeper)) {
    const CosineSet dirs(nq, o.hit_samples, rng);
    double open = 0.0, all = 0.0;
    for (int j = 0; j < o.hit_samples; ++j) {
      const Vec3d l = dirs[j];
      const double w = AoWeight(o, env_radiance, l);
      all += w;
      if (!deeper) {
        if (!bvh.Occluded(A(q), A(l), 0.0, TFar(o))) open += w;
        continue;
      }
      const Hit h = bvh.Intersect(A(q), A(l), 0.0, TFar(o));
      if (!h.valid) {
        open += w;
        continue;
      }
      const SurfaceAttributes a = bvh.Attributes(h);
      const Vec3d wo = l * -1.0;
      Vec3d n2 = V(a.normal);
      if (Dot(n2, wo) < 0.0) n2 = n2 * -1.0;
      const Vec3d g2 = V(h.ng);
      const Vec3d q2 = V(a.position) + g2 * (Dot(g2, wo) > 0.0 ? eps : -eps);
      next += BounceRadiance(scene, lights, bvh, o, env, env_radiance, scene.meshes[size_t(h.mesh)], q2,
                             n2, rng, depth + 1, eps);
    }
    ao_q = Ratio(open, all);
    next = next * (1.0 / double(o.hit_samples));  // E_next / pi (cosine-weighted estimate)
  }
  if (env) e += env(nq) * ao_q;
  if (unit) *unit = e + next;  // the radiance per unit albedo
  return kd * (e + next);
}

}  // namespace

double SpecularOcclusion(double dotNV, double ao, double roughness) {
  const double v = std::pow(dotNV + ao, std::exp2(-16.0 * roughness - 1.0)) - 1.0 + ao;
  return std::clamp(v, 0.0, 1.0);
}

void ApplySpecularOcclusion(float* tables, size_t n_tables, int K, double NoV, double ao) {
  const double nv = std::clamp(NoV, 0.0, 1.0);
  for (int k = 0; k < K; ++k) {
    const double so = SpecularOcclusion(nv, ao, double(k) / double(K - 1));
    for (size_t j = 0; j < n_tables; ++j)
      for (int ch = 0; ch < 3; ++ch) {
        float& v = tables[(j * size_t(K) + size_t(k)) * 3 + size_t(ch)];
        v = float(double(v) * so);
      }
  }
}

void ValidateVisibilityOptions(const VisibilityOptions& o) {
  if (!o.enabled()) return;
  if (o.samples < 1 || o.samples > 1 << 16)
    throw std::invalid_argument("preview: visibility.samples " + std::to_string(o.samples) +
                                " not in [1, 65536]");
  if (o.bounces < 1 || o.bounces > 4)
    throw std::invalid_argument("preview: visibility.bounces " + std::to_string(o.bounces) +
                                " not in [1, 4]");
  if (o.hit_samples < 0 || o.hit_samples > 4096)
    throw std::invalid_argument("preview: visibility.hit_samples " +
                                std::to_string(o.hit_samples) + " not in [0, 4096]");
  if (!(o.max_distance >= 0.0) || !std::isfinite(o.max_distance))
    throw std::invalid_argument("preview: visibility.max_distance " +
                                std::to_string(o.max_distance) + " must be finite and >= 0");
  if (o.uv_size < 0 || o.uv_size > 2048)
    throw std::invalid_argument("preview: visibility.uv_size " + std::to_string(o.uv_size) +
                                " not in [0, 2048]");
  for (double a : o.fabric_albedo)
    if (!std::isfinite(a) || a > 1.0)
      throw std::invalid_argument("preview: visibility.fabric_albedo " + std::to_string(a) +
                                  " must be finite and <= 1 (< 0: the glTF base colour)");
}

VisibilityTerms ComputeVisibility(const Scene& scene, const EmbreeScene& bvh,
                                  const VisibilityOptions& o, const IrradianceOverPiFn& env,
                                  const Vec3d& p, const Vec3d& n, const Vec3d& ng,
                                  size_t pixel, double eps, const RadianceFn& env_radiance,
                                  const std::vector<Light>* lights) {
  VisibilityTerms t;
  if (!o.enabled()) return t;
  Pcg32 rng(uint64_t(o.seed), uint64_t(pixel));
  const CosineSet dirs(n, o.samples, rng);
  const double tfar = TFar(o);
  double open = 0.0, all = 0.0;
  Rgb<double> sum(0.0, 0.0, 0.0), fabric(0.0, 0.0, 0.0);
  for (int j = 0; j < o.samples; ++j) {
    const Vec3d l = dirs[j];
    const double w = AoWeight(o, env_radiance, l);
    all += w;
    if (Dot(l, ng) <= 0.0) {  // below the flat triangle: open (see visibility.h)
      open += w;
      continue;
    }
    if (!o.indirect) {  // AO only: an any-hit query
      if (!bvh.Occluded(A(p), A(l), 0.0, tfar)) open += w;
      continue;
    }
    const Hit h = bvh.Intersect(A(p), A(l), 0.0, tfar);
    if (!h.valid) {
      open += w;
      continue;
    }
    const SurfaceAttributes a = bvh.Attributes(h);
    const Mesh& mesh = scene.meshes[size_t(h.mesh)];
    const Vec3d wo = l * -1.0;  // from the hit back to p
    Vec3d nq = V(a.normal);
    if (Dot(nq, wo) < 0.0) nq = nq * -1.0;
    const Vec3d gq = V(h.ng);
    const Vec3d q = V(a.position) + gq * (Dot(gq, wo) > 0.0 ? eps : -eps);
    Rgb<double> unit(0.0, 0.0, 0.0);
    sum += BounceRadiance(scene, lights ? *lights : scene.lights, bvh, o, env, env_radiance, mesh, q,
                          nq, rng, 0, eps, &unit);
    if (mesh.is_fabric && o.bounces == 1) fabric += unit;
  }
  t.ao = Ratio(open, all);
  if (o.indirect) {
    t.indirect_over_pi = sum * (1.0 / double(o.samples));
    t.fabric_unit = fabric * (1.0 / double(o.samples));
  }
  return t;
}

VisibilityTerms UvVisibilityMap::Sample(double u, double v) const {
  VisibilityTerms t;
  if (size <= 0) return t;
  const double fu = (u - uv_min[0]) / (uv_max[0] - uv_min[0]) * size - 0.5;
  const double fv = (v - uv_min[1]) / (uv_max[1] - uv_min[1]) * size - 0.5;
  const double cu = std::clamp(fu, 0.0, double(size - 1)), cv = std::clamp(fv, 0.0, double(size - 1));
  const int i0 = std::min(int(std::floor(cu)), size - 1), j0 = std::min(int(std::floor(cv)), size - 1);
  const int i1 = std::min(i0 + 1, size - 1), j1 = std::min(j0 + 1, size - 1);
  const double a = cu - i0, b = cv - j0;
  const size_t q[4] = {size_t(j0) * size_t(size) + size_t(i0), size_t(j0) * size_t(size) + size_t(i1),
                       size_t(j1) * size_t(size) + size_t(i0), size_t(j1) * size_t(size) + size_t(i1)};
  const double w[4] = {(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b};
  t.ao = 0.0;
  const bool unit = !indirect_unit.empty();
  for (int k = 0; k < 4; ++k) {
    t.ao += w[k] * double(ao[q[k]]);
    for (int c = 0; c < 3; ++c) {
      t.indirect_over_pi[c] += w[k] * double(indirect[q[k] * 3 + size_t(c)]);
      if (unit) t.fabric_unit[c] += w[k] * double(indirect_unit[q[k] * 3 + size_t(c)]);
    }
  }
  return t;
}

UvVisibilityMap BakeUvVisibility(const Scene& scene, const EmbreeScene& bvh,
                                 const VisibilityOptions& o, const IrradianceOverPiFn& env,
                                 int mesh_index, double eps, const RadianceFn& env_radiance,
                                 const std::vector<Light>* lights) {
  ValidateVisibilityOptions(o);
  if (mesh_index < 0 || size_t(mesh_index) >= scene.meshes.size())
    throw std::invalid_argument("preview: visibility uv bake: no mesh " + std::to_string(mesh_index));
  const Mesh& m = scene.meshes[size_t(mesh_index)];
  if (m.uvs.size() != m.positions.size() || m.normals.size() != m.positions.size())
    throw std::invalid_argument("preview: visibility uv bake: mesh '" + m.name +
                                "' has no TEXCOORD_0 (or no normals) for the uv_size bake");
  UvVisibilityMap map;
  map.mesh = mesh_index;
  map.size = o.uv_size;
  map.uv_min = {1e300, 1e300};
  map.uv_max = {-1e300, -1e300};
  for (const auto& uv : m.uvs)
    for (int k = 0; k < 2; ++k) {
      map.uv_min[size_t(k)] = std::min(map.uv_min[size_t(k)], double(uv[size_t(k)]));
      map.uv_max[size_t(k)] = std::max(map.uv_max[size_t(k)], double(uv[size_t(k)]));
    }
  if (!(map.uv_max[0] > map.uv_min[0]) || !(map.uv_max[1] > map.uv_min[1]) ||
      !std::isfinite(map.uv_max[0] - map.uv_min[0]) || !std::isfinite(map.uv_max[1] - map.uv_min[1]))
    throw std::invalid_argument("preview: visibility uv bake: mesh '" + m.name +
                                "' has a degenerate or non-finite TEXCOORD_0 box");
  const int N = map.size;
  const size_t texels = size_t(N) * size_t(N);
  // Which triangle covers each texel centre, and where (barycentrics): rasterised serially in
  // uv (the first triangle wins where charts overlap).
  std::vector<int> tri(texels, -1);
  std::vector<std::array<double, 3>> bary(texels);
  const double su = N / (map.uv_max[0] - map.uv_min[0]), sv = N / (map.uv_max[1] - map.uv_min[1]);
  for (size_t f = 0; f + 2 < m.indices.size(); f += 3) {
    double x[3], y[3];
    for (int k = 0; k < 3; ++k) {
      const auto& uv = m.uvs[m.indices[f + size_t(k)]];
      x[k] = (double(uv[0]) - map.uv_min[0]) * su;
      y[k] = (double(uv[1]) - map.uv_min[1]) * sv;
    }
    const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
    if (!(std::abs(area) > 0.0)) continue;
    const int i0 = std::max(0, int(std::floor(std::min({x[0], x[1], x[2]}) - 0.5)));
    const int i1 = std::min(N - 1, int(std::ceil(std::max({x[0], x[1], x[2]}) - 0.5)));
    const int j0 = std::max(0, int(std::floor(std::min({y[0], y[1], y[2]}) - 0.5)));
    const int j1 = std::min(N - 1, int(std::ceil(std::max({y[0], y[1], y[2]}) - 0.5)));
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) {
        const double px = i + 0.5, py = j + 0.5;
        const double b0 = ((x[1] - px) * (y[2] - py) - (x[2] - px) * (y[1] - py)) / area;
        const double b1 = ((x[2] - px) * (y[0] - py) - (x[0] - px) * (y[2] - py)) / area;
        const double b2 = 1.0 - b0 - b1;
        const double tol = -1e-9;
        const size_t t = size_t(j) * size_t(N) + size_t(i);
        if (b0 < tol || b1 < tol || b2 < tol || tri[t] >= 0) continue;
        tri[t] = int(f / 3);
        bary[t] = {b0, b1, b2};
      }
  }
  map.ao.assign(texels, 1.f);
  map.indirect.assign(texels * 3, 0.f);
  if (o.indirect && o.bounces == 1) map.indirect_unit.assign(texels * 3, 0.f);
  auto v3 = [](const std::array<float, 3>& q) {
    return Vec3d(double(q[0]), double(q[1]), double(q[2]));
  };
  tbb::parallel_for(0, N, [&](int j) {
    for (int i = 0; i < N; ++i) {
      const size_t t = size_t(j) * size_t(N) + size_t(i);
      if (tri[t] < 0) continue;
      const uint32_t* idx = &m.indices[size_t(tri[t]) * 3];
      const auto& b = bary[t];
      const Vec3d P[3] = {v3(m.positions[idx[0]]), v3(m.positions[idx[1]]), v3(m.positions[idx[2]])};
      const Vec3d p = P[0] * b[0] + P[1] * b[1] + P[2] * b[2];
      const Vec3d ns = v3(m.normals[idx[0]]) * b[0] + v3(m.normals[idx[1]]) * b[1] +
                       v3(m.normals[idx[2]]) * b[2];
      Vec3d ng = Cross(P[1] - P[0], P[2] - P[0]);
      if (!(Length(ns) > 0.0) || !(Length(ng) > 0.0)) continue;
      const Vec3d n = Normalize(ns);
      ng = Normalize(ng);
      if (Dot(ng, n) < 0.0) ng = ng * -1.0;
      const VisibilityTerms v = ComputeVisibility(scene, bvh, o, env, p + ng * eps, n, ng, t, eps,
                                                  env_radiance, lights);
      map.ao[t] = float(v.ao);
      for (int c = 0; c < 3; ++c) map.indirect[t * 3 + size_t(c)] = float(v.indirect_over_pi[c]);
      if (!map.indirect_unit.empty())
        for (int c = 0; c < 3; ++c) map.indirect_unit[t * 3 + size_t(c)] = float(v.fabric_unit[c]);
    }
  });
  // Fill the uncovered texels outwards from the covered ones (mean of covered 4-neighbours).
  std::vector<char> done(texels, 0);
  for (size_t t = 0; t < texels; ++t) done[t] = tri[t] >= 0;
  map.covered = size_t(std::count(done.begin(), done.end(), char(1)));
  for (int pass = 0; pass < 2 * N && map.covered > 0; ++pass) {
    std::vector<char> next = done;
    bool any = false;
    for (int j = 0; j < N; ++j)
      for (int i = 0; i < N; ++i) {
        const size_t t = size_t(j) * size_t(N) + size_t(i);
        if (done[t]) continue;
        double ao_sum = 0.0, e[3] = {0, 0, 0}, eu[3] = {0, 0, 0};
        int n = 0;
        const int di[4] = {-1, 1, 0, 0}, dj[4] = {0, 0, -1, 1};
        for (int k = 0; k < 4; ++k) {
          const int a = i + di[k], c = j + dj[k];
          if (a < 0 || a >= N || c < 0 || c >= N) continue;
          const size_t q = size_t(c) * size_t(N) + size_t(a);
          if (!done[q]) continue;
          ao_sum += double(map.ao[q]);
          for (int ch = 0; ch < 3; ++ch) e[ch] += double(map.indirect[q * 3 + size_t(ch)]);
          if (!map.indirect_unit.empty())
            for (int ch = 0; ch < 3; ++ch) eu[ch] += double(map.indirect_unit[q * 3 + size_t(ch)]);
          ++n;
        }
        if (n == 0) continue;
        map.ao[t] = float(ao_sum / n);
        for (int ch = 0; ch < 3; ++ch) map.indirect[t * 3 + size_t(ch)] = float(e[ch] / n);
        if (!map.indirect_unit.empty())
          for (int ch = 0; ch < 3; ++ch) map.indirect_unit[t * 3 + size_t(ch)] = float(eu[ch] / n);
        next[t] = 1;
        any = true;
      }
    done.swap(next);
    if (!any) break;
  }
  return map;
}

}  // namespace clothfit::render
