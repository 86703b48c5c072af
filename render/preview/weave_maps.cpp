#include "render/preview/weave_maps.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <utility>

#include "render/scene/embree_scene.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
#include "render/scene/scene.h"

namespace clothfit::render {
namespace {

constexpr std::array<const char*, WeaveMaps::kChannels> kChannelNames{"warp", "weft", "kd.R",
                                                                       "kd.G", "kd.B"};
// A view band's channel: "view<k>.<channel>".
std::string ViewChannelName(size_t k, const char* channel) {
  return "view" + std::to_string(k) + "." + channel;
}

constexpr const char* kConvention =
    "texel (i, j) covers TEXCOORD_0 [i, i+1) / (size uv_repeats) x [j, j+1) / (size uv_repeats), "
    "i = column from the left, j = row from the top; texel centres at +0.5; REPEAT on both axes";
constexpr const char* kColourSpace =
    "linear; every channel a ratio to its tile mean (mean 1); kd channels linear sRGB";

bool PowerOfTwo(int n) { return n > 0 && (n & (n - 1)) == 0; }


// Bilinear (REPEAT, texel centres at +0.5) sample of an N-channel level of side s.
template <int N>
std::array<double, N> Bilinear(const std::vector<float>& lv, int s, double uv_repeats, double u,
                               double v) {
  auto wrap = [](double x) { return x - std::floor(x); };
  const double x = wrap(u * uv_repeats) * s - 0.5;
  const double y = wrap(v * uv_repeats) * s - 0.5;
  const double fx = std::floor(x), fy = std::floor(y);
  const double tx = x - fx, ty = y - fy;
  auto idx = [s](double k) { return int(((long long)(k) % s + s) % s); };
  const int i0 = idx(fx), i1 = idx(fx + 1), j0 = idx(fy), j1 = idx(fy + 1);
  std::array<double, N> out{};
  for (int ch = 0; ch < N; ++ch) {
    auto at = [&](int i, int j) {
      return double(lv[(size_t(j) * size_t(s) + size_t(i)) * N + size_t(ch)]);
    };
    out[size_t(ch)] = (1 - ty) * ((1 - tx) * at(i0, j0) + tx * at(i1, j0)) +
                      ty * ((1 - tx) * at(i0, j1) + tx * at(i1, j1));
  }
  return out;
}

// 2 x 2 box mips of an N-channel level-0 image of side `size`.
template <int N>
void BuildBoxMips(int size, std::vector<std::vector<float>>* levels) {
  for (int s = size / 2; s >= 1; s /= 2) {
    const std::vector<float>& up = levels->back();
    const int su = s * 2;
    std::vector<float> lv(size_t(s) * size_t(s) * N);
    for (int j = 0; j < s; ++j)
      for (int i = 0; i < s; ++i)
        for (int ch = 0; ch < N; ++ch) {
          auto at = [&](int ii, int jj) {
            return double(up[(size_t(jj) * size_t(su) + size_t(ii)) * N + size_t(ch)]);
          };
          lv[(size_t(j) * size_t(s) + size_t(i)) * N + size_t(ch)] =
              float(0.25 * (at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) +
                            at(2 * i + 1, 2 * j + 1)));
        }
    levels->push_back(std::move(lv));
  }
}

// Trilinear sample of an N-channel mip chain (level 0 of side `size`) at level l in
// [0, levels - 1]: bilinear in levels floor(l) and floor(l) + 1, blended by the fraction.
template <int N>
std::array<double, N> Trilinear(const std::vector<std::vector<float>>& levels, int size,
                                double uv_repeats, double u, double v, double l) {
  const int l0 = int(std::floor(l));
  const int l1 = std::min(l0 + 1, int(levels.size()) - 1);
  const double t = l - double(l0);
  std::array<double, N> a = Bilinear<N>(levels[size_t(l0)], size >> l0, uv_repeats, u, v);
  if (t > 0.0 && l1 != l0) {
    const std::array<double, N> b = Bilinear<N>(levels[size_t(l1)], size >> l1, uv_repeats, u, v);
    for (int k = 0; k < N; ++k) a[size_t(k)] = (1 - t) * a[size_t(k)] + t * b[size_t(k)];
  }
  return a;
}

// A requested level of detail clamped to the chain [0, top]; NaN selects the top.
double ClampLod(double lambda, double top) {
  return std::clamp(std::isfinite(lambda) ? lambda : top, 0.0, top);
}

// The mean of fp.n trilinear probes (REPEAT) along the footprint's major axis, probe i (0-based)
// at uv + step (i - (n - 1) / 2): the centres of n equal segments of [-1/2, 1/2] x the axis.
// n = 1: exactly Trilinear at (u, v) (the isotropic path).
template <int N>
std::array<double, N> TrilinearAniso(const std::vector<std::vector<float>>& levels, int size,
                                     double uv_repeats, double u, double v,
                                     const WeaveMaps::Footprint& fp) {
  const double l = ClampLod(fp.lambda, double(levels.size()) - 1.0);
  if (fp.n <= 1) return Trilinear<N>(levels, size, uv_repeats, u, v, l);
  std::array<double, N> sum{};
  const double c = 0.5 * double(fp.n - 1);
  for (int i = 0; i < fp.n; ++i) {
    const double t = double(i) - c;
    const std::array<double, N> a =
        Trilinear<N>(levels, size, uv_repeats, u + t * fp.step_u, v + t * fp.step_v, l);
    for (int k = 0; k < N; ++k) sum[size_t(k)] += a[size_t(k)];
  }
  for (int k = 0; k < N; ++k) sum[size_t(k)] /= double(fp.n);
  return sum;
}

}  // namespace

