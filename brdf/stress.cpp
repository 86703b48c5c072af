#include "brdf/stress.h"

#include <ceres/jet.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>

#include "brdf/microcylinder.h"
#include "brdf/yarn_lobe.h"

namespace clothfit::stress {
namespace {

constexpr int kMaxParams = kMaxModelParameters;  // Jet slots: one per parameter
using Jet = ceres::Jet<double, kMaxParams>;

constexpr std::array<double, 8> kAdversarialCos{0.0, 1e-8,       1e-4,  1.0 - 1e-7,
                                                1.0, 1.0 + 1e-7, -1e-8, -0.3};

// SplitMix64: a counter-based generator, so chunk k's stream depends only on (seed, k).
struct SplitMix {
  uint64_t s;
  uint64_t Next() {
    uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double Uniform() { return double(Next() >> 11) * 0x1.0p-53; }
  int Index(int n) { return int(Next() % uint64_t(n)); }
};

struct Input {
  std::array<double, kMaxParams> x{};
  Cosines<double> c{};
  TangentCosines<double> t{};  // raw tangent-frame cosines (read by anisotropic models only)
};

// Which flat parameters are roughness-like (clamped by the engine).
std::vector<bool> ClampedFlags(ModelId m) {
  std::vector<bool> out;
  auto fill = [&](std::span<const ParamInfo> table) {
    for (const ParamInfo& p : table)
      for (int c = 0; c < p.size; ++c)
        out.push_back(std::string_view(p.name).find("roughness") != std::string_view::npos);
  };
  switch (m) {
    case ModelId::kStandard: fill(standard::kParameterTable); break;
    case ModelId::kPhysicalSheen: fill(physical_sheen::kParameterTable); break;
    case ModelId::kGltfSheen: fill(gltf_sheen::kParameterTable); break;
    case ModelId::kWoven: fill(woven::kParameterTable); break;
    case ModelId::kPhysicalAniso: fill(physical_aniso::kParameterTable); break;
    default: fill(cloth::kParameterTable); break;
  }
  return out;
}

Input Draw(ModelId m, SplitMix& rng) {
  Input in;
  const int n = ParameterCount(m);
  std::array<double, kMaxParams> lo{}, hi{};
  FlatBounds(m, lo.data(), hi.data());
  // Colours and metalness stay inside [0, 1] (out-of-range values are rejected as bad input
  // before they reach a model); roughness parameters, which the engines clamp, also go
  // beyond their clamps on both sides.
  const std::vector<bool> clamped = ClampedFlags(m);
  const int mode = rng.Index(4);
  for (int k = 0; k < n; ++k) {
    const double span = hi[k] - lo[k];
    const bool beyond = clamped[size_t(k)];
    if (mode == 0 || (mode == 1 && !beyond)) {  // in range
      in.x[k] = lo[k] + span * rng.Uniform();
    } else if (mode == 1) {  // up to 10 % beyond either bound
      in.x[k] = lo[k] - 0.1 * span + 1.2 * span * rng.Uniform();
    } else if (!beyond) {  // adversarial: a bound
      in.x[k] = rng.Index(2) ? hi[k] : lo[k];
    } else {  // adversarial: a bound, 0, 1, or beyond the clamps
      const std::array<double, 7> picks{lo[k], hi[k], 0.0, 1.0, lo[k] * 0.5, -0.05, 1.05};
      in.x[k] = picks[size_t(rng.Index(int(picks.size())))];
    }
  }
  const int cmode = rng.Index(3);
  if (cmode == 0) {  // consistent geometry from random directions on the sphere
    auto dir = [&]() {
      const double z = 2.0 * rng.Uniform() - 1.0;
      const double phi = 2.0 * kPi * rng.Uniform();
      const double s = std::sqrt(std::max(0.0, 1.0 - z * z));
      return Vec3<double>(s * std::cos(phi), s * std::sin(phi), z);
    };
    const Vec3<double> v = dir(), l = dir();
    in.c = CosinesFromDirections(v, l);
    in.t = TangentCosinesFromDirections(v, l);
  } else if (cmode == 1) {  // independent raw cosines
    auto u = [&]() { return -0.25 + 1.5 * rng.Uniform(); };
    in.c = {u(), u(), u(), u()};
    auto w = [&]() { return -1.25 + 2.5 * rng.Uniform(); };
    in.t = {w(), w(), w(), w(), w(), w()};
  } else {  // adversarial cosines
    auto a = [&]() { return kAdversarialCos[size_t(rng.Index(int(kAdversarialCos.size())))]; };
    in.c = {a(), a(), a(), a()};
    // tangent cosines: 0, +-1 (h along t or b) and the adversarial set
    auto b = [&]() {
      const int k = rng.Index(int(kAdversarialCos.size()) + 2);
      return k < int(kAdversarialCos.size()) ? kAdversarialCos[size_t(k)] : (k % 2 ? -1.0 : 1.0);
    };
    in.t = {b(), b(), b(), b(), b(), b()};
  }
  return in;
}

template <typename T>
bool Finite(const T& v) {
  if constexpr (std::is_arithmetic_v<T>) {
    return std::isfinite(v);
  } else {
    return ceres::isfinite(v);  // value and every derivative
  }
}

std::string Describe(ModelId m, const Input& in, const char* what) {
  std::ostringstream os;
  os.precision(9);
  os << what << " at NoV=" << in.c.NoV << " NoL=" << in.c.NoL << " NoH=" << in.c.NoH
     << " LoH=" << in.c.LoH << " ToV,BoV,ToL,BoL,ToH,BoH=" << in.t.ToV << "," << in.t.BoV << ","
     << in.t.ToL << "," << in.t.BoL << "," << in.t.ToH << "," << in.t.BoH << " params=[";
  for (int k = 0; k < ParameterCount(m); ++k) os << (k ? "," : "") << in.x[size_t(k)];
  os << "]";
  return os.str();
}

struct Tally {
  int64_t evaluations = 0, non_finite = 0, negative = 0;
  double max_dev = 0.0;
  Input worst;  // input of the largest float deviation
  std::string first_failure;
  void Fail(std::string msg) {
    if (first_failure.empty()) first_failure = std::move(msg);
  }
};

void EvaluateOne(ModelId m, const Input& in, Tally& t) {
  const int n = ParameterCount(m);
  // double
  Rgb<double> dd, di;
  EvaluateFlat<double>(m, in.x.data(), in.c, dd, di, &in.t);
  // float
  std::array<float, kMaxParams> xf{};
  for (int k = 0; k < n; ++k) xf[size_t(k)] = float(in.x[size_t(k)]);
  const Cosines<float> cf{float(in.c.NoV), float(in.c.NoL), float(in.c.NoH), float(in.c.LoH)};
  Rgb<float> fd, fi;
  const TangentCosines<float> tf{float(in.t.ToV), float(in.t.BoV), float(in.t.ToL),
                                 float(in.t.BoL), float(in.t.ToH), float(in.t.BoH)};
  EvaluateFlat<float>(m, xf.data(), cf, fd, fi, &tf);
  // Jet: one derivative slot per parameter
  std::array<Jet, kMaxParams> xj{};
  for (int k = 0; k < n; ++k) xj[size_t(k)] = Jet(in.x[size_t(k)], k);
  const Cosines<Jet> cj{Jet(in.c.NoV), Jet(in.c.NoL), Jet(in.c.NoH), Jet(in.c.LoH)};
  Rgb<Jet> jd, ji;
  const TangentCosines<Jet> tj{Jet(in.t.ToV), Jet(in.t.BoV), Jet(in.t.ToL),
                               Jet(in.t.BoL), Jet(in.t.ToH), Jet(in.t.BoH)};
  EvaluateFlat<Jet>(m, xj.data(), cj, jd, ji, &tj);

  ++t.evaluations;
  bool bad_finite = false, bad_negative = false;
  for (int ch = 0; ch < 3; ++ch) {
    const double d[2] = {dd[ch], di[ch]};
    const float f[2] = {fd[ch], fi[ch]};
    const Jet* j[2] = {&jd[ch], &ji[ch]};
    for (int k = 0; k < 2; ++k) {
      if (!std::isfinite(d[k]) || !std::isfinite(f[k]) || !Finite(*j[k])) bad_finite = true;
      if (d[k] < 0.0 || f[k] < 0.0f || j[k]->a < 0.0) bad_negative = true;
      if (std::isfinite(d[k]) && std::isfinite(f[k])) {
        const double dev = std::abs(double(f[k]) - d[k]) / std::max(std::abs(d[k]), 1e-3);
        if (dev > t.max_dev) {
          t.max_dev = dev;
          t.worst = in;
        }
      }
    }
  }
  if (bad_finite) {
    ++t.non_finite;
    t.Fail(Describe(m, in, "non-finite"));
  }
  if (bad_negative) {
    ++t.negative;
    t.Fail(Describe(m, in, "negative"));
  }
}

// Session 19: woven's microcylinder lobe (brdf/microcylinder.h through yarn_lobe::Lobe, which
// merges duplicate tangents and caches the wo-only work): `count` evaluations over random
// fabrics (every constant uniform in its documented range, a quarter of them at a bound: eta
// 1 + 1e-9 or 3 - 1e-9, kd 0 or 1, widths 1e-3 or 90 degrees, a_1 + a_2 = 1, offsets +-90 or 0,
// repeated offsets) and directions (uniform, and adversarial: z in {0, 1e-12, 1e-8, 1}, wi = wo,
// the mirror direction, wi or wo along a fibre tangent, below the surface). A new fabric every
// 16 evaluations. Counts non-finite and negative values of both outputs; the lobe is evaluated
// in double only (the browser's float version is tested against it in tests/browser/unit.mjs).
void EvaluateMicrocylinder(int64_t count, SplitMix& rng, Tally& t) {
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * rng.Uniform(); };
  auto bound = [&]() { return rng.Index(4) == 0; };
  auto dir = [&](double z) {
    const double phi = uniform(0.0, 2.0 * kPi), r = std::sqrt(std::max(0.0, 1.0 - z * z));
    return Vec3<double>(r * std::cos(phi), r * std::sin(phi), z);
  };
  constexpr std::array<double, 6> kZ{0.0, 1e-12, 1e-8, 1.0, -1e-8, -0.3};
  yarn_lobe::FarField f;
  f.kind = yarn_lobe::FarField::Kind::kMicrocylinder;
  std::vector<microcylinder::Tangent> tangents;
  std::unique_ptr<yarn_lobe::Lobe> lobe;
  for (int64_t e = 0; e < count; ++e) {
    if (e % 16 == 0) {
      for (int j = 0; j < 2; ++j) {
        microcylinder::Thread& th = f.threads[j];
        th.eta = bound() ? (rng.Index(2) ? 1.0 + 1e-9 : 3.0 - 1e-9) : uniform(1.0 + 1e-6, 3.0 - 1e-6);
        th.kd = bound() ? double(rng.Index(2)) : rng.Uniform();
        th.gamma_s = bound() ? (rng.Index(2) ? 1e-3 : 90.0) : uniform(0.5, 90.0);
        th.gamma_v = bound() ? (rng.Index(2) ? 1e-3 : 90.0) : uniform(0.5, 90.0);
        th.volume_scale = bound() ? double(rng.Index(2)) : rng.Uniform();
        th.offsets.assign(size_t(1 + rng.Index(8)), 0.0);
        for (double& o : th.offsets) o = bound() ? 90.0 * double(rng.Index(3) - 1) : uniform(-90.0, 90.0);
        if (rng.Index(4) == 0) th.offsets.push_back(th.offsets.front());  // a repeated offset
      }
      f.threads[0].a = bound() ? double(rng.Index(2)) : rng.Uniform();
      f.threads[1].a = bound() ? 1.0 - f.threads[0].a : rng.Uniform() * (1.0 - f.threads[0].a);
      lobe = std::make_unique<yarn_lobe::Lobe>(f);
      tangents = microcylinder::MakeTangents(f.threads);
    }
    Vec3<double> wo = rng.Index(3) ? dir(rng.Uniform()) : dir(kZ[size_t(rng.Index(int(kZ.size())))]);
    Vec3<double> wi = dir(rng.Uniform());
    switch (rng.Index(6)) {
      case 0: wi = dir(kZ[size_t(rng.Index(int(kZ.size())))]); break;
      case 1: wi = wo; break;
      case 2: wi = Vec3<double>(-wo.x, -wo.y, wo.z); break;
      case 3: {
        const Vec3<double> tg = tangents[size_t(rng.Index(int(tangents.size())))].t;
        (rng.Index(2) ? wi : wo) = tg * (rng.Index(2) ? 1.0 : -1.0);
        break;
      }
      default: break;
    }
    double v[2];
    lobe->Eval(wo, wi, v);
    ++t.evaluations;
    if (!std::isfinite(v[0]) || !std::isfinite(v[1])) {
      ++t.non_finite;
      std::ostringstream os;
      os.precision(17);
      os << "non-finite at wo=(" << wo.x << "," << wo.y << "," << wo.z << ") wi=(" << wi.x << ","
         << wi.y << "," << wi.z << ")";
      t.Fail(os.str());
    } else if (v[0] < 0.0 || v[1] < 0.0) {
      ++t.negative;
      t.Fail("negative");
    }
  }
}

}  // namespace

Report Run(int64_t evals, uint64_t seed, const std::function<void(int64_t, int64_t)>& progress) {
  // Build the shared tables before the parallel section (and outside any timing).
  (void)lut::DefaultDfg();
  (void)lut::DefaultSheenAlbedo();
  (void)lut::DefaultWovenPhase();

  // kAllModels, then woven's microcylinder lobe (session 19) as one more row
  const int num_models = int(kAllModels.size()) + 1;
  const int64_t per_model = (evals + num_models - 1) / num_models;
  constexpr int64_t kChunk = 4096;
  const int64_t chunks_per_model = (per_model + kChunk - 1) / kChunk;
  const int64_t total_chunks = chunks_per_model * num_models;

  std::vector<Tally> tallies(static_cast<size_t>(total_chunks));
  std::atomic<int64_t> done{0};
  std::mutex progress_mutex;
  tbb::parallel_for(int64_t(0), total_chunks, [&](int64_t chunk) {
    const int mi = int(chunk / chunks_per_model);
    const int64_t ci = chunk % chunks_per_model;
    const int64_t begin = ci * kChunk;
    const int64_t end = std::min(per_model, begin + kChunk);
    SplitMix rng{seed * 0x100000001B3ull + uint64_t(chunk) * 0x9E3779B97F4A7C15ull};
    Tally& t = tallies[size_t(chunk)];
    if (mi == int(kAllModels.size())) {
      EvaluateMicrocylinder(end - begin, rng, t);
    } else {
      const ModelId m = kAllModels[size_t(mi)];
      for (int64_t e = begin; e < end; ++e) EvaluateOne(m, Draw(m, rng), t);
    }
    const int64_t d = done.fetch_add(end - begin) + (end - begin);
    if (progress) {
      std::lock_guard<std::mutex> lock(progress_mutex);
      progress(d, per_model * num_models);
    }
  });

  Report r;
  for (int mi = 0; mi < num_models; ++mi) {
    const bool lobe = mi == int(kAllModels.size());
    ModelReport mr;
    mr.model = lobe ? std::string("woven lobe: microcylinder") : std::string(ModelName(kAllModels[size_t(mi)]));
    for (int64_t ci = 0; ci < chunks_per_model; ++ci) {  // merge in chunk order: deterministic
      const Tally& t = tallies[size_t(mi * chunks_per_model + ci)];
      mr.evaluations += t.evaluations;
      mr.non_finite += t.non_finite;
      mr.negative += t.negative;
      if (!lobe && t.max_dev > mr.max_rel_float_dev) {
        mr.max_rel_float_dev = t.max_dev;
        mr.worst_float_deviation =
            Describe(kAllModels[size_t(mi)], t.worst, "largest float deviation");
      }
      if (mr.first_failure.empty()) mr.first_failure = t.first_failure;
    }
    r.evaluations += mr.evaluations;
    r.non_finite += mr.non_finite;
    r.negative += mr.negative;
    r.models.push_back(std::move(mr));
  }
  return r;
}

}  // namespace clothfit::stress
