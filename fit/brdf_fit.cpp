#include "fit/brdf_fit.h"

#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "brdf/lut.h"
#include "fit/parameter_layout.h"
#include "render/reference/irawan.h"

namespace clothfit::fit {
namespace {

std::vector<DirectionPair> BuildDirections() {
  // View cosines: Gauss-Legendre on [0, 1]; weight w_GL(mu_v) 2 mu_v (brdf_fit.h).
  const lut::GaussLegendre gv(kDirNodes), gt(kHalfNodes);
  std::vector<DirectionPair> out;
  for (int a = 0; a < kDirNodes; ++a) {
    const double mv = 0.5 * (gv.x[size_t(a)] + 1.0), sv = std::sqrt(1.0 - mv * mv);
    const double view_weight = 0.5 * gv.w[size_t(a)] * 2.0 * mv;
    const Vec3<double> v(sv, 0.0, mv);
    // Light directions through the half vector: theta_h = (pi/2) t^2, t at Gauss-Legendre nodes
    // of [0, 1] (d theta_h = pi t dt: nodes crowd the mirror configuration; MERL's mapping),
    // phi_h = (k + 0.5) pi / kHalfAzimuths relative to v's azimuth; l = 2 (v.h) h - v,
    // d omega_l = 4 (v.h) d omega_h, d omega_h = sin theta_h d theta_h d phi_h. Half vectors
    // whose l falls below the horizon (or behind v) lie outside the domain and are dropped.
    const size_t first = out.size();
    double measure = 0.0;
    for (int b = 0; b < kHalfNodes; ++b) {
      const double t = 0.5 * (gt.x[size_t(b)] + 1.0), wt = 0.5 * gt.w[size_t(b)];
      const double th = 0.5 * kPi * t * t, dth = kPi * t;
      for (int k = 0; k < kHalfAzimuths; ++k) {
        const double ph = (k + 0.5) * kPi / kHalfAzimuths;
        const Vec3<double> h(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph),
                             std::cos(th));
        const double vh = Dot(v, h);
        if (!(vh > 0.0)) continue;
        const Vec3<double> l = h * (2.0 * vh) - v;
        if (!(l.z > kMinLightCosine)) continue;
        DirectionPair d;
        d.v = v;
        d.l = Normalize(l);
        d.cos = CosinesFromDirections(d.v, d.l);
        d.weight = wt * dth * std::sin(th) * (kPi / kHalfAzimuths) * 4.0 * vh;
        measure += d.weight;
        out.push_back(d);
      }
    }
    // Per view, the light weights are rescaled to sum to pi (the solid angle of the half
    // hemisphere phi in [0, pi]) exactly: the horizon cuts the (theta_h, phi_h) grid, and the
    // truncated product rule's own total is off by a few percent at grazing views.
    for (size_t i = first; i < out.size(); ++i) out[i].weight *= view_weight * kPi / measure;
  }
  double total = 0.0;
  for (const DirectionPair& d : out) total += d.weight;
  for (DirectionPair& d : out) d.weight /= total;
  return out;
}

// The square-root compression of brdf_fit.h (Hellinger): sqrt(max(x, 0) + eps).
template <typename T>
T Compress(const T& x) {
  using std::sqrt;
  return sqrt(Max(x, Const<T>(0.0)) + Const<T>(kCompressEps));
}
// Its inverse on the compressed targets: y = t^2 - eps.
double Expand(double t) { return std::max(t * t - kCompressEps, 0.0); }

// The valid samples, compressed, with sqrt weights renormalised over them.
struct Target {
  std::vector<Cosines<double>> cos;
  std::vector<Rgb<double>> t;
  std::vector<double> sw;
};

Target MakeTarget(const BrdfSamples& s) {
  const auto& dirs = CanonicalDirections();
  if (s.value.size() != dirs.size() || s.valid.size() != dirs.size())
    throw std::invalid_argument("BRDF samples do not match the canonical direction set");
  Target t;
  double total = 0.0;
  for (size_t k = 0; k < dirs.size(); ++k)
    if (s.valid[k]) total += dirs[k].weight;
  for (size_t k = 0; k < dirs.size(); ++k) {
    if (!s.valid[k]) continue;
    t.cos.push_back(dirs[k].cos);
    Rgb<double> c;
    for (int ch = 0; ch < 3; ++ch) c[ch] = Compress(s.value[k][ch]);
    t.t.push_back(c);
    t.sw.push_back(std::sqrt(dirs[k].weight / total));
  }
  if (t.cos.size() < 16)
    throw std::invalid_argument("source BRDF has only " + std::to_string(t.cos.size()) +
                                " valid samples on the canonical directions (need 16)");
  return t;
}

struct BrdfResidual {
  const Target* target;
  render::ModelKind model;
  cloth::Options co;

  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    const T* x = p[0];
    for (size_t k = 0; k < target->cos.size(); ++k) {
      const Cosines<double>& c = target->cos[k];
      const Cosines<T> cs{Const<T>(c.NoV), Const<T>(c.NoL), Const<T>(c.NoH), Const<T>(c.LoH)};
      const Rgb<T> f = EvalDirectFlat(model, co, x, cs);
      for (int ch = 0; ch < 3; ++ch)
        r[3 * k + size_t(ch)] = Const<T>(target->sw[k]) * (Compress(f[ch]) - target->t[k][ch]);
    }
    return true;
  }
};

