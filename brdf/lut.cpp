#include "brdf/lut.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <type_traits>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <unistd.h>

#include "brdf/terms.h"

namespace clothfit::lut {
namespace {

// Panel breakpoints in theta_h: uniform every pi/8, plus points clustered where the
// distribution varies on its own scale (GGX: tan(theta) = alpha s near the normal;
// Charlie: pi/2 - sqrt(alpha) s near the tangent plane).
std::vector<double> Breakpoints(double alpha, bool charlie) {
  std::vector<double> b;
  for (int k = 0; k <= 4; ++k) b.push_back(k * kPi / 8.0);
  for (double s : {0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 64.0}) {
    b.push_back(charlie ? 0.5 * kPi - std::sqrt(alpha) * s : std::atan(alpha * s));
  }
  std::vector<double> out;
  std::sort(b.begin(), b.end());
  for (double t : b) {
    if (t < 0.0 || t > 0.5 * kPi) continue;
    if (out.empty() || t - out.back() > 1e-9) out.push_back(t);
  }
  return out;
}

// int over the hemisphere of directions l of f(l) where f(l) = D(h) g(h, l) and the change
// of variables dl = 4 (v.h) dh is applied by the caller's g. Integrates in the half vector:
//   int_0^{pi/2} int_{valid phi} D(theta_h) g sin(theta_h) dphi dtheta_h,
// with Gauss-Legendre panels in theta_h and midpoints over the azimuth arc where
// n.l = 2 (v.h) cos(theta_h) - NoV > 0 (solved in closed form, so the integrand has no
// discontinuity in phi), using the mirror symmetry about the plane of n and v.
// `g` returns an std::array of integrands (several channels share one quadrature).
template <typename DFn, typename GFn,
          typename Acc = std::invoke_result_t<GFn, double, double, double>>
Acc HalfVectorIntegral(double NoV, double alpha, bool charlie, const Settings& s, DFn D, GFn g) {
  static thread_local GaussLegendre gl_cache(8);
  if (int(gl_cache.x.size()) != s.gauss_legendre_order)
    gl_cache = GaussLegendre(s.gauss_legendre_order);
  const GaussLegendre& gl = gl_cache;
  const double sin_v = std::sqrt(std::max(0.0, 1.0 - NoV * NoV));
  const Vec3<double> v(sin_v, 0.0, NoV);
  const std::vector<double> br = Breakpoints(alpha, charlie);
  Acc total{};
  for (size_t p = 0; p + 1 < br.size(); ++p) {
    const double t0 = br[p], t1 = br[p + 1];
    for (size_t k = 0; k < gl.x.size(); ++k) {
      const double th = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * gl.x[k];
      const double wt = 0.5 * (t1 - t0) * gl.w[k];
      const double ch = std::cos(th), sh = std::sin(th);
      // n.l > 0  <=>  cos(phi) > (NoV / (2 cos_h) - NoV cos_h) / (sin_v sin_h)
      const double num = NoV / (2.0 * ch) - NoV * ch;
      const double den = sin_v * sh;
      double phi_max;
      if (den < 1e-12) {
        phi_max = num < 0.0 ? kPi : 0.0;
      } else {
        const double c0 = num / den;
        phi_max = c0 <= -1.0 ? kPi : (c0 >= 1.0 ? 0.0 : std::acos(c0));
      }
      if (phi_max <= 0.0) continue;
      Acc acc{};
      // Midpoints phi_b = (b + 0.5) dphi by rotation recurrence (no sincos per sample).
      const double dphi = phi_max / s.azimuth_samples;
      const double cd = std::cos(dphi), sd = std::sin(dphi);
      double cphi = std::cos(0.5 * dphi), sphi = std::sin(0.5 * dphi);
      for (int b = 0; b < s.azimuth_samples; ++b) {
        const Vec3<double> h(sh * cphi, sh * sphi, ch);
        const double c_next = cphi * cd - sphi * sd;
        sphi = sphi * cd + cphi * sd;
        cphi = c_next;
        const double VoH = Dot(v, h);
        const double NoL = 2.0 * VoH * ch - NoV;
        if (NoL <= 0.0 || VoH <= 0.0) continue;
        const Acc x = g(NoL, VoH, ch);
        for (size_t m = 0; m < x.size(); ++m) acc[m] += x[m];
      }
      // 2 phi_max: both halves of the symmetric arc
      const double scale = wt * D(ch) * sh * 2.0 * phi_max / s.azimuth_samples;
      for (size_t m = 0; m < acc.size(); ++m) total[m] += scale * acc[m];
    }
  }
  return total;
}

}  // namespace

void IntegrateGgx(double NoV, double r, const Settings& s, double& A, double& B) {
  const double alpha = std::max(r * r, kMinAlpha);
  // f cos dl = D V F NoL 4 VoH dh; A and B share one quadrature.
  auto D = [alpha](double ch) { return D_GGX(alpha, ch); };
  const std::array<double, 2> ab =
      HalfVectorIntegral(NoV, alpha, false, s, D, [&](double NoL, double VoH, double) {
        const double w = V_SmithGGXCorrelated(alpha, NoV, NoL) * NoL * 4.0 * VoH;
        const double Fc = Pow5(1.0 - VoH);
        return std::array<double, 2>{w * (1.0 - Fc), w * Fc};
      });
  A = ab[0];
  B = ab[1];
}

double IntegrateClothDg(double NoV, double r, const Settings& s) {
  const double alpha = std::max(r * r, kMinAlpha);
  return HalfVectorIntegral(
      NoV, alpha, true, s, [alpha](double ch) { return D_Charlie(alpha, ch, false); },
      [&](double NoL, double VoH, double) {
        return std::array<double, 1>{V_Neubelt(NoV, NoL) * NoL * 4.0 * VoH};
      })[0];
}

double IntegrateSheenAlbedo(double NoV, double r, const Settings& s) {
  const double alpha = std::max(r * r, kMinAlpha);
  return HalfVectorIntegral(
      NoV, alpha, true, s, [alpha](double ch) { return D_Charlie(alpha, ch, false); },
      [&](double NoL, double VoH, double) {
        return std::array<double, 1>{V_Charlie(NoV, NoL, alpha) * NoL * 4.0 * VoH};
      })[0];
}

std::array<double, 9> IntegrateWovenPhase(double NoV, double r, const Settings& s) {
  const double alpha = std::max(r * r, kMinAlpha);
  auto D = [alpha](double ch) { return D_GGX(alpha, ch); };
  return HalfVectorIntegral(NoV, alpha, false, s, D, [&](double NoL, double VoH, double) {
    const double w = V_SmithGGXCorrelated(alpha, NoV, NoL) * NoL * 4.0 * VoH;
    std::array<double, 9> out{};
    for (size_t k = 0; k < out.size(); ++k)
      out[k] = w * std::exp(-2.0 * kWovenPhaseBetas[k] * VoH * VoH);
    return out;
  });
}

namespace {
template <typename RowFn>
void ParallelRows(int rows, const Progress& progress, RowFn fn) {
  std::atomic<int> done{0};
  tbb::parallel_for(0, rows, [&](int j) {
    fn(j);
    const int d = ++done;
    if (progress) progress(d, rows);
  });
}
}  // namespace

namespace {

// One texel of each table; ComputeX and the cache's spot check both use these, so a cached
// texel and a recomputed one are bit-identical unless the integrator changed.
void DfgTexel(int i, int j, const Settings& s, float* out) {
  const double r = Table2D::Centre(j, s.size), NoV = Table2D::Centre(i, s.size);
  double A, B;
  IntegrateGgx(NoV, r, s, A, B);
  out[0] = float(A);
  out[1] = float(B);
  out[2] = float(IntegrateClothDg(NoV, r, s));
}

void SheenTexel(int i, int j, const Settings& s, float* out) {
  out[0] = float(IntegrateSheenAlbedo(Table2D::Centre(i, s.size), Table2D::Centre(j, s.size), s));
}

void WovenPhaseTexel(int i, int j, const Settings& s, float* out) {
  const std::array<double, 9> p =
      IntegrateWovenPhase(Table2D::Centre(i, s.size), Table2D::Centre(j, s.size), s);
  for (size_t k = 0; k < p.size(); ++k) out[k] = float(p[k]);
}

using TexelFn = void (*)(int, int, const Settings&, float*);

Table2D Compute(const Settings& s, int channels, TexelFn texel, const Progress& progress) {
  Table2D t(s.size, s.size, channels);
  ParallelRows(s.size, progress, [&](int j) {
    for (int i = 0; i < s.size; ++i) texel(i, j, s, &t.at(i, j, 0));
  });
  return t;
}

// ---- On-disk cache of the default tables ---------------------------------------------------
// Building the DFG table costs ~0.8 s of quadrature on 2 cores, paid by every process that
// touches the IBL (fit, preview, report...). The tables are cached as raw float files in
// $CLOTHFIT_TABLE_CACHE (default ${XDG_CACHE_HOME:-$HOME/.cache}/clothfit/tables; "off"
// disables). A cached file is used only if (1) its header matches the table's name, size and
// quadrature settings, (2) the FNV-1a checksum of its floats matches (corruption), and (3) 16
// spot texels recomputed now are bit-identical to the cached ones (a file left by an older
// integrator: any change to the integrand or quadrature moves these values). Otherwise the
// table is recomputed and the file rewritten atomically (temporary file + rename).

uint64_t Fnv1a(const void* data, size_t n) {
  uint64_t h = 0xcbf29ce484222325ull;
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

std::string CacheDir() {
  if (const char* d = std::getenv("CLOTHFIT_TABLE_CACHE")) return d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/clothfit/tables";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/clothfit/tables";
  return "";
}

std::string Header(const std::string& name, const Settings& s, int channels) {
  return "clothfit-table v1 " + name + " size=" + std::to_string(s.size) +
         " gl=" + std::to_string(s.gauss_legendre_order) + " az=" + std::to_string(s.azimuth_samples) +
         " channels=" + std::to_string(channels) + "\n";
}

bool SpotCheck(const Table2D& t, const Settings& s, TexelFn texel) {
  for (int k = 0; k < 16; ++k) {
    // Deterministic spread over the table, corners included.
    const int i = k == 0 ? 0 : k == 1 ? s.size - 1 : int((uint32_t(k) * 2654435761u) % uint32_t(s.size));
    const int j = k == 0 ? 0 : k == 1 ? s.size - 1 : int((uint32_t(k) * 40503u + 7u) % uint32_t(s.size));
    float v[16] = {};
    texel(i, j, s, v);
    for (int c = 0; c < t.channels; ++c)
      if (std::memcmp(&v[c], &t.data[(size_t(j) * size_t(t.width) + size_t(i)) * size_t(t.channels) + size_t(c)],
                      sizeof(float)) != 0)
        return false;
  }
  return true;
}

std::optional<Table2D> ReadCached(const std::string& path, const std::string& header,
                                  const Settings& s, int channels, TexelFn texel) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::string line;
  if (!std::getline(in, line) || line + "\n" != header) return std::nullopt;
  Table2D t(s.size, s.size, channels);
  uint64_t sum = 0;
  in.read(reinterpret_cast<char*>(t.data.data()), std::streamsize(t.data.size() * sizeof(float)));
  in.read(reinterpret_cast<char*>(&sum), sizeof sum);
  if (!in || in.peek() != std::char_traits<char>::eof()) return std::nullopt;
  if (sum != Fnv1a(t.data.data(), t.data.size() * sizeof(float))) return std::nullopt;
  if (!SpotCheck(t, s, texel)) return std::nullopt;
  return t;
}

void WriteCached(const std::string& path, const std::string& header, const Table2D& t) {
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(path).parent_path(), ec);
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    const uint64_t sum = Fnv1a(t.data.data(), t.data.size() * sizeof(float));
    out << header;
    out.write(reinterpret_cast<const char*>(t.data.data()), std::streamsize(t.data.size() * sizeof(float)));
    out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
    if (!out) {
      std::filesystem::remove(tmp, ec);
      return;  // a cache that cannot be written is not an error: the table is still correct
    }
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) std::filesystem::remove(tmp, ec);
}

