// render/preview/threejs_ibl.cpp: see threejs_ibl.h. Written from the behaviour described in
// docs/preview-threejs.md (what three.js r187's PMREMGenerator and shader chunks compute);
// no three.js code is used.
#include "render/preview/threejs_ibl.h"

#include "render/scene/sampler.h"  // RadicalInverse2

#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <tuple>

#include "brdf/lut.h"
#include "render/preview/preview.h"

namespace clothfit::render {
namespace {

using V3 = Vec3<double>;

// OpenGL cube face selection (ES 3.0 table 3.21): face, and (s, t) in [-1, 1].
void DirToFace(const V3& d, int* face, double* s, double* t) {
  const double ax = std::abs(d.x), ay = std::abs(d.y), az = std::abs(d.z);
  double sc, tc, ma;
  if (ax >= ay && ax >= az) {
    *face = d.x > 0 ? 0 : 1;
    ma = ax;
    sc = d.x > 0 ? -d.z : d.z;
    tc = -d.y;
  } else if (ay >= az) {
    *face = d.y > 0 ? 2 : 3;
    ma = ay;
    sc = d.x;
    tc = d.y > 0 ? d.z : -d.z;
  } else {
    *face = d.z > 0 ? 4 : 5;
    ma = az;
    sc = d.z > 0 ? d.x : -d.x;
    tc = -d.y;
  }
  *s = sc / ma;
  *t = tc / ma;
}

V3 FaceToDir(int face, double s, double t) {
  switch (face) {
    case 0: return {1.0, -t, -s};
    case 1: return {-1.0, -t, s};
    case 2: return {s, 1.0, t};
    case 3: return {s, -1.0, -t};
    case 4: return {s, -t, 1.0};
    default: return {-s, -t, -1.0};
  }
}

double Coord(int i, int n) { return (i + 0.5) / n * 2.0 - 1.0; }

// Texel (face, ix, iy) of a level, where at most one of ix, iy may lie one texel outside
// [0, n - 1]: then the texel across that edge on the adjacent face (seamless cube filtering).
// Returns false for a corner (both outside).
bool Fetch(const ThreejsPmrem::Level& L, int face, int ix, int iy, float out[3]) {
  const int n = L.n;
  const bool ox = ix < 0 || ix >= n, oy = iy < 0 || iy >= n;
  if (ox && oy) return false;
  if (!ox && !oy) {
    const float* p = L.texel(face, ix, iy);
    out[0] = p[0];
    out[1] = p[1];
    out[2] = p[2];
    return true;
  }
  V3 P = FaceToDir(face, Coord(ix, n), Coord(iy, n));
  double* c[3] = {&P.x, &P.y, &P.z};
  int over = -1, major = -1;
  for (int k = 0; k < 3; ++k) {
    const double a = std::abs(*c[k]);
    if (a > 1.0 + 0.5 / n) over = k;
    else if (a == 1.0) major = k;
  }
  // The overflowing axis becomes the major axis; the old major coordinate moves to the last
  // texel centre before the edge; the third coordinate is unchanged.
  *c[over] = std::copysign(1.0, *c[over]);
  *c[major] = std::copysign(1.0 - 1.0 / n, *c[major]);
  int f;
  double s, t;
  DirToFace(P, &f, &s, &t);
  const int jx = std::clamp(int(std::lround((s + 1.0) * 0.5 * n - 0.5)), 0, n - 1);
  const int jy = std::clamp(int(std::lround((t + 1.0) * 0.5 * n - 0.5)), 0, n - 1);
  const float* p = L.texel(f, jx, jy);
  out[0] = p[0];
  out[1] = p[1];
  out[2] = p[2];
  return true;
}

// Van der Corput radical inverse in base 2 (32-bit bit reversal).
double VdC(uint32_t b) {
  b = (b << 16u) | (b >> 16u);
  b = ((b & 0x55555555u) << 1u) | ((b & 0xAAAAAAAAu) >> 1u);
  b = ((b & 0x33333333u) << 2u) | ((b & 0xCCCCCCCCu) >> 2u);
  b = ((b & 0x0F0F0F0Fu) << 4u) | ((b & 0xF0F0F0F0u) >> 4u);
  b = ((b & 0x00FF00FFu) << 8u) | ((b & 0xFF00FF00u) >> 8u);
  return double(b) * 2.3283064365386963e-10;
}

// Bilinear equirect read with clamp-to-edge (three.js DataTexture defaults), map space.
void Equirect(const Environment& env, const V3& d, double out[3]) {
  const int W = env.width(), H = env.height();
  const double u = std::atan2(d.z, d.x) / (2.0 * kPi) + 0.5;
  const double v = std::asin(std::clamp(d.y, -1.0, 1.0)) / kPi + 0.5;
  const double x = u * W - 0.5, y = v * H - 0.5;  // y: GL rows from the bottom
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  const std::vector<float>& px = env.pixels();
  auto tex = [&](int i, int j, int c) {
    i = std::clamp(i, 0, W - 1);
    j = std::clamp(j, 0, H - 1);
    return double(px[(size_t(H - 1 - j) * size_t(W) + size_t(i)) * 3 + size_t(c)]);
  };
  for (int c = 0; c < 3; ++c) {
    out[c] = (1 - fy) * ((1 - fx) * tex(x0, y0, c) + fx * tex(x0 + 1, y0, c)) +
             fy * ((1 - fx) * tex(x0, y0 + 1, c) + fx * tex(x0 + 1, y0 + 1, c));
  }
}

ThreejsPmrem::Level MakeLevel(int n) {
  ThreejsPmrem::Level L;
  L.n = n;
  L.rgb.assign(size_t(6) * size_t(n) * size_t(n) * 3, 0.f);
  return L;
}

// Runs f(face, i, j) over every texel of an n x n cube level, in parallel over rows.
template <typename F>
void ForEachTexel(int n, const F& f) {
  tbb::parallel_for(0, 6 * n, [&](int row) {
    const int face = row / n, j = row % n;
    for (int i = 0; i < n; ++i) f(face, i, j);
  });
}

}  // namespace

float RoundToHalf(float x) {
  if (!std::isfinite(x) || x == 0.f) return x;
  const float a = std::fabs(x);
  int e;
  std::frexp(a, &e);
  const float ulp = std::ldexp(1.f, std::max(e - 11, -24));
  const float r = std::nearbyint(a / ulp) * ulp;  // default rounding: ties to even
  return std::copysign(std::min(r, 65504.f), x);
}

V3 ThreejsPmrem::TexelDirection(int face, int i, int j, int n) {
  return FaceToDir(face, Coord(i, n), Coord(j, n));
}

void ThreejsPmrem::Bilinear(const Level& L, const V3& d, float out[3]) {
  int face;
  double s, t;
  DirToFace(d, &face, &s, &t);
  const int n = L.n;
  const double x = (s + 1.0) * 0.5 * n - 0.5, y = (t + 1.0) * 0.5 * n - 0.5;
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const float fx = float(x - x0), fy = float(y - y0);
  float tap[4][3];
  bool ok[4];
  ok[0] = Fetch(L, face, x0, y0, tap[0]);
  ok[1] = Fetch(L, face, x0 + 1, y0, tap[1]);
  ok[2] = Fetch(L, face, x0, y0 + 1, tap[2]);
  ok[3] = Fetch(L, face, x0 + 1, y0 + 1, tap[3]);
  for (int k = 0; k < 4; ++k) {
    if (ok[k]) continue;  // a cube corner: the mean of the three real texels
    for (int c = 0; c < 3; ++c) {
      float s3 = 0.f;
      for (int m = 0; m < 4; ++m)
        if (m != k) s3 += tap[m][c];
      tap[k][c] = s3 / 3.f;
    }
  }
  for (int c = 0; c < 3; ++c) {
    out[c] = (1 - fy) * ((1 - fx) * tap[0][c] + fx * tap[1][c]) +
             fy * ((1 - fx) * tap[2][c] + fx * tap[3][c]);
  }
}

void ThreejsPmrem::Trilinear(const std::vector<Level>& chain, const V3& d, double lod,
                             float out[3]) {
  const double top = double(chain.size() - 1);
  lod = std::clamp(lod, 0.0, top);
  const int l0 = int(std::floor(lod));
  const float f = float(lod - l0);
  Bilinear(chain[size_t(l0)], d, out);
  if (f > 0.f && l0 + 1 < int(chain.size())) {
    float b[3];
    Bilinear(chain[size_t(l0 + 1)], d, b);
    for (int c = 0; c < 3; ++c) out[c] += f * (b[c] - out[c]);
  }
}

void ThreejsPmrem::SetLookup(const Environment& env) {
  intensity_ = env.intensity();
  cos_rot_ = std::cos(env.rotation_y());
  sin_rot_ = std::sin(env.rotation_y());
}

ThreejsPmrem::ThreejsPmrem(const Environment& env) {
  SetLookup(env);
  int fp2 = 1;
  while (fp2 * 2 <= env.width() / 4) fp2 *= 2;
  size_ = std::max(256, fp2);
  const int log2s = int(std::lround(std::log2(double(size_))));
  max_lod_ = log2s - 3;

  // Source cube, mip 0: 2 x 2 supersampling with offsets of a quarter of the quad derivative.
  source_.push_back(MakeLevel(size_));
  {
    Level& L = source_[0];
    const int n = size_;
    auto dir = [n](int face, int i, int j) { return Normalize(TexelDirection(face, i, j, n)); };
    ForEachTexel(n, [&](int face, int i, int j) {
      const V3 d = dir(face, i, j);
      const int i0 = i & ~1, j0 = j & ~1;
      const V3 dx = (dir(face, i0 + 1, j) - dir(face, i0, j)) * 0.25;
      const V3 dy = (dir(face, i, j0 + 1) - dir(face, i, j0)) * 0.25;
      double acc[3] = {0, 0, 0};
      for (int sy = -1; sy <= 1; sy += 2)
        for (int sx = -1; sx <= 1; sx += 2) {
          double c[3];
          Equirect(env, Normalize(d + dx * double(sx) + dy * double(sy)), c);
          for (int k = 0; k < 3; ++k) acc[k] += c[k];
        }
      float* o = L.texel(face, i, j);
      for (int k = 0; k < 3; ++k) o[k] = RoundToHalf(float(acc[k] * 0.25));
    });
  }
  // Full mip chain: 2 x 2 box, fp16.
  for (int n = size_ / 2; n >= 1; n /= 2) {
    const Level& up = source_.back();
    Level L = MakeLevel(n);
    ForEachTexel(n, [&](int face, int i, int j) {
      float* o = L.texel(face, i, j);
      for (int k = 0; k < 3; ++k) {
        const float s = up.texel(face, 2 * i, 2 * j)[k] + up.texel(face, 2 * i + 1, 2 * j)[k] +
                        up.texel(face, 2 * i, 2 * j + 1)[k] + up.texel(face, 2 * i + 1, 2 * j + 1)[k];
        o[k] = RoundToHalf(0.25f * s);
      }
    });
    source_.push_back(std::move(L));
  }

  // PMREM levels.
  pmrem_.push_back(source_[0]);  // lod 0: roughness 0, a copy
  const double source_top = double(log2s);
  for (int lod = 1; lod <= max_lod_; ++lod) {
    const int n = size_ >> lod;
    const double r = 1.0 - std::sqrt(1.0 - double(lod) / double(max_lod_));
    const double alpha = r * r, a2 = alpha * alpha;
    Level L = MakeLevel(n);
    if (lod <= max_lod_ - 3) {
      const double bias = double(log2s) + 0.5 * std::log2(6.0 / (256.0 * a2)) + 0.5;
      ForEachTexel(n, [&](int face, int i, int j) {
        const V3 N = Normalize(TexelDirection(face, i, j, n));
        const V3 up = std::abs(N.z) < 0.999 ? V3(0, 0, 1) : V3(1, 0, 0);
        const V3 T = Normalize(Cross(up, N));
        const V3 B = Cross(N, T);
        double acc[3] = {0, 0, 0}, w = 0;
        for (uint32_t s = 0; s < 256; ++s) {
          const double x1 = double(s) / 256.0, x2 = VdC(s);
          const double invQ = 1.0 / (1.0 - x1 + a2 * x1);
          const double NoL = (1.0 - x1 - a2 * x1) * invQ;
          if (!(NoL > 0.0)) continue;
          const double phi = 2.0 * kPi * x2;
          const double sinT = 2.0 * alpha * std::sqrt(x1 * (1.0 - x1)) * invQ;
          const V3 Ld = N * NoL + (T * std::cos(phi) + B * std::sin(phi)) * sinT;
          const double ls = std::clamp(std::log2(a2 * invQ) + bias, 0.0, source_top);
          float c[3];
          Trilinear(source_, Ld, ls, c);
          for (int k = 0; k < 3; ++k) acc[k] += NoL * double(c[k]);
          w += NoL;
        }
        float* o = L.texel(face, i, j);
        for (int k = 0; k < 3; ++k) o[k] = RoundToHalf(float(acc[k] / w));
      });
    } else {
      const Level& src = source_[size_t(log2s - 4)];  // the 16 x 16 mip
      ForEachTexel(n, [&](int face, int i, int j) {
        const V3 N = Normalize(TexelDirection(face, i, j, n));
        double acc[3] = {0, 0, 0}, w = 0;
        for (int f = 0; f < 3; ++f)
          for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x) {
              const double ux = (x + 0.5) * (2.0 / 16.0) - 1.0, uy = (y + 0.5) * (2.0 / 16.0) - 1.0;
              V3 t = f == 0 ? V3(1, ux, uy) : f == 1 ? V3(ux, 1, uy) : V3(ux, uy, 1);
              const double invDist = 1.0 / std::sqrt(1.0 + ux * ux + uy * uy);
              const double c = Dot(N, t);
              if (c < 0) t = t * -1.0;
              const double NoL = std::abs(c) * invDist;
              const double dd = 1.0 + a2 + (a2 - 1.0) * NoL;
              const double wt = NoL * invDist * invDist * invDist / (dd * dd);
              float v[3];
              Bilinear(src, t, v);
              for (int k = 0; k < 3; ++k) acc[k] += wt * double(v[k]);
              w += wt;
            }
        float* o = L.texel(face, i, j);
        for (int k = 0; k < 3; ++k) o[k] = RoundToHalf(float(acc[k] / w));
      });
    }
    pmrem_.push_back(std::move(L));
  }
}

