#include "render/reference/path_tracer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "render/scene/embree_scene.h"
#include "render/scene/image_io.h"
#include "render/scene/lights.h"
#include "render/scene/sampler.h"

namespace clothfit::render {
namespace {

using A3 = std::array<double, 3>;

Vec3d V(const A3& a) { return {a[0], a[1], a[2]}; }
A3 A(const Vec3d& v) { return {v.x, v.y, v.z}; }

// Orthonormal shading frame: x = tangent, y = bitangent, z = normal.
struct Frame {
  Vec3d t, b, n;
  Vec3d ToLocal(const Vec3d& w) const { return {Dot(w, t), Dot(w, b), Dot(w, n)}; }
  Vec3d ToWorld(const Vec3d& w) const { return t * w.x + b * w.y + n * w.z; }
};

// atan2 to about 1e-5 rad, for cache prefetch hints only (never for a result).
double RoughAtan2(double y, double x) {
  const double ax = std::abs(x), ay = std::abs(y);
  const double mx = std::max(ax, ay), mn = std::min(ax, ay);
  if (!(mx > 0.0)) return 0.0;
  const double a = mn / mx, s = a * a;
  double r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a;
  if (ay > ax) r = 0.5 * kPi - r;
  if (x < 0.0) r = kPi - r;
  return y < 0.0 ? -r : r;
}

double PowerHeuristic(double a, double b) {
  const double a2 = a * a, b2 = b * b;
  return a2 + b2 > 0.0 ? a2 / (a2 + b2) : 0.0;
}

// What one camera sample returns: its radiance and the camera ray's first hit (for the AOVs).
struct SampleOut {
  Rgbd L{0, 0, 0};
  bool hit = false, fabric = false;
  SurfaceAttributes first;
  double depth = 0.0;
};

// Random numbers of the first vertex (the camera ray's hit), drawn stratified per batch:
// the BSDF sample (u.x, u.y, uc) and env_samples environment samples (2 each).
constexpr int kMaxFirstEnvSamples = 16;
struct FirstVertexU {
  double bsdf[3];
  double env[2 * kMaxFirstEnvSamples];
};

// One path vertex: the hit seen from the incoming ray, in a two-sided shading frame.
struct Vertex {
  Vec3d p;         // position
  Vec3d ng;        // geometric normal, on the viewer's side
  Frame fr;        // shading frame, its normal on the side of ng
  Vec3d wo_local;  // towards the viewer, in fr
  const Bsdf* bsdf;
  ShadingPoint sp;
};

// The state a path carries from vertex to vertex.
struct PathState {
  Rgbd T{1, 1, 1};  // throughput
  double prev_bsdf_pdf = 0.0, prev_light_count = 1.0;
  bool specular_bounce = true;  // camera ray: env seen directly with weight 1
};

// Batches for the standard-error estimate (see PathTracer::Render).
struct SamplingPlan {
  int K;            // batches
  int M;            // samples per batch, K x M = spp
  int env_samples;  // environment samples at the first vertex
};

// Running estimates of one pixel: Welford over the K batch means of the colour (the standard
// error is estimated from their spread), plain sums of the first-hit attributes for the AOVs.
struct PixelEstimate {
  double mean[3] = {0, 0, 0}, m2[3] = {0, 0, 0};
  double batch_sum[3] = {0, 0, 0};
  double half[3] = {0, 0, 0};  // mean of the first half_batches batch means (see Store)
  int batch_count = 0;
  int hits = 0, fabric_hits = 0;
  double aov_n[3] = {0, 0, 0}, aov_p[3] = {0, 0, 0}, aov_t[3] = {0, 0, 0}, aov_uv[2] = {0, 0};
  double aov_z = 0.0;

  // Sample m (0-based) of its batch of M; half_batches: the batch count of the first half.
  void Add(const SampleOut& so, int m, int M, int half_batches, double max_sample_value) {
    double v[3] = {so.L.r, so.L.g, so.L.b};
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(v[c])) v[c] = 0.0;  // never let one bad sample poison a pixel
      if (max_sample_value > 0.0) v[c] = std::min(v[c], max_sample_value);
      batch_sum[c] += v[c];
    }
    if (m == M - 1) {  // batch complete: Welford over batch means
      ++batch_count;
      for (int c = 0; c < 3; ++c) {
        const double bm = batch_sum[c] / M;
        const double delta = bm - mean[c];
        mean[c] += delta / batch_count;
        m2[c] += delta * (bm - mean[c]);
        batch_sum[c] = 0.0;
      }
      // The running mean of the first half_batches batch means: half image A.
      if (batch_count == half_batches)
        for (int c = 0; c < 3; ++c) half[c] = mean[c];
    }
    if (so.hit) {
      ++hits;
      if (so.fabric) ++fabric_hits;
      for (int c = 0; c < 3; ++c) {
        aov_n[c] += so.first.normal[size_t(c)];
        aov_p[c] += so.first.position[size_t(c)];
        aov_t[c] += so.first.tangent[size_t(c)];
      }
      aov_uv[0] += so.first.uv[0];
      aov_uv[1] += so.first.uv[1];
      aov_z += so.depth;
    }
  }