WeaveMaps WeaveMaps::FromLevel0(int size, double uv_repeats, std::vector<float> level0) {
  if (!PowerOfTwo(size) || size > 4096)
    throw std::invalid_argument("weave maps: size " + std::to_string(size) +
                                " is not a power of two in [1, 4096]");
  if (!(uv_repeats > 0.0) || !std::isfinite(uv_repeats))
    throw std::invalid_argument("weave maps: uv_repeats must be positive and finite");
  const size_t n = size_t(size) * size_t(size);
  if (level0.size() != n * kChannels)
    throw std::invalid_argument("weave maps: level 0 has " + std::to_string(level0.size()) +
                                " values, expected " + std::to_string(n * kChannels));
  for (int ch = 0; ch < kChannels; ++ch) {
    double mean = 0.0;
    for (size_t t = 0; t < n; ++t) {
      const double x = double(level0[t * kChannels + size_t(ch)]);
      if (!std::isfinite(x) || x < 0.0)
        throw std::invalid_argument(std::string("weave maps: channel ") + kChannelNames[size_t(ch)] +
                                    " has a negative or non-finite texel");
      mean += x;
    }
    mean /= double(n);
    if (!(mean > 0.0))
      throw std::invalid_argument(std::string("weave maps: channel ") + kChannelNames[size_t(ch)] +
                                  " has a zero mean");
    for (size_t t = 0; t < n; ++t)
      level0[t * kChannels + size_t(ch)] = float(double(level0[t * kChannels + size_t(ch)]) / mean);
  }
  WeaveMaps m;
  m.size = size;
  m.uv_repeats = uv_repeats;
  m.levels.push_back(std::move(level0));
  BuildBoxMips<kChannels>(size, &m.levels);
  std::vector<float> an(n * 3);
  for (size_t t = 0; t < n; ++t) {
    const double wa = double(m.levels[0][t * kChannels]);
    const double wb = double(m.levels[0][t * kChannels + 1]);
    const bool warp = wa >= wb;
    an[t * 3] = warp ? 1.f : 0.5f;
    an[t * 3 + 1] = warp ? 0.5f : 1.f;
    an[t * 3 + 2] = float(wa + wb > 0.0 ? std::abs(wa - wb) / (wa + wb) : 0.0);
  }
  m.aniso_levels.push_back(std::move(an));
  BuildBoxMips<3>(size, &m.aniso_levels);
  return m;
}

std::array<double, 2> WeaveMaps::SampleAnisotropy(double u, double v, double lambda) const {
  if (aniso_levels.empty()) return {0.0, 0.0};
  const std::array<double, 3> a = Trilinear<3>(aniso_levels, size, uv_repeats, u, v,
                                               ClampLod(lambda, double(level_count() - 1)));
  const double dx = 2.0 * a[0] - 1.0, dy = 2.0 * a[1] - 1.0;
  const double len = std::hypot(dx, dy);
  if (!(len > 0.0)) return {0.0, 0.0};
  return {dx / len * a[2], dy / len * a[2]};
}

// SwiftShader's log2sqrt (src/Pipeline/SamplerCore.cpp): 1/4 of a piecewise-linear log2 of
// x^2 in float (the exponent plus the mantissa fraction), x = the squared LOD scale.
static double SwiftShaderLog2Sqrt(double x) {
  const float y = float(x) * float(x);
  int e = 0;
  const float m = std::frexp(y, &e);  // y = m 2^e, m in [0.5, 1)
  return 0.25 * (double(e - 1) + (2.0 * double(m) - 1.0));
}

// Round to nearest, ties to even: SwiftShader's RoundInt (Reactor: cvtss2si under the default
// MXCSR mode on x86, Subzero's nearbyint, the mantissa trick on ARM; all ties-to-even), which
// picks its probe count from the anisotropy a. Explicit, so it does not depend on the FP
// environment's rounding mode. std::lround would round a = k + 0.5 away from zero.
static int RoundHalfEven(double a) {
  const double f = std::floor(a);
  const double d = a - f;
  if (d > 0.5) return int(f) + 1;
  if (d < 0.5) return int(f);
  return std::fmod(f, 2.0) == 0.0 ? int(f) : int(f) + 1;
}