Table2D LoadOrCompute(const std::string& name, const Settings& s, int channels, TexelFn texel,
                      const char* u_axis, const char* v_axis) {
  const std::string dir = CacheDir();
  const bool use_cache = !dir.empty() && dir != "off";
  const std::string header = Header(name, s, channels);
  const std::string path = use_cache ? dir + "/" + name + "-" + std::to_string(s.size) + ".bin" : "";
  std::optional<Table2D> t;
  if (use_cache) t = ReadCached(path, header, s, channels, texel);
  if (!t) {
    t = Compute(s, channels, texel, {});
    if (use_cache) WriteCached(path, header, *t);
  }
  t->u_axis = u_axis;
  t->v_axis = v_axis;
  return std::move(*t);
}

constexpr const char* kNoVAxis = "NoV = (i + 0.5) / N";
constexpr const char* kDfgVAxis = "perceptual roughness r = (j + 0.5) / N; alpha = r^2";
constexpr const char* kWovenPhaseVAxis =
    "perceptual roughness r = (j + 0.5) / N; alpha = r^2; channel k: beta = kWovenPhaseBetas[k]";
constexpr const char* kSheenVAxis = "sheen roughness r_s = (j + 0.5) / N; alpha = r_s^2";

}  // namespace

Table2D ComputeDfg(const Settings& s, const Progress& progress) {
  Table2D t = Compute(s, 3, DfgTexel, progress);
  t.u_axis = kNoVAxis;
  t.v_axis = kDfgVAxis;
  return t;
}