  // Writes pixel `pix` of r: mean, standard error from K batches, coverage, fabric, AOVs.
  void Store(size_t pix, int K, int spp, const AovSet& aovs, RenderResult& r) const {
    for (int c = 0; c < 3; ++c) {
      // A mean beyond float range would be UB to convert: it becomes Inf, which WriteRenderExr
      // refuses (the environment and light budgets keep radiance far below it).
      r.rgb[pix * 3 + size_t(c)] = std::abs(mean[c]) <= double(std::numeric_limits<float>::max())
                                       ? float(mean[c])
                                       : std::numeric_limits<float>::infinity();
      const double var = K > 1 ? m2[c] / (K - 1) : 0.0;  // variance of one batch mean
      r.std_error[pix * 3 + size_t(c)] = float(std::sqrt(var / K));
      if (!r.half.empty())
        r.half[pix * 3 + size_t(c)] = std::abs(half[c]) <= double(std::numeric_limits<float>::max())
                                          ? float(half[c])
                                          : std::numeric_limits<float>::infinity();
    }
    r.coverage[pix] = float(hits) / float(spp);
    r.fabric[pix] = float(fabric_hits) / float(spp);
    if (hits > 0) {
      const double inv = 1.0 / hits;
      for (int c = 0; c < 3; ++c) {
        if (aovs.normal) r.normal[pix * 3 + size_t(c)] = float(aov_n[c] * inv);
        if (aovs.position) r.position[pix * 3 + size_t(c)] = float(aov_p[c] * inv);
        if (aovs.tangent) r.tangent[pix * 3 + size_t(c)] = float(aov_t[c] * inv);
      }
      if (aovs.uv) {
        r.uv[pix * 2] = float(aov_uv[0] * inv);
        r.uv[pix * 2 + 1] = float(aov_uv[1] * inv);
      }
      if (aovs.depth) r.depth[pix] = float(aov_z * inv);
    }
  }
};

// A zeroed result of W x H pixels with the requested AOV buffers.
RenderResult AllocateResult(int W, int H, const AovSet& aovs) {
  RenderResult r;
  r.width = W;
  r.height = H;
  const size_t np = size_t(W) * size_t(H);
  r.rgb.assign(np * 3, 0.f);
  r.std_error.assign(np * 3, 0.f);
  r.half.assign(np * 3, 0.f);
  r.coverage.assign(np, 0.f);
  r.fabric.assign(np, 0.f);
  if (aovs.normal) r.normal.assign(np * 3, 0.f);
  if (aovs.position) r.position.assign(np * 3, 0.f);
  if (aovs.tangent) r.tangent.assign(np * 3, 0.f);
  if (aovs.uv) r.uv.assign(np * 2, 0.f);
  if (aovs.depth) r.depth.assign(np, 0.f);
  return r;
}

// Image-wide statistics: mean standard error, mean value, mean relative standard error.
void Summarize(RenderResult* r) {
  const size_t np = size_t(r->width) * size_t(r->height);
  double se_sum = 0.0, v_sum = 0.0, rel_sum = 0.0;
  size_t rel_n = 0;
  for (size_t p = 0; p < np; ++p) {
    double v = 0.0, se = 0.0;
    for (int c = 0; c < 3; ++c) {
      v += double(r->rgb[p * 3 + size_t(c)]);
      se += double(r->std_error[p * 3 + size_t(c)]);
    }
    se_sum += se;
    v_sum += v;
    if (r->coverage[p] > 0.0f && v > 1e-6) {
      rel_sum += se / v;
      ++rel_n;
    }
  }
  r->mean_std_error = se_sum / double(np * 3);
  r->mean_value = v_sum / double(np * 3);
  r->mean_relative_std_error = rel_n ? rel_sum / double(rel_n) : 0.0;
}

}  // namespace

struct PathTracer::Impl {
  const Scene& scene;
  const Bsdf& fabric;
  const Environment* env;
  EmbreeScene bvh;
  std::vector<std::unique_ptr<Bsdf>> lamberts;  // per mesh (null for fabric meshes)
  bool has_env = false;
  double env_cos_rot = 1.0, env_sin_rot = 0.0;  // of env->rotation_y()

