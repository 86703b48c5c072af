// render/reference/sadeghi.cpp: the Sadeghi et al. 2013 microcylinder cloth BSDF (formulas in sadeghi.h).
#include "render/reference/sadeghi.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <stdexcept>

#include "render/reference/woven_sampling.h"

namespace clothfit::render {
namespace {

constexpr double kDegToRad = kPi / 180.0;

std::atomic<uint64_t> g_next_sadeghi_id{1};
uint64_t Bits(double x) { return std::bit_cast<uint64_t>(x); }

double Gaussian(double sigma, double x) {
  return std::exp(-x * x / (2.0 * sigma * sigma)) / (sigma * std::sqrt(2.0 * kPi));
}

double WrapAngle(double a) {
  while (a > kPi) a -= 2.0 * kPi;
  while (a < -kPi) a += 2.0 * kPi;
  return a;
}

SadeghiThread Thread(double eta, Rgbd colour, double scale, double kd, double gs, double gv,
                     double a, std::vector<double> offsets) {
  SadeghiThread t;
  t.eta = eta;
  t.albedo = colour * scale;
  t.kd = kd;
  t.gamma_s = gs;
  t.gamma_v = gv;
  t.a = a;
  t.offsets = std::move(offsets);
  return t;
}

}  // namespace

double FresnelDielectric(double cos_i, double eta) {
  const double ci = std::clamp(cos_i, 0.0, 1.0);
  const double sin_t2 = (1.0 - ci * ci) / (eta * eta);
  if (sin_t2 >= 1.0) return 1.0;
  const double ct = std::sqrt(1.0 - sin_t2);
  const double rs = (ci - eta * ct) / (ci + eta * ct);
  const double rp = (eta * ci - ct) / (eta * ci + ct);
  return 0.5 * (rs * rs + rp * rp);
}

const std::vector<SadeghiFabric>& SadeghiPresets() {
  // Sadeghi et al. 2013, table 2 (as publicly transcribed; shared/reference/woven-cloth.md 2).
  static const std::vector<SadeghiFabric> presets = [] {
    std::vector<SadeghiFabric> p;
    const Rgbd linen(0.2, 0.8, 1.0), silk(1.0, 0.95, 0.05), satin(1.0, 0.37, 0.3);
    const Rgbd velvet(0.05, 0.02, 0.0);
    SadeghiFabric f;
    f.name = "linen_plain";
    f.thread[0] = Thread(1.46, linen, 0.3, 0.3, 12, 24, 0.33, {-25, 25});
    f.thread[1] = f.thread[0];
    p.push_back(f);
    f.name = "silk_crepe_de_chine";
    f.thread[0] = Thread(1.345, silk, 0.12, 0.2, 5, 10, 0.75, {-35, -35, 35, 35});
    f.thread[1] = Thread(1.345, silk, 0.16, 0.3, 18, 32, 0.25, {0});
    p.push_back(f);
    f.name = "polyester_satin_charmeuse";
    f.thread[0] = Thread(1.539, satin, 0.035, 0.1, 2.5, 5, 0.9, {-32, -32, -18, 0, 0, 18, 32, 32});
    f.thread[1] = Thread(1.539, satin, 0.02, 0.7, 30, 60, 0.1, {0});
    p.push_back(f);
    f.name = "polyester_satin_charmeuse_back";
    f.thread[0] = Thread(1.539, satin, 0.035, 0.1, 2.5, 5, 0.67, {-30, -30, 30, 30, -5, -5, 5, 5});
    f.thread[1] = Thread(1.539, satin, 0.02, 0.7, 30, 60, 0.33, {0});
    p.push_back(f);
    f.name = "silk_shot";
    f.thread[0] = Thread(1.345, Rgbd(0.1, 1.0, 0.4), 0.2, 0.1, 4, 8, 0.86, {-25, -25, 25, 25});
    f.thread[1] = Thread(1.345, Rgbd(1.0, 0.0, 0.1), 0.6, 0.1, 5, 10, 0.14, {0});
    p.push_back(f);
    f.name = "velvet";
    f.thread[0] = Thread(1.46, velvet, 0.3, 0.1, 6, 12, 0.5, {-90, -50});
    f.thread[1] = Thread(1.46, velvet, 0.3, 0.1, 6, 12, 0.5, {-90, -55, 55, 90});
    p.push_back(f);
    return p;
  }();
  return presets;
}

const SadeghiFabric& SadeghiPreset(const std::string& name) {
  std::string valid;
  for (const SadeghiFabric& f : SadeghiPresets()) {
    if (f.name == name) return f;
    valid += (valid.empty() ? "" : ", ") + f.name;
  }
  throw std::invalid_argument("unknown Sadeghi fabric '" + name + "' (valid: " + valid + ")");
}

SadeghiBsdf::SadeghiBsdf(SadeghiFabric fabric) : fabric_(std::move(fabric)) {
  double a_sum = 0.0;
  for (int j = 0; j < 2; ++j) {
    const SadeghiThread& th = fabric_.thread[j];
    const std::string where =
        "Sadeghi fabric '" + fabric_.name + "' thread " + std::to_string(j + 1) + ": ";
    if (!(th.eta > 1.0 && th.eta < 3.0))
      throw std::invalid_argument(where + "eta must be in (1, 3)");
    if (!(th.kd >= 0.0 && th.kd <= 1.0))
      throw std::invalid_argument(where + "kd must be in [0, 1]");
    if (!(th.gamma_s > 0.0 && th.gamma_s <= 90.0) || !(th.gamma_v > 0.0 && th.gamma_v <= 90.0)) {
      throw std::invalid_argument(where + "gamma_s and gamma_v must be in (0, 90] degrees");
    }
    if (!(th.a >= 0.0 && th.a <= 1.0)) throw std::invalid_argument(where + "a must be in [0, 1]");
    for (int c = 0; c < 3; ++c) {
      if (!(th.albedo[c] >= 0.0 && th.albedo[c] <= 1.0)) {
        throw std::invalid_argument(where + "albedo must be in [0, 1]");
      }
    }
    if (th.offsets.empty() || th.offsets.size() > 64) {
      throw std::invalid_argument(where + "needs 1 to 64 tangent offsets");
    }
    a_sum += th.a;
    const Vec3d d = j == 0 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0);
    const Vec3d n(0, 0, 1);
    for (double off : th.offsets) {
      if (!(off >= -90.0 && off <= 90.0)) {
        throw std::invalid_argument(where + "offsets must be in [-90, 90] degrees");
      }
      const double o = off * kDegToRad;
      Tangent tg;
      tg.t = d * std::cos(o) + n * std::sin(o);
      tg.n = d * -std::sin(o) + n * std::cos(o);
      tg.b = Cross(tg.t, tg.n);
      tg.thread = j;
      tg.weight = th.a / double(th.offsets.size());
      tangents_.push_back(tg);
    }
    scale_s_[j] = 2.0 * th.gamma_s * kDegToRad * std::sqrt(3.0) / kPi;
    scale_v_[j] = 2.0 * th.gamma_v * kDegToRad * std::sqrt(3.0) / kPi;
  }
  instance_id_ = g_next_sadeghi_id.fetch_add(1, std::memory_order_relaxed);
  if (!(a_sum <= 1.0 + 1e-9)) {
    throw std::invalid_argument("Sadeghi fabric '" + fabric_.name + "': a1 + a2 must be <= 1");
  }
}

