// render/reference/irawan.cpp: the Irawan-Marschner woven-cloth BSDF (formulas in irawan.h).
#include "render/reference/irawan.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>

#include "render/scene/sampler.h"
#include "render/reference/woven_sampling.h"

namespace clothfit::render {
namespace {

constexpr double kDegToRad = kPi / 180.0;

// Uniform double in (0, 1) from a 64-bit key (SplitMix64 finaliser, render/scene/sampler.h).
double Hash01(uint64_t key) { return (double(Mix64(key) >> 11) + 0.5) * 0x1.0p-53; }

uint64_t Key(int64_t a, int64_t b, uint64_t salt) {
  return Mix64(uint64_t(a) * 0x9E3779B97F4A7C15ull ^ Mix64(uint64_t(b) + salt));
}

// 1-D gradient noise (Perlin's construction: random slopes at the integers, quintic fade),
// scaled by 2 so its range is about [-1, 1]; `salt` selects an independent sequence.
double GradientNoise1D(double x, uint64_t salt) {
  const double fl = std::floor(x);
  const double f = x - fl;
  const auto i = int64_t(fl);
  const double g0 = 2.0 * Hash01(Key(i, 0, salt)) - 1.0;
  const double g1 = 2.0 * Hash01(Key(i + 1, 0, salt)) - 1.0;
  const double fade = f * f * f * (f * (6.0 * f - 15.0) + 10.0);
  return 2.0 * (g0 * f * (1.0 - fade) + g1 * (f - 1.0) * fade);
}

std::atomic<uint64_t> g_next_instance_id{1};

uint64_t Bits(double x) { return std::bit_cast<uint64_t>(x); }

}  // namespace

Vec3d ToYarnFrame(const Vec3d& d, YarnType type) {
  return type == YarnType::kWarp ? Vec3d(-d.y, d.x, d.z) : Vec3d(-d.x, -d.y, d.z);
}
Vec3d FromYarnFrame(const Vec3d& d, YarnType type) {
  return type == YarnType::kWarp ? Vec3d(d.y, -d.x, d.z) : Vec3d(-d.x, -d.y, d.z);
}

IrawanBsdf::IrawanBsdf(WeavePattern pattern, double repeat_u, double repeat_v)
    : pattern_(std::move(pattern)), repeat_u_(repeat_u), repeat_v_(repeat_v) {
  if (!(repeat_u > 0.0) || !(repeat_v > 0.0) || !std::isfinite(repeat_u) ||
      !std::isfinite(repeat_v)) {
    throw std::invalid_argument("IrawanBsdf: repeat_u and repeat_v must be finite and > 0");
  }
  DeriveSegmentCentres(&pattern_, "IrawanBsdf(" + pattern_.name + ")");
  ValidateWeave(pattern_, "IrawanBsdf(" + pattern_.name + ")");
  phase_.alpha = pattern_.alpha;
  phase_.beta = pattern_.beta;
  phase_.von_mises_norm = 1.0 / (2.0 * kPi * BesselI0(std::abs(pattern_.beta)));
  phase_.h_width = pattern_.h_width;
  phase_.ss = pattern_.ss;
  instance_id_ = g_next_instance_id.fetch_add(1, std::memory_order_relaxed);
  for (const Yarn& y : pattern_.yarns) {
    YarnConst yc;
    yc.psi = y.psi * kDegToRad;
    yc.sin_psi = std::sin(yc.psi);
    yc.cos_psi = std::cos(yc.psi);
    yc.tan_psi = std::tan(yc.psi);
    yc.area_factor = (pattern_.warp_area + pattern_.weft_area) /
                     (y.type == YarnType::kWarp ? pattern_.warp_area : pattern_.weft_area);
    yarn_const_.push_back(yc);
    yarn_lobe::Yarn ys;
    ys.warp = y.type == YarnType::kWarp;
    ys.psi = yc.psi;
    ys.sin_psi = yc.sin_psi;
    ys.tan_psi = yc.tan_psi;
    ys.width = y.width;
    ys.length = y.length;
    ys.kappa = y.kappa;
    ys.area_factor = yc.area_factor;
    yarn_shape_.push_back(ys);
  }

  // Specular normalisation: 10 000 deterministic draws over 16 x 16 tiles (so the umax
  // noise is averaged too) with cosine-distributed wi and wo; intensity variation excluded
  // (its mean is 1 - e^-10).
  Pcg32 rng(0x5EEDC10Full, 0x1A4A3Dull);
  const int n = 10000;
  double sum = 0.0;
  const double W = pattern_.tile_width, H = pattern_.tile_height;
  for (int i = 0; i < n; ++i) {
    const double X = 16.0 * W * rng.Uniform(), Y = 16.0 * H * rng.Uniform();
    const Vec3d wi = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
    const Vec3d wo = SampleCosineHemisphere({rng.Uniform(), rng.Uniform()});
    sum += SpecularIntegrand(LocateDraft(X, Y), wo, wi);
  }
  const double mean = sum / n;
  spec_norm_ = mean > 0.0 ? 1.0 / (kPi * mean) : 0.0;
}

IrawanPoint IrawanBsdf::Locate(const Point2d& uv) const {
  return LocateDraft(-uv.y * repeat_v_ * pattern_.tile_width,
                     uv.x * repeat_u_ * pattern_.tile_height);
}

IrawanPoint IrawanBsdf::LocateDraft(double X, double Y) const {
  const int W = pattern_.tile_width, H = pattern_.tile_height;
  const double tx = std::floor(X / W), ty = std::floor(Y / H);
  const double lx = std::clamp(X - tx * W, 0.0, double(W));
  const double ly = std::clamp(Y - ty * H, 0.0, double(H));
  const int col = std::min(int(lx), W - 1);
  const int row_from_bottom = std::min(int(ly), H - 1);
  const int id = pattern_.IdAt(col, H - 1 - row_from_bottom);
  const Yarn& y = pattern_.yarns[size_t(id - 1)];
  IrawanPoint p;
  p.yarn = id - 1;
  const double cx = y.center_u * W, cy = y.center_v * H;
  const double px = lx - cx, py = ly - cy;
  const bool warp = y.type == YarnType::kWarp;
  p.across = warp ? px : -py;
  p.along = warp ? py : px;

  double umax = y.umax * kDegToRad;
  if (pattern_.period > 0.0) {
    // One value per segment: noise along the warp (Y) and along the weft (X) at the segment
    // centre; each yarn line gets its own sequence (salted by the other coordinate).
    const double gx = tx * W + cx, gy = ty * H + cy;
    const double r1 =
        GradientNoise1D(gy / pattern_.period, Mix64(uint64_t(int64_t(std::floor(gx * 2.0)))));
    const double r2 = GradientNoise1D(gx / pattern_.period,
                                      Mix64(uint64_t(int64_t(std::floor(gy * 2.0))) ^ 0xABCDEFull));
    const double d1 = warp ? pattern_.d_warp_umax_over_d_warp : pattern_.d_weft_umax_over_d_warp;
    const double d2 = warp ? pattern_.d_warp_umax_over_d_weft : pattern_.d_weft_umax_over_d_weft;
    umax += (r1 * d1 + r2 * d2) * kDegToRad;
    // Keep the noisy yarn valid: umax in [0.5 deg, 89 deg] and w sin(umax) < l.
    double hi = 89.0 * kDegToRad;
    if (y.width > y.length) hi = std::min(hi, 0.999 * std::asin(y.length / y.width));
    umax = std::clamp(umax, 0.5 * kDegToRad, hi);
  }
  p.umax = umax;
  p.u = std::clamp(p.along / (0.5 * y.length) * umax, -umax, umax);
  p.v = std::clamp(p.across * kPi / y.width, -0.5 * kPi, 0.5 * kPi);
  p.sin_u = std::sin(p.u);
  p.cos_u = std::cos(p.u);
  if (y.psi != 0.0) p.spine_radius = SpineRadius(std::abs(p.u), umax, y.kappa, y.width, y.length);
  if (pattern_.fineness > 0.0) {
    const double xi = Hash01(Key(int64_t(std::floor(X * pattern_.fineness)),
                                 int64_t(std::floor(Y * pattern_.fineness)), 0xF1BEull));
    p.intensity = std::min(-std::log(xi), 10.0);
  }
  return p;
}

double IrawanBsdf::SpecularIntegrand(const IrawanPoint& p, const Vec3d& wo_s,
                                     const Vec3d& wi_s) const {
  return Specular(p, wo_s, wi_s, 0.0);
}

double IrawanBsdf::SpecularBandAverage(const IrawanPoint& p, const Vec3d& wo_s,
                                       const Vec3d& wi_s, double half_extent) const {
  if (!(half_extent > 0.0)) return 0.0;
  return Specular(p, wo_s, wi_s, half_extent);
}

double IrawanBsdf::Specular(const IrawanPoint& p, const Vec3d& wo_s, const Vec3d& wi_s,
                            double band_extent) const {
  const yarn_lobe::Point q{p.umax, p.across, p.along, p.u, p.v, p.sin_u, p.cos_u, p.spine_radius};
  return yarn_lobe::SegmentSpecular(phase_, yarn_shape_[size_t(p.yarn)], q, wo_s, wi_s, band_extent);
}

struct IrawanBsdf::Memo {
  uint64_t id = 0;  // instance_id_ of the owner; 0: empty
  uint64_t uv[2] = {0, 0};
  bool has_local = false;
  uint64_t wo[3] = {0, 0, 0};
  Local local;
};

IrawanBsdf::Memo& IrawanBsdf::ThreadMemo() {
  thread_local Memo memo;
  return memo;
}

const IrawanPoint& IrawanBsdf::PointAt(const ShadingPoint& sp) const {
  Memo& m = ThreadMemo();
  const uint64_t ux = Bits(sp.uv.x), uy = Bits(sp.uv.y);
  if (m.id != instance_id_ || m.uv[0] != ux || m.uv[1] != uy) {
    m.id = instance_id_;
    m.uv[0] = ux;
    m.uv[1] = uy;
    m.has_local = false;
    m.local.p = Locate(sp.uv);
  }
  return m.local.p;
}

const IrawanBsdf::Local& IrawanBsdf::LocalAt(const Vec3d& wo, const ShadingPoint& sp) const {
  PointAt(sp);
  Memo& m = ThreadMemo();
  const uint64_t wx = Bits(wo.x), wy = Bits(wo.y), wz = Bits(wo.z);
  if (!m.has_local || m.wo[0] != wx || m.wo[1] != wy || m.wo[2] != wz) {
    Local& l = m.local;
    l.lobe = Cones(l.p, wo, l.cones);
    l.c = l.lobe ? CosineProbability(l.p) : 1.0;
    m.wo[0] = wx;
    m.wo[1] = wy;
    m.wo[2] = wz;
    m.has_local = true;
  }
  return m.local;
}

double IrawanBsdf::MixturePdf(const Local& l, const Vec3d& wi) const {
  double pdf = l.c * CosineHemispherePdf(wi.z);
  if (l.c < 1.0) {
    double sum = 0.0;
    for (const woven::Cone& cone : l.cones) sum += woven::ConePdf(cone, wi);
    pdf += (1.0 - l.c) * sum / kTangents;
  }
  return pdf;
}

Rgbd IrawanBsdf::Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return Rgbd(0, 0, 0);
  const IrawanPoint& p = PointAt(sp);
  const Yarn& y = pattern_.yarns[size_t(p.yarn)];
  const double spec = SpecularIntegrand(p, wo, wi) * p.intensity * spec_norm_;
  return y.ks * spec + y.kd * kInvPi;
}