  Impl(const Scene& s, const Bsdf& f, const Environment* e)
      : scene(s), fabric(f), env(e), bvh(s), has_env(e != nullptr) {
    if (env) {
      env_cos_rot = std::cos(env->rotation_y());
      env_sin_rot = std::sin(env->rotation_y());
    }
    for (const Mesh& m : s.meshes) {
      if (m.is_fabric) {
        lamberts.emplace_back(nullptr);
      } else {
        lamberts.emplace_back(std::make_unique<LambertBsdf>(
            Rgbd(m.base_color[0], m.base_color[1], m.base_color[2])));
      }
    }
  }

  // A bounce ray that escapes reads the environment map at its direction (Eval, bilinear) after
  // the intersection test; start loading those texels now so the cache misses overlap the
  // traversal. A hint only: (u, v) per environment.h's convention, approximately.
  void PrefetchEnvironment(const Vec3d& d) const {
    const int w = env->width(), h = env->height();
    if (w <= 0 || h <= 0) return;
    const double mx = env_cos_rot * d.x - env_sin_rot * d.z;
    const double mz = env_sin_rot * d.x + env_cos_rot * d.z;
    const double u = RoughAtan2(mz, mx) * (0.5 * kInvPi) + 0.5;
    const double v = RoughAtan2(d.y, std::sqrt(mx * mx + mz * mz)) * kInvPi + 0.5;
    const double x = u * w - 0.5, y = (1.0 - v) * h - 0.5;
    if (!std::isfinite(x) || !std::isfinite(y)) return;
    const int i0 = std::clamp(int(std::floor(x)), 0, w - 1);
    const int i1 = std::min(i0 + 1, w - 1);
    const int j0 = std::clamp(int(std::floor(y)), 0, h - 1);
    const int j1 = std::min(j0 + 1, h - 1);
    const float* px = env->pixels().data();
    for (const int j : {j0, j1}) {
      __builtin_prefetch(px + (size_t(j) * size_t(w) + size_t(i0)) * 3);
      __builtin_prefetch(px + (size_t(j) * size_t(w) + size_t(i1)) * 3 + 2);
    }
  }

  const Bsdf& BsdfOf(int mesh) const {
    return scene.meshes[size_t(mesh)].is_fabric ? fabric : *lamberts[size_t(mesh)];
  }

  // Direct light from the punctual lights at a shading point (delta lights: no MIS).
  Rgbd PunctualLights(const Vec3d& p, const Vec3d& ng, const Frame& fr, const Vec3d& wo_local,
                      const Bsdf& bsdf, const ShadingPoint& sp, double eps,
                      uint64_t& rays) const {
    Rgbd sum(0, 0, 0);
    for (const Light& light : scene.lights) {
      const LightSample ls = EvaluateLight(light, p);
      const Vec3d wi = ls.wi;
      const double dist = ls.distance;
      const double scale = ls.scale;
      if (scale <= 0.0) continue;
      const Vec3d wi_local = fr.ToLocal(wi);
      if (wi_local.z <= 0.0 || Dot(wi, ng) <= 0.0) continue;
      const Rgbd f = bsdf.Eval(wo_local, wi_local, sp);
      if (f.r <= 0.0 && f.g <= 0.0 && f.b <= 0.0) continue;
      ++rays;
      const double tfar = std::isinf(dist) ? dist : dist * (1.0 - 1e-6) - eps;
      if (bvh.Occluded(A(p + ng * eps), A(wi), 0.0, tfar)) continue;
      const Rgbd c(light.color[0], light.color[1], light.color[2]);
      sum += f * c * (scale * wi_local.z);
    }
    return sum;
  }

  // A ray that left the scene: the environment, MIS-weighted against the previous vertex's
  // environment samples after a BSDF bounce; without one, the card's background for a camera
  // ray and nothing for a bounce.
  void AddEscaped(const Vec3d& dir, int depth, const PathState& ps, Rgbd& L) const {
    if (has_env) {
      const Rgbd Le = env->Eval(dir);
      const double w = ps.specular_bounce
                           ? 1.0
                           : PowerHeuristic(ps.prev_bsdf_pdf, ps.prev_light_count * env->Pdf(dir));
      L += ps.T * Le * w;
    } else if (depth == 0) {
      L += Rgbd(scene.card.background[0], scene.card.background[1], scene.card.background[2]);
    }
  }

