#include "fit/weave_maps.h"

#include <tbb/parallel_for.h>

#include <array>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "brdf/lut.h"
#include "brdf/woven.h"

namespace clothfit::fit {
namespace {

constexpr int kN = render::WeaveMaps::kChannels;  // unknowns: a_w, a_f, kd_R, kd_G, kd_B
constexpr double kEps = 1e-4;  // the cube-root metric's eps (fit/brdf_fit.h's before session 27)

struct Pair {
  render::Vec3d v, l;
  double weight;
  // Basis of the linear per-texel model (cosine included): constant (sheen), warp, weft, kd.
  Rgb<double> b0, bw, bf, bkd;
};

// The basis of the per-texel model for (v, l) in a frame with normal n (t = +x Gram-Schmidt'd
// against n, b = n x t): what the preview shades with a relief normal n.
void Basis(const woven::Params<double>& p, const render::Vec3d& n, Pair* q) {
  const woven::Options wo;  // tints 1 (the maps carry the per-yarn differences)
  const render::Vec3d x(1, 0, 0);
  const render::Vec3d t = Normalize(x - n * Dot(x, n));
  const render::Vec3d b = Cross(n, t);
  const render::Vec3d h = Normalize(q->v + q->l);
  const Cosines<double> cs{Dot(n, q->v), Dot(n, q->l), Dot(n, h), Dot(q->l, h)};
  const TangentCosines<double> tc{Dot(t, q->v), Dot(b, q->v), Dot(t, q->l),
                                  Dot(b, q->l), Dot(t, h),    Dot(b, h)};
  auto eval = [&](double w, double f, double kd) {
    woven::WeaveSample<double> ws;
    ws.warp = w;
    ws.weft = f;
    ws.kd = Rgb<double>(kd, kd, kd);
    return woven::EvalDirect(p, wo, cs, tc, ws, lut::DefaultDfg(), lut::DefaultWovenPhase());
  };
  q->b0 = eval(0, 0, 0);
  q->bw = eval(1, 0, 0) - q->b0;
  q->bf = eval(0, 1, 0) - q->b0;
  q->bkd = eval(0, 0, 1) - q->b0;
}

std::vector<Pair> BuildPairs(const render::MaterialPreset& preset, const WeaveBakeOptions& o) {
  const lut::GaussLegendre gl(o.mu_nodes);
  const woven::Params<double> p = woven::FromFlat(preset.values.data());
  std::vector<Pair> out;
  double total = 0.0;
  for (int a = 0; a < o.mu_nodes; ++a) {
    if (o.view_band >= 0 && a != o.view_band) continue;
    const double mv = 0.5 * (gl.x[size_t(a)] + 1.0), wv = 0.5 * gl.w[size_t(a)];
    const double sv = std::sqrt(1.0 - mv * mv);
    for (int b = 0; b < o.mu_nodes; ++b) {
      const double ml = 0.5 * (gl.x[size_t(b)] + 1.0), wl = 0.5 * gl.w[size_t(b)];
      const double sl = std::sqrt(1.0 - ml * ml);
      for (int i = 0; i < o.phi_v; ++i) {
        const double pv = (i + 0.5) * kPi / o.phi_v;
        for (int k = 0; k < o.phi_l; ++k) {
          const double pl = (k + 0.5) * 2.0 * kPi / o.phi_l;
          Pair q;
          q.v = render::Vec3d(sv * std::cos(pv), sv * std::sin(pv), mv);
          q.l = render::Vec3d(sl * std::cos(pl), sl * std::sin(pl), ml);
          q.weight = wv * wl * 2.0 * mv;
          total += q.weight;
          Basis(p, render::Vec3d(0, 0, 1), &q);
          out.push_back(q);
        }
      }
    }
  }
  for (Pair& q : out) q.weight /= total;
  return out;
}

// Solves the symmetric positive definite system A x = r (Gaussian elimination with partial
// pivoting on the active unknowns; inactive ones are 0). Returns false if singular.
bool Solve(std::array<std::array<double, kN>, kN> A, std::array<double, kN> r,
           const std::array<bool, kN>& active, std::array<double, kN>* x) {
  std::array<int, kN> idx{};
  int n = 0;
  for (int k = 0; k < kN; ++k)
    if (active[size_t(k)]) idx[size_t(n++)] = k;
  std::vector<std::vector<double>> M(size_t(n), std::vector<double>(size_t(n) + 1));
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) M[size_t(a)][size_t(b)] = A[size_t(idx[size_t(a)])][size_t(idx[size_t(b)])];
    M[size_t(a)][size_t(n)] = r[size_t(idx[size_t(a)])];
  }
  for (int c = 0; c < n; ++c) {
    int piv = c;
    for (int a = c + 1; a < n; ++a)
      if (std::abs(M[size_t(a)][size_t(c)]) > std::abs(M[size_t(piv)][size_t(c)])) piv = a;
    if (!(std::abs(M[size_t(piv)][size_t(c)]) > 1e-300)) return false;
    std::swap(M[size_t(c)], M[size_t(piv)]);
    for (int a = c + 1; a < n; ++a) {
      const double f = M[size_t(a)][size_t(c)] / M[size_t(c)][size_t(c)];
      for (int b = c; b <= n; ++b) M[size_t(a)][size_t(b)] -= f * M[size_t(c)][size_t(b)];
    }
  }
  x->fill(0.0);
  for (int a = n - 1; a >= 0; --a) {
    double s = M[size_t(a)][size_t(n)];
    for (int b = a + 1; b < n; ++b) s -= M[size_t(a)][size_t(b)] * (*x)[size_t(idx[size_t(b)])];
    (*x)[size_t(idx[size_t(a)])] = s / M[size_t(a)][size_t(a)];
  }
  return true;
}