WeaveMaps::Footprint WeaveMaps::FootprintFor(const std::array<double, 4>& duv, double texels,
                                             int levels, int aniso, double footprint_scale,
                                             AnisoRule rule) {
  // EXT_texture_filter_anisotropic (weave_maps.h): footprint in texels of this map.
  Footprint fp;
  const double top = double(levels - 1);
  const double k = texels * footprint_scale;
  const double px = std::hypot(duv[0], duv[1]) * k;
  const double py = std::hypot(duv[2], duv[3]) * k;
  const double pmax = std::max(px, py), pmin = std::min(px, py);
  if (!(pmax > 0.0)) return fp;  // no footprint (or NaN): level 0, one sample
  if (!std::isfinite(pmax)) {    // ray parallel to the plane: the coarsest level
    fp.lambda = top;
    return fp;
  }
  const double maxn = double(std::max(aniso, 1));
  if (rule == AnisoRule::kSwiftShader) {  // weave_maps.h: area-based minor axis, unrounded a
    const double det = std::abs(duv[0] * duv[3] - duv[2] * duv[1]) * k * k;
    const double a = det > 0.0 ? std::min(pmax * pmax / det, maxn) : maxn;
    fp.n = std::max(1, RoundHalfEven(a));
    fp.lambda = std::clamp(SwiftShaderLog2Sqrt(pmax * pmax / (a * a)), 0.0, top);
    if (fp.n > 1) {
      const bool x_major = px >= py;
      const double s = footprint_scale / double(fp.n);
      fp.step_u = (x_major ? duv[0] : duv[2]) * s;
      fp.step_v = (x_major ? duv[1] : duv[3]) * s;
    }
    return fp;
  }
  const double ratio = pmin > 0.0 ? pmax / pmin : std::numeric_limits<double>::infinity();
  fp.n = int(std::min(std::ceil(ratio), maxn));
  fp.lambda = std::clamp(std::log2(pmax / double(fp.n)), 0.0, top);
  if (fp.n > 1) {  // the major axis (x when Px > Py, else y, as the spec), in uv, split in n
    const bool x_major = px > py;
    const double s = footprint_scale / double(fp.n);
    fp.step_u = (x_major ? duv[0] : duv[2]) * s;
    fp.step_v = (x_major ? duv[1] : duv[3]) * s;
  }
  return fp;
}

WeaveMaps::Footprint WeaveMaps::FootprintAt(const std::array<double, 4>& duv,
                                            double footprint_scale) const {
  if (anisotropy <= 1) {  // the isotropic path, unchanged
    Footprint fp;
    fp.lambda = Lod(duv, footprint_scale);
    return fp;
  }
  return FootprintFor(duv, double(size) * uv_repeats, level_count(), anisotropy, footprint_scale,
                      aniso_rule);
}

std::array<double, WeaveMaps::kChannels> WeaveMaps::Sample(double u, double v,
                                                           const Footprint& fp) const {
  if (fp.n <= 1) return Sample(u, v, fp.lambda);
  return TrilinearAniso<kChannels>(levels, size, uv_repeats, u, v, fp);
}

std::vector<double> WeaveMaps::ViewWeights(double nov) const {
  const size_t K = view_cosines.size();
  std::vector<double> w(K, 0.0);
  if (K == 0) return w;
  // Cosines are strictly decreasing: band K-1 is the most grazing, band 0 the most frontal.
  const double x = std::isfinite(nov) ? nov : 0.0;
  if (x >= view_cosines[0]) {
    w[0] = 1.0;
    return w;
  }
  if (x <= view_cosines[K - 1]) {
    w[K - 1] = 1.0;
    return w;
  }
  for (size_t k = 0; k + 1 < K; ++k)
    if (x <= view_cosines[k] && x >= view_cosines[k + 1]) {
      const double t = (view_cosines[k] - x) / (view_cosines[k] - view_cosines[k + 1]);
      w[k] = 1.0 - t;
      w[k + 1] = t;
      break;
    }
  return w;
}

void WeaveMaps::SetViews(std::vector<double> cosines, std::vector<std::vector<float>> level0s) {
  if (cosines.size() < 2 || cosines.size() > 8 || level0s.size() != cosines.size())
    throw std::invalid_argument("weave maps: view bands: expected 2 to 8 cosines with one map each");
  for (size_t k = 0; k < cosines.size(); ++k) {
    if (!std::isfinite(cosines[k]) || !(cosines[k] > 0.0) || cosines[k] > 1.0)
      throw std::invalid_argument("weave maps: view bands: cosine " + std::to_string(k) +
                                  " not in (0, 1]");
    if (k > 0 && !(cosines[k] < cosines[k - 1]))
      throw std::invalid_argument("weave maps: view bands: cosines not strictly decreasing");
  }
  std::vector<std::vector<std::vector<float>>> levels_out;
  for (std::vector<float>& l0 : level0s)
    levels_out.push_back(FromLevel0(size, uv_repeats, std::move(l0)).levels);
  view_cosines = std::move(cosines);
  view_levels = std::move(levels_out);
}