double ErrorOf(const Target& t, render::ModelKind m, const cloth::Options& co, const double* x) {
  double se = 0.0;
  for (size_t k = 0; k < t.cos.size(); ++k) {
    const Rgb<double> f = EvalDirectFlat(m, co, x, t.cos[k]);
    for (int ch = 0; ch < 3; ++ch) se += std::pow(t.sw[k] * (Compress(f[ch]) - t.t[k][ch]), 2);
  }
  return std::sqrt(se / 3.0);  // weights sum to 1 over the valid samples
}

// Cloth (explicit sheen, no subsurface) is linear in its colours for a fixed roughness:
// f n.l = base * a + sheen * b with a = n.l / pi and b = D V n.l. Per channel, the 2 x 2
// weighted least squares in linear space, weighted by the compression's slope
// (d sqrt(y + eps) = dy / (2 sqrt(y + eps))), gives the colours that are best to first order
// in the fit space; a bound hit is clamped and the other colour re-solved.
void ClosedFormClothColours(const Target& t, const cloth::Options& co, std::vector<double>& x) {
  double unit_base[10] = {1, 1, 1, 0, 0, 0, x[6], 0, 0, 0};
  double unit_sheen[10] = {0, 0, 0, 1, 1, 1, x[6], 0, 0, 0};
  double aa[3] = {0, 0, 0}, ab[3] = {0, 0, 0}, bb[3] = {0, 0, 0}, ay[3] = {0, 0, 0},
         by[3] = {0, 0, 0};
  for (size_t k = 0; k < t.cos.size(); ++k) {
    const Rgb<double> a = EvalDirectFlat(render::ModelKind::kCloth, co, unit_base, t.cos[k]);
    const Rgb<double> b = EvalDirectFlat(render::ModelKind::kCloth, co, unit_sheen, t.cos[k]);
    for (int ch = 0; ch < 3; ++ch) {
      const double y = Expand(t.t[k][ch]);
      const double slope = 1.0 / (2.0 * std::sqrt(y + kCompressEps));
      const double w = Sq(t.sw[k] * slope);
      aa[ch] += w * a[ch] * a[ch];
      ab[ch] += w * a[ch] * b[ch];
      bb[ch] += w * b[ch] * b[ch];
      ay[ch] += w * a[ch] * y;
      by[ch] += w * b[ch] * y;
    }
  }
  for (int ch = 0; ch < 3; ++ch) {
    const double det = aa[ch] * bb[ch] - ab[ch] * ab[ch];
    if (!(std::abs(det) > 1e-300)) continue;
    double c = (ay[ch] * bb[ch] - by[ch] * ab[ch]) / det;
    double s = (aa[ch] * by[ch] - ab[ch] * ay[ch]) / det;
    if (c < 0.0 || c > 1.0) {
      c = std::clamp(c, 0.0, 1.0);
      s = (by[ch] - ab[ch] * c) / std::max(bb[ch], 1e-300);
    }
    if (s < 0.0 || s > 1.0) {
      s = std::clamp(s, 0.0, 1.0);
      c = std::clamp((ay[ch] - ab[ch] * s) / std::max(aa[ch], 1e-300), 0.0, 1.0);
    }
    x[size_t(ch)] = c;
    x[size_t(3 + ch)] = s;
  }
}