double IrawanBsdf::CosineProbability(const IrawanPoint& p) const {
  const Yarn& y = pattern_.yarns[size_t(p.yarn)];
  const double kd = Max3(y.kd), ks = Max3(y.ks);
  if (!(ks > 0.0)) return 1.0;
  return 0.1 + 0.8 * kd / (kd + ks);
}

bool IrawanBsdf::Tangents(const IrawanPoint& p, Vec3d* t, double* scale) const {
  const Yarn& y = pattern_.yarns[size_t(p.yarn)];
  const double psi = y.psi * kDegToRad;
  // The band centre is clamped to +-(extent - delta)/2 (SpecularIntegrand), so a point
  // within delta of a segment end also sees every highlight beyond the clamp.
  const bool filament = psi == 0.0;
  const double extent = filament ? y.length : y.width;
  const double delta = extent * pattern_.h_width;
  const double pos = filament ? p.along : p.across;
  const double clamp_at = 0.5 * (extent - delta);
  double lo_pos = pos - 0.5 * delta, hi_pos = pos + 0.5 * delta;
  if (lo_pos < -clamp_at) lo_pos = -1e30;
  if (hi_pos > clamp_at) hi_pos = 1e30;
  double lo, hi, gain;
  if (filament) {  // u_h = y_h / (l/2) * umax, |u_h| < umax
    const double k = p.umax / (0.5 * y.length);
    lo = std::max(-p.umax, lo_pos * k);
    hi = std::min(p.umax, hi_pos * k);
    gain = 1.0;
  } else {  // v_h = x_h pi / w, |v_h| < pi/2
    const double k = kPi / y.width;
    lo = std::max(-0.5 * kPi, lo_pos * k);
    hi = std::min(0.5 * kPi, hi_pos * k);
    gain = std::abs(std::sin(psi));  // |dt/dv| <= |sin psi|
  }
  if (!(hi > lo)) return false;
  const double step = (hi - lo) / kTangents;
  const YarnConst& yc = yarn_const_[size_t(p.yarn)];
  const double su = p.sin_u, cu = p.cos_u, sp = yc.sin_psi, cp = yc.cos_psi;
  // s_k = lo + (k + 1/2) step: sin and cos by rotating (sin s_0, cos s_0) by step each time.
  const double s0 = lo + 0.5 * step;
  double ss = std::sin(s0), cs = std::cos(s0);
  const double sd = std::sin(step), cd = std::cos(step);
  for (int k = 0; k < kTangents; ++k) {
    Vec3d ty;
    if (psi == 0.0) {
      ty = Vec3d(0.0, cs, -ss);
    } else {
      // Unit by construction: |ty|^2 = sin^2 psi (cs^2 + ss^2) + cos^2 psi = 1.
      ty = Vec3d(-cs * sp, cu * cp + su * ss * sp, -su * cp + cu * ss * sp);
    }
    t[k] = FromYarnFrame(ty, y.type);
    const double ss_next = ss * cd + cs * sd;
    cs = cs * cd - ss * sd;
    ss = ss_next;
  }
  // Logistic scale: half the angular spacing of neighbouring cones, at least 0.03 rad.
  *scale = std::max(0.5 * step * gain, 0.03);
  return true;
}