std::array<double, WeaveMaps::kChannels> WeaveMaps::SampleView(double u, double v,
                                                               const Footprint& fp,
                                                               double nov) const {
  if (!has_views()) return Sample(u, v, fp);
  const std::vector<double> w = ViewWeights(nov);
  std::array<double, kChannels> out{};
  for (size_t k = 0; k < w.size(); ++k) {
    if (w[k] == 0.0) continue;
    // the main maps' rules exactly (Sample(u, v, fp)): trilinear, or the anisotropic probes
    const std::array<double, kChannels> s =
        fp.n <= 1 ? Trilinear<kChannels>(view_levels[k], size, uv_repeats, u, v,
                                         ClampLod(fp.lambda, double(view_levels[k].size() - 1)))
                  : TrilinearAniso<kChannels>(view_levels[k], size, uv_repeats, u, v, fp);
    for (int c = 0; c < kChannels; ++c) out[size_t(c)] += w[k] * s[size_t(c)];
  }
  return out;
}

std::array<double, 2> WeaveMaps::SampleAnisotropy(double u, double v, const Footprint& fp) const {
  if (fp.n <= 1 || aniso_levels.empty()) return SampleAnisotropy(u, v, fp.lambda);
  // The texture is filtered (its encoded RG / B), then decoded, as the GPU and three.js do.
  const std::array<double, 3> a = TrilinearAniso<3>(aniso_levels, size, uv_repeats, u, v, fp);
  const double dx = 2.0 * a[0] - 1.0, dy = 2.0 * a[1] - 1.0;
  const double len = std::hypot(dx, dy);
  if (!(len > 0.0)) return {0.0, 0.0};
  return {dx / len * a[2], dy / len * a[2]};
}

std::array<double, 3> WeaveMaps::SampleNormal(double u, double v, const Footprint& fp) const {
  if (fp.n <= 1 || normal_levels.empty()) return SampleNormal(u, v, fp.lambda);
  const std::array<double, 3> a = TrilinearAniso<3>(normal_levels, size, uv_repeats, u, v, fp);
  const double len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(len > 1e-9)) return {0.0, 0.0, 1.0};
  return {a[0] / len, a[1] / len, a[2] / len};
}

double WeaveMaps::Lod(const std::array<double, 4>& duv, double footprint_scale) const {
  const double texels = double(size) * uv_repeats * footprint_scale;
  const double rx = std::hypot(duv[0], duv[1]) * texels;
  const double ry = std::hypot(duv[2], duv[3]) * texels;
  const double rho = std::max(rx, ry);
  const double top = double(level_count() - 1);
  if (!(rho > 1.0)) return 0.0;  // magnification (or NaN): level 0
  if (!std::isfinite(rho)) return top;
  return std::min(std::log2(rho), top);
}


void WeaveMaps::SetNormals(std::vector<float> level0) {
  if (level0.size() != size_t(size) * size_t(size) * 3)
    throw std::invalid_argument("weave maps: the normal map has the wrong size");
  for (float x : level0)
    if (!std::isfinite(x)) throw std::invalid_argument("weave maps: non-finite normal");
  normal_levels.clear();
  normal_levels.push_back(std::move(level0));
  BuildBoxMips<3>(size, &normal_levels);
}

std::array<double, 3> WeaveMaps::SampleNormal(double u, double v, double lambda) const {
  if (normal_levels.empty()) return {0.0, 0.0, 1.0};
  const std::array<double, 3> a = Trilinear<3>(normal_levels, size, uv_repeats, u, v,
                                               ClampLod(lambda, double(level_count() - 1)));
  const double len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(len > 1e-9)) return {0.0, 0.0, 1.0};
  return {a[0] / len, a[1] / len, a[2] / len};
}

void WeaveMaps::SetGlint(int gsize, std::vector<float> level0) {
  if (!PowerOfTwo(gsize) || gsize > 8192 || level0.size() != size_t(gsize) * size_t(gsize))
    throw std::invalid_argument("weave maps: the glint map size is not a power of two <= 8192");
  for (float x : level0)
    if (!std::isfinite(x) || x < 0.f) throw std::invalid_argument("weave maps: bad glint value");
  glint_size = gsize;
  glint_levels.clear();
  glint_levels.push_back(std::move(level0));
  BuildBoxMips<1>(gsize, &glint_levels);
}

double WeaveMaps::SampleGlint(double u, double v, const std::array<double, 4>& duv,
                              double footprint_scale) const {
  if (glint_levels.empty()) return 1.0;
  if (anisotropy > 1)  // the glint map's own texel density (repeat 1), same rule
    return TrilinearAniso<1>(glint_levels, glint_size, 1.0, u, v,
                             FootprintFor(duv, double(glint_size), int(glint_levels.size()),
                                          anisotropy, footprint_scale, aniso_rule))[0];
  const double texels = double(glint_size) * footprint_scale;
  const double rho = std::max(std::hypot(duv[0], duv[1]), std::hypot(duv[2], duv[3])) * texels;
  const int n = int(glint_levels.size());
  const double top = double(n - 1);
  const double l = !(rho > 1.0) ? 0.0 : std::isfinite(rho) ? std::min(std::log2(rho), top) : top;
  return Trilinear<1>(glint_levels, glint_size, 1.0, u, v, l)[0];
}