// The design row of unknown j for pair q, channel c.
inline double Design(const Pair& q, int c, int j) {
  switch (j) {
    case 0: return q.bw[c];
    case 1: return q.bf[c];
    default: return j - 2 == c ? q.bkd[c] : 0.0;
  }
}

double SquaredError(const std::vector<Pair>& pairs, const std::vector<Rgb<double>>& target,
                    const std::array<double, kN>& x) {
  double e = 0.0;
  for (size_t k = 0; k < pairs.size(); ++k)
    for (int c = 0; c < 3; ++c) {
      double f = pairs[k].b0[c];
      for (int j = 0; j < kN; ++j) f += x[size_t(j)] * Design(pairs[k], c, j);
      const double d = std::cbrt(std::max(target[k][c], 0.0) + kEps) - std::cbrt(std::max(f, 0.0) + kEps);
      e += pairs[k].weight * d * d;
    }
  return e;
}

// One texel's unknowns: weighted least squares on the cube-root residuals linearised at the
// target (weight (y + eps)^(-4/3) / 9), a ridge towards 1 relative to the diagonal's scale, and
// negative unknowns dropped and the rest re-solved. `target[k]` is the reference BSDF times
// cos for ps[k].
std::array<double, kN> FitTexel(const Pair* ps, const Rgb<double>* target, size_t n, double ridge) {
  std::array<std::array<double, kN>, kN> A{};
  std::array<double, kN> r{};
  for (size_t k = 0; k < n; ++k) {
    const Pair& q = ps[k];
    for (int c = 0; c < 3; ++c) {
      const double y = std::max(target[k][c], 0.0) + kEps;
      const double w = q.weight * std::pow(y, -4.0 / 3.0) / 9.0;
      const double res = target[k][c] - q.b0[c];
      for (int a = 0; a < kN; ++a) {
        const double da = Design(q, c, a);
        if (da == 0.0) continue;
        r[size_t(a)] += w * da * res;
        for (int b = 0; b < kN; ++b) A[size_t(a)][size_t(b)] += w * da * Design(q, c, b);
      }
    }
  }
  double diag = 0.0;
  for (int a = 0; a < kN; ++a) diag = std::max(diag, A[size_t(a)][size_t(a)]);
  for (int a = 0; a < kN; ++a) {
    A[size_t(a)][size_t(a)] += ridge * diag;
    r[size_t(a)] += ridge * diag * 1.0;
  }
  std::array<bool, kN> active;
  active.fill(true);
  std::array<double, kN> x{};
  for (int it = 0; it <= kN; ++it) {
    if (!Solve(A, r, active, &x)) {
      x.fill(1.0);
      break;
    }
    bool neg = false;
    for (int a = 0; a < kN; ++a)
      if (active[size_t(a)] && x[size_t(a)] < 0.0) {
        active[size_t(a)] = false;
        neg = true;
      }
    if (!neg) break;
  }
  for (double& v : x) v = std::max(v, 0.0);
  return x;
}