// Mean albedo-like colour of the source: pi f over the weighted set (f = value / n.l).
Rgb<double> SourceAlbedo(const Target& target) {
  Rgb<double> albedo(0, 0, 0);
  for (size_t k = 0; k < target.cos.size(); ++k) {
    const double w = target.sw[k] * target.sw[k];
    for (int ch = 0; ch < 3; ++ch) {
      albedo[ch] += w * kPi * Expand(target.t[k][ch]) / std::max(target.cos[k].NoL, 1e-3);
    }
  }
  for (int ch = 0; ch < 3; ++ch) albedo[ch] = std::clamp(albedo[ch], 0.02, 0.95);
  return albedo;
}

// Which flat entries the solver may move, and their bounds.
struct FlatBounds {
  std::vector<int> constant;  // flat indices held fixed (locked or ignored blocks)
  std::vector<double> lo, hi;

  void ClampToBounds(std::vector<double>& x) const {
    for (size_t i = 0; i < x.size(); ++i) x[i] = std::clamp(x[i], lo[i], hi[i]);
  }
};

FlatBounds MakeBounds(const ParameterLayout& layout, const BrdfFitOptions& opt) {
  const render::ModelKind model = opt.model;
  FlatBounds fb;
  fb.lo.resize(size_t(layout.flat_size));
  fb.hi.resize(size_t(layout.flat_size));
  for (const Block& b : layout.blocks) {
    const bool ignored =
        model == render::ModelKind::kCloth &&
        ((b.name == "sheen_color" && opt.cloth.sheen_default != cloth::SheenDefault::kExplicit) ||
         (b.name == "subsurface_color" && !opt.cloth.subsurface));
    double lower = b.lower;
    if (model == render::ModelKind::kCloth && b.name == "roughness")
      lower = cloth::MinRoughness(opt.cloth);
    // gltf-sheen's roughness reaches 0 (alpha floored at 1e-8): held at kMinFitRoughness or
    // above (brdf_fit.h), except down to the source's own value when it is of this model.
    if (model == render::ModelKind::kGltfSheen && b.name == "roughness") {
      lower = std::max(lower, kMinFitRoughness);
      if (opt.source_preset && opt.source_preset->model == model)
        lower = std::min(lower, opt.source_preset->values[size_t(b.offset)]);
    }
    for (int c = 0; c < b.size; ++c) {
      fb.lo[size_t(b.offset + c)] = lower;
      fb.hi[size_t(b.offset + c)] = b.upper;
      if (b.locked || ignored) fb.constant.push_back(b.offset + c);
    }
  }
  return fb;
}