void WriteGlintMap(const std::string& path, const WeaveMaps& maps) {
  io::Image img;
  img.width = maps.glint_size;
  img.height = maps.glint_size;
  img.channel_names = {"I"};
  img.pixels = maps.glint_levels.at(0);
  img.metadata["clothfit:glint_map"] = "1";
  img.metadata["clothfit:convention"] =
      "texel (i, j) covers TEXCOORD_0 [i, i+1) / size x [j, j+1) / size, row j from the top; "
      "REPEAT with repeat 1; linear fineness intensity (reference mean 1)";
  io::WriteExr(path, img);
}

void ReadGlintMap(const std::string& path, WeaveMaps* maps) {
  const io::Image img = io::ReadImage(path);
  if (img.width != img.height || img.channels() < 1 || img.channel_names[0] != "I")
    throw std::invalid_argument(path + ": glint map: expected a square image with channel I");
  std::vector<float> v(size_t(img.width) * size_t(img.height));
  for (size_t t = 0; t < v.size(); ++t) v[t] = img.pixels[t * size_t(img.channels())];
  try {
    maps->SetGlint(img.width, std::move(v));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(path + ": " + e.what());
  }
}

std::array<double, WeaveMaps::kChannels> WeaveMaps::SampleLevel(double u, double v,
                                                                int level) const {
  return Bilinear<kChannels>(levels[size_t(level)], size >> level, uv_repeats, u, v);
}

std::array<double, WeaveMaps::kChannels> WeaveMaps::Sample(double u, double v,
                                                           double lambda) const {
  return Trilinear<kChannels>(levels, size, uv_repeats, u, v,
                              ClampLod(lambda, double(level_count() - 1)));
}

void WriteWeaveMaps(const std::string& path, const WeaveMaps& maps,
                    const std::map<std::string, std::string>& metadata) {
  io::Image img;
  img.width = maps.size;
  img.height = maps.size;
  img.channel_names.assign(kChannelNames.begin(), kChannelNames.end());
  // Per texel: the five ratio channels, then N.X N.Y N.Z (relief normals), then each view
  // band's five channels (view{k}.warp ... view{k}.kd.B).
  const size_t n = size_t(maps.size) * size_t(maps.size);
  if (maps.has_normals())
    for (const char* c : {"N.X", "N.Y", "N.Z"}) img.channel_names.push_back(c);
  for (size_t k = 0; k < maps.view_levels.size(); ++k)
    for (const char* c : kChannelNames) img.channel_names.push_back(ViewChannelName(k, c));
  const size_t nc = img.channel_names.size();
  img.pixels.assign(n * nc, 0.f);
  for (size_t t = 0; t < n; ++t) {
    size_t o = t * nc;
    for (size_t c = 0; c < 5; ++c) img.pixels[o++] = maps.levels[0][t * 5 + c];
    if (maps.has_normals())
      for (size_t c = 0; c < 3; ++c) img.pixels[o++] = maps.normal_levels[0][t * 3 + c];
    for (const auto& band : maps.view_levels)
      for (size_t c = 0; c < 5; ++c) img.pixels[o++] = band[0][t * 5 + c];
  }
  img.metadata = metadata;
  img.metadata["clothfit:weave_maps"] = "1";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", maps.uv_repeats);
  img.metadata["clothfit:uv_repeats"] = buf;
  img.metadata["clothfit:convention"] = kConvention;
  img.metadata["clothfit:colour_space"] = kColourSpace;
  if (maps.has_views()) {
    std::string cos;
    for (double c : maps.view_cosines) {
      std::snprintf(buf, sizeof buf, "%s%.17g", cos.empty() ? "" : " ", c);
      cos += buf;
    }
    img.metadata["clothfit:view_cosines"] = cos;
  }
  io::WriteExr(path, img);
}