double ThreejsPmrem::MipForRoughness(double r) const {
  r = std::clamp(r, 0.0, 1.0);
  return double(max_lod_) * r * (2.0 - r);
}

Rgb<double> ThreejsPmrem::Sample(const V3& d, double mip) const {
  const V3 m{cos_rot_ * d.x - sin_rot_ * d.z, d.y, sin_rot_ * d.x + cos_rot_ * d.z};
  float c[3];
  Trilinear(pmrem_, m, mip, c);
  return {double(c[0]) * intensity_, double(c[1]) * intensity_, double(c[2]) * intensity_};
}

// ---- Filtered importance sampling (threejs_ibl.h; session-8 spec) ----

namespace {

// The PMREM roughness whose lobe covers a tap of solid angle kFisSolidAngleBias / (N pdf).
// Deviation from the session-8 spec (which had no bias): Colbert & Krivanek's +1 LOD bias, i.e.
// 4x the tap's solid angle. Measured on the demo's sphere, three.js engine, woven at the demo's
// parameters against --exact-ibl 1024 (docs/fitting.md "Filtered importance sampling for woven's
// IBL"): twill 0.01580 (no bias) / 0.01344 (x4) / 0.01707 (x16), canvas 0.00209 / 0.00131 /
// 0.00144 (display RMSE, 16 taps); the spec's mapping under-filters (aliasing of the studio's
// softboxes between the taps).
constexpr double kFisSolidAngleBias = 4.0;
double FisTapRoughness(int n, double pdf) {
  const double omega = kFisSolidAngleBias / (double(n) * pdf);
  const double a_t = std::sqrt(omega / (4.0 * kPi));
  return std::min(std::sqrt(a_t), 1.0);
}
}  // namespace