  // The vertex at hit h of a ray along dir; false when the shading normal faces away from
  // the viewer (no contribution).
  bool MakeVertex(const Hit& h, const SurfaceAttributes& a, const Vec3d& dir, Vertex* vx) const {
    // Two-sided: put the frame on the viewer's side of the geometric normal.
    Vec3d ng = V(h.ng), n = V(a.normal);
    const Vec3d wo = dir * -1.0;
    if (Dot(ng, wo) < 0.0) ng = ng * -1.0;
    if (Dot(n, ng) < 0.0) n = n * -1.0;
    Vec3d t = V(a.tangent);
    t = Normalize(t - n * Dot(t, n));
    const Vec3d b = Cross(n, t) * a.tangent_sign;
    vx->fr = Frame{t, b, n};
    vx->wo_local = vx->fr.ToLocal(wo);
    if (vx->wo_local.z <= 0.0) return false;
    vx->ng = ng;
    vx->bsdf = &BsdfOf(h.mesh);
    vx->sp = ShadingPoint{{a.uv[0], a.uv[1]}};
    vx->p = V(a.position);
    return true;
  }

  // Environment next-event estimation at a vertex: n_l samples, their numbers from
  // first_u (the first vertex's strata) or else drawn from rng, each weighted by the power
  // heuristic against the BSDF and counting 1 / n_l; adds T x contribution to L.
  void AddEnvironmentLight(const Vertex& vx, const Rgbd& T, int n_l, const FirstVertexU* first_u,
                           Pcg32& rng, double eps, Rgbd& L, uint64_t& rays) const {
    for (int k = 0; k < n_l; ++k) {
      double pdf_l = 0.0, u1, u2;
      if (first_u) {
        u1 = first_u->env[2 * k];
        u2 = first_u->env[2 * k + 1];
      } else {
        u1 = rng.Uniform();
        u2 = rng.Uniform();
      }
      // Radiance looked up only for a sample that contributes (below).
      const Vec3d wi = env->Sample(u1, u2, &pdf_l, nullptr);
      const Vec3d wi_local = vx.fr.ToLocal(wi);
      if (!(pdf_l > 0.0 && wi_local.z > 0.0 && Dot(wi, vx.ng) > 0.0)) continue;
      const Rgbd f = vx.bsdf->Eval(vx.wo_local, wi_local, vx.sp);
      if (!(f.r > 0.0 || f.g > 0.0 || f.b > 0.0)) continue;
      ++rays;
      if (bvh.Occluded(A(vx.p + vx.ng * eps), A(wi), 0.0,
                       std::numeric_limits<double>::infinity())) {
        continue;
      }
      const Rgbd Le = env->Eval(wi);
      const double pdf_b = vx.bsdf->Pdf(vx.wo_local, wi_local, vx.sp);
      const double w = PowerHeuristic(n_l * pdf_l, pdf_b);
      L += T * f * Le * (wi_local.z * w / (n_l * pdf_l));
    }
  }

  // BSDF sampling continues the path (numbers from first_u at the first vertex, else from
  // rng): false when the path ends here; else *wi is the new direction and ps is updated.
  bool SampleBsdf(const Vertex& vx, const FirstVertexU* first_u, int n_l, Pcg32& rng, PathState& ps,
                  Vec3d* wi) const {
    BsdfSample bs;
    Point2d u;
    double uc;
    if (first_u) {
      u = {first_u->bsdf[0], first_u->bsdf[1]};
      uc = first_u->bsdf[2];
    } else {
      u.x = rng.Uniform();
      u.y = rng.Uniform();
      uc = rng.Uniform();
    }
    if (!vx.bsdf->Sample(vx.wo_local, u, uc, vx.sp, &bs) || bs.pdf <= 0.0) return false;
    if (bs.wi.z <= 0.0) return false;
    *wi = vx.fr.ToWorld(bs.wi);
    if (Dot(*wi, vx.ng) <= 0.0) return false;
    ps.T = ps.T * bs.f * (bs.wi.z / bs.pdf);
    ps.prev_bsdf_pdf = bs.pdf;
    ps.prev_light_count = n_l;
    ps.specular_bounce = false;
    return true;
  }

