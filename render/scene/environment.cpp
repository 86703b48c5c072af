#include "render/scene/environment.h"
#include "render/scene/input_limits.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>

#include "render/scene/image_io.h"

namespace clothfit::render {
namespace {

// Rec. 709 / linear sRGB luminance.
double Luminance(double r, double g, double b) { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }

void CheckIntensityAndRotation(double intensity, double rotation_y, const char* who) {
  if (!std::isfinite(intensity) || intensity < 0.0) {
    throw std::invalid_argument(std::string(who) + ": intensity must be finite and >= 0, got " +
                                std::to_string(intensity));
  }
  if (intensity > limits::kMaxRadiance) {
    throw std::invalid_argument(std::string(who) + ": intensity " + std::to_string(intensity) +
                                " is above the radiance limit 1e+12 " +
                                limits::LimitRef("kMaxRadiance"));
  }
  if (!std::isfinite(rotation_y)) {
    throw std::invalid_argument(std::string(who) + ": rotation_y must be finite");
  }
}

// Index of the interval [cdf[k], cdf[k+1]) holding x (cdf[0] = 0, cdf[n] = 1, x in [0, 1)).
// Empty intervals (zero-weight entries) are never returned: upper_bound skips past them.
int FindInterval(const double* cdf, int n, double x) {
  const double* it = std::upper_bound(cdf, cdf + n + 1, x);
  const long k = long(it - cdf) - 1;
  return int(std::clamp(k, 0L, long(n - 1)));
}

// FindInterval with a guide table of G = guide_size entries (guide[g] = FindInterval(g / G)):
// the answer for x lies in [guide[g], guide[g + 1]] with g = floor(x G), so the binary search
// runs over that short range only and returns exactly what FindInterval returns.
int FindIntervalGuided(const double* cdf, int n, const int* guide, int guide_size, double x) {
  const int g = std::clamp(int(x * guide_size), 0, guide_size - 1);
  const int lo = guide[g];
  const int hi = g + 1 < guide_size ? guide[g + 1] : n - 1;
  const double* it = std::upper_bound(cdf + lo, cdf + hi + 2, x);
  const long k = long(it - cdf) - 1;
  return int(std::clamp(k, long(lo), long(hi)));
}

void BuildGuide(const double* cdf, int n, int guide_size, int* guide) {
  for (int g = 0; g < guide_size; ++g) guide[g] = FindInterval(cdf, n, double(g) / guide_size);
}

// Largest double below 1: keeps uniform inputs inside [0, 1).
constexpr double kOneMinusEpsilon = 0x1.fffffffffffffp-1;

// Procedural sky (map space, d unit, +Y up; docs/environments.md section 5), linear RGB:
//   y >= 0 (sky):    L = mix(horizon, zenith, sqrt(y))
//   y <  0 (ground): L = mix(horizon, ground, min(1, -y / 0.1))   (6 degrees of haze)
//   plus the sun:    L += sun  where angle(d, sun_dir) <= 2 degrees
// zenith (0.12, 0.30, 0.80), horizon (0.85, 0.90, 1.00), ground (0.20, 0.18, 0.16),
// sun (1000, 950, 880) at elevation 35 degrees, map azimuth 45 degrees (u = 0.625). The disc
// subtends 2 pi (1 - cos 2 deg) = 3.83e-3 sr, so it adds about 3.6 (luminance) of irradiance
// at normal incidence; the sky dome gives a horizontal surface 2 pi (0.1 Y_horizon + 0.4
// Y_zenith) = 1.3.
struct SkyModel {
  Rgb<double> zenith{0.12, 0.30, 0.80};
  Rgb<double> horizon{0.85, 0.90, 1.00};
  Rgb<double> ground{0.20, 0.18, 0.16};
  Rgb<double> sun{1000.0, 950.0, 880.0};
  Vec3<double> sun_dir;
  double cos_sun_radius = 0.0;