Table2D ComputeSheenAlbedo(const Settings& s, const Progress& progress) {
  Table2D t = Compute(s, 1, SheenTexel, progress);
  t.u_axis = kNoVAxis;
  t.v_axis = kSheenVAxis;
  return t;
}

Table2D ComputeWovenPhase(const Settings& s, const Progress& progress) {
  Table2D t = Compute(s, 9, WovenPhaseTexel, progress);
  t.u_axis = kNoVAxis;
  t.v_axis = kWovenPhaseVAxis;
  return t;
}

Table2D CachedWovenPhase(const Settings& s) {
  return LoadOrCompute("woven-phase", s, 9, WovenPhaseTexel, kNoVAxis, kWovenPhaseVAxis);
}

Table2D CachedDfg(const Settings& s) {
  return LoadOrCompute("dfg", s, 3, DfgTexel, kNoVAxis, kDfgVAxis);
}

Table2D CachedSheenAlbedo(const Settings& s) {
  return LoadOrCompute("sheen-albedo", s, 1, SheenTexel, kNoVAxis, kSheenVAxis);
}

const Table2D& DefaultDfg() {
  static const Table2D table = CachedDfg(Settings{128});
  return table;
}

const Table2D& DefaultWovenPhase() {
  static const Table2D table = CachedWovenPhase(Settings{32});
  return table;
}

const Table2D& DefaultSheenAlbedo() {
  static const Table2D table = CachedSheenAlbedo(Settings{32});
  return table;
}

}  // namespace clothfit::lut