WeaveMaps ReadWeaveMaps(const std::string& path) {
  const io::Image img = io::ReadImage(path);
  auto bad = [&](const std::string& why) {
    return std::invalid_argument(path + ": weave maps: " + why);
  };
  if (img.width != img.height) throw bad("not square");
  std::array<int, WeaveMaps::kChannels> col{};
  for (int ch = 0; ch < WeaveMaps::kChannels; ++ch) {
    const auto it = std::find(img.channel_names.begin(), img.channel_names.end(),
                              std::string(kChannelNames[size_t(ch)]));
    if (it == img.channel_names.end())
      throw bad(std::string("no channel ") + kChannelNames[size_t(ch)]);
    col[size_t(ch)] = int(it - img.channel_names.begin());
  }
  const auto rep = img.metadata.find("clothfit:uv_repeats");
  if (rep == img.metadata.end()) throw bad("no clothfit:uv_repeats metadata");
  double repeats = 0.0;
  try {
    repeats = std::stod(rep->second);
  } catch (const std::exception&) {
    throw bad("clothfit:uv_repeats is not a number");
  }
  const size_t n = size_t(img.width) * size_t(img.height);
  std::vector<float> l0(n * WeaveMaps::kChannels);
  const size_t nc = size_t(img.channels());
  for (size_t t = 0; t < n; ++t)
    for (int ch = 0; ch < WeaveMaps::kChannels; ++ch)
      l0[t * WeaveMaps::kChannels + size_t(ch)] = img.pixels[t * nc + size_t(col[size_t(ch)])];
  try {
    WeaveMaps m = WeaveMaps::FromLevel0(img.width, repeats, std::move(l0));
    std::array<int, 3> nc3{-1, -1, -1};
    const std::array<const char*, 3> nn{"N.X", "N.Y", "N.Z"};
    for (size_t k = 0; k < 3; ++k) {
      const auto it = std::find(img.channel_names.begin(), img.channel_names.end(), std::string(nn[k]));
      if (it != img.channel_names.end()) nc3[k] = int(it - img.channel_names.begin());
    }
    if (nc3[0] >= 0 || nc3[1] >= 0 || nc3[2] >= 0) {
      if (nc3[0] < 0 || nc3[1] < 0 || nc3[2] < 0) throw bad("needs all of N.X, N.Y, N.Z or none");
      std::vector<float> nv(n * 3);
      for (size_t t = 0; t < n; ++t)
        for (size_t k = 0; k < 3; ++k) nv[t * 3 + k] = img.pixels[t * nc + size_t(nc3[k])];
      m.SetNormals(std::move(nv));
    }
    const auto vc = img.metadata.find("clothfit:view_cosines");
    if (vc != img.metadata.end()) {  // view bands (session 14): K cosines, K x 5 channels
      std::vector<double> cosines;
      const std::string& text = vc->second;
      size_t pos = 0;
      while (pos < text.size() && cosines.size() <= 8) {
        while (pos < text.size() && text[pos] == ' ') ++pos;
        if (pos >= text.size()) break;
        size_t used = 0;
        double x = 0.0;
        try {
          x = std::stod(text.substr(pos, 32), &used);
        } catch (const std::exception&) {
          throw bad("clothfit:view_cosines is not a list of numbers");
        }
        if (used == 0) throw bad("clothfit:view_cosines is not a list of numbers");
        pos += used;
        if (pos < text.size() && text[pos] != ' ')
          throw bad("clothfit:view_cosines is not a list of numbers");
        cosines.push_back(x);
      }
      if (cosines.size() < 2 || cosines.size() > 8)
        throw bad("clothfit:view_cosines: expected 2 to 8 numbers");
      std::vector<std::vector<float>> bands;
      for (size_t k = 0; k < cosines.size(); ++k) {
        std::array<int, WeaveMaps::kChannels> vcol{};
        for (int ch = 0; ch < WeaveMaps::kChannels; ++ch) {
          const std::string name = ViewChannelName(k, kChannelNames[size_t(ch)]);
          const auto it = std::find(img.channel_names.begin(), img.channel_names.end(), name);
          if (it == img.channel_names.end()) throw bad("no channel " + name + " (clothfit:view_cosines names " + std::to_string(cosines.size()) + " bands)");
          vcol[size_t(ch)] = int(it - img.channel_names.begin());
        }
        std::vector<float> l(n * WeaveMaps::kChannels);
        for (size_t t = 0; t < n; ++t)
          for (int ch = 0; ch < WeaveMaps::kChannels; ++ch)
            l[t * WeaveMaps::kChannels + size_t(ch)] = img.pixels[t * nc + size_t(vcol[size_t(ch)])];
        bands.push_back(std::move(l));
      }
      m.SetViews(std::move(cosines), std::move(bands));
    }
    return m;
  } catch (const std::invalid_argument& e) {
    throw bad(e.what());
  }
}

nlohmann::json WeaveMapsPresetField(const std::string& file, const WeaveMaps& maps,
                                    const nlohmann::json& source) {
  nlohmann::json f = {{"file", std::filesystem::absolute(file).lexically_normal().string()},
                      {"size", maps.size},
                      {"uv_repeats", maps.uv_repeats},
                      {"channels", kChannelNames},
                      {"colour_space", kColourSpace},
                      {"convention", kConvention},
                      {"source", source}};
  if (maps.has_views()) f["view_cosines"] = maps.view_cosines;
  return f;
}

namespace {

// The weave_maps path fields: (absolute or as given, relative to the preset's directory).
constexpr std::array<std::pair<const char*, const char*>, 2> kPathKeys{
    {{"file", "uri"}, {"glint_file", "glint_uri"}}};

bool HasWeaveMapsField(const MaterialPreset& preset) {
  if ((preset.model != ModelKind::kWoven && preset.model != ModelKind::kPhysicalAniso) ||
      !preset.extra.is_object())
    return false;
  const auto it = preset.extra.find("weave_maps");
  return it != preset.extra.end() && !it->is_null();
}


}  // namespace