FisPattern::FisPattern(int taps) : n(taps) {
  if (taps < 1 || taps > (1 << 20))
    throw std::invalid_argument("FIS: " + std::to_string(taps) + " taps not in [1, 2^20]");
  u1.resize(size_t(taps));
  cos_phi.resize(size_t(taps));
  sin_phi.resize(size_t(taps));
  for (int i = 0; i < taps; ++i) {
    u1[size_t(i)] = (double(i) + 0.5) / double(taps);
    const double phi = 2.0 * kPi * RadicalInverse2(uint32_t(i));
    cos_phi[size_t(i)] = std::cos(phi);
    sin_phi[size_t(i)] = std::sin(phi);
  }
}

void FisFrame(const V3& n, V3* t1, V3* t2) {
  const double s = n.z >= 0.0 ? 1.0 : -1.0;
  const double a = -1.0 / (s + n.z);
  const double b = n.x * n.y * a;
  *t1 = V3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
  *t2 = V3(b, s + n.y * n.y * a, -n.y);
}

Rgb<double> FisGgxRadiance(const ThreejsPmrem& pmrem, const FisPattern& taps, const V3& n,
                           const V3& v, double r, int* taps_used) {
  V3 t1, t2;
  FisFrame(n, &t1, &t2);
  const double alpha = std::max(r * r, 1e-3), a2 = alpha * alpha;
  Rgb<double> sum(0, 0, 0);
  double wsum = 0.0;
  int used = 0;
  for (int i = 0; i < taps.n; ++i) {
    const double u1 = taps.u1[size_t(i)];
    const double cos_h = std::sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1));
    const double sin_h = std::sqrt(std::max(0.0, 1.0 - cos_h * cos_h));
    const V3 h = t1 * (sin_h * taps.cos_phi[size_t(i)]) + t2 * (sin_h * taps.sin_phi[size_t(i)]) +
                 n * cos_h;
    const double VoH = Dot(v, h);
    const V3 l = h * (2.0 * VoH) - v;
    const double NoL = Dot(n, l);
    if (NoL <= 0.0 || VoH <= 0.0) continue;
    const double q = (a2 - 1.0) * cos_h * cos_h + 1.0;
    const double D = a2 / (kPi * q * q);
    const double pdf = D * cos_h / (4.0 * VoH);
    const double r_t = FisTapRoughness(taps.n, pdf);
    sum += pmrem.Sample(l, pmrem.MipForRoughness(r_t)) * NoL;
    wsum += NoL;
    ++used;
  }
  if (taps_used) *taps_used = used;
  if (!(wsum > 0.0)) return Rgb<double>(0, 0, 0);
  return sum * (1.0 / wsum);
}

