#include "render/reference/path_tracer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>

#include "render/reference/adaptive_allocation.h"
#include "render/scene/embree_scene.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
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
            Rgbd(double(m.base_color[0]), double(m.base_color[1]), double(m.base_color[2]))));
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
    std::vector<double> ys;  // the M positions' second coordinates (stratified for any M)
    StratifiedRadicalInverses(M, &ys);
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
      double ju = (m + 0.5) / M + shift_u, jv = ys[size_t(m)] + shift_v;
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

  // Pilot of one tile for adaptive sampling: sums over its pilot pixels, by half (a
  // checkerboard of the pilot's cells; adaptive_allocation.h), and the rays traced.
  struct PilotStats {
    adaptive::TilePilot tp;  // weight and cost are filled in by Render
    uint64_t rays = 0;
    int pixels() const { return tp.pixels[0] + tp.pixels[1]; }
    double se() const { return tp.se[0] + tp.se[1]; }
    double value() const { return tp.value[0] + tp.value[1]; }
  };
  // Pilot pixels: one per stride x stride cell of the tile (cells from the tile's corner; the
  // last ones clipped by the tile). jitter false: at offset (stride - 1) / 2 in every cell
  // (stage 1); true: at a position in the cell hashed from pilot_seed and the cell (stage 2),
  // so the pilot pixels are a random sample of the tile's pixels, independent of the image's
  // streams. pilot_seed must differ from the image's seed (independent streams).
  PilotStats PilotTile(const RenderSettings& st, const SamplingPlan& pilot, int tile,
                       int tiles_x, int stride, uint64_t pilot_seed, bool jitter) const {
    const TileRect t = Rect(st, tile, tiles_x);
    PilotStats ps;
    BatchStrata strata({{2, 1}, {1, 1}, {2, pilot.env_samples}});
    const int off = (stride - 1) / 2;
    for (int cy = t.y0, iy = 0; cy < t.y1; cy += stride, ++iy) {
      double prev_s = 0.0, prev_v = 0.0;  // the row's cell 2k, for the pair (2k, 2k + 1)
      bool have_prev = false;
      for (int cx = t.x0, ix = 0; cx < t.x1; cx += stride, ++ix) {
        const int cw = std::min(stride, t.x1 - cx), ch = std::min(stride, t.y1 - cy);
        int x = cx + off, y = cy + off;
        if (jitter) {
          const uint64_t h = Mix64(pilot_seed ^ Mix64(uint64_t(cy) * uint64_t(scene.card.width) +
                                                      uint64_t(cx) + 0x9E3779B97F4A7C15ull));
          x = cx + int((h & 0xFFFFFFFFull) % uint64_t(cw));
          y = cy + int((h >> 32) % uint64_t(ch));
        }
        if (x >= t.x1 || y >= t.y1) continue;
        const int half = (ix + iy) & 1;
        const PixelEstimate est = EstimatePixel(st, pilot_seed, pilot.K * pilot.M, pilot.M,
                                                pilot.env_samples, x, y, strata, ps.rays);
        double sp = 0.0, vp = 0.0;
        for (int c = 0; c < 3; ++c) {
          const double var = pilot.K > 1 ? est.m2[c] / (pilot.K - 1) : 0.0;
          sp += std::sqrt(var / pilot.K) / 3.0;
          vp += est.mean[c] / 3.0;
        }
        ps.tp.se[half] += sp;
        ps.tp.value[half] += vp;
        ++ps.tp.pixels[half];
        // Cell pairs (2k, 2k + 1) of a row (adaptive_allocation.h, collapsed strata).
        if ((ix & 1) == 0) {
          prev_s = sp, prev_v = vp, have_prev = true;
        } else if (have_prev) {
          have_prev = false;
          ps.tp.se_pair2 += (sp - prev_s) * (sp - prev_s);
          ps.tp.value_pair2 += (vp - prev_v) * (vp - prev_v);
          ++ps.tp.pairs;
        }
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

}  // namespace

PathTracer::PathTracer(const Scene& scene, const Bsdf& fabric, const Environment* environment)
    : impl_(std::make_unique<Impl>(scene, fabric, environment)) {}
PathTracer::~PathTracer() = default;

RenderResult PathTracer::Render(const RenderSettings& st,
                                const std::function<void(int, int)>& progress) const {
  const auto t0 = std::chrono::steady_clock::now();
  const Scene& scene = impl_->scene;
  const int W = scene.card.width, H = scene.card.height;
  // Session 28: a reference the project's own reader refuses (4096 x 4096 is 704 MiB as float
  // with no AOV) was rendered, for hours, and written; refused here before any allocation.
  const size_t exr_bytes =
      size_t(W) * size_t(H) * size_t(RenderExrChannels(st.aovs)) * sizeof(float);
  if (exr_bytes > limits::kMaxImageBytes)
    throw std::invalid_argument(
        limits::EscapeForMessage(scene.card.path, 400) + ": field 'width'/'height': a " +
        std::to_string(W) + " x " + std::to_string(H) + " reference with " +
        std::to_string(RenderExrChannels(st.aovs)) + " channels is " +
        std::to_string(exr_bytes >> 20) + " MiB as float, over the " +
        std::to_string(limits::kMaxImageBytes >> 20) + " MiB an image may have to be read back " +
        limits::LimitRef("kMaxImageBytes") +
        " (fit, evaluate and compare could not read it); "
        "lower the width or height, or ask for fewer --aov");
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
  int env_samples = st.first_env_samples;
  if (adaptive) {
    if (!(st.target_error < 1e3) || st.min_spp < 32 || st.min_spp % 16 != 0 ||
        st.spp < st.min_spp || st.first_env_samples < 1 ||
        !(std::isfinite(st.allocation_z) && st.allocation_z >= 0.0) ||
        !(std::isfinite(st.pilot_calibration) && st.pilot_calibration > 0.0))
      throw std::invalid_argument(
          "adaptive sampling: need target_error in (0, 1000), min_spp a multiple of 16 >= 32, "
          "spp >= min_spp, first_env_samples >= 1, a finite allocation_z >= 0 and a finite "
          "pilot_calibration > 0");
    // Sums of a pilot over all tiles.
    struct PilotSum {
      double se = 0.0, value = 0.0, pixels = 0.0, rays = 0.0;
    };
    auto run_pilot = [&](const SamplingPlan& plan, int stride, uint64_t pilot_seed, bool jitter,
                         std::vector<Impl::PilotStats>* per_tile) {
      std::vector<Impl::PilotStats> stats(static_cast<size_t>(tiles));
      tbb::parallel_for(0, tiles, [&](int tile) {
        stats[size_t(tile)] =
            impl_->PilotTile(st, plan, tile, tiles_x, stride, pilot_seed, jitter);
        total_rays += stats[size_t(tile)].rays;
      });
      PilotSum sum;  // se and value: sums of the pixels' channel means
      for (const Impl::PilotStats& ps : stats) {
        sum.se += ps.se();
        sum.value += ps.value();
        sum.pixels += ps.pixels();
        sum.rays += double(ps.rays);
      }
      pilot_samples += sum.pixels * plan.K * plan.M;
      if (per_tile) *per_tile = std::move(stats);
      return sum;
    };
    // Stage 1 (docs/reference-renderer.md "Adaptive sampling, version 4"): every 8th pixel in
    // x and y, 32 spp (16 batches of 2), once per candidate count of first-vertex environment
    // samples (st.choose_env_samples: 2, 4 and 8; else st.first_env_samples). Efficiency of candidate e
    // = 1 / (relative error^2 x cost per sample), cost = rays per camera sample + e (each
    // environment sample's BSDF evaluation, pdf and map lookups counted as one ray: a fixed
    // cost model, so the choice, and the image, are deterministic).
    const std::vector<int> candidates =
        st.choose_env_samples ? std::vector<int>{2, 4, 8}
                              : std::vector<int>{st.first_env_samples};
    // Pilot densities: 1/64 and 1/16 of the pixels, denser on small images (at least about
    // 256 and 1024 pilot pixels where the image has them).
    const double pixels = double(W) * double(H);
    const int stride1 = pixels >= 64.0 * 256 ? 8 : pixels >= 16.0 * 256 ? 4 : 2;
    const int stride2 = pixels >= 16.0 * 1024 ? 4 : 2;
    double best_eff = -1.0, rel1 = 0.0;
    for (const int e : candidates) {
      const PilotSum p = run_pilot(PlanFor(32, e), stride1,
                                   st.seed ^ 0x3C6EF372FE94F82Bull ^ Mix64(uint64_t(e)), false,
                                   nullptr);
      if (!(p.pixels > 0.0)) continue;
      const double err = p.se / p.pixels, value = p.value / p.pixels;
      const double cost = p.rays / (p.pixels * 32.0) + e;
      const double rel = value > 0.0 ? err / value : 0.0;
      const double eff = rel > 0.0 ? 1.0 / (rel * rel * cost) : 1e300;
      r.env_candidates.push_back({e, rel, cost});
      if (eff > best_eff) {
        best_eff = eff;
        env_samples = e;
        rel1 = rel;
      }
    }
    if (best_eff < 0.0) env_samples = candidates.front();
    // The spp the target needs by stage 1 (error ~ spp^-1/2); stage 2 measures the per-tile
    // spread with that batch length M (16 batches of M), so the stratification the image's
    // batches get is the one measured (a pilot with shorter batches overestimates the error).
    const double need = 32.0 * (rel1 / st.target_error) * (rel1 / st.target_error);
    const int m2 = std::clamp(int(std::ceil(need / 16.0 - 1e-9)), 2, st.spp / 16);
    const SamplingPlan pilot = PlanFor(16 * m2, env_samples);
    std::vector<Impl::PilotStats> stats;
    const PilotSum p2 =
        run_pilot(pilot, stride2, st.seed ^ 0x5DEECE66D1CE4E5Bull, st.robust_allocation, &stats);
    tick(pilot_units);
    const double n_pilot = 16.0 * m2;
    std::vector<adaptive::TilePilot> tps(static_cast<size_t>(tiles));
    for (int t = 0; t < tiles; ++t) {
      const Impl::PilotStats& ps = stats[size_t(t)];
      const Impl::TileRect rc = impl_->Rect(st, t, tiles_x);
      adaptive::TilePilot& tp = tps[size_t(t)];
      tp = ps.tp;
      tp.weight = double(rc.x1 - rc.x0) * double(rc.y1 - rc.y0);
      // (A tile without pilot pixels, a sliver at the image's edge, takes the image's means.)
      tp.cost = ps.pixels() > 0
                    ? double(ps.rays) / (double(ps.pixels()) * n_pilot) + env_samples
                    : 0.0;
    }
    // The rate between the stages: relative error rel1 at 32 spp (batches of 2), rel2 at
    // n_pilot (batches of m2): gamma = 2 log(rel1 / rel2) / log(n_pilot / 32), in [1, 2]
    // (1 = plain Monte Carlo; 1 when the stages have the same spp).
    const double px2 = std::max(p2.pixels, 1.0);
    const double mean_value = p2.value / px2;
    const double rel2 = mean_value > 0.0 ? p2.se / px2 / mean_value : 0.0;
    double gamma = 1.0;
    if (m2 > 2 && rel1 > 0.0 && rel2 > 0.0)
      gamma = std::clamp(2.0 * std::log(rel1 / rel2) / std::log(n_pilot / 32.0), 1.0, 2.0);
    r.error_rate = gamma;
    adaptive::Params ap;
    ap.n_pilot = n_pilot;
    ap.gamma = gamma;
    ap.target = st.target_error;
    ap.lo = st.min_spp;
    ap.hi = st.spp;
    ap.tiles_x = tiles_x;
    ap.robust = st.robust_allocation;
    ap.z = st.allocation_z;
    ap.calibration = st.pilot_calibration;
    const adaptive::Allocation al = adaptive::Allocate(tps, ap);
    tile_spp = al.spp;
    r.predicted_error = al.predicted;
    r.predicted_upper = al.upper;
    r.allocation_reliability = al.reliability;
    r.pilot_value_rel_sd = al.value_rel_sd;
    r.pilot_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  r.env_samples = PlanFor(32, env_samples).env_samples;

  // Batches per tile (see PlanFor); r.batches is the count of the first tile (16 whenever
  // every tile's spp is a multiple of 16 >= 32, as adaptive counts always are).
  r.batches = PlanFor(tile_spp[0], env_samples).K;
  // One batch count K for the whole image (so the half images' metadata is one number): a
  // fixed spp gives one K; adaptive counts are multiples of 16 >= 32, i.e. K = 16 everywhere.
  for (int n : tile_spp)
    if (PlanFor(n, env_samples).K != r.batches)
      throw std::logic_error("Render: tiles with different batch counts");
  r.half_batches = HalfBatches(r.batches);
  tbb::parallel_for(0, tiles, [&](int tile) {
    const int spp = tile_spp[size_t(tile)];
    total_rays +=
        impl_->RenderTile(st, PlanFor(spp, env_samples), spp, tile, tiles_x, r);
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

int RenderExrChannels(const AovSet& aovs) {
  return 11 + (aovs.normal ? 3 : 0) + (aovs.position ? 3 : 0) + (aovs.tangent ? 3 : 0) +
         (aovs.uv ? 2 : 0) + (aovs.depth ? 1 : 0);
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