  SkyModel() {
    const double elevation = 35.0 * kPi / 180.0, azimuth = 45.0 * kPi / 180.0;
    sun_dir = {std::cos(elevation) * std::cos(azimuth), std::sin(elevation),
               std::cos(elevation) * std::sin(azimuth)};
    cos_sun_radius = std::cos(2.0 * kPi / 180.0);
  }

  Rgb<double> Radiance(const Vec3<double>& d) const {
    Rgb<double> c;
    if (d.y >= 0.0) {
      const double t = std::sqrt(d.y);  // fast rise above the horizon, slow towards the zenith
      c = horizon + (zenith - horizon) * t;
    } else {
      const double t = std::min(1.0, -d.y / 0.1);  // 0.1 ~ 6 degrees of horizon haze
      c = horizon + (ground - horizon) * t;
    }
    if (Dot(d, sun_dir) >= cos_sun_radius) c += sun;
    return c;
  }
};

// Map-space direction m -> (u, v) (Environment::DirectionToUv) plus the cosine of its
// elevation, cos(elevation) = sin(pi v) = sqrt(x^2 + z^2) / |m|. A path that escapes calls Eval
// and then Pdf for the same direction, so the last result is kept in a one-entry thread-local
// memo keyed by the bits of m (a pure function of m: identical to recomputing it).
struct MapUv {
  double u = 0.0, v = 0.0, cos_elevation = 0.0;
};

MapUv DirectionToMapUv(const Vec3<double>& m) {
  struct Memo {
    uint64_t key[3] = {~0ull, ~0ull, ~0ull};  // a NaN pattern: never a valid key
    MapUv uv;
  };
  thread_local Memo memo;
  const uint64_t kx = std::bit_cast<uint64_t>(m.x), ky = std::bit_cast<uint64_t>(m.y),
                 kz = std::bit_cast<uint64_t>(m.z);
  if (memo.key[0] != kx || memo.key[1] != ky || memo.key[2] != kz) {
    MapUv r;
    Environment::DirectionToUv(m, &r.u, &r.v);
    const double rxz = std::sqrt(m.x * m.x + m.z * m.z);
    const double len = std::sqrt(rxz * rxz + m.y * m.y);
    r.cos_elevation = len > 0.0 ? rxz / len : 0.0;
    memo.key[0] = kx;
    memo.key[1] = ky;
    memo.key[2] = kz;
    memo.uv = r;
  }
  return memo.uv;
}

// The bilinear lookup of Environment::Eval at map coordinates (u, v).
Rgb<double> BilinearAt(const std::vector<float>& rgb, int width, int height, double intensity,
                       double u, double v) {
  // Continuous texel coordinates with texel centres at integers (+0.5 rule).
  const double x = u * width - 0.5;
  const double y = (1.0 - v) * height - 0.5;
  const double x0 = std::floor(x), y0 = std::floor(y);
  const double fx = x - x0, fy = y - y0;
  // Wrap in u (the seam at u = 0 / 1 is continuous), clamp in v (the poles).
  const int w = width;
  const int i0 = ((int(x0) % w) + w) % w;
  const int i1 = i0 + 1 == w ? 0 : i0 + 1;
  const int j0 = std::clamp(int(y0), 0, height - 1);
  const int j1 = std::clamp(int(y0) + 1, 0, height - 1);
  const auto texel = [&](int i, int j) {
    const size_t p = (size_t(j) * size_t(w) + size_t(i)) * 3;
    return Rgb<double>(double(rgb[p]), double(rgb[p + 1]), double(rgb[p + 2]));
  };
  // a + t (b - a) form: exact for a constant map.
  const Rgb<double> a = texel(i0, j0), b = texel(i1, j0), c = texel(i0, j1), e = texel(i1, j1);
  const Rgb<double> top = a + (b - a) * fx;
  const Rgb<double> bottom = c + (e - c) * fx;
  return (top + (bottom - top) * fy) * intensity;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Orientation.

void Environment::DirectionToUv(const Vec3<double>& d, double* u, double* v) {
  // atan2 on both angles: scale-invariant and accurate near the poles (asin(y) is not).
  const double phi = std::atan2(d.z, d.x);                                     // [-pi, pi]
  const double elevation = std::atan2(d.y, std::sqrt(d.x * d.x + d.z * d.z));  // [-pi/2, pi/2]
  *u = phi / (2.0 * kPi) + 0.5;
  *v = elevation / kPi + 0.5;
}

Vec3<double> Environment::UvToDirection(double u, double v) {
  const double phi = (u - 0.5) * 2.0 * kPi;
  const double elevation = (v - 0.5) * kPi;
  const double c = std::cos(elevation);
  return {c * std::cos(phi), std::sin(elevation), c * std::sin(phi)};
}

// Map space = R_y(-rotation_y) world. R_y(a) is the right-handed rotation about +Y:
//   x' = cos(a) x + sin(a) z,   z' = -sin(a) x + cos(a) z   (+X turns towards -Z).
Vec3<double> Environment::WorldToMap(const Vec3<double>& d) const {
  return {cos_rot_ * d.x - sin_rot_ * d.z, d.y, sin_rot_ * d.x + cos_rot_ * d.z};
}
Vec3<double> Environment::MapToWorld(const Vec3<double>& m) const {
  return {cos_rot_ * m.x + sin_rot_ * m.z, m.y, -sin_rot_ * m.x + cos_rot_ * m.z};
}

void Environment::SetRotation(double rotation_y) {
  rotation_y_ = rotation_y;
  cos_rot_ = std::cos(rotation_y);
  sin_rot_ = std::sin(rotation_y);
}

// ---------------------------------------------------------------------------------------------
// Construction.

Environment Environment::Load(const std::string& path, double intensity, double rotation_y,
                              const std::function<void(const std::string&)>& warn) {
  CheckIntensityAndRotation(intensity, rotation_y, path.c_str());
  const io::Image img = io::ReadImage(path);  // throws io::IoError naming the file
  if (img.width <= 0 || img.height <= 0 || img.channels() <= 0) {
    throw io::IoError(path + ": empty environment map");
  }
  // An 8/16-bit PNG holds display-encoded (sRGB) codes clipped at 1, not radiance: read as
  // radiance it lights the scene dimly and without its sun, with no error (session 28).
  if (!img.float_source) {
    throw io::IoError(limits::EscapeForMessage(path, 400) +
                      ": an environment map must be "
                      "linear radiance (float or half EXR, or Radiance HDR); this is a " +
                      img.source_format + " " + img.file_format +
                      " with display-encoded values clipped at 1 (docs/environments.md)");
  }
  const int nc = img.channels();
  Environment env;
  env.width_ = img.width;
  env.height_ = img.height;
  env.intensity_ = intensity;
  env.SetRotation(rotation_y);
  env.source_ = path;
  const size_t n = size_t(img.width) * size_t(img.height);
  env.rgb_.resize(n * 3);
  float most_negative = 0.0f;
  // A finite texel may still be huge: 3e38 x intensity overflows float in the renderers (Inf
  // pixels written and cached). Radiance is bounded at load, naming the texel.
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < std::min(nc, 3); ++c) {
      const double x = double(img.pixels[p * size_t(nc) + size_t(c)]);
      if (std::isfinite(x) && x * intensity > limits::kMaxRadiance) {
        std::ostringstream msg;
        msg << limits::EscapeForMessage(path, 400) << ": texel (" << p % size_t(img.width) << ", "
            << p / size_t(img.width) << ") channel " << c << " has radiance " << x
            << " x intensity " << intensity << " = " << x * intensity
            << ", above the limit 1e+12 " << limits::LimitRef("kMaxRadiance");
        throw io::IoError(msg.str());
      }
    }
  }
  for (size_t p = 0; p < n; ++p) {
    bool negative = false, nonfinite = false;
    for (int c = 0; c < 3; ++c) {
      // RGB from the first three channels; one or two channels: the first is grey.
      const int src = nc >= 3 ? c : 0;
      float x = img.pixels[p * size_t(nc) + size_t(src)];
      if (!std::isfinite(x)) {
        nonfinite = true;
        x = 0.0f;
      } else if (x < 0.0f) {
        negative = true;
        most_negative = std::min(most_negative, x);
        x = 0.0f;
      }
      env.rgb_[p * 3 + size_t(c)] = x;
    }
    env.stats_.negative_texels += negative ? 1 : 0;
    env.stats_.nonfinite_texels += nonfinite ? 1 : 0;
  }
  // Negative texels are clamped to 0 either way. They are reported only when they matter: a
  // NaN/Inf, or a negative value beyond 1e-4 of the map's mean radiance. Lossy or half-float
  // encoders leave a few texels a hair below zero (the bundled studio map: 3 texels, the most
  // negative -3e-6 against a mean of order 1), which changes no pixel of any render.
  double sum = 0.0;
  for (const float x : env.rgb_) sum += double(x);
  const double mean = sum / double(std::max<size_t>(env.rgb_.size(), 1));
  const bool negative_matters = double(most_negative) < -1e-4 * mean;
  if (warn && ((env.stats_.negative_texels > 0 && negative_matters) ||
               env.stats_.nonfinite_texels > 0)) {
    std::ostringstream msg;
    msg << path << ": " << img.width << "x" << img.height << " environment map has "
        << env.stats_.negative_texels << " texels with negative values (most negative "
        << double(most_negative) << ") and " << env.stats_.nonfinite_texels
        << " texels with NaN/Inf values; those channels were set to 0";
    warn(msg.str());
  }
  env.BuildDistribution();
  return env;
}

Environment Environment::ProceduralSky(double intensity, double rotation_y, int width) {
  CheckIntensityAndRotation(intensity, rotation_y, "procedural-sky");
  if (width < 4 || width > io::kMaxDimension) {
    throw std::invalid_argument("procedural-sky: width must be in [4, " +
                                std::to_string(io::kMaxDimension) + "], got " +
                                std::to_string(width));
  }
  const SkyModel sky;
  Environment env;
  env.width_ = width;
  env.height_ = width / 2;
  env.intensity_ = intensity;
  env.SetRotation(rotation_y);
  env.source_ = "procedural-sky";
  env.rgb_.resize(size_t(env.width_) * size_t(env.height_) * 3);
  // Each texel is the mean of a k x k grid of sub-samples over its (u, v) cell: k = 8 for
  // texels within two texel heights of the sun disc (anti-aliased edge), k = 2 elsewhere (the
  // gradient is smooth). The result depends on nothing but `width`.
  const double texel_angle = kPi / env.height_;  // >= the texel's angular width and height
  const double near_sun =
      std::cos(std::min(kPi, std::acos(sky.cos_sun_radius) + 2.0 * texel_angle));
  for (int j = 0; j < env.height_; ++j) {
    for (int i = 0; i < env.width_; ++i) {
      const Vec3<double> centre =
          UvToDirection((i + 0.5) / env.width_, 1.0 - (j + 0.5) / env.height_);
      const int k = Dot(centre, sky.sun_dir) >= near_sun ? 8 : 2;
      Rgb<double> sum;
      for (int sj = 0; sj < k; ++sj) {
        for (int si = 0; si < k; ++si) {
          const double u = (i + (si + 0.5) / k) / env.width_;
          const double v = 1.0 - (j + (sj + 0.5) / k) / env.height_;
          sum += sky.Radiance(UvToDirection(u, v));
        }
      }
      const size_t p = (size_t(j) * size_t(env.width_) + size_t(i)) * 3;
      for (int c = 0; c < 3; ++c) env.rgb_[p + size_t(c)] = float(sum[c] / double(k * k));
    }
  }
  env.BuildDistribution();
  return env;
}

Environment Environment::Constant(const std::array<double, 3>& radiance, int width) {
  for (double x : radiance) {
    if (!std::isfinite(x) || x < 0.0 || x > limits::kMaxRadiance) {
      throw std::invalid_argument(
          "constant environment: radiance must be finite, >= 0 and <= 1e+12 " +
          limits::LimitRef("kMaxRadiance"));
    }
  }
  if (width < 2 || width > io::kMaxDimension) {
    throw std::invalid_argument("constant environment: width must be in [2, " +
                                std::to_string(io::kMaxDimension) + "], got " +
                                std::to_string(width));
  }
  Environment env;
  env.width_ = width;
  env.height_ = width / 2;
  env.intensity_ = 1.0;
  env.SetRotation(0.0);
  env.source_ = "constant";
  env.rgb_.resize(size_t(env.width_) * size_t(env.height_) * 3);
  for (size_t p = 0; p < env.rgb_.size(); p += 3) {
    for (size_t c = 0; c < 3; ++c) env.rgb_[p + c] = float(radiance[c]);
  }
  env.BuildDistribution();
  return env;
}

Environment Environment::FromPixels(int width, int height, std::vector<float> rgb,
                                    double intensity, double rotation_y,
                                    const std::string& source) {
  CheckIntensityAndRotation(intensity, rotation_y, source.c_str());
  if (width < 1 || height < 1 || width > io::kMaxDimension || height > io::kMaxDimension ||
      rgb.size() != size_t(width) * size_t(height) * 3) {
    throw std::invalid_argument(source + ": environment of " + std::to_string(width) + " x " +
                                std::to_string(height) + " with " + std::to_string(rgb.size()) +
                                " values (expected width x height x 3, each dimension in [1, " +
                                std::to_string(io::kMaxDimension) + "])");
  }
  for (size_t k = 0; k < rgb.size(); ++k) {
    if (!std::isfinite(rgb[k]) || rgb[k] < 0.0f || double(rgb[k]) * intensity > limits::kMaxRadiance)
      throw std::invalid_argument(source + ": texel " + std::to_string(k / 3) + " channel " +
                                  std::to_string(k % 3) +
                                  " must be finite, >= 0 and <= 1e+12 after intensity " +
                                  limits::LimitRef("kMaxRadiance"));
  }
  Environment env;
  env.width_ = width;
  env.height_ = height;
  env.intensity_ = intensity;
  env.SetRotation(rotation_y);
  env.source_ = source;
  env.rgb_ = std::move(rgb);
  env.BuildDistribution();
  return env;
}

// ---------------------------------------------------------------------------------------------
// Lookup.

Rgb<double> Environment::Texel(int i, int j) const {
  const size_t p = (size_t(j) * size_t(width_) + size_t(i)) * 3;
  return {double(rgb_[p]), double(rgb_[p + 1]), double(rgb_[p + 2])};
}

Rgb<double> Environment::Eval(const Vec3<double>& d) const {
  if (width_ <= 0) return {};
  const MapUv m = DirectionToMapUv(WorldToMap(d));
  if (!std::isfinite(m.u) || !std::isfinite(m.v)) return {};
  if (total_weight_ > 0.0) {
    // The path tracer asks Pdf(d) right after Eval(d) for an escaping path: start loading the
    // CDF entries Pdf reads (TexelDensity) so that miss overlaps the texel loads below.
    const int i = std::clamp(int(m.u * width_), 0, width_ - 1);
    const int j = std::clamp(int((1.0 - m.v) * height_), 0, height_ - 1);
    __builtin_prefetch(&conditional_cdf_[size_t(j) * size_t(width_ + 1) + size_t(i)]);
  }
  return BilinearAt(rgb_, width_, height_, intensity_, m.u, m.v);
}

// ---------------------------------------------------------------------------------------------
// Importance sampling.
//
// Texel weight w(i, j) = Y_filtered(i, j) * sin(theta_j), where theta_j = pi (j + 0.5) / H is
// the polar angle of row j's centre and Y_filtered is the Rec. 709 luminance of the bilinear
// reconstruction (what Eval returns) averaged over the texel: the separable [1 6 1] / 8 filter
// of the texel luminances (wrapping in u, clamping in v). The filter makes the weight positive
// wherever Eval can be positive (a bilinear lookup in texel (i, j) only reads its 3x3
// neighbourhood), so the estimator stays unbiased next to isolated bright texels.
//
// The (u, v) density is piecewise constant: p(u, v) = w(i, j) / sum(w) * W * H in texel
// (i, j). With d omega = 2 pi^2 sin(theta) du dv, the solid-angle pdf is
//   pdf(d) = p(u, v) / (2 pi^2 sin(theta)),  sin(theta) = sin(pi v)  (at the sampled point).

void Environment::BuildDistribution() {
  const int w = width_, h = height_;
  std::vector<double> lum(size_t(w) * size_t(h));
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      const Rgb<double> t = Texel(i, j);
      lum[size_t(j) * size_t(w) + size_t(i)] = Luminance(t.r, t.g, t.b);
    }
  }
  // Horizontal [1 6 1] / 8 (wrap), then vertical (clamp).
  std::vector<double> hor(lum.size());
  for (int j = 0; j < h; ++j) {
    const double* row = &lum[size_t(j) * size_t(w)];
    for (int i = 0; i < w; ++i) {
      const double left = row[(i + w - 1) % w], right = row[(i + 1) % w];
      hor[size_t(j) * size_t(w) + size_t(i)] = (left + 6.0 * row[i] + right) / 8.0;
    }
  }
  std::vector<double> weight(lum.size());
  for (int j = 0; j < h; ++j) {
    const double* up = &hor[size_t(std::max(j - 1, 0)) * size_t(w)];
    const double* mid = &hor[size_t(j) * size_t(w)];
    const double* down = &hor[size_t(std::min(j + 1, h - 1)) * size_t(w)];
    const double sin_theta = std::sin(kPi * (j + 0.5) / h);  // > 0 at every row centre
    for (int i = 0; i < w; ++i) {
      weight[size_t(j) * size_t(w) + size_t(i)] =
          (up[i] + 6.0 * mid[i] + down[i]) / 8.0 * sin_theta;
    }
  }

  conditional_cdf_.assign(size_t(h) * size_t(w + 1), 0.0);
  row_weight_.assign(size_t(h), 0.0);
  for (int j = 0; j < h; ++j) {
    double* cdf = &conditional_cdf_[size_t(j) * size_t(w + 1)];
    const double* row = &weight[size_t(j) * size_t(w)];
    double sum = 0.0;
    for (int i = 0; i < w; ++i) {
      sum += row[i];
      cdf[i + 1] = sum;
    }
    row_weight_[size_t(j)] = sum;
    if (sum > 0.0) {
      for (int i = 1; i < w; ++i) cdf[i] /= sum;
    } else {
      // A black row is never drawn (its marginal mass is 0); keep a valid uniform CDF anyway.
      for (int i = 1; i < w; ++i) cdf[i] = double(i) / w;
    }
    cdf[w] = 1.0;
  }
  marginal_cdf_.assign(size_t(h + 1), 0.0);
  double total = 0.0;
  for (int j = 0; j < h; ++j) {
    total += row_weight_[size_t(j)];
    marginal_cdf_[size_t(j + 1)] = total;
  }
  total_weight_ = total;
  if (total > 0.0 && std::isfinite(total)) {
    for (int j = 1; j < h; ++j) marginal_cdf_[size_t(j)] /= total;
  } else {
    // All-black map (or an overflowing sum): Sample and Pdf fall back to uniform sphere
    // sampling; total_weight_ = 0 marks it.
    total_weight_ = 0.0;
    for (int j = 1; j < h; ++j) marginal_cdf_[size_t(j)] = double(j) / h;
  }
  marginal_cdf_[size_t(h)] = 1.0;
  marginal_guide_.assign(size_t(h), 0);
  BuildGuide(marginal_cdf_.data(), h, h, marginal_guide_.data());
  conditional_guide_.assign(size_t(h) * size_t(w), 0);
  for (int j = 0; j < h; ++j)
    BuildGuide(&conditional_cdf_[size_t(j) * size_t(w + 1)], w, w,
               &conditional_guide_[size_t(j) * size_t(w)]);
}