// The tile means of the texels' solutions, and level 0 of the ratio maps (a channel with a zero
// tile mean, e.g. no weft lobe anywhere, stays uniform).
std::vector<float> Level0(const std::vector<std::array<double, kN>>& xs,
                          std::array<double, kN>* mean_out) {
  const size_t texels = xs.size();
  std::array<double, kN> mean{};
  for (const auto& x : xs)
    for (int a = 0; a < kN; ++a) mean[size_t(a)] += x[size_t(a)] / double(texels);
  std::vector<float> level0(texels * kN);
  for (size_t t = 0; t < texels; ++t)
    for (int a = 0; a < kN; ++a)
      level0[t * kN + size_t(a)] = mean[size_t(a)] > 1e-9 ? float(xs[t][size_t(a)]) : 1.f;
  if (mean_out) *mean_out = mean;
  return level0;
}

}  // namespace

double WeaveViewBandCosine(int k, int mu_nodes) {
  const lut::GaussLegendre gl(mu_nodes);
  if (k < 0 || k >= mu_nodes) throw std::invalid_argument("weave maps: no view band " + std::to_string(k));
  return 0.5 * (gl.x[size_t(k)] + 1.0);
}

WeaveBakeResult BakeWeaveMaps(const render::IrawanBsdf& source,
                              const render::MaterialPreset& preset, const WeaveBakeOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  if (preset.model != render::ModelKind::kWoven)
    throw std::invalid_argument("BakeWeaveMaps: the preset is not a woven preset");
  if (source.repeat_u() != source.repeat_v())
    throw std::invalid_argument("BakeWeaveMaps: the fabric's repeat_u and repeat_v differ");
  if (o.size < 1 || (o.size & (o.size - 1)) != 0 || o.mu_nodes < 1 || o.phi_v < 1 || o.phi_l < 1 ||
      o.view_band < -1 || o.view_band >= o.mu_nodes)
    throw std::invalid_argument("BakeWeaveMaps: bad options (size a power of two, counts >= 1, "
                                "view_band -1 or a view node)");
  if (o.view_bands && (o.indicator || o.relief || o.glint || o.view_band >= 0))
    throw std::invalid_argument("BakeWeaveMaps: view bands only with the plain fitted maps");
  // The reference without its fineness glints (a global, non-periodic hash; E[I] = 1).
  render::WeavePattern pattern = source.pattern();
  pattern.fineness = 0.0;
  const double R = source.repeat_u();
  const render::IrawanBsdf bsdf(pattern, R, R);
  const std::vector<Pair> pairs = BuildPairs(preset, o);
  const int S = o.size;
  const size_t texels = size_t(S) * size_t(S);
  std::vector<std::array<double, kN>> xs(texels);
  const woven::Params<double> wp = woven::FromFlat(preset.values.data());
  // Relief normals (tangent space: x = warp t, y = weft b, z = n): the yarn surface normal of
  // the reference's geometry at each of 4 x 4 sub-positions, n_yarn = (sin v, sin u cos v,
  // cos u cos v) in the yarn frame (irawan.h: u along, v across), to the shading frame by
  // FromYarnFrame, averaged (a box prefilter; the preview normalises after sampling).
  // Texel (i, j) as 4 x 4 sub-positions of the pattern: fn(point, its yarn, weight 1/16).
  const auto for_each_sub = [&](int i, int j, const auto& fn) {
    constexpr int kSub = 4;
    for (int q = 0; q < kSub; ++q)
      for (int p = 0; p < kSub; ++p) {
        const render::IrawanPoint ip = bsdf.Locate(
            {(i + (p + 0.5) / kSub) / (S * R), (j + (q + 0.5) / kSub) / (S * R)});
        fn(ip, pattern.yarns[size_t(ip.yarn)], 1.0 / (kSub * kSub));
      }
  };
  std::vector<float> normals;
  if (o.relief) {
    normals.resize(texels * 3);
    for (int j = 0; j < S; ++j)
      for (int i = 0; i < S; ++i) {
        render::Vec3d acc(0, 0, 0);
        for_each_sub(i, j, [&](const render::IrawanPoint& ip, const render::Yarn& y, double w) {
          const render::Vec3d ny(std::sin(ip.v), std::sin(ip.u) * std::cos(ip.v),
                                 std::cos(ip.u) * std::cos(ip.v));
          acc = acc + render::FromYarnFrame(ny, y.type) * w;
        });
        const size_t t = size_t(j) * size_t(S) + size_t(i);
        for (int c = 0; c < 3; ++c) normals[t * 3 + size_t(c)] = float(c == 0 ? acc.x : c == 1 ? acc.y : acc.z);
      }
  }
  std::vector<std::vector<Rgb<double>>> targets(texels);
  // The view bands (o.view_bands): band k is what a bake with view_band = k would fit, solved
  // here from the main bake's targets (band k's pairs are the main pairs [k M, (k + 1) M), the
  // view cosine being BuildPairs' outer loop), so the reference BSDF is evaluated once.
  std::vector<std::vector<Pair>> band_pairs;
  if (o.view_bands)
    for (int k = 0; k < o.mu_nodes; ++k) {
      WeaveBakeOptions ok = o;
      ok.view_bands = false;
      ok.view_band = k;
      band_pairs.push_back(BuildPairs(preset, ok));
      if (band_pairs.back().size() * size_t(o.mu_nodes) != pairs.size())
        throw std::logic_error("BakeWeaveMaps: view band pairs do not partition the pairs");
    }
  std::vector<std::vector<std::array<double, kN>>> band_xs(
      band_pairs.size(), std::vector<std::array<double, kN>>(texels));

  tbb::parallel_for(0, S, [&](int j) {
    for (int i = 0; i < S; ++i) {
      const size_t t = size_t(j) * size_t(S) + size_t(i);
      if (o.indicator) {
        std::array<double, kN> x{};
        for_each_sub(i, j, [&](const render::IrawanPoint&, const render::Yarn& y, double w) {
          x[y.type == render::YarnType::kWarp ? 0 : 1] += w;
          for (int c = 0; c < 3; ++c) x[size_t(2 + c)] += y.kd[c] * w;
        });
        xs[t] = x;
        targets[t].clear();
        continue;
      }
      render::ShadingPoint sp;
      sp.uv = {(i + 0.5) / (S * R), (j + 0.5) / (S * R)};
      std::vector<Pair> local;  // relief: the basis in the texel's normal-mapped frame
      if (o.relief) {
        local = pairs;
        const render::Vec3d n = Normalize(render::Vec3d(
            double(normals[t * 3]), double(normals[t * 3 + 1]), double(normals[t * 3 + 2])));
        for (Pair& q : local) Basis(wp, n, &q);
      }
      const std::vector<Pair>& pairs_t = o.relief ? local : pairs;
      std::vector<Rgb<double>>& target = targets[t];
      target.resize(pairs.size());
      for (size_t k = 0; k < pairs_t.size(); ++k)
        target[k] = bsdf.Eval(pairs_t[k].v, pairs_t[k].l, sp) * pairs_t[k].l.z;
      xs[t] = FitTexel(pairs_t.data(), target.data(), pairs_t.size(), o.ridge);
      // The view bands from the same targets: band k's pairs are the main pairs [k M, (k + 1) M)
      // with their weights renormalised over the band (BuildPairs, view_band = k).
      for (size_t k = 0; k < band_pairs.size(); ++k)
        band_xs[k][t] = FitTexel(band_pairs[k].data(), target.data() + k * band_pairs[k].size(),
                                 band_pairs[k].size(), o.ridge);
    }
  });

  const std::vector<float> normals_copy = normals;
  WeaveBakeResult res;
  res.pairs = int(pairs.size());
  std::array<double, kN> mean{};
  std::vector<float> level0 = Level0(xs, &mean);
  double eu = 0.0, em = 0.0;
  for (size_t t = 0; t < texels; ++t) {
    if (targets[t].empty()) {  // indicator maps: the targets were not evaluated
      render::ShadingPoint sp;
      sp.uv = {(double(t % size_t(S)) + 0.5) / (S * R), (double(t / size_t(S)) + 0.5) / (S * R)};
      targets[t].resize(pairs.size());
      for (size_t k = 0; k < pairs.size(); ++k)
        targets[t][k] = bsdf.Eval(pairs[k].v, pairs[k].l, sp) * pairs[k].l.z;
    }
    eu += SquaredError(pairs, targets[t], mean);  // the uniform model (flat normal)
    if (o.relief) {
      std::vector<Pair> local = pairs;
      const render::Vec3d n = Normalize(
          render::Vec3d(double(normals_copy[t * 3]), double(normals_copy[t * 3 + 1]),
                        double(normals_copy[t * 3 + 2])));
      for (Pair& q : local) Basis(wp, n, &q);
      em += SquaredError(local, targets[t], xs[t]);
    } else {
      em += SquaredError(pairs, targets[t], xs[t]);
    }
  }
  res.error_uniform = std::sqrt(eu / (3.0 * double(texels)));
  res.error_mapped = std::sqrt(em / (3.0 * double(texels)));
  res.mean_warp = mean[0];
  res.mean_weft = mean[1];
  res.mean_kd = {mean[2], mean[3], mean[4]};
  res.maps = render::WeaveMaps::FromLevel0(S, R, std::move(level0));
  if (o.relief) res.maps.SetNormals(std::move(normals));
  if (o.glint && source.pattern().fineness > 0.0) {
    const render::WeavePattern& sp = source.pattern();
    const double cells = sp.fineness * R * double(std::max(sp.tile_width, sp.tile_height));
    int G = 1;
    while (G < cells && G < 2048) G *= 2;
    std::vector<float> g(size_t(G) * size_t(G));
    tbb::parallel_for(0, G, [&](int j) {
      for (int i = 0; i < G; ++i) {
        double acc = 0.0;
        for (int q = 0; q < 2; ++q)
          for (int p = 0; p < 2; ++p)
            acc += source.Locate({(i + (p + 0.5) / 2) / G, (j + (q + 0.5) / 2) / G}).intensity;
        g[size_t(j) * size_t(G) + size_t(i)] = float(acc / 4.0);
      }
    });
    res.maps.SetGlint(G, std::move(g));
  }
  if (o.view_bands) {
    // lut::GaussLegendre lists its nodes by decreasing x, the order the bands are stored in
    // (SetViews refuses any other). Each band's level 0 is what its own bake returns
    // (FromLevel0's ratio maps), bit for bit (test S15ViewBands.OnePassEqualsSeparateBakes).
    std::vector<double> cs;
    std::vector<std::vector<float>> bs;
    for (size_t k = 0; k < band_xs.size(); ++k) {
      cs.push_back(WeaveViewBandCosine(int(k), o.mu_nodes));
      bs.push_back(render::WeaveMaps::FromLevel0(S, R, Level0(band_xs[k], nullptr)).levels.at(0));
    }
    res.maps.SetViews(std::move(cs), std::move(bs));
  }
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace clothfit::fit