struct SadeghiBsdf::Memo {
  uint64_t id = 0;  // instance_id_ of the owner; 0: empty
  uint64_t wo[3] = {0, 0, 0};
  WoState state;
};

void SadeghiBsdf::ComputeState(const Vec3d& wo, WoState* s) const {
  s->q = (1.0 - fabric_.thread[0].a - fabric_.thread[1].a) * wo.z;
  double total = 0.0;
  for (size_t k = 0; k < tangents_.size(); ++k) {
    const Tangent& tg = tangents_[k];
    WoTangent& w = s->tg[k];
    w.proj = std::max(0.0, Dot(wo, tg.n));
    s->q += tg.weight * w.proj;
    s->prob[k] = 0.0;
    if (w.proj <= 0.0) continue;
    w.sin_o = std::clamp(Dot(wo, tg.t), -1.0, 1.0);
    w.theta_o = std::asin(w.sin_o);
    w.cos_o = std::sqrt(std::max(0.0, 1.0 - w.sin_o * w.sin_o));  // = cos(asin(sin_o))
    const double x = Dot(wo, tg.n), y = Dot(wo, tg.b);
    w.phi_o = std::atan2(y, x);
    const double r = std::sqrt(x * x + y * y);
    // cos and sin of atan2(y, x); atan2(0, 0) = 0.
    w.cos_phi_o = r > 0.0 ? x / r : 1.0;
    w.sin_phi_o = r > 0.0 ? y / r : 0.0;
    const int j = tg.thread;
    w.cone_s = woven::MakeCone(wo, tg.t, scale_s_[j]);
    w.cone_v = woven::MakeCone(wo, tg.t, scale_v_[j]);
    // Selection weight: visible weight of the tangent times the fraction of its volume-width
    // cone that can reach above the surface (woven::ConeMass).
    woven::TruncatedLogistic full = w.cone_v.theta;
    full.lo = -0.5 * kPi;
    full.hi = 0.5 * kPi;
    const double m = full.Mass();
    s->prob[k] = tg.weight * w.proj * (m > 0.0 ? w.cone_v.mass / m : 0.0);
    total += s->prob[k];
  }
  s->lobe = total > 0.0;
  if (s->lobe)
    for (size_t k = 0; k < tangents_.size(); ++k) s->prob[k] /= total;
  s->c = s->lobe ? kCosineProbability : 1.0;
}