// Candidate starts: the source itself (same model), then one per roughness start with
// colours from the source's albedo (cloth: closed-form colours, ClosedFormClothColours).
// Screening: only the candidate with the lowest error is solved (each solve costs ~15
// iterations); the source's own parameters, when given, are solved first and end the search
// if they already reproduce the samples.
std::vector<std::vector<double>> CandidateStarts(const Target& target,
                                                 const ParameterLayout& layout,
                                                 const FlatBounds& fb,
                                                 const render::MaterialPreset& base,
                                                 const BrdfFitOptions& opt) {
  const render::ModelKind model = opt.model;
  const Rgb<double> albedo = SourceAlbedo(target);
  std::vector<std::vector<double>> starts;
  for (double r0 : opt.start_roughness) {
    std::vector<double> x = base.values;
    for (const Block& b : layout.blocks) {
      if (b.locked) continue;
      double* p = &x[size_t(b.offset)];
      if (b.name == "roughness" || b.name == "sheen_roughness") p[0] = r0;
      if (b.name == "base_color")
        for (int c = 0; c < 3; ++c) p[c] = albedo[c];
      if (b.name == "sheen_color")
        for (int c = 0; c < 3; ++c) p[c] = 0.5;
      if (b.name == "subsurface_color")
        for (int c = 0; c < 3; ++c) p[c] = 0.1;
    }
    fb.ClampToBounds(x);
    const bool linear_colours = model == render::ModelKind::kCloth && !opt.cloth.subsurface &&
                                opt.cloth.sheen_default == cloth::SheenDefault::kExplicit &&
                                !layout.Find("base_color").locked &&
                                !layout.Find("sheen_color").locked;
    if (linear_colours) ClosedFormClothColours(target, opt.cloth, x);
    starts.push_back(x);
  }
  std::stable_sort(starts.begin(), starts.end(), [&](const auto& a, const auto& b) {
    return ErrorOf(target, model, opt.cloth, a.data()) <
           ErrorOf(target, model, opt.cloth, b.data());
  });
  starts.resize(std::min<size_t>(starts.size(), size_t(std::max(opt.solved_starts, 1))));
  if (opt.source_preset && opt.source_preset->model == model)
    starts.insert(starts.begin(), opt.source_preset->values);
  return starts;
}

// Solves from x in place (x holds the start on entry, the solution on return).
ceres::Solver::Summary SolveFrom(const Target& target, const ParameterLayout& layout,
                                 const FlatBounds& fb, const BrdfFitOptions& opt,
                                 std::vector<double>& x) {
  auto* cost = new ceres::DynamicAutoDiffCostFunction<BrdfResidual, 10>(
      new BrdfResidual{&target, opt.model, opt.cloth});
  cost->AddParameterBlock(layout.flat_size);
  cost->SetNumResiduals(int(3 * target.cos.size()));
  ceres::Problem problem;
  problem.AddResidualBlock(cost, nullptr, x.data());
  const std::vector<int>& constant = fb.constant;
  if (int(constant.size()) == layout.flat_size) {
    problem.SetParameterBlockConstant(x.data());
  } else {
    if (!constant.empty())
      problem.SetManifold(x.data(), new ceres::SubsetManifold(layout.flat_size, constant));
    for (int i = 0; i < layout.flat_size; ++i) {
      if (std::find(constant.begin(), constant.end(), i) != constant.end()) continue;
      problem.SetParameterLowerBound(x.data(), i, fb.lo[size_t(i)]);
      problem.SetParameterUpperBound(x.data(), i, fb.hi[size_t(i)]);
    }
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = 1e-8;
  so.parameter_tolerance = 1e-8;
  so.num_threads = 1;  // materials run in parallel, one fit per thread
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  return summary;
}

}  // namespace

const std::vector<DirectionPair>& CanonicalDirections() {
  static const std::vector<DirectionPair> dirs = BuildDirections();
  return dirs;
}

