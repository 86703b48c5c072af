// brdf/yarn_lobe.cpp: see yarn_lobe.h.
#include "brdf/yarn_lobe.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>

#include <tbb/parallel_for.h>

namespace clothfit::yarn_lobe {

namespace {
constexpr double kDegToRad = kPi / 180.0;
}

double SmoothStep01(double x) {
  const double c = std::clamp(x, 0.0, 1.0);
  return c * c * (3.0 - 2.0 * c);
}

double Seeliger(double cos1, double cos2) {
  const double c1 = std::max(0.0, cos1), c2 = std::max(0.0, cos2);
  if (c1 <= 0.0 || c2 <= 0.0) return 0.0;
  return (1.0 / (4.0 * kPi)) * c1 * c2 / (c1 + c2);
}

double BesselI0(double x) {
  // sum_k (x^2/4)^k / (k!)^2; terms decrease once k > |x|/2, converged to 1e-17 relative.
  const double q = 0.25 * x * x;
  double term = 1.0, sum = 1.0;
  for (int k = 1; k < 500; ++k) {
    term *= q / (double(k) * double(k));
    sum += term;
    if (term < 1e-17 * sum) break;
  }
  return sum;
}

// Yarn spine in the (along, height) plane: a conic arc whose slope angle runs over
// [-umax, umax] and whose half-extent is hx = l/2 - a sin(umax) (the surface, offset by
// a = w/2 from the spine, then spans l). With rhat = 1 + kappa (1 + 1/tan umax):
//   circle    (rhat = 1): R = hx / sin(umax).
//   ellipse   (rhat > 0): x = B sin t, z = C cos t, tan u = (C/B) tan t, C = B / rhat;
//             t_max = atan(rhat tan umax), B = hx / sin(t_max);
//             R = (B^2 cos^2 t + C^2 sin^2 t)^(3/2) / (B C), t = atan(rhat tan u).
//   parabola  (rhat = 0): z = -x^2 tan(umax) / (2 hx); R = hx / tan(umax) (1 + tan^2 u)^(3/2).
//   hyperbola (rhat < 0): x = B sinh s, z = -C cosh s, tan u = (C/B) tanh s, C = B / |rhat|;
//             s = atanh(|rhat| tan u), B = hx / sinh(s_max);
//             R = (B^2 cosh^2 s + C^2 sinh^2 s)^(3/2) / (B C).
// kappa >= -1 gives |rhat| tan(umax) <= 1; at kappa = -1 exactly the hyperbola degenerates
// (s_max infinite), so |rhat| tan is clamped to 1 - 1e-9 (documented guard).
double SpineRadius(double u_abs, double umax, double kappa, double width, double length) {
  const double a = 0.5 * width;
  const double hx = 0.5 * length - a * std::sin(umax);
  const double rhat = kappa == 0.0 ? 1.0 : 1.0 + kappa * (1.0 + 1.0 / std::tan(umax));
  const double u = std::min(u_abs, umax);
  if (std::abs(rhat - 1.0) < 1e-12) return hx / std::sin(umax);
  if (rhat > 1e-9) {
    const double tmax = std::atan(rhat * std::tan(umax));
    const double b = hx / std::sin(tmax);
    const double c = b / rhat;
    const double t = std::atan(rhat * std::tan(u));
    const double ct = std::cos(t), st = std::sin(t);
    return std::pow(b * b * ct * ct + c * c * st * st, 1.5) / (b * c);
  }
  if (rhat > -1e-9) {
    const double tu = std::tan(u);
    return hx / std::tan(umax) * std::pow(1.0 + tu * tu, 1.5);
  }
  const double rho = -rhat;
  const double smax = std::atanh(std::min(rho * std::tan(umax), 1.0 - 1e-9));
  const double b = hx / std::sinh(smax);
  const double c = b / rho;
  const double s = std::atanh(std::min(rho * std::tan(u), 1.0 - 1e-9));
  const double ch = std::cosh(s), sh = std::sinh(s);
  return std::pow(b * b * ch * ch + c * c * sh * sh, 1.5) / (b * c);
}

double FilamentRadius(double u_h_abs, double umax, double ss, double kappa, double width,
                      double length) {
  if (ss <= 0.0) return SpineRadius(u_h_abs, umax, kappa, width, length);
  const double umax_s = (1.0 - ss) * umax;
  return SpineRadius(std::min(u_h_abs, umax_s), umax_s, kappa, width, length);
}

namespace {
using Vec3d = Vec3<double>;

// The band indicator's mean over the band coordinate uniform in [-extent, extent]: the overlap
// of [centre - delta/2, centre + delta/2] with it, over its length.
double BandMean(double centre, double delta, double extent) {
  const double lo = std::max(centre - 0.5 * delta, -extent);
  const double hi = std::min(centre + 0.5 * delta, extent);
  return std::max(hi - lo, 0.0) / (2.0 * extent);
}

// What SegmentSpecular computes before it looks at the point: the yarn frame, the half vector
// and the phase; for a filament yarn (psi = 0) also u_h, the highlight band and the spine
// radius, which depend on h only. Lobe::GroupSum computes it once per (wo, wi) for all nodes.
struct PairTerms {
  bool lit = false;  // false: every point of the yarn gives 0
  Vec3d wi{0, 0, 0}, wo{0, 0, 0}, h{0, 0, 0};
  double len = 0.0, fc = 0.0;
  double u_h = 0.0, delta = 0.0, y_h = 0.0, cos_uh = 1.0, sin_uh = 0.0, R = 0.0, txh_x = 0.0;
  double fade = 1.0;  // filament smoothing (ss > 0)
};

PairTerms PreparePair(const Phase& ph, const Yarn& y, double umax, const Vec3d& wo_s,
                      const Vec3d& wi_s) {
  PairTerms q;
  q.wi = ToYarnFrame(wi_s, y.warp);
  q.wo = ToYarnFrame(wo_s, y.warp);
  const Vec3d sum = q.wi + q.wo;
  q.len = Length(sum);
  if (!(q.len > 1e-12)) return q;
  q.h = sum * (1.0 / q.len);
  // Phase function: uniform + von Mises about the forward direction.
  q.fc = ph.alpha + std::exp(ph.beta * -Dot(q.wi, q.wo)) * ph.von_mises_norm;
  if (y.psi == 0.0) {
    // u_h = atan(h_y / h_z) with h_z > 0 (wi, wo above the surface): cos u_h = 1/sqrt(1 + t^2),
    // sin u_h = t cos u_h, t = h_y / h_z.
    const double t = q.h.y / q.h.z;
    q.u_h = std::atan(t);
    if (!(std::abs(q.u_h) < umax)) return q;
    const double l = y.length;
    q.delta = l * ph.h_width;
    // Band centre clamped so the band stays inside the segment.
    q.y_h = std::clamp(q.u_h / umax * 0.5 * l, -0.5 * (l - q.delta), 0.5 * (l - q.delta));
    q.cos_uh = 1.0 / std::sqrt(1.0 + t * t);
    q.sin_uh = t * q.cos_uh;
    const Vec3d tangent(0.0, q.cos_uh, -q.sin_uh);
    q.R = FilamentRadius(std::abs(q.u_h), umax, ph.ss, y.kappa, y.width, l);
    q.txh_x = tangent.y * q.h.z - tangent.z * q.h.y;
    if (ph.ss > 0.0) q.fade = 1.0 - SmoothStep01((std::abs(q.u_h) - (1.0 - ph.ss) * umax) / (ph.ss * umax));
  }
  q.lit = true;
  return q;
}

// A filament yarn's specular at the point with sin v = sv, cos v = cv; `band` = the highlight
// band's indicator (1) or its mean over the band coordinate. q.lit must hold.
double FilamentPoint(const Phase& ph, const Yarn& y, const PairTerms& q, double sv, double cv,
                     double band) {
  const double a = 0.5 * y.width;
  const Vec3d n(sv, q.sin_uh * cv, q.cos_uh * cv);
  const double G = a * (q.R + a * cv) / (q.len * std::abs(q.txh_x));
  double A = Seeliger(Dot(n, q.wi), Dot(n, q.wo));
  if (ph.ss > 0.0) A *= q.fade;
  const double fs = G * q.fc * A * kPi * y.length / q.delta * band;
  return fs * y.area_factor;
}

// A staple yarn's specular at p (band_extent as SegmentSpecular's). q.lit must hold.
double StaplePoint(const Phase& ph, const Yarn& y, const PairTerms& q, const Point& p,
                   double band_extent) {
  const Vec3d& h = q.h;
  const double w = y.width, a = 0.5 * w;
  const double su = p.sin_u, cu = p.cos_u;
  const double bterm = h.y * su + h.z * cu;
  const double r = std::sqrt(h.x * h.x + bterm * bterm);
  const double D = (h.y * cu - h.z * su) / (r * y.tan_psi);
  if (!(std::abs(D) < 1.0)) return 0.0;  // also rejects r = 0 (D infinite or NaN)
  // v_h = atan2(-bterm, h_x) + acos(D), wrapped to (-pi, pi]: its sine and cosine by the
  // angle-sum formulas (cos of the atan2 = h_x / r, sin = -bterm / r; sin acos D =
  // sqrt(1 - D^2)), the angle itself by one atan2.
  const double ca = h.x / r, sa = -bterm / r, sb = std::sqrt(1.0 - D * D);
  const double cos_vh = ca * D - sa * sb, sin_vh = sa * D + ca * sb;
  const double v_h = std::atan2(sin_vh, cos_vh);
  if (!(std::abs(v_h) < 0.5 * kPi)) return 0.0;
  const double delta = w * ph.h_width;
  const double x_h = std::clamp(v_h * w / kPi, -0.5 * (w - delta), 0.5 * (w - delta));
  const bool band_average = band_extent > 0.0;
  if (!band_average && !(std::abs(p.across - x_h) < 0.5 * delta)) return 0.0;
  const Vec3d n(sin_vh, su * cos_vh, cu * cos_vh);
  const double NoH = Dot(n, h);
  if (!(NoH > 0.0)) return 0.0;
  const double G = a * (p.spine_radius + a * cos_vh) / (q.len * NoH * std::abs(y.sin_psi));
  const double A = Seeliger(Dot(n, q.wi), Dot(n, q.wo));
  const double fs =
      G * q.fc * A * 2.0 * w * p.umax / delta * (band_average ? BandMean(x_h, delta, band_extent) : 1.0);
  return fs * y.area_factor;
}
}  // namespace

double SegmentSpecular(const Phase& ph, const Yarn& y, const Point& p, const Vec3<double>& wo_s,
                       const Vec3<double>& wi_s, double band_extent) {
  if (!(wo_s.z > 0.0) || !(wi_s.z > 0.0)) return 0.0;
  const PairTerms q = PreparePair(ph, y, p.umax, wo_s, wi_s);
  if (!q.lit) return 0.0;
  if (y.psi != 0.0) return StaplePoint(ph, y, q, p, band_extent);
  const bool band_average = band_extent > 0.0;
  if (!band_average && !(std::abs(p.along - q.y_h) < 0.5 * q.delta)) return 0.0;
  // band_average: the band indicator's mean over `along` in place of the indicator
  return FilamentPoint(ph, y, q, std::sin(p.v), std::cos(p.v),
                       band_average ? BandMean(q.y_h, q.delta, band_extent) : 1.0);
}

Yarn MakeYarn(bool warp, double psi_deg, double width, double length, double kappa,
              double area_factor) {
  Yarn y;
  y.warp = warp;
  y.psi = psi_deg * kDegToRad;
  y.sin_psi = std::sin(y.psi);
  y.tan_psi = std::tan(y.psi);
  y.width = width;
  y.length = length;
  y.kappa = kappa;
  y.area_factor = area_factor;
  return y;
}

void Validate(const FarField& f, const std::string& where, bool need_ibl) {
  auto bad = [&](const std::string& field, const std::string& what) {
    throw std::invalid_argument(where + "." + field + ": " + what);
  };
  auto finite = [](double x) { return std::isfinite(x); };
  if (f.kind == FarField::Kind::kMicrocylinder) {
    double a_sum = 0.0;
    for (int j = 0; j < 2; ++j) {
      const microcylinder::Thread& th = f.threads[j];
      const std::string tj = "threads[" + std::to_string(j) + "].";
      if (!finite(th.eta) || !(th.eta > 1.0 && th.eta < 3.0)) bad(tj + "eta", "expected a number in (1, 3)");
      if (!finite(th.kd) || th.kd < 0.0 || th.kd > 1.0) bad(tj + "kd", "expected a number in [0, 1]");
      if (!finite(th.gamma_s) || !(th.gamma_s > 0.0) || th.gamma_s > 90.0)
        bad(tj + "gamma_s", "expected degrees in (0, 90]");
      if (!finite(th.gamma_v) || !(th.gamma_v > 0.0) || th.gamma_v > 90.0)
        bad(tj + "gamma_v", "expected degrees in (0, 90]");
      if (!finite(th.a) || th.a < 0.0 || th.a > 1.0) bad(tj + "a", "expected a number in [0, 1]");
      if (!finite(th.volume_scale) || th.volume_scale < 0.0 || th.volume_scale > 1.0)
        bad(tj + "volume_scale", "expected a number in [0, 1] (this thread's albedo over the lobe's)");
      if (th.offsets.empty() || th.offsets.size() > size_t(microcylinder::kMaxOffsets))
        bad(tj + "offsets", "expected 1 to 64 tangent offsets");
      for (size_t k = 0; k < th.offsets.size(); ++k)
        if (!finite(th.offsets[k]) || th.offsets[k] < -90.0 || th.offsets[k] > 90.0)
          bad(tj + "offsets[" + std::to_string(k) + "]", "expected degrees in [-90, 90]");
      a_sum += th.a;
    }
    if (!(a_sum <= 1.0 + 1e-9)) bad("threads", "a_1 + a_2 must be <= 1");
  } else {
    if (f.nodes < 1 || f.nodes > FarField::kMaxNodes) bad("nodes", "expected an integer in [1, 64]");
    if (!finite(f.alpha) || f.alpha < 0.0) bad("alpha", "expected a finite number >= 0");
    if (!finite(f.beta) || f.beta < 0.0) bad("beta", "expected a finite number >= 0");
    if (!finite(f.h_width) || !(f.h_width > 0.0) || f.h_width > 1.0) bad("h_width", "expected a number in (0, 1]");
    if (!finite(f.ss) || f.ss < 0.0 || !(f.ss < 1.0)) bad("ss", "expected a number in [0, 1)");
    if (!finite(f.scale) || f.scale < 0.0) bad("scale", "expected a finite number >= 0");
    if (f.groups.empty() || f.groups.size() > size_t(FarField::kMaxGroups))
      bad("groups", "expected 1 to " + std::to_string(FarField::kMaxGroups) + " groups");
    for (size_t i = 0; i < f.groups.size(); ++i) {
      const FarField::Group& g = f.groups[i];
      const std::string gi = "groups[" + std::to_string(i) + "].";
      if (!finite(g.share) || !(g.share > 0.0) || g.share > 1.0) bad(gi + "share", "expected a number in (0, 1]");
      for (auto [name, v] : {std::pair<const char*, double>{"width", g.width}, {"length", g.length},
                             {"across", g.across}, {"along", g.along}})
        if (!finite(v) || !(v > 0.0) || v > 1e6) bad(gi + name, "expected a number in (0, 1e6]");
      if (!finite(g.umax) || !(g.umax > 0.0) || !(g.umax < 90.0)) bad(gi + "umax", "expected degrees in (0, 90)");
      if (!(g.width * std::sin(g.umax * kDegToRad) < g.length))
        bad(gi + "umax", "width sin(umax) must be < length");
      if (!finite(g.psi) || !(std::abs(g.psi) < 90.0)) bad(gi + "psi", "expected degrees in (-90, 90)");
      if (!finite(g.kappa) || g.kappa < -1.0 || g.kappa > 1e6) bad(gi + "kappa", "expected a number in [-1, 1e6]");
      if (!finite(g.area_factor) || g.area_factor < 1.0 || g.area_factor > 1e6)
        bad(gi + "area_factor", "expected a number in [1, 1e6]");
    }
  }
  const yarn_table::Table& t = f.ibl;
  if (!need_ibl && t.n_theta == 0 && t.n_phi == 0 && t.ibl.empty()) return;
  if (t.n_theta < 2 || t.n_theta > 64) bad("ibl.n_theta", "expected an integer in [2, 64]");
  if (t.n_phi < 3 || t.n_phi > 128) bad("ibl.n_phi", "expected an integer in [3, 128]");
  if (t.ibl.size() != size_t(2) * size_t(t.n_theta) * size_t(t.n_phi) * 5)
    bad("ibl.summary", "expected 2 n_theta n_phi 5 = " +
                           std::to_string(2 * t.n_theta * t.n_phi * 5) + " numbers, got " +
                           std::to_string(t.ibl.size()));
  for (size_t i = 0; i < t.ibl.size(); ++i)
    if (!std::isfinite(t.ibl[i])) bad("ibl.summary[" + std::to_string(i) + "]", "not finite");
}

Lobe::Lobe(const FarField& f) : f_(f) {
  Validate(f, "yarn lobe", false);
  if (f.kind == FarField::Kind::kMicrocylinder) {
    tangents_ = microcylinder::MergeDuplicates(microcylinder::MakeTangents(f.threads));
    static std::atomic<uint64_t> next_id{1};
    id_ = next_id.fetch_add(1);
    return;
  }
  phase_.alpha = f.alpha;
  phase_.beta = f.beta;
  phase_.von_mises_norm = 1.0 / (2.0 * kPi * BesselI0(std::abs(f.beta)));
  phase_.h_width = f.h_width;
  phase_.ss = f.ss;
  for (const FarField::Group& g : f.groups) {
    G q;
    q.yarn = MakeYarn(g.warp, g.psi, g.width, g.length, g.kappa, g.area_factor);
    // (SegmentSpecular multiplies by area_factor itself)
    q.weight = f.scale * g.share / f.nodes;
    const double umax = g.umax * kDegToRad;
    const bool staple = g.psi != 0.0;
    q.band_extent = staple ? g.across : g.along;
    for (int j = 0; j < f.nodes; ++j) {
      const double s = -1.0 + (2.0 * j + 1.0) / f.nodes;  // midpoints of (-1, 1)
      Point p;
      p.umax = umax;
      if (staple) {  // u along the segment's cells, the band across them
        p.along = s * g.along;
        p.u = std::clamp(p.along / (0.5 * g.length) * umax, -umax, umax);
        p.sin_u = std::sin(p.u);
        p.cos_u = std::cos(p.u);
        p.spine_radius = SpineRadius(std::abs(p.u), umax, g.kappa, g.width, g.length);
      } else {  // filament: v across the segment's cells, the band along them
        p.across = s * g.across;
        p.v = std::clamp(p.across * kPi / g.width, -0.5 * kPi, 0.5 * kPi);
      }
      q.sin_v.push_back(std::sin(p.v));
      q.cos_v.push_back(std::cos(p.v));
      q.nodes.push_back(p);
    }
    groups_.push_back(std::move(q));
  }
}

// sum_p SegmentSpecular(phase_, g.yarn, p, wo_s, wi_s, g.band_extent) over g's nodes, with the
// point-independent part (PreparePair) computed once, and each filament node's sin v, cos v
// from the constructor. The same functions as SegmentSpecular's, so the same values (test
// S12YarnLobe.EvalIsTheSumOfSegmentSpecular). band_extent > 0 (Validate: along, across > 0).
double Lobe::GroupSum(const G& g, const Vec3<double>& wo_s, const Vec3<double>& wi_s) const {
  if (g.nodes.empty()) return 0.0;
  const PairTerms q = PreparePair(phase_, g.yarn, g.nodes[0].umax, wo_s, wi_s);
  if (!q.lit) return 0.0;
  double total = 0.0;
  if (g.yarn.psi == 0.0) {
    const double band = BandMean(q.y_h, q.delta, g.band_extent);
    for (size_t k = 0; k < g.nodes.size(); ++k)
      total += FilamentPoint(phase_, g.yarn, q, g.sin_v[k], g.cos_v[k], band);
  } else {
    for (const Point& p : g.nodes) total += StaplePoint(phase_, g.yarn, q, p, g.band_extent);
  }
  return total;
}

void Lobe::Eval(const Vec3<double>& wo, const Vec3<double>& wi, double out[2]) const {
  if (f_.kind == FarField::Kind::kMicrocylinder) {
    // The wo-only work once per wo and thread: a bake runs every wi of one wo on one thread,
    // the preview every light of one pixel. Keyed by the lobe's id (unique per constructed
    // lobe; copies share the description) and wo's bits; the same values as EvalSplit.
    thread_local struct {
      uint64_t id = 0;
      double wo[3] = {0, 0, 0};
      double q = 0.0;
      microcylinder::Outgoing w[2 * microcylinder::kMaxOffsets];
    } cache;
    out[0] = out[1] = 0.0;
    if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
    if (cache.id != id_ || cache.wo[0] != wo.x || cache.wo[1] != wo.y || cache.wo[2] != wo.z) {
      cache.q = microcylinder::PrepareOutgoing(tangents_, f_.threads, wo, cache.w);
      cache.id = id_;
      cache.wo[0] = wo.x;
      cache.wo[1] = wo.y;
      cache.wo[2] = wo.z;
    }
    microcylinder::EvalSplitPrepared(tangents_, f_.threads, cache.w, cache.q, wo, wi, out);
    return;
  }
  out[0] = out[1] = 0.0;
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return;
  for (const G& g : groups_) out[g.yarn.warp ? 0 : 1] += g.weight * GroupSum(g, wo, wi);
}

yarn_table::Table Bake(const std::function<void(const Vec3<double>&, const Vec3<double>&, double[2])>& eval,
                       int n_theta, int n_phi, bool with_lobe, int wi_sub) {
  if (n_theta < 2 || n_theta > 64 || n_phi < 3 || n_phi > 128)
    throw std::invalid_argument("yarn table: resolution " + std::to_string(n_theta) + " x " +
                                std::to_string(n_phi) + " not in [2, 64] x [3, 128]");
  if (wi_sub < 1 || wi_sub > 16 || (with_lobe && wi_sub != 1))
    throw std::invalid_argument("yarn table: wi subdivision " + std::to_string(wi_sub) +
                                " not in [1, 16] (1 with the lobe table)");
  yarn_table::Table t;
  t.n_theta = n_theta;
  t.n_phi = n_phi;
  const size_t D = size_t(n_theta) * size_t(n_phi);
  if (with_lobe) t.lobe.assign(2 * D * D, 0.f);
  t.ibl.assign(2 * D * 5, 0.f);
  std::vector<Vec3<double>> dirs(D);
  for (int it = 0; it < n_theta; ++it)
    for (int ip = 0; ip < n_phi; ++ip) dirs[size_t(it) * size_t(n_phi) + size_t(ip)] = t.Direction(it, ip);
  // The wi quadrature: the bin centres (wi_sub = 1), or a wi_sub times finer midpoint grid
  // for lobes narrower than a bin (session 19: the microcylinder's surface Gaussian).
  yarn_table::Table fine;
  fine.n_theta = n_theta * wi_sub;
  fine.n_phi = n_phi * wi_sub;
  const size_t Di = size_t(fine.n_theta) * size_t(fine.n_phi);
  std::vector<Vec3<double>> wis(Di);
  std::vector<double> solid(Di);
  const double dth = 0.5 * kPi / fine.n_theta, dph = 2.0 * kPi / fine.n_phi;
  for (int it = 0; it < fine.n_theta; ++it)
    for (int ip = 0; ip < fine.n_phi; ++ip) {
      wis[size_t(it) * size_t(fine.n_phi) + size_t(ip)] = fine.Direction(it, ip);
      solid[size_t(it) * size_t(fine.n_phi) + size_t(ip)] = std::sin((it + 0.5) * dth) * dth * dph;
    }
  tbb::parallel_for(size_t(0), D, [&](size_t o) {
    double A[2] = {0, 0};
    Vec3<double> m[2] = {{0, 0, 0}, {0, 0, 0}};
    for (size_t i = 0; i < Di; ++i) {
      double v[2] = {0.0, 0.0};
      eval(dirs[o], wis[i], v);
      const double w = wis[i].z * solid[i];
      for (int k = 0; k < 2; ++k) {
        if (with_lobe) t.lobe[(size_t(k) * D + o) * D + i] = float(v[k]);
        A[k] += v[k] * w;
        m[k] = m[k] + wis[i] * (v[k] * w);
      }
    }
    for (int k = 0; k < 2; ++k) {
      float* e = &t.ibl[(size_t(k) * D + o) * 5];
      const double len = Length(m[k]);
      const Vec3<double> d = len > 0.0 ? m[k] * (1.0 / len) : Vec3<double>(0, 0, 1);
      e[0] = float(A[k]);
      e[1] = float(d.x);
      e[2] = float(d.y);
      e[3] = float(d.z);
      e[4] = float(A[k] > 0.0 ? yarn_table::RoughnessForMeanCosine(len / A[k]) : 1.0);
    }
  });
  return t;
}

}  // namespace clothfit::yarn_lobe