Rgb<double> FisIrradianceOverPi(const ThreejsPmrem& pmrem, const FisPattern& taps, const V3& n) {
  V3 t1, t2;
  FisFrame(n, &t1, &t2);
  Rgb<double> sum(0, 0, 0);
  for (int i = 0; i < taps.n; ++i) {
    const double u1 = taps.u1[size_t(i)];
    const double cos_t = std::sqrt(1.0 - u1), sin_t = std::sqrt(u1);
    const V3 l = t1 * (sin_t * taps.cos_phi[size_t(i)]) + t2 * (sin_t * taps.sin_phi[size_t(i)]) +
                 n * cos_t;
    const double r_t = FisTapRoughness(taps.n, cos_t * kInvPi);
    sum += pmrem.Sample(l, pmrem.MipForRoughness(r_t));
  }
  return sum * (1.0 / double(taps.n));
}

namespace {

// Bump when the PMREM computation changes: old cache files then no longer match.
constexpr const char* kPmremVersion = "clothfit-threejs-pmrem v1";

uint64_t Fnv1a(const void* data, size_t n, uint64_t h = 0xcbf29ce484222325ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

std::string PmremCacheDir() {
  if (const char* d = std::getenv("CLOTHFIT_TABLE_CACHE")) return d;
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/clothfit/tables";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/clothfit/tables";
  return "";
}

}  // namespace

std::shared_ptr<const ThreejsPmrem> SharedThreejsPmrem(const Environment& env) {
  using Key = std::tuple<const float*, int, int, double, double, std::string>;
  static std::mutex mu;
  static std::map<Key, std::shared_ptr<const ThreejsPmrem>> cache;
  const Key key{env.pixels().data(), env.width(), env.height(), env.rotation_y(), env.intensity(),
                env.source()};
  {
    std::lock_guard<std::mutex> lock(mu);
    if (auto it = cache.find(key); it != cache.end()) return it->second;
  }
  // On-disk cache of the PMREM levels.
  const std::string dir = PmremCacheDir();
  const bool use_disk = !dir.empty() && dir != "off";
  uint64_t h = Fnv1a(env.pixels().data(), env.pixels().size() * sizeof(float));
  const int wh[2] = {env.width(), env.height()};
  h = Fnv1a(wh, sizeof wh, h);
  h = Fnv1a(kPmremVersion, std::char_traits<char>::length(kPmremVersion), h);
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  const std::string path = use_disk ? dir + "/threejs-pmrem-" + hex + ".bin" : "";
  std::shared_ptr<ThreejsPmrem> p;
  if (use_disk) {
    std::ifstream in(path, std::ios::binary);
    std::string header;
    if (in && std::getline(in, header)) {
      int S = 0, max_lod = 0;
      char file_key[17] = {};
      if (std::sscanf(header.c_str(), "clothfit-threejs-pmrem v1 S=%d maxLod=%d key=%16s", &S,
                      &max_lod, file_key) == 3 &&
          std::string(file_key) == hex && S >= 8 && max_lod >= 0 && (S >> max_lod) >= 1) {
        auto q = std::shared_ptr<ThreejsPmrem>(new ThreejsPmrem());
        q->size_ = S;
        q->max_lod_ = max_lod;
        uint64_t sum = 0xcbf29ce484222325ull;
        bool ok = true;
        for (int lod = 0; lod <= max_lod && ok; ++lod) {
          ThreejsPmrem::Level L = MakeLevel(S >> lod);
          in.read(reinterpret_cast<char*>(L.rgb.data()), std::streamsize(L.rgb.size() * sizeof(float)));
          ok = bool(in);
          sum = Fnv1a(L.rgb.data(), L.rgb.size() * sizeof(float), sum);
          q->pmrem_.push_back(std::move(L));
        }
        uint64_t stored = 0;
        in.read(reinterpret_cast<char*>(&stored), sizeof stored);
        if (ok && in && stored == sum) p = q;
      }
    }
  }
  if (!p) {
    p = std::shared_ptr<ThreejsPmrem>(new ThreejsPmrem(env));
    p->source_.clear();  // only the PMREM levels are read after the build
    p->source_.shrink_to_fit();
    if (use_disk) {
      std::error_code ec;
      std::filesystem::create_directories(dir, ec);
      const std::string tmp = path + ".tmp." + std::to_string(::getpid());
      std::ofstream out(tmp, std::ios::binary);
      out << kPmremVersion << " S=" << p->size_ << " maxLod=" << p->max_lod_ << " key=" << hex << "\n";
      uint64_t sum = 0xcbf29ce484222325ull;
      for (const ThreejsPmrem::Level& L : p->pmrem_) {
        out.write(reinterpret_cast<const char*>(L.rgb.data()), std::streamsize(L.rgb.size() * sizeof(float)));
        sum = Fnv1a(L.rgb.data(), L.rgb.size() * sizeof(float), sum);
      }
      out.write(reinterpret_cast<const char*>(&sum), sizeof sum);
      out.close();
      if (out) std::filesystem::rename(tmp, path, ec);
      else std::filesystem::remove(tmp, ec);
    }
  }
  p->SetLookup(env);
  std::lock_guard<std::mutex> lock(mu);
  return cache.emplace(key, p).first->second;
}

bool UsesThreejsIbl(const PreviewOptions& o) {
  switch (o.ibl_engine) {
    case IblEngine::kFilament: return false;
    case IblEngine::kThreejs: return true;
    case IblEngine::kAuto: break;
  }
  if (o.model == ModelKind::kStandard || o.model == ModelKind::kPhysicalSheen ||
      o.model == ModelKind::kPhysicalAniso || o.model == ModelKind::kWoven)
    return true;
  return o.model == ModelKind::kCloth && o.cloth.variant == cloth::Variant::kSeedThreejs;
}

bool UsesWovenFis(const PreviewOptions& o) {
  return o.model == ModelKind::kWoven && o.woven.ibl == woven::IblMode::kFis &&
         o.exact_ibl_samples <= 0 && UsesThreejsIbl(o);
}

bool UsesWovenBent(const PreviewOptions& o) {
  return o.model == ModelKind::kWoven && o.woven.ibl == woven::IblMode::kBent &&
         o.exact_ibl_samples <= 0;
}

void CheckWovenBentFrame(const PreviewOptions& o, double anisotropy, double twist) {
  if (!UsesWovenBent(o)) return;
  if (anisotropy != o.woven.bent_anisotropy || twist != o.woven.bent_twist)
    throw std::invalid_argument(
        "preview: woven \"ibl\": \"bent\": the frame's anisotropy / twist (" +
        std::to_string(anisotropy) + ", " + std::to_string(twist) +
        ") differ from the values the bent-normal tables were built for (" +
        std::to_string(o.woven.bent_anisotropy) + ", " + std::to_string(o.woven.bent_twist) +
        "): hold them fixed (the woven fit does)");
}

bool RasterBarycentrics(const Scene& scene, const std::array<V3, 3>& P, double sx, double sy,
                        int subpixel_bits, double b[3]) {
  const Camera& cam = scene.camera;
  const V3 eye(cam.position[0], cam.position[1], cam.position[2]);
  const V3 right(cam.right[0], cam.right[1], cam.right[2]), up(cam.up[0], cam.up[1], cam.up[2]),
      fwd(cam.forward[0], cam.forward[1], cam.forward[2]);
  const double W = scene.card.width, H = scene.card.height;
  const double tan_half = std::tan(0.5 * cam.yfov), aspect = W / H;
  // Window coordinates (x right, y up from the bottom row; pixel centres at +0.5) and clip w.
  double X[3], Y[3], w[3];
  for (int k = 0; k < 3; ++k) {
    const V3 q = P[size_t(k)] - eye;
    w[k] = Dot(q, fwd);
    if (!(w[k] > 0.0)) return false;
    X[k] = (Dot(q, right) / (w[k] * tan_half * aspect) + 1.0) * 0.5 * W;
    Y[k] = (Dot(q, up) / (w[k] * tan_half) + 1.0) * 0.5 * H;
    if (subpixel_bits >= 0) {  // fixed point, round to nearest (ties to even, as cvtps2dq)
      const double f = std::ldexp(1.0, subpixel_bits);
      X[k] = std::nearbyint(X[k] * f) / f;
      Y[k] = std::nearbyint(Y[k] * f) / f;
    }
  }
  const double x = sx, y = H - sy;  // the sample in window coordinates
  const double area = (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0]);
  if (area == 0.0) return false;
  // Screen-space (linear) barycentrics, then perspective correction by 1 / w.
  double l[3];
  l[1] = ((x - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (y - Y[0])) / area;
  l[2] = ((X[1] - X[0]) * (y - Y[0]) - (x - X[0]) * (Y[1] - Y[0])) / area;
  l[0] = 1.0 - l[1] - l[2];
  double sum = 0.0;
  for (int k = 0; k < 3; ++k) {
    b[k] = l[k] / w[k];
    sum += b[k];
  }
  if (sum == 0.0 || !std::isfinite(sum)) return false;
  for (int k = 0; k < 3; ++k) b[k] /= sum;
  return true;
}

double ThreejsGeometryRoughness(const Scene& scene, int mesh, int triangle, int x, int y,
                                int subpixel_bits) {
  const Mesh& m = scene.meshes[size_t(mesh)];
  const uint32_t* idx = &m.indices[size_t(triangle) * 3];
  auto v3 = [](const std::array<float, 3>& a) {
    return V3(double(a[0]), double(a[1]), double(a[2]));
  };
  const std::array<V3, 3> P{v3(m.positions[idx[0]]), v3(m.positions[idx[1]]),
                            v3(m.positions[idx[2]])};
  const V3 N0 = v3(m.normals[idx[0]]), N1 = v3(m.normals[idx[1]]), N2 = v3(m.normals[idx[2]]);
  const Camera& cam = scene.camera;
  const V3 right(cam.right[0], cam.right[1], cam.right[2]), up(cam.up[0], cam.up[1], cam.up[2]),
      fwd(cam.forward[0], cam.forward[1], cam.forward[2]);
  // View-space interpolated normal at pixel (px, py) on the triangle's attribute plane (the
  // rasteriser's perspective-correct barycentrics, extrapolated outside the triangle); false
  // when the triangle has no usable plane there.
  auto normal_at = [&](int px, int py, V3* out) {
    double b[3];
    if (!RasterBarycentrics(scene, P, px + 0.5, py + 0.5, subpixel_bits, b)) return false;
    const V3 n = Normalize(N0 * b[0] + N1 * b[1] + N2 * b[2]);
    *out = V3(Dot(n, right), Dot(n, up), Dot(n, fwd));
    return true;
  };
  // Coarse derivatives, as SwiftShader evaluates GLSL dFdx / dFdy (OpDPdx = OpDPdxCoarse): one
  // value per 2 x 2 quad, dFdx = n(lane 1) - n(lane 0), dFdy = n(lane 2) - n(lane 0), lane 0 the
  // quad's corner with even window x and even window y. Window y runs up from the bottom row,
  // image rows down from the top: window row H - 1 - y. Measured against the browser on the
  // drape (docs/preview.md): coarse with this lane 0 matched best (fine derivatives, or coarse
  // with lane 0 at another corner, gave 1.5-2 x more pixels whose geometryRoughness differs by
  // more than 0.01).
  const int H = scene.card.height;
  const int x0 = x & ~1, yw0 = (H - 1 - y) & ~1;
  const int y0 = H - 1 - yw0, y1 = H - 2 - yw0;  // image rows of window rows yw0, yw0 + 1
  V3 n, nx, ny;
  if (!normal_at(x0, y0, &n)) return 0.0;
  double g = 0.0;
  if (normal_at(x0 + 1, y0, &nx))
    g = std::max({g, std::abs(nx.x - n.x), std::abs(nx.y - n.y), std::abs(nx.z - n.z)});
  if (normal_at(x0, y1, &ny))
    g = std::max({g, std::abs(ny.x - n.x), std::abs(ny.y - n.y), std::abs(ny.z - n.z)});
  return g;
}

bool ThreejsGeometryRoughnessApplies(const PreviewOptions& o) {
  return UsesThreejsIbl(o) &&
         (o.model == ModelKind::kStandard || o.model == ModelKind::kPhysicalSheen ||
          o.model == ModelKind::kPhysicalAniso);
}

const Table2D& ThreejsDfgTable() {
  static const Table2D table = [] {
    constexpr int n = 16;
    Table2D t(n, n, 3);
    const lut::Settings s;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        double A, B;
        lut::IntegrateGgx(Table2D::Centre(i, n), Table2D::Centre(j, n), s, A, B);
        t.at(i, j, 0) = RoundToHalf(float(A));
        t.at(i, j, 1) = RoundToHalf(float(B));
      }
    return t;
  }();
  return table;
}

}  // namespace clothfit::render