bool IrawanBsdf::Cones(const IrawanPoint& p, const Vec3d& wo, woven::Cone* cones) const {
  Vec3d t[kTangents];
  double scale = 0.0;
  if (!Tangents(p, t, &scale)) return false;
  for (int k = 0; k < kTangents; ++k) cones[k] = woven::MakeCone(wo, t[k], scale);
  return true;
}

double IrawanBsdf::Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint& sp) const {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return 0.0;
  return MixturePdf(LocalAt(wo, sp), wi);
}

bool IrawanBsdf::Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
                        BsdfSample* out) const {
  if (!(wo.z > 0.0)) return false;
  const Local& l = LocalAt(wo, sp);
  const double c = l.c;
  Vec3d wi;
  if (uc < c) {
    wi = SampleCosineHemisphere(u);
  } else {
    const double r = std::clamp((uc - c) / (1.0 - c), 0.0, 1.0);
    const int k = std::min(int(r * kTangents), kTangents - 1);
    if (!woven::SampleCone(l.cones[k], u, &wi)) return false;
  }
  if (!(wi.z > 0.0)) return false;
  const double pdf = MixturePdf(l, wi);
  if (!(pdf > 0.0)) return false;
  const Yarn& y = pattern_.yarns[size_t(l.p.yarn)];
  out->wi = wi;
  out->pdf = pdf;
  out->f = y.ks * (SpecularIntegrand(l.p, wo, wi) * l.p.intensity * spec_norm_) + y.kd * kInvPi;
  return true;
}

}  // namespace clothfit::render