const SadeghiBsdf::WoState& SadeghiBsdf::StateFor(const Vec3d& wo) const {
  thread_local Memo memo;
  const uint64_t wx = Bits(wo.x), wy = Bits(wo.y), wz = Bits(wo.z);
  if (memo.id != instance_id_ || memo.wo[0] != wx || memo.wo[1] != wy || memo.wo[2] != wz) {
    ComputeState(wo, &memo.state);
    memo.id = instance_id_;
    memo.wo[0] = wx;
    memo.wo[1] = wy;
    memo.wo[2] = wz;
  }
  return memo.state;
}

// Per tangent, only what depends on wi is computed here; the trigonometry of the angles in
// sadeghi.h is evaluated through identities (exact in real arithmetic):
//   cos(asin(s)) = sqrt(1 - s^2);  cos(atan2(y, x)) = x / sqrt(x^2 + y^2);
//   cos(theta_d) = sqrt((1 + cos(theta_i - theta_o)) / 2), theta_d in [-pi/2, pi/2];
//   cos(phi_d / 2) = sqrt((1 + cos(phi_i - phi_o)) / 2), phi_d in [-pi, pi] (wrapped; the
//   cosine of the difference does not depend on the wrap).
Rgbd SadeghiBsdf::Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return Rgbd(0, 0, 0);
  const WoState& s = StateFor(wo);
  const double sigma_m = kMaskingSigmaDeg * kDegToRad;
  Rgbd sum(0, 0, 0);
  for (size_t k = 0; k < tangents_.size(); ++k) {
    const Tangent& tg = tangents_[k];
    const WoTangent& w = s.tg[k];
    if (w.proj <= 0.0) continue;
    const double x = Dot(wi, tg.n), y = Dot(wi, tg.b);
    const double r = std::sqrt(x * x + y * y);
    const double cos_phi_i = r > 0.0 ? x / r : 1.0;
    // Masking-shadowing (Sadeghi et al. eq. 10): correlated when phi_d is small. Both
    // terms vanish when either factor does (m_o > 0 here, since wo.n_k > 0).
    const double m_i = std::max(0.0, cos_phi_i), m_o = std::max(0.0, w.cos_phi_o);
    if (m_i <= 0.0 || m_o <= 0.0) continue;
    const double phi_d = WrapAngle(std::atan2(y, x) - w.phi_o);
    const double uu = std::exp(-phi_d * phi_d / (2.0 * sigma_m * sigma_m));
    const double mask = (1.0 - uu) * m_i * m_o + uu * std::min(m_i, m_o);
    if (mask <= 0.0) continue;
    const SadeghiThread& th = fabric_.thread[tg.thread];
    const double sin_i = std::clamp(Dot(wi, tg.t), -1.0, 1.0);
    const double theta_i = std::asin(sin_i);
    const double cos_i = std::sqrt(std::max(0.0, 1.0 - sin_i * sin_i));
    const double theta_h = 0.5 * (theta_i + w.theta_o);
    const double cos_diff = cos_i * w.cos_o + sin_i * w.sin_o;  // cos(theta_i - theta_o)
    const double cos_d = std::sqrt(std::clamp(0.5 * (1.0 + cos_diff), 0.0, 1.0));
    const double sin_phi_i = r > 0.0 ? y / r : 0.0;
    const double cos_phi_diff = cos_phi_i * w.cos_phi_o + sin_phi_i * w.sin_phi_o;
    const double cos_half_phi = std::sqrt(std::clamp(0.5 * (1.0 + cos_phi_diff), 0.0, 1.0));
    const double fr = FresnelDielectric(cos_d * cos_half_phi, th.eta);
    const double ft = 1.0 - fr;
    // Surface reflection (eq. 4) and volume scattering (eq. 5).
    const double f_surface = fr * cos_half_phi * Gaussian(th.gamma_s * kDegToRad, theta_h);
    // Guard: cos_i + cos_o vanishes only when both directions run along the fibre; floored
    // at 1e-4 (changes nothing elsewhere).
    const double vol = ft * ft *
                       ((1.0 - th.kd) * Gaussian(th.gamma_v * kDegToRad, theta_h) + th.kd) /
                       std::max(cos_i + w.cos_o, 1e-4);
    // Guard: cos^2(theta_d) floored at 1e-4 (theta_d within 0.6 deg of 90 deg only).
    const double inv_cd2 = 1.0 / std::max(cos_d * cos_d, 1e-4);
    const double wt = tg.weight * w.proj * mask * cos_i * inv_cd2;
    sum += Rgbd::Splat(wt * f_surface) + th.albedo * (wt * vol);
  }
  if (!(s.q > 0.0)) return Rgbd(0, 0, 0);
  return sum * (1.0 / (s.q * wi.z));
}