void AddPresetWeaveMapUris(MaterialPreset* preset, const std::string& preset_path) {
  namespace fs = std::filesystem;
  if (!HasWeaveMapsField(*preset) || !preset->extra["weave_maps"].is_object()) return;
  nlohmann::json& f = preset->extra["weave_maps"];
  const fs::path dir = fs::absolute(fs::path(preset_path)).parent_path().lexically_normal();
  for (const auto& [file_key, uri_key] : kPathKeys) {
    if (!f.contains(file_key) || !f[file_key].is_string()) continue;
    const fs::path abs = fs::absolute(fs::path(f[file_key].get<std::string>())).lexically_normal();
    const fs::path rel = abs.lexically_relative(dir);
    if (rel.empty() || *rel.begin() == "..") continue;  // not inside: no uri
    f[uri_key] = rel.generic_string();
  }
}

int PresetMapAnisotropy(const nlohmann::json& f, const std::string& where) {
  if (!f.is_object() || !f.contains("anisotropy")) return 1;
  const nlohmann::json& a = f["anisotropy"];
  const std::string range = "expected an integer in [1, " +
                            std::to_string(WeaveMaps::kMaxAnisotropy) + "] (texture.anisotropy)";
  if (!a.is_number_integer())
    throw MaterialError(where + ": field weave_maps.anisotropy: " + range + ", got " +
                        (a.is_number() ? limits::EscapeForMessage(a.dump(), 40)
                                       : std::string(a.type_name())));
  // a.dump(): an unsigned value above LLONG_MAX is reported as written, not wrapped.
  const bool too_big = a.is_number_unsigned() &&
                       a.get<unsigned long long>() > (unsigned long long)WeaveMaps::kMaxAnisotropy;
  const long long n = too_big ? 0 : a.get<long long>();
  if (too_big || n < 1 || n > WeaveMaps::kMaxAnisotropy)
    throw MaterialError(where + ": field weave_maps.anisotropy: " + range + ", got " + a.dump());
  return int(n);
}

void ResolvePresetWeaveMapPaths(MaterialPreset* preset, const std::string& preset_path) {
  if (!HasWeaveMapsField(*preset)) return;
  nlohmann::json& f = preset->extra["weave_maps"];
  if (!f.is_object())
    throw MaterialError(limits::EscapeForMessage(preset_path, 400) +
                        ": field weave_maps: expected an object");
  PresetMapAnisotropy(f, limits::EscapeForMessage(preset_path, 400));
  for (const auto& [file_key, uri_key] : kPathKeys) {
    if (!f.contains(uri_key)) continue;
    if (!f[uri_key].is_string())
      throw MaterialError(limits::EscapeForMessage(preset_path, 400) + ": field weave_maps." +
                          uri_key + ": expected a string");
    f[file_key] = ResolvePresetRelativeUri(preset_path, std::string("weave_maps.") + uri_key,
                                     f[uri_key].get<std::string>());
    f.erase(uri_key);
  }
}

std::shared_ptr<const WeaveMaps> LoadPresetWeaveMaps(const MaterialPreset& preset,
                                                     const std::string& preset_path) {
  if (!HasWeaveMapsField(preset)) return nullptr;
  MaterialPreset resolved = preset;
  ResolvePresetWeaveMapPaths(&resolved, preset_path);
  try {
    return LoadPresetWeaveMaps(resolved);
  } catch (const MaterialError& e) {  // "preset field weave_maps...": name the preset file too
    const std::string what = e.what();
    const std::string generic = "preset field ";
    if (what.compare(0, generic.size(), generic) != 0) throw;
    throw MaterialError(limits::EscapeForMessage(preset_path, 400) + ": field " +
                        what.substr(generic.size()));
  }
}