double Environment::TexelDensity(int i, int j) const {
  // p(u, v) in texel (i, j): the probability of the texel over its (u, v) area 1 / (W H).
  // Sample and Pdf both use this expression, so they agree exactly.
  const double p_row = marginal_cdf_[size_t(j + 1)] - marginal_cdf_[size_t(j)];
  const double* cdf = &conditional_cdf_[size_t(j) * size_t(width_ + 1)];
  const double p_col = cdf[i + 1] - cdf[i];
  return p_row * p_col * double(width_) * double(height_);
}

Vec3<double> Environment::Sample(double u1, double u2, double* pdf, Rgb<double>* radiance) const {
  u1 = std::clamp(u1, 0.0, kOneMinusEpsilon);
  u2 = std::clamp(u2, 0.0, kOneMinusEpsilon);
  if (!(total_weight_ > 0.0)) {
    // Uniform sphere (black map): y = 1 - 2 u2, phi = 2 pi u1.
    const double y = 1.0 - 2.0 * u2;
    const double r = std::sqrt(std::max(0.0, 1.0 - y * y));
    const double phi = 2.0 * kPi * u1;
    const Vec3<double> d(r * std::cos(phi), y, r * std::sin(phi));
    if (pdf) *pdf = 1.0 / (4.0 * kPi);
    if (radiance) *radiance = Eval(d);
    return d;
  }
  // Row from the marginal CDF (u2), column from the row's conditional CDF (u1); the remainder
  // of each uniform places the point inside the texel.
  const int j = FindIntervalGuided(marginal_cdf_.data(), height_, marginal_guide_.data(),
                                   height_, u2);
  const double row_lo = marginal_cdf_[size_t(j)], row_hi = marginal_cdf_[size_t(j + 1)];
  const double dv = std::clamp((u2 - row_lo) / (row_hi - row_lo), 0.0, kOneMinusEpsilon);
  const double* cdf = &conditional_cdf_[size_t(j) * size_t(width_ + 1)];
  const int i = FindIntervalGuided(cdf, width_, &conditional_guide_[size_t(j) * size_t(width_)],
                                   width_, u1);
  const double du = std::clamp((u1 - cdf[i]) / (cdf[i + 1] - cdf[i]), 0.0, kOneMinusEpsilon);
  const double u = (i + du) / width_;
  const double v = 1.0 - (j + dv) / height_;
  // UvToDirection(u, v), keeping cos(elevation) = sin(theta) = sin(pi v) for the pdf.
  const double phi = (u - 0.5) * 2.0 * kPi;
  const double elevation = (v - 0.5) * kPi;
  const double c = std::cos(elevation);
  const Vec3<double> d = MapToWorld({c * std::cos(phi), std::sin(elevation), c * std::sin(phi)});
  if (pdf) {
    // sin(theta) = 0 only exactly at a pole (a measure-zero set): report pdf 0 there, which
    // callers treat as "discard this sample", instead of dividing by zero.
    const double sin_theta = v > 0.0 && v < 1.0 ? c : 0.0;
    *pdf = sin_theta > 0.0 ? TexelDensity(i, j) / (2.0 * kPi * kPi * sin_theta) : 0.0;
  }
  if (radiance) *radiance = Eval(d);  // exactly Eval's value (not a lookup at (u, v))
  return d;
}

double Environment::Pdf(const Vec3<double>& d) const {
  if (width_ <= 0) return 0.0;
  if (!(total_weight_ > 0.0)) return 1.0 / (4.0 * kPi);
  const MapUv m = DirectionToMapUv(WorldToMap(d));
  const double u = m.u, v = m.v;
  if (!std::isfinite(u) || !std::isfinite(v)) return 0.0;
  const double sin_theta = m.cos_elevation;  // = sin(pi v)
  if (!(sin_theta > 0.0)) return 0.0;        // exactly at a pole; see Sample
  const int i = std::clamp(int(u * width_), 0, width_ - 1);
  const int j = std::clamp(int((1.0 - v) * height_), 0, height_ - 1);
  return TexelDensity(i, j) / (2.0 * kPi * kPi * sin_theta);
}

}  // namespace clothfit::render