  // first: stratified numbers for the first vertex, or null to draw them from rng (then one
  // environment sample). env_samples: environment samples at the first vertex (Veach's
  // multi-sample MIS: with n_l light samples and one BSDF sample, the power heuristic weighs
  // n_l pdf_l against pdf_b; each light sample counts 1 / n_l).
  SampleOut TracePath(const Vec3d& org0, const Vec3d& dir0, Pcg32& rng, const FirstVertexU* first,
                      int env_samples, const RenderSettings& st, uint64_t& rays) const {
    SampleOut out;
    Vec3d org = org0, dir = dir0;
    PathState ps;
    const double eps = 1e-5 * bvh.scale();
    for (int depth = 0;; ++depth) {
      ++rays;
      const Hit h = bvh.Intersect(A(org), A(dir), depth == 0 ? 0.0 : eps);
      if (!h.valid) {
        AddEscaped(dir, depth, ps, out.L);
        break;
      }
      SurfaceAttributes a = bvh.Attributes(h);
      if (depth == 0) {
        out.hit = true;
        out.fabric = scene.meshes[size_t(h.mesh)].is_fabric;
        out.first = a;
        out.depth = h.t;
      }
      if (depth >= st.max_depth) break;
      Vertex vx;
      if (!MakeVertex(h, a, dir, &vx)) break;  // shading normal facing away: no contribution
      const FirstVertexU* first_u = depth == 0 ? first : nullptr;

      // Next-event estimation: punctual lights, then the environment (MIS).
      out.L += ps.T * PunctualLights(vx.p, vx.ng, vx.fr, vx.wo_local, *vx.bsdf, vx.sp, eps, rays);
      const int n_l = first_u ? env_samples : 1;
      if (has_env) AddEnvironmentLight(vx, ps.T, n_l, first_u, rng, eps, out.L, rays);

      // BSDF sampling continues the path.
      Vec3d wi;
      if (!SampleBsdf(vx, first_u, n_l, rng, ps, &wi)) break;
      // Without an environment, an escaping bounce ray carries nothing: stop early.
      org = vx.p + vx.ng * eps;
      dir = wi;
      if (has_env) PrefetchEnvironment(dir);
      if (depth + 1 >= st.rr_start_depth) {
        const double q = std::max(0.05, 1.0 - std::max({ps.T.r, ps.T.g, ps.T.b}));
        if (rng.Uniform() < q) break;
        ps.T = ps.T * (1.0 / (1.0 - q));
      }
    }
    return out;
  }

  // All spp samples of pixel (x, y) from the streams of `seed`, in batches of M.
  // strata: the tile's, reused pixel to pixel.
  PixelEstimate EstimatePixel(const RenderSettings& st, uint64_t seed, int spp, int M,
                              int env_samples, int x, int y, BatchStrata& strata,
                              uint64_t& rays) const {
    const size_t pix = size_t(y) * size_t(scene.card.width) + size_t(x);
    // Pixel positions: K independently shifted copies (Cranley-Patterson rotations) of
    // an M-point stratified set (Hammersley), K x M = spp. Each batch's mean is an
    // unbiased estimate and the K batch means are i.i.d., so the standard error is
    // estimated from their spread: stratification lowers the error (the weave's
    // sub-pixel structure is antialiased far better than by i.i.d. jitter) and the
    // estimate of it stays honest.
    PixelEstimate est;
    Pcg32 shift_rng = PixelSampler(seed ^ 0xA5A5A5A5DEADBEEFull, pix, 0);
    double shift_u = 0.0, shift_v = 0.0;
    for (int s = 0; s < spp; ++s) {
      const int m = s % M;  // sample m of batch s / M
      if (m == 0) {
        shift_u = shift_rng.Uniform();
        shift_v = shift_rng.Uniform();
        if (M > 1) strata.Reset(M, shift_rng);
      }
      FirstVertexU first;
      if (M > 1) {
        strata.Get(0, m, 0, first.bsdf);
        strata.Get(1, m, 0, first.bsdf + 2);
        for (int k = 0; k < env_samples; ++k) strata.Get(2, m, k, first.env + 2 * k);
      }
      Pcg32 rng = PixelSampler(seed, pix, uint64_t(s));
      double ju = (m + 0.5) / M + shift_u, jv = RadicalInverse2(uint32_t(m)) + shift_v;
      ju -= std::floor(ju);
      jv -= std::floor(jv);
      if (M == 1) {
        ju = rng.Uniform();
        jv = rng.Uniform();
      }
      A3 org, dir;
      scene.CameraRay(x + ju, y + jv, org, dir);
      const SampleOut so =
          TracePath(V(org), V(dir), rng, M > 1 ? &first : nullptr, env_samples, st, rays);
      est.Add(so, m, M, HalfBatches(spp / M), st.max_sample_value);
    }
    return est;
  }

  // The tile's pixel range.
  struct TileRect {
    int x0, y0, x1, y1;
  };
  TileRect Rect(const RenderSettings& st, int tile, int tiles_x) const {
    const int W = scene.card.width, H = scene.card.height;
    const int tx = tile % tiles_x, ty = tile / tiles_x;
    return {tx * st.tile_size, ty * st.tile_size, std::min(W, (tx + 1) * st.tile_size),
            std::min(H, (ty + 1) * st.tile_size)};
  }