BrdfSamples SampleAnalytic(const render::MaterialPreset& preset) {
  const auto& dirs = CanonicalDirections();
  BrdfSamples s;
  if (preset.model == render::ModelKind::kWoven && preset.yarn_lobe) {
    // "woven": {"yarn_lobe"}: the far-field lobe in place of the GGX yarn lobes, as the preview's
    // light term (render/preview/preview.cpp WovenKernel far_field: additive layer, the yarn
    // term scaled by the sheen's min(S(NoV), S(NoL))), at the pair's own directions (x = t).
    const yarn_lobe::Lobe lobe(*preset.yarn_lobe);
    const woven::Params<double> p = woven::FromFlat(preset.values.data());
    woven::Params<double> rest = p;
    rest.specular_color = Rgb<double>(0.0, 0.0, 0.0);
    const woven::Lobes<double> lb = woven::PrepareLobes(p);
    const Table2D& dfg = lut::DefaultDfg();
    for (const DirectionPair& d : dirs) {
      Rgb<double> v = woven::EvalDirect(rest, preset.woven, d.cos, woven::TangentCosinesInPlane(d.cos),
                                        woven::WeaveSample<double>{}, dfg, lut::DefaultWovenPhase());
      double t[2];
      lobe.Eval(d.v, d.l, t);
      const double NoV = std::clamp(d.cos.NoV, kMinNoV, 1.0), NoL = std::clamp(d.cos.NoL, 0.0, 1.0);
      const double sh = std::min(woven::SheenScaling(p, lb, dfg, NoV), woven::SheenScaling(p, lb, dfg, NoL));
      const double m = lb.m;
      for (int c = 0; c < 3; ++c)
        v[c] += p.specular_color[c] *
                (preset.woven.tint_warp[c] * 2.0 * m * t[0] + preset.woven.tint_weft[c] * 2.0 * (1.0 - m) * t[1]) *
                sh * NoL;
      s.value.push_back(v);
      s.valid.push_back(1);
    }
    return s;
  }
  for (const DirectionPair& d : dirs) {
    s.value.push_back(EvalDirectFlat(preset.model, preset.cloth, preset.values.data(), d.cos));
    s.valid.push_back(1);
  }
  return s;
}

BrdfSamples SampleBsdf(const render::Bsdf& bsdf, double period_uv, int samples) {
  if (samples < 1 || !(period_uv > 0.0))
    throw std::invalid_argument("SampleBsdf: samples must be >= 1 and period_uv > 0");
  const auto& dirs = CanonicalDirections();
  // Draw i: the position inside the weave period and the azimuth from the R3 low-discrepancy
  // sequence (Roberts 2018: alpha_k = g^-k, g the real root of x^4 = x + 1), the period itself
  // one of kSourcePeriods x kSourcePeriods in turn (i mod kSourcePeriods^2). R3 within the
  // period keeps the weave's structure evenly covered; many periods let position-hashed detail
  // (Irawan's fineness glints, a draw per cell of the absolute position) enter by its mean; a
  // continuous azimuth averages a sharp anisotropic lobe (Sadeghi's satin) instead of hitting
  // it at a few angles.
  constexpr double kG = 1.22074408460575947536;
  const double a1 = 1.0 / kG, a2 = a1 / kG, a3 = a2 / kG;
  const int tiles = int(kSourcePeriods);
  std::vector<Rgb<double>> sum(dirs.size(), Rgb<double>(0, 0, 0));
  // Draws outside, directions inside: the Irawan BSDF locates a surface point once per point
  // (its per-thread memo of the last uv), not once per evaluation.
  for (int i = 0; i < samples; ++i) {
    const double x = 0.5 + a1 * i, y = 0.5 + a2 * i, z = 0.5 + a3 * i;
    const int t = i % (tiles * tiles);
    render::ShadingPoint sp;
    sp.uv = {(t % tiles + x - std::floor(x)) * period_uv,
             (t / tiles + y - std::floor(y)) * period_uv};
    const double phi = 2.0 * kPi * (z - std::floor(z)), c = std::cos(phi), sn = std::sin(phi);
    for (size_t k = 0; k < dirs.size(); ++k) {
      const DirectionPair& d = dirs[k];
      const render::Vec3d wo(c * d.v.x - sn * d.v.y, sn * d.v.x + c * d.v.y, d.v.z);
      const render::Vec3d wi(c * d.l.x - sn * d.l.y, sn * d.l.x + c * d.l.y, d.l.z);
      // The pair and its mirror image (y -> -y in the shading frame): the direction set holds
      // one side of the plane of incidence only (brdf_fit.h), which is exact for a
      // mirror-symmetric source; a chiral weave (twill) contributes its symmetric part, the
      // part an isotropic target model can fit. Over phi in [0, 2 pi) the two make the
      // average over all rotations and reflections.
      sum[k] += bsdf.Eval(wo, wi, sp) * wi.z;
      sum[k] += bsdf.Eval({wo.x, -wo.y, wo.z}, {wi.x, -wi.y, wi.z}, sp) * wi.z;
    }
  }
  BrdfSamples s;
  const double n = 2.0 * double(samples);
  for (const Rgb<double>& v : sum) {
    const Rgb<double> mean = v * (1.0 / n);
    s.value.push_back(mean);
    s.valid.push_back(std::isfinite(mean[0]) && std::isfinite(mean[1]) && std::isfinite(mean[2]));
  }
  return s;
}

