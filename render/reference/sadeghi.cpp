// render/reference/sadeghi.cpp: the Sadeghi et al. 2013 microcylinder cloth BSDF (formulas in sadeghi.h).
#include "render/reference/sadeghi.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <stdexcept>

#include "brdf/microcylinder.h"
#include "render/reference/woven_sampling.h"

namespace clothfit::render {
namespace {

constexpr double kDegToRad = kPi / 180.0;

std::atomic<uint64_t> g_next_sadeghi_id{1};
uint64_t Bits(double x) { return std::bit_cast<uint64_t>(x); }

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
  return microcylinder::FresnelDielectric(cos_i, eta);
}

microcylinder::Thread MicrocylinderThread(const SadeghiThread& t, double volume_scale) {
  microcylinder::Thread th;
  th.eta = t.eta;
  th.kd = t.kd;
  th.gamma_s = t.gamma_s;
  th.gamma_v = t.gamma_v;
  th.a = t.a;
  th.offsets = t.offsets;
  th.volume_scale = volume_scale;
  return th;
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
    for (double off : th.offsets) {
      if (!(off >= -90.0 && off <= 90.0)) {
        throw std::invalid_argument(where + "offsets must be in [-90, 90] degrees");
      }
      tangents_.push_back(microcylinder::MakeTangent(j, off, th.a / double(th.offsets.size())));
    }
    optics_[j] = MicrocylinderThread(th);
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
    const microcylinder::Tangent& tg = tangents_[k];
    WoTangent& w = s->tg[k];
    microcylinder::OutgoingAngles(tg, wo, &w.angles);
    s->q += tg.weight * w.angles.proj;
    s->prob[k] = 0.0;
    if (w.angles.proj <= 0.0) continue;
    const int j = tg.thread;
    w.cone_s = woven::MakeCone(wo, tg.t, scale_s_[j]);
    w.cone_v = woven::MakeCone(wo, tg.t, scale_v_[j]);
    // Selection weight: visible weight of the tangent times the fraction of its volume-width
    // cone that can reach above the surface (woven::ConeMass).
    woven::TruncatedLogistic full = w.cone_v.theta;
    full.lo = -0.5 * kPi;
    full.hi = 0.5 * kPi;
    const double m = full.Mass();
    s->prob[k] = tg.weight * w.angles.proj * (m > 0.0 ? w.cone_v.mass / m : 0.0);
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

// Per tangent, only what depends on wi is computed here (brdf/microcylinder.h Scatter; the
// wo part is in the memo).
Rgbd SadeghiBsdf::Eval(const Vec3d& wo, const Vec3d& wi, const ShadingPoint&) const {
  if (!(wo.z > 0.0) || !(wi.z > 0.0)) return Rgbd(0, 0, 0);
  const WoState& s = StateFor(wo);
  Rgbd sum(0, 0, 0);
  for (size_t k = 0; k < tangents_.size(); ++k) {
    const microcylinder::Tangent& tg = tangents_[k];
    double surface = 0.0, volume = 0.0;
    if (!microcylinder::Scatter(tg, s.tg[k].angles, optics_[tg.thread], wi, &surface, &volume))
      continue;
    sum += Rgbd::Splat(surface) + fabric_.thread[tg.thread].albedo * volume;
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