  // The pixels of tile `tile` (row-major, tiles_x per row) with spp samples each (the plan's
  // batches); returns the rays traced.
  uint64_t RenderTile(const RenderSettings& st, const SamplingPlan& plan, int spp, int tile,
                      int tiles_x, RenderResult& r) const {
    const TileRect t = Rect(st, tile, tiles_x);
    uint64_t rays = 0;
    BatchStrata strata({{2, 1}, {1, 1}, {2, plan.env_samples}});
    for (int y = t.y0; y < t.y1; ++y) {
      for (int x = t.x0; x < t.x1; ++x) {
        const PixelEstimate est =
            EstimatePixel(st, st.seed, spp, plan.M, plan.env_samples, x, y, strata, rays);
        est.Store(size_t(y) * size_t(scene.card.width) + size_t(x), plan.K, spp, st.aovs, r);
      }
    }
    return rays;
  }

  // Pilot of one tile for adaptive sampling: every other pixel in x and y (the tile's corner
  // always), pilot_spp samples each (16 batches) from streams independent of the image's.
  struct PilotStats {
    double se_sum = 0.0, value_sum = 0.0;  // over pilot pixels and channels
    int pixels = 0;
    uint64_t rays = 0;
  };
  PilotStats PilotTile(const RenderSettings& st, const SamplingPlan& pilot, int tile,
                       int tiles_x) const {
    const TileRect t = Rect(st, tile, tiles_x);
    PilotStats ps;
    BatchStrata strata({{2, 1}, {1, 1}, {2, pilot.env_samples}});
    const uint64_t pilot_seed = st.seed ^ 0x5DEECE66D1CE4E5Bull;  // disjoint from st.seed's
    for (int y = t.y0; y < t.y1; y += 2) {
      for (int x = t.x0; x < t.x1; x += 2) {
        const PixelEstimate est = EstimatePixel(st, pilot_seed, pilot.K * pilot.M, pilot.M,
                                                pilot.env_samples, x, y, strata, ps.rays);
        for (int c = 0; c < 3; ++c) {
          const double var = pilot.K > 1 ? est.m2[c] / (pilot.K - 1) : 0.0;
          ps.se_sum += std::sqrt(var / pilot.K);
          ps.value_sum += est.mean[c];
        }
        ++ps.pixels;
      }
    }
    return ps;
  }
};

namespace {

// Batches for a given spp: K = 16 batches of M = spp / 16 stratified samples when spp is a
// multiple of 16 (>= 32), else K = spp batches of one i.i.d. sample.
SamplingPlan PlanFor(int spp, int env_samples) {
  SamplingPlan plan;
  plan.K = (spp >= 32 && spp % 16 == 0) ? 16 : spp;
  plan.M = spp / plan.K;
  plan.env_samples = std::clamp(env_samples, 1, kMaxFirstEnvSamples);
  return plan;
}

// Adaptive allocation (docs/reference-renderer.md, "Adaptive sampling"). Tile t has w_t
// pixels, a per-sample spread s_t (its pilot pixels' mean standard error x sqrt(pilot spp):
// at n samples the tile's mean standard error is about s_t / sqrt(n)) and a cost c_t (rays
// per sample). The counts minimise the cost sum w_t c_t n_t subject to the image's mean
// standard error sum w_t s_t / sqrt(n_t) / sum w_t <= target: n_t = lambda (s_t / c_t)^(2/3)
// (Lagrange), clamped to [lo, hi], lambda found by bisection, then rounded up to a multiple
// of 16. Each tile thus stops at its own standard error s_t / sqrt(n_t).
std::vector<int> AllocateTileSpp(const std::vector<double>& w, const std::vector<double>& s,
                                 const std::vector<double>& c, double target, int lo, int hi) {
  const size_t n = w.size();
  double wsum = 0.0;
  for (double x : w) wsum += x;
  auto counts = [&](double lambda, std::vector<double>* out) {
    double err = 0.0;
    for (size_t t = 0; t < n; ++t) {
      const double shape = s[t] > 0.0 ? std::cbrt((s[t] / std::max(c[t], 1e-6)) *
                                                  (s[t] / std::max(c[t], 1e-6)))
                                      : 0.0;
      const double nt = std::clamp(lambda * shape, double(lo), double(hi));
      if (out) (*out)[t] = nt;
      err += w[t] * s[t] / std::sqrt(nt);
    }
    return err / wsum;
  };
  std::vector<double> nt(n, double(hi));
  if (counts(1e30, nullptr) > target) {
    counts(1e30, &nt);  // even the budget everywhere misses the target: use the budget
  } else {
    double a = -60.0, b = 80.0;  // log lambda
    for (int it = 0; it < 100; ++it) {
      const double m = 0.5 * (a + b);
      (counts(std::exp(m), nullptr) > target ? a : b) = m;
    }
    counts(std::exp(b), &nt);
  }
  std::vector<int> spp(n);
  for (size_t t = 0; t < n; ++t) {
    const int k = int(std::ceil(nt[t] / 16.0 - 1e-9));
    spp[t] = std::clamp(16 * k, lo, hi);
  }
  return spp;
}

}  // namespace