double SadeghiBsdf::MixturePdf(const WoState& s, const Vec3d& wi) const {
  double pdf = s.c * CosineHemispherePdf(wi.z);
  if (s.lobe) {
    double lobe = 0.0;
    for (size_t k = 0; k < tangents_.size(); ++k) {
      if (s.prob[k] <= 0.0) continue;
      lobe += s.prob[k] * 0.5 *
              (woven::ConePdf(s.tg[k].cone_s, wi) + woven::ConePdf(s.tg[k].cone_v, wi));
    }
    pdf += (1.0 - s.c) * lobe;
  }
  return pdf;
}

double SadeghiBsdf::Pdf(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return 0.0;
  return MixturePdf(StateFor(wo), wi);
}

bool SadeghiBsdf::Sample(const Vec3d& wo, const Point2d& u, double uc, const ShadingPoint& sp,
                         BsdfSample* out) const {
  if (!(wo.z > 0.0)) return false;
  const WoState& s = StateFor(wo);
  const double c = s.c;
  Vec3d wi;
  if (uc < c) {
    wi = SampleCosineHemisphere(u);
  } else {
    // Remap uc to choose the tangent, then the width (surface or volume).
    double r = std::clamp((uc - c) / (1.0 - c), 0.0, 1.0 - 1e-16);
    size_t k = 0;
    double acc = 0.0;
    for (k = 0; k < tangents_.size(); ++k) {
      if (s.prob[k] <= 0.0) continue;
      if (r < acc + s.prob[k]) break;
      acc += s.prob[k];
    }
    if (k == tangents_.size()) {  // rounding: take the last selectable tangent
      for (k = tangents_.size(); k-- > 0;) {
        if (s.prob[k] > 0.0) break;
      }
      acc = 1.0 - s.prob[k];
    }
    const double r2 = std::clamp((r - acc) / s.prob[k], 0.0, 1.0);
    const woven::Cone& cone = r2 < 0.5 ? s.tg[k].cone_s : s.tg[k].cone_v;
    if (!woven::SampleCone(cone, u, &wi)) return false;
  }
  if (!(wi.z > 0.0)) return false;
  const double pdf = MixturePdf(s, wi);
  if (!(pdf > 0.0)) return false;
  out->wi = wi;
  out->pdf = pdf;
  out->f = Eval(wo, wi, sp);
  return true;
}

}  // namespace clothfit::render
