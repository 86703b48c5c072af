#include "render/preview/prefilter.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "render/scene/sampler.h"

namespace clothfit::render {
namespace {

using Level = PrefilteredEnvironment::Level;

// Elevation range of row j (top first) of an image of height h: E = pi (v - 1/2).
double RowElevationTop(int j, int h) { return (0.5 - double(j) / h) * kPi; }

// Solid angle of row j per unit of u, up to the constant 2 pi: sin(E_top) - sin(E_bottom).
double RowWeight(int j, int h) {
  return std::sin(RowElevationTop(j, h)) - std::sin(RowElevationTop(j + 1, h));
}

// Map-space direction of the centre of texel (i, j).
Vec3<double> TexelCentre(int i, int j, int w, int h) {
  return Environment::UvToDirection((i + 0.5) / w, 1.0 - (j + 0.5) / h);
}

Level MakeLevel(int w, int h, double roughness) {
  Level l;
  l.width = w;
  l.height = h;
  l.roughness = roughness;
  l.rgb.assign(static_cast<size_t>(w) * static_cast<size_t>(h) * 3, 0.0f);
  return l;
}

void Store(Level* l, int i, int j, const Rgb<double>& c) {
  const size_t p = (static_cast<size_t>(j) * static_cast<size_t>(l->width) + size_t(i)) * 3;
  for (int k = 0; k < 3; ++k) l->rgb[p + size_t(k)] = static_cast<float>(c[k]);
}

Rgb<double> Load(const Level& l, int i, int j) {
  const size_t p = (static_cast<size_t>(j) * static_cast<size_t>(l.width) + size_t(i)) * 3;
  return {double(l.rgb[p]), double(l.rgb[p + 1]), double(l.rgb[p + 2])};
}

// Overlap weights of destination cells with source cells along one axis, both partitioning
// [0, 1] uniformly; `measure(a, b)` is the measure of [a, b] (length, or solid angle).
struct Tap {
  int src;
  double weight;
};
template <typename Measure>
std::vector<std::vector<Tap>> OverlapTaps(int dst, int src, Measure measure) {
  std::vector<std::vector<Tap>> taps(static_cast<size_t>(dst));
  for (int d = 0; d < dst; ++d) {
    const double a = double(d) / dst, b = double(d + 1) / dst;
    const int s0 = std::clamp(static_cast<int>(std::floor(a * src)), 0, src - 1);
    const int s1 = std::clamp(static_cast<int>(std::ceil(b * src)) - 1, 0, src - 1);
    for (int s = s0; s <= s1; ++s) {
      const double lo = std::max(a, double(s) / src), hi = std::min(b, double(s + 1) / src);
      if (hi > lo) taps[static_cast<size_t>(d)].push_back({s, measure(lo, hi)});
    }
  }
  return taps;
}

// Level 0: the plain environment (intensity applied) at the base resolution.
// Downsampling (source at least as wide): the solid-angle-weighted mean of the piecewise
// constant source over each destination cell (a box filter that preserves the integral).
// Upsampling: the mean of 4 x 4 bilinear lookups per cell, weighted by cos(elevation).
Level BaseLevel(const Environment& env, int w, int h) {
  Level src = MakeLevel(env.width(), env.height(), 0.0);
  const float s = static_cast<float>(env.intensity());
  for (size_t p = 0; p < src.rgb.size(); ++p) src.rgb[p] = env.pixels()[p] * s;
  src.SetPoles();
  Level dst = MakeLevel(w, h, 0.0);
  if (src.width >= w && src.height >= h) {
    // Rows: t = 1 - v from the top; solid-angle measure of [t0, t1] is sin E(t0) - sin E(t1).
    const auto rows = OverlapTaps(h, src.height, [](double t0, double t1) {
      return std::sin((0.5 - t0) * kPi) - std::sin((0.5 - t1) * kPi);
    });
    const auto cols = OverlapTaps(w, src.width, [](double a, double b) { return b - a; });
    tbb::parallel_for(0, h, [&](int j) {
      for (int i = 0; i < w; ++i) {
        Rgb<double> sum;
        double wsum = 0.0;
        for (const Tap& r : rows[static_cast<size_t>(j)]) {
          for (const Tap& c : cols[static_cast<size_t>(i)]) {
            sum += Load(src, c.src, r.src) * (r.weight * c.weight);
            wsum += r.weight * c.weight;
          }
        }
        Store(&dst, i, j, sum * (1.0 / wsum));
      }
    });
  } else {
    constexpr int kSub = 4;
    tbb::parallel_for(0, h, [&](int j) {
      for (int i = 0; i < w; ++i) {
        Rgb<double> sum;
        double wsum = 0.0;
        for (int sj = 0; sj < kSub; ++sj) {
          for (int si = 0; si < kSub; ++si) {
            const double u = (i + (si + 0.5) / kSub) / w;
            const double v = 1.0 - (j + (sj + 0.5) / kSub) / h;
            const double weight = std::cos((v - 0.5) * kPi);
            sum += src.Bilinear(Environment::UvToDirection(u, v)) * weight;
            wsum += weight;
          }
        }
        Store(&dst, i, j, sum * (1.0 / wsum));
      }
    });
  }
  dst.SetPoles();
  return dst;
}

// 2 x 2 box downsample with solid-angle row weights (preserves the integral exactly).
Level Downsample2(const Level& src) {
  Level dst = MakeLevel(src.width / 2, src.height / 2, src.roughness);
  for (int j = 0; j < dst.height; ++j) {
    const double w0 = RowWeight(2 * j, src.height), w1 = RowWeight(2 * j + 1, src.height);
    for (int i = 0; i < dst.width; ++i) {
      const Rgb<double> top = Load(src, 2 * i, 2 * j) + Load(src, 2 * i + 1, 2 * j);
      const Rgb<double> bottom = Load(src, 2 * i, 2 * j + 1) + Load(src, 2 * i + 1, 2 * j + 1);
      Store(&dst, i, j, (top * w0 + bottom * w1) * (0.5 / (w0 + w1)));
    }
  }
  dst.SetPoles();
  return dst;
}

// Trilinear lookup in a pyramid (lod clamped to its range).
Rgb<double> Trilinear(const std::vector<Level>& pyramid, const Vec3<double>& map_dir, double lod) {
  const double max_lod = double(pyramid.size() - 1);
  lod = std::isfinite(lod) ? std::clamp(lod, 0.0, max_lod) : 0.0;
  const int k0 = static_cast<int>(std::floor(lod));
  const int k1 = std::min(k0 + 1, static_cast<int>(pyramid.size()) - 1);
  const double f = lod - k0;
  const Rgb<double> a = pyramid[static_cast<size_t>(k0)].Bilinear(map_dir);
  if (f == 0.0 || k1 == k0) return a;
  const Rgb<double> b = pyramid[static_cast<size_t>(k1)].Bilinear(map_dir);
  return a + (b - a) * f;
}

// One importance sample of the prefilter, in the frame where n = v = R = +z.
struct KernelSample {
  Vec3<double> l;  // local light direction
  double NoL;      // its weight
  double lod;      // source-pyramid lod (filtered importance sampling)
};

// Samples h from D(h) NoH restricted to NoH >= 1/sqrt(2) (exactly the h whose mirror
// direction l = 2 NoH h - n has NoL = 2 NoH^2 - 1 >= 0): the engines draw h from the whole
// distribution and drop NoL <= 0; restricting the draw to the kept region (the truncated
// density pdf / u_max) has the same ratio estimator in expectation and wastes no samples,
// which matters for Charlie at low roughness, where all but a fraction u_max ~ 1e-4 of the
// full distribution lies below the horizon.
std::vector<KernelSample> KernelSamples(PrefilteredEnvironment::Kernel kernel, double r, int n,
                                        double texel_solid_angle, int pyramid_levels) {
  const double alpha = std::max(r * r, 1e-8);  // kMinAlpha (docs/conventions.md section 5)
  const bool ggx = kernel == PrefilteredEnvironment::Kernel::kGgx;
  // CDF value (in the theta coordinate u) at NoH^2 = 1/2.
  const double u_max =
      ggx ? 1.0 / (1.0 + alpha * alpha) : std::pow(0.5, (2.0 * alpha + 1.0) / (2.0 * alpha));
  std::vector<KernelSample> out;
  out.reserve(static_cast<size_t>(n));
  for (int s = 0; s < n; ++s) {
    const double u = (s + 0.5) / n * u_max;
    const double phi = 2.0 * kPi * RadicalInverse2(static_cast<unsigned>(s));
    double cos_h = 0.0, sin_h = 0.0, d = 0.0;
    if (ggx) {
      // Karis 2013: cos^2 theta_h = (1 - u) / (1 + (alpha^2 - 1) u).
      const double a2 = alpha * alpha;
      const double cos2 = (1.0 - u) / (1.0 + (a2 - 1.0) * u);
      cos_h = std::sqrt(cos2);
      sin_h = std::sqrt(std::max(0.0, 1.0 - cos2));
      const double den = cos2 * (a2 - 1.0) + 1.0;
      d = a2 / (kPi * den * den);  // D_GGX
    } else {
      // Estevez & Kulla 2017: sin theta_h = u^(alpha / (2 alpha + 1)).
      sin_h = std::pow(u, alpha / (2.0 * alpha + 1.0));
      cos_h = std::sqrt(std::max(0.0, 1.0 - sin_h * sin_h));
      d = (2.0 + 1.0 / alpha) * std::pow(sin_h, 1.0 / alpha) / (2.0 * kPi);  // D_Charlie
    }
    const double NoL = 2.0 * cos_h * cos_h - 1.0;
    if (!(NoL > 0.0)) continue;
    // pdf(l) = pdf(h) / (4 VoH) = D NoH / (4 NoH) = D / 4 (v = n), over the truncated range.
    const double pdf = d / 4.0 / u_max;
    const double omega_s = 1.0 / (n * pdf);
    double lod = 0.5 * std::log2(omega_s / texel_solid_angle) + 1.0;  // +1: Karis's bias
    lod = std::isfinite(lod) ? std::clamp(lod, 0.0, double(pyramid_levels - 1))
                             : double(pyramid_levels - 1);
    const Vec3<double> h(sin_h * std::cos(phi), sin_h * std::sin(phi), cos_h);
    out.push_back({Vec3<double>(2.0 * cos_h * h.x, 2.0 * cos_h * h.y, NoL), NoL, lod});
  }
  return out;
}

// Orthonormal basis around unit n (Duff et al. 2017, "Building an Orthonormal Basis,
// Revisited", JCGT 6(1)).
void Frame(const Vec3<double>& n, Vec3<double>* t, Vec3<double>* b) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double c = n.x * n.y * a;
  *t = Vec3<double>(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = Vec3<double>(c, sign + n.y * n.y * a, -n.y);
}

void Check(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("PrefilteredEnvironment::Build: " + what);
}

}  // namespace

Rgb<double> PrefilteredEnvironment::Level::Bilinear(const Vec3<double>& map_dir) const {
  double u = 0.0, v = 0.0;
  Environment::DirectionToUv(map_dir, &u, &v);
  if (!std::isfinite(u) || !std::isfinite(v)) return {};
  // Texel centres at integers after the -1/2 shift; wrap in u.
  const double x = u * width - 0.5, y = (1.0 - v) * height - 0.5;
  const double x0 = std::floor(x);
  const double fx = x - x0;
  const int i0 = ((static_cast<int>(x0) % width) + width) % width;
  const int i1 = (i0 + 1) % width;
  const auto row = [&](int j) {
    const Rgb<double> a = Load(*this, i0, j), b = Load(*this, i1, j);
    return a + (b - a) * fx;
  };
  // Pole caps: y in [-1/2, 0) lies between the pole (y = -1/2) and the first row's centres.
  if (y < 0.0) {
    const double t = std::clamp(2.0 * y + 1.0, 0.0, 1.0);
    return pole_top + (row(0) - pole_top) * t;
  }
  if (y > height - 1.0) {
    const double t = std::clamp(2.0 * (height - 0.5 - y), 0.0, 1.0);
    return pole_bottom + (row(height - 1) - pole_bottom) * t;
  }
  const int j0 = std::max(0, std::min(static_cast<int>(std::floor(y)), height - 2));
  const double fy = y - j0;
  const Rgb<double> top = row(j0), bottom = row(std::min(j0 + 1, height - 1));
  return top + (bottom - top) * fy;
}

void PrefilteredEnvironment::Level::SetPoles() {
  Rgb<double> top, bottom;
  for (int i = 0; i < width; ++i) {
    top += Load(*this, i, 0);
    bottom += Load(*this, i, height - 1);
  }
  pole_top = top * (1.0 / width);
  pole_bottom = bottom * (1.0 / width);
}

double PrefilteredEnvironment::RoughnessForLevel(Kernel kernel, int k, int levels) {
  if (levels <= 1) return 0.0;
  const double t = std::clamp(double(k) / (levels - 1), 0.0, 1.0);
  // kGgx: lod / lodsForRoughnessOne = r (2 - r)  =>  r = 1 - sqrt(1 - t).
  return kernel == Kernel::kGgx ? 1.0 - std::sqrt(1.0 - t) : t;
}

double PrefilteredEnvironment::LodForRoughness(double r) const {
  r = std::isfinite(r) ? std::clamp(r, 0.0, 1.0) : 0.0;
  const double lods_for_roughness_one = double(levels_.size() - 1);
  return kernel_ == Kernel::kGgx ? lods_for_roughness_one * r * (2.0 - r)
                                 : lods_for_roughness_one * r;
}

Rgb<double> PrefilteredEnvironment::Sample(const Vec3<double>& dir, double lod) const {
  // World -> map: R_y(-rotation_y) (environment.h).
  const Vec3<double> m(cos_rot_ * dir.x - sin_rot_ * dir.z, dir.y,
                       sin_rot_ * dir.x + cos_rot_ * dir.z);
  return Trilinear(levels_, m, lod);
}

PrefilteredEnvironment PrefilteredEnvironment::Build(const Environment& env, Kernel kernel,
                                                     int levels, int base_width, int samples,
                                                     const Progress& progress) {
  Check(env.width() > 0 && env.height() > 0, "the environment is empty");
  Check(levels >= 1, "levels must be >= 1, got " + std::to_string(levels));
  Check(base_width >= 8 && base_width <= 8192 && (base_width & (base_width - 1)) == 0,
        "base_width must be a power of two in [8, 8192], got " + std::to_string(base_width));
  Check(levels <= 30 && (base_width >> (levels - 1)) >= 4,
        "base_width / 2^(levels - 1) must be >= 4, got base_width " + std::to_string(base_width) +
            " with levels " + std::to_string(levels));
  Check(samples >= 1 && samples <= 65536,
        "samples must be in [1, 65536], got " + std::to_string(samples));

  PrefilteredEnvironment out;
  out.kernel_ = kernel;
  out.rotation_y_ = env.rotation_y();
  out.cos_rot_ = std::cos(out.rotation_y_);
  out.sin_rot_ = std::sin(out.rotation_y_);

  // Source pyramid of the plain environment, base width down to 4 x 2.
  std::vector<Level> pyramid;
  pyramid.push_back(BaseLevel(env, base_width, base_width / 2));
  while (pyramid.back().width > 4) pyramid.push_back(Downsample2(pyramid.back()));

  out.levels_.push_back(pyramid[0]);
  if (progress) progress(1, levels);
  // Solid angle of a base texel at the equator: (2 pi / W) (pi / H).
  const double texel_solid_angle = 2.0 * kPi * kPi / (double(base_width) * (base_width / 2));
  for (int k = 1; k < levels; ++k) {
    const double r = RoughnessForLevel(kernel, k, levels);
    const std::vector<KernelSample> taps =
        KernelSamples(kernel, r, samples, texel_solid_angle, static_cast<int>(pyramid.size()));
    double weight = 0.0;
    for (const KernelSample& s : taps) weight += s.NoL;
    Level lvl = MakeLevel(base_width >> k, (base_width >> k) / 2, r);
    tbb::parallel_for(tbb::blocked_range<int>(0, lvl.height), [&](const auto& rows) {
      for (int j = rows.begin(); j < rows.end(); ++j) {
        for (int i = 0; i < lvl.width; ++i) {
          const Vec3<double> n = TexelCentre(i, j, lvl.width, lvl.height);
          Rgb<double> sum;
          if (weight > 0.0) {
            Vec3<double> t, b;
            Frame(n, &t, &b);
            for (const KernelSample& s : taps) {
              const Vec3<double> l = t * s.l.x + b * s.l.y + n * s.l.z;
              sum += Trilinear(pyramid, l, s.lod) * s.NoL;
            }
            sum = sum * (1.0 / weight);
          } else {
            // No sample above the horizon (cannot happen with the truncated draw; kept so a
            // degenerate kernel yields the unfiltered radiance instead of 0/0).
            sum = pyramid[0].Bilinear(n);
          }
          Store(&lvl, i, j, sum);
        }
      }
    });
    lvl.SetPoles();
    out.levels_.push_back(std::move(lvl));
    if (progress) progress(k + 1, levels);
  }
  return out;
}

}  // namespace clothfit::render