int SourceSampleCount(const render::Fabric& fabric) {
  // Irawan's BSDF depends on the surface point; the others (Sadeghi, lambert, ggx_conductor)
  // do not, and need azimuths only.
  return fabric.model == "irawan" ? kSourceSamples : kSourceSamplesUniform;
}

BrdfSamples SampleFabric(const render::Fabric& fabric) {
  const auto* irawan = dynamic_cast<const render::IrawanBsdf*>(fabric.bsdf.get());
  if (!irawan || !(irawan->pattern().fineness > 0.0))
    return SampleBsdf(*fabric.bsdf, fabric.weave_period_uv, SourceSampleCount(fabric));
  // The fineness glints multiply the specular by I = min(-log xi, 10), xi a uniform hash per
  // cell of the absolute position, independent of where in the weave the cell lies; so the
  // average over many periods is the glint-free BSDF with the specular scaled by
  // E[I] = 1 - e^-10 (render/reference/irawan.cpp Locate). Drawn from it directly, the
  // average has no glint variance (denim, the most glints: a few percent at 4096 draws).
  render::WeavePattern pattern = irawan->pattern();
  pattern.fineness = 0.0;
  for (render::Yarn& y : pattern.yarns) y.ks = y.ks * (1.0 - std::exp(-10.0));
  const render::IrawanBsdf mean(pattern, irawan->repeat_u(), irawan->repeat_v());
  return SampleBsdf(mean, fabric.weave_period_uv, SourceSampleCount(fabric));
}

double BrdfError(const BrdfSamples& source, const render::MaterialPreset& preset) {
  return ErrorOf(MakeTarget(source), preset.model, preset.cloth, preset.values.data());
}

BrdfFitResult FitBrdf(const BrdfSamples& source, const BrdfFitOptions& opt) {
  const Target target = MakeTarget(source);
  const render::ModelKind model = opt.model;
  const auto table = render::ParameterTable(model);
  const ParameterLayout layout = MakeLayout(table, opt.locked);

  render::MaterialPreset base = render::DefaultPreset(model);
  if (model == render::ModelKind::kCloth) base.cloth = opt.cloth;

  const FlatBounds fb = MakeBounds(layout, opt);
  const std::vector<std::vector<double>> starts = CandidateStarts(target, layout, fb, base, opt);

  BrdfFitResult best;
  best.message = "no start converged to a usable solution";
  double best_error = std::numeric_limits<double>::infinity();
  for (std::vector<double> x : starts) {
    if (best.usable && best.error < 1e-6) break;  // exact already (the source start)
    fb.ClampToBounds(x);
    const ceres::Solver::Summary summary = SolveFrom(target, layout, fb, opt, x);
    ++best.starts;
    best.iterations += int(summary.iterations.size());
    bool finite = true;
    for (double v : x) finite = finite && std::isfinite(v);
    if (!summary.IsSolutionUsable() || !finite) continue;
    const double e = ErrorOf(target, model, opt.cloth, x.data());
    if (e < best_error) {
      best_error = e;
      best.usable = true;
      best.message.clear();
      best.preset = base;
      best.preset.values = x;
      best.error = e;
    }
  }
  return best;
}

}  // namespace clothfit::fit