std::shared_ptr<const WeaveMaps> LoadPresetWeaveMaps(const MaterialPreset& preset) {
  if (!HasWeaveMapsField(preset)) return nullptr;
  const auto it = preset.extra.find("weave_maps");
  if (it->is_object() && (it->contains("uri") || it->contains("glint_uri")))
    throw MaterialError("preset field weave_maps.uri: relative to the preset file, which this "
                        "reader was not given (render::ResolvePresetWeaveMapPaths first)");
  if (!it->is_object() || !it->contains("file") || !(*it)["file"].is_string())
    throw MaterialError("preset field weave_maps: expected an object with a string \"file\"");
  const int aniso = PresetMapAnisotropy(*it, "preset");
  auto maps = std::make_shared<WeaveMaps>(ReadWeaveMaps((*it)["file"].get<std::string>()));
  maps->anisotropy = aniso;
  if (it->contains("uv_repeats")) {
    const auto& r = (*it)["uv_repeats"];
    if (!r.is_number() || !(r.get<double>() > 0.0))
      throw MaterialError("preset field weave_maps.uv_repeats: expected a positive number");
    maps->uv_repeats = r.get<double>();  // the preset's value wins over the file's metadata
  }
  if (it->contains("glint_file")) {
    if (!(*it)["glint_file"].is_string())
      throw MaterialError("preset field weave_maps.glint_file: expected a string");
    ReadGlintMap((*it)["glint_file"].get<std::string>(), maps.get());
  }
  // View bands are drawn only when the preset names them, and then the file must carry the
  // same cosines (web/ reads the preset's list and the file's channels).
  if (it->contains("view_cosines")) {
    const auto& vc = (*it)["view_cosines"];
    if (!vc.is_array() || vc.size() < 2 || vc.size() > 8)
      throw MaterialError("preset field weave_maps.view_cosines: expected 2 to 8 numbers");
    for (size_t k = 0; k < vc.size(); ++k) {
      if (!vc[k].is_number() || !std::isfinite(vc[k].get<double>()) || !(vc[k].get<double>() > 0.0) ||
          vc[k].get<double>() > 1.0 || (k > 0 && !(vc[k].get<double>() < vc[k - 1].get<double>())))
        throw MaterialError("preset field weave_maps.view_cosines: expected numbers in (0, 1], "
                            "strictly decreasing");
    }
    if (maps->view_cosines.size() != vc.size())
      throw MaterialError("preset field weave_maps.view_cosines: the map file has " +
                          std::to_string(maps->view_cosines.size()) + " view bands, the preset names " +
                          std::to_string(vc.size()));
    for (size_t k = 0; k < vc.size(); ++k)
      if (!(std::abs(maps->view_cosines[k] - vc[k].get<double>()) <= 1e-9))
        throw MaterialError("preset field weave_maps.view_cosines: differs from the map file's "
                            "clothfit:view_cosines");
  } else {
    maps->view_cosines.clear();
    maps->view_levels.clear();
  }
  return maps;
}

std::array<double, 4> UvDerivatives(const Scene& scene, const Hit& hit, double px, double py) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const Mesh& m = scene.meshes.at(size_t(hit.mesh));
  if (m.uvs.empty()) return {0.0, 0.0, 0.0, 0.0};
  const size_t t3 = size_t(hit.triangle) * 3;
  std::array<std::array<double, 3>, 3> p;
  std::array<std::array<double, 2>, 3> uv;
  for (int k = 0; k < 3; ++k) {
    const uint32_t vi = m.indices[t3 + size_t(k)];
    for (int c = 0; c < 3; ++c) p[size_t(k)][size_t(c)] = double(m.positions[vi][size_t(c)]);
    for (int c = 0; c < 2; ++c) uv[size_t(k)][size_t(c)] = double(m.uvs[vi][size_t(c)]);
  }
  auto sub = [](const std::array<double, 3>& a, const std::array<double, 3>& b) {
    return std::array<double, 3>{a[0] - b[0], a[1] - b[1], a[2] - b[2]};
  };
  auto dot = [](const std::array<double, 3>& a, const std::array<double, 3>& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  };
  const auto e1 = sub(p[1], p[0]), e2 = sub(p[2], p[0]);
  const double d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
  const double den = d00 * d11 - d01 * d01;
  const std::array<double, 3>& ng = hit.ng;
  bool ok = den > 0.0;
  // uv of the triangle's plane where the ray through pixel position (x, y) meets it.
  auto uv_at = [&](double x, double y) {
    std::array<double, 3> o, d;
    scene.CameraRay(x, y, o, d);
    const double dn = dot(d, ng);
    if (std::abs(dn) < 1e-12) {
      ok = false;
      return std::array<double, 2>{0.0, 0.0};
    }
    const double t = dot(sub(p[0], o), ng) / dn;
    const std::array<double, 3> w{o[0] + t * d[0] - p[0][0], o[1] + t * d[1] - p[0][1],
                                  o[2] + t * d[2] - p[0][2]};
    const double d20 = dot(w, e1), d21 = dot(w, e2);
    const double b1 = (d11 * d20 - d01 * d21) / den, b2 = (d00 * d21 - d01 * d20) / den;
    return std::array<double, 2>{uv[0][0] + b1 * (uv[1][0] - uv[0][0]) + b2 * (uv[2][0] - uv[0][0]),
                                 uv[0][1] + b1 * (uv[1][1] - uv[0][1]) + b2 * (uv[2][1] - uv[0][1])};
  };
  if (!ok) return {kInf, kInf, kInf, kInf};
  const auto c0 = uv_at(px, py), cx = uv_at(px + 1.0, py), cy = uv_at(px, py + 1.0);
  if (!ok) return {kInf, kInf, kInf, kInf};
  return {cx[0] - c0[0], cx[1] - c0[1], cy[0] - c0[0], cy[1] - c0[1]};
}

}  // namespace clothfit::render