PathTracer::PathTracer(const Scene& scene, const Bsdf& fabric, const Environment* environment)
    : impl_(std::make_unique<Impl>(scene, fabric, environment)) {}
PathTracer::~PathTracer() = default;

RenderResult PathTracer::Render(const RenderSettings& st,
                                const std::function<void(int, int)>& progress) const {
  const auto t0 = std::chrono::steady_clock::now();
  const Scene& scene = impl_->scene;
  const int W = scene.card.width, H = scene.card.height;
  RenderResult r = AllocateResult(W, H, st.aovs);

  const int tiles_x = (W + st.tile_size - 1) / st.tile_size;
  const int tiles_y = (H + st.tile_size - 1) / st.tile_size;
  const int tiles = tiles_x * tiles_y;
  std::atomic<int> done{0};
  std::atomic<uint64_t> total_rays{0};
  std::mutex progress_mutex;
  const bool adaptive = st.target_error > 0.0;
  // Progress: the pilot counts as a quarter of the tiles' work.
  const int pilot_units = adaptive ? (tiles + 3) / 4 : 0;
  auto tick = [&](int units) {
    const int d = (done += units);
    if (progress) {
      std::lock_guard<std::mutex> lock(progress_mutex);
      progress(d, tiles + pilot_units);
    }
  };

  // Samples per pixel of every tile: st.spp, or the adaptive allocation from a pilot.
  std::vector<int> tile_spp(static_cast<size_t>(tiles), st.spp);
  double pilot_samples = 0.0;
  if (adaptive) {
    if (!(st.target_error < 1e3) || st.min_spp < 32 || st.min_spp % 16 != 0 ||
        st.spp < st.min_spp || st.pilot_spp < 32 || st.pilot_spp % 16 != 0)
      throw std::invalid_argument(
          "adaptive sampling: need target_error in (0, 1000), min_spp and pilot_spp multiples "
          "of 16 >= 32, spp >= min_spp");
    const SamplingPlan pilot = PlanFor(st.pilot_spp, st.first_env_samples);
    std::vector<Impl::PilotStats> stats(static_cast<size_t>(tiles));
    tbb::parallel_for(0, tiles, [&](int tile) {
      stats[size_t(tile)] = impl_->PilotTile(st, pilot, tile, tiles_x);
      total_rays += stats[size_t(tile)].rays;
      if (tile % 4 == 0) tick(1);
    });
    const size_t nt = static_cast<size_t>(tiles);
    std::vector<double> w(nt), spread(nt), cost(nt);
    double value_sum = 0.0, pilot_pixels = 0.0;
    for (int t = 0; t < tiles; ++t) {
      const Impl::PilotStats& ps = stats[size_t(t)];
      const Impl::TileRect rc = impl_->Rect(st, t, tiles_x);
      w[size_t(t)] = double(rc.x1 - rc.x0) * double(rc.y1 - rc.y0);
      spread[size_t(t)] = ps.se_sum / (3.0 * ps.pixels) * std::sqrt(double(st.pilot_spp));
      cost[size_t(t)] = double(ps.rays) / (double(ps.pixels) * st.pilot_spp);
      value_sum += ps.value_sum;
      pilot_pixels += ps.pixels;
    }
    pilot_samples = pilot_pixels * st.pilot_spp;
    const double mean_value = value_sum / (3.0 * pilot_pixels);
    for (double& x : spread) x *= st.pilot_calibration;
    tile_spp = AllocateTileSpp(w, spread, cost, st.target_error * mean_value, st.min_spp, st.spp);
    r.pilot_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  // Batches per tile (see PlanFor); r.batches is the count of the first tile (16 whenever
  // every tile's spp is a multiple of 16 >= 32, as adaptive counts always are).
  r.batches = PlanFor(tile_spp[0], st.first_env_samples).K;
  // One batch count K for the whole image (so the half images' metadata is one number): a
  // fixed spp gives one K; adaptive counts are multiples of 16 >= 32, i.e. K = 16 everywhere.
  for (int n : tile_spp)
    if (PlanFor(n, st.first_env_samples).K != r.batches)
      throw std::logic_error("Render: tiles with different batch counts");
  r.half_batches = HalfBatches(r.batches);
  tbb::parallel_for(0, tiles, [&](int tile) {
    const int spp = tile_spp[size_t(tile)];
    total_rays +=
        impl_->RenderTile(st, PlanFor(spp, st.first_env_samples), spp, tile, tiles_x, r);
    tick(1);
  });

  double samples = pilot_samples;
  for (int t = 0; t < tiles; ++t) {
    const Impl::TileRect rc = impl_->Rect(st, t, tiles_x);
    samples += double(rc.x1 - rc.x0) * double(rc.y1 - rc.y0) * tile_spp[size_t(t)];
  }
  r.mean_spp = samples / (double(W) * double(H));
  if (adaptive) {
    r.tile_spp = tile_spp;
    r.tile_size = st.tile_size;
  }
  r.rays = total_rays.load();
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Summarize(&r);
  return r;
}

void WriteRenderExr(const std::string& path, const RenderResult& r,
                    const std::vector<std::pair<std::string, std::string>>& extra) {
  io::Image img;
  img.width = r.width;
  img.height = r.height;
  struct Plane {
    std::string name;
    const std::vector<float>* data;
    int stride, offset;
  };
  std::vector<Plane> planes = {{"R", &r.rgb, 3, 0},          {"G", &r.rgb, 3, 1},
                               {"B", &r.rgb, 3, 2},          {"A", &r.coverage, 1, 0},
                               {"fabric", &r.fabric, 1, 0},  {"stderr.R", &r.std_error, 3, 0},
                               {"stderr.G", &r.std_error, 3, 1}, {"stderr.B", &r.std_error, 3, 2}};
  auto add3 = [&](const char* prefix, const std::vector<float>& v) {
    if (v.empty()) return;
    const char* s[3] = {"X", "Y", "Z"};
    for (int c = 0; c < 3; ++c) planes.push_back({std::string(prefix) + "." + s[c], &v, 3, c});
  };
  add3("N", r.normal);
  add3("P", r.position);
  add3("T", r.tangent);
  if (!r.uv.empty()) {
    planes.push_back({"uv.U", &r.uv, 2, 0});
    planes.push_back({"uv.V", &r.uv, 2, 1});
  }
  if (!r.depth.empty()) planes.push_back({"Z", &r.depth, 1, 0});
  // Half image A (docs/reference-renderer.md "Half images"): only with two non-empty halves.
  const bool halves = r.half_batches >= 1 && r.batches - r.half_batches >= 1 &&
                      r.half.size() == r.rgb.size();
  if (halves) {
    planes.push_back({"half.R", &r.half, 3, 0});
    planes.push_back({"half.G", &r.half, 3, 1});
    planes.push_back({"half.B", &r.half, 3, 2});
  }
  const size_t np = size_t(r.width) * size_t(r.height);
  size_t nonfinite = 0;
  for (float v : r.rgb) nonfinite += std::isfinite(v) ? 0 : 1;
  if (halves)
    for (float v : r.half) nonfinite += std::isfinite(v) ? 0 : 1;
  if (nonfinite > 0)  // never written, so never cached as a reference
    throw io::IoError(path + ": refusing to write a render with " + std::to_string(nonfinite) +
                      " non-finite radiance values (kMaxRadiance; docs/reliability.md)");
  img.pixels.resize(np * planes.size());
  for (const Plane& pl : planes) img.channel_names.push_back(pl.name);
  for (size_t p = 0; p < np; ++p)
    for (size_t k = 0; k < planes.size(); ++k)
      img.pixels[p * planes.size() + k] =
          (*planes[k].data)[p * size_t(planes[k].stride) + size_t(planes[k].offset)];
  for (const auto& [k, v] : extra) img.metadata[k] = v;
  img.metadata["clothfit:colour_space"] = "linear Rec.709 / sRGB primaries, scene-referred radiance";
  img.metadata["clothfit:stderr"] = "stderr.* = standard error of the pixel mean, sqrt(var/n)";
  img.metadata["clothfit:alpha"] = "A = fraction of camera samples that hit geometry";
  if (r.batches > 0) img.metadata["clothfit:batches"] = std::to_string(r.batches);
  if (halves) {
    img.metadata["clothfit:half_batches"] = std::to_string(r.half_batches);
    img.metadata["clothfit:half"] =
        "half.* = mean of the first clothfit:half_batches of the clothfit:batches i.i.d. batch "
        "means (the same K in every pixel); the other half B = (K mean - kA half) / (K - kA)";
  }
  io::WriteExr(path, img);
}

}  // namespace clothfit::render
