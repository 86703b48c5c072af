// render/scene/sun.cpp: the sun split of render/scene/sun.h (docs/sun.md). web/clothfit.js
// (splitEnvironmentSun) is a line-by-line port: change both together.
#include "render/scene/sun.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <mutex>
#include <stdexcept>
#include <tuple>

namespace clothfit::render {

SunMode ParseSunMode(const std::string& value, const std::string& field) {
  if (value == "auto") return SunMode::kAuto;
  if (value == "off") return SunMode::kOff;
  if (value == "panels") return SunMode::kPanels;
  throw std::invalid_argument(field + ": expected \"auto\", \"off\" or \"panels\", got \"" +
                              value + "\"");
}

const char* SunModeName(SunMode m) {
  switch (m) {
    case SunMode::kAuto: return "auto";
    case SunMode::kPanels: return "panels";
    case SunMode::kOff: break;
  }
  return "off";
}

SunMode EffectiveSunMode(const Scene& scene, const std::optional<SunMode>& forced,
                         SunMode fallback) {
  if (forced) return *forced;
  if (scene.card.environment && scene.card.environment->sun) return *scene.card.environment->sun;
  return fallback;
}

namespace {

constexpr double kY[3] = {0.2126, 0.7152, 0.0722};  // Rec.709 luminance

float Clean(float x) { return std::isfinite(x) && x > 0.0f ? x : 0.0f; }

// Lower median (sorted element (n - 1) / 2); v is reordered.
template <typename T>
T LowerMedian(std::vector<T>& v) {
  const size_t k = (v.size() - 1) / 2;
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(k), v.end());
  return v[k];
}

std::string Fmt(const char* f, double a, double b = 0, double c = 0, double d = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c, d);
  return buf;
}

}  // namespace

SunSplit DetectSun(int W, int H, const float* rgb, double intensity, double rotation_y,
                   const SunDetectParams& prm, std::vector<float>* sun_free) {
  SunSplit s;
  if (W < 1 || H < 1 || !rgb) throw std::invalid_argument("DetectSun: empty map");
  const size_t n = size_t(W) * size_t(H);
  // Per row: solid angle of a texel and the centre's elevation.
  std::vector<double> dw(static_cast<size_t>(H)), cos_e(dw.size()), sin_e(dw.size());
  for (int j = 0; j < H; ++j) {
    const double e_top = kPi / 2 - kPi * j / H, e_bot = kPi / 2 - kPi * (j + 1) / H;
    dw[size_t(j)] = (2.0 * kPi / W) * (std::sin(e_top) - std::sin(e_bot));
    const double e = kPi / 2 - kPi * (j + 0.5) / H;
    cos_e[size_t(j)] = std::cos(e);
    sin_e[size_t(j)] = std::sin(e);
  }
  std::vector<double> cos_p(static_cast<size_t>(W)), sin_p(cos_p.size());
  for (int i = 0; i < W; ++i) {
    const double phi = ((i + 0.5) / W - 0.5) * 2.0 * kPi;
    cos_p[size_t(i)] = std::cos(phi);
    sin_p[size_t(i)] = std::sin(phi);
  }
  auto lum = [&](size_t t) {
    return kY[0] * double(Clean(rgb[t * 3])) + kY[1] * double(Clean(rgb[t * 3 + 1])) +
           kY[2] * double(Clean(rgb[t * 3 + 2]));
  };
  // 1. Power and peak.
  double P = 0.0, peak_y = 0.0;
  size_t peak = 0;
  for (int j = 0; j < H; ++j) {
    for (int i = 0; i < W; ++i) {
      const size_t t = size_t(j) * size_t(W) + size_t(i);
      const double y = lum(t);
      P += y * dw[size_t(j)];
      if (y > peak_y) peak_y = y, peak = t;
    }
  }
  s.map_power = P;
  if (!(P > 0.0)) {
    s.summary = "no sun: the map is black";
    return s;
  }
  const int pj = int(peak / size_t(W)), pi = int(peak % size_t(W));
  auto dir_of = [&](size_t t, double* d) {
    const size_t j = t / size_t(W), i = t % size_t(W);
    d[0] = cos_e[j] * cos_p[i];
    d[1] = sin_e[j];
    d[2] = cos_e[j] * sin_p[i];
  };
  double d0[3];
  dir_of(peak, d0);
  const double r = prm.max_radius_deg * kPi / 180.0;
  const double cos_in = std::cos(r), cos_out = std::cos(std::min(kPi, 2.0 * r));
  // The window's centre: the luminance-weighted centroid of the texels within max_radius_deg
  // of the peak at >= half its luminance (a clipped, flat-topped sun's peak texel is the first
  // of many equal ones, at its edge; the centroid is its middle).
  double dp[3] = {0, 0, 0};
  for (size_t t = 0; t < n; ++t) {
    double d[3];
    dir_of(t, d);
    const double y = lum(t);
    if (y >= 0.5 * peak_y && d[0] * d0[0] + d[1] * d0[1] + d[2] * d0[2] >= cos_in)
      for (int k = 0; k < 3; ++k) dp[k] += y * d[k];
  }
  const double dn = std::sqrt(dp[0] * dp[0] + dp[1] * dp[1] + dp[2] * dp[2]);
  for (int k = 0; k < 3; ++k) dp[k] /= dn;
  // 2. Window and annulus (by the angle between texel centres and that centre).
  std::vector<size_t> inner, ring;
  for (int j = 0; j < H; ++j) {
    for (int i = 0; i < W; ++i) {
      const double c = cos_e[size_t(j)] * cos_p[size_t(i)] * dp[0] + sin_e[size_t(j)] * dp[1] +
                       cos_e[size_t(j)] * sin_p[size_t(i)] * dp[2];
      const size_t t = size_t(j) * size_t(W) + size_t(i);
      if (c >= cos_in) inner.push_back(t);
      else if (c >= cos_out) ring.push_back(t);
    }
  }
  if (int(ring.size()) < prm.min_annulus_texels) {
    s.summary = "no sun: the map is too coarse (" + std::to_string(ring.size()) +
                " texels in the annulus, fewer than " + std::to_string(prm.min_annulus_texels) + ")";
    return s;
  }
  // 3. Fill and threshold.
  std::vector<float> ch(ring.size());
  for (int k = 0; k < 3; ++k) {
    for (size_t q = 0; q < ring.size(); ++q) ch[q] = Clean(rgb[ring[q] * 3 + size_t(k)]);
    s.fill[size_t(k)] = LowerMedian(ch);
  }
  std::vector<double> ry(ring.size());
  for (size_t q = 0; q < ring.size(); ++q) ry[q] = lum(ring[q]);
  const double B = LowerMedian(ry);
  const double T = prm.contrast * B;
  const double fill_y =
      kY[0] * double(s.fill[0]) + kY[1] * double(s.fill[1]) + kY[2] * double(s.fill[2]);
  // 4. Sun texels, compactness, power.
  double ex[3] = {0, 0, 0}, ex_y = 0.0, dir[3] = {0, 0, 0}, ring_ex = 0.0;
  for (size_t t : inner) {
    const double y = lum(t);
    if (!(y > T)) continue;
    const int j = int(t / size_t(W)), i = int(t % size_t(W));
    const double w = dw[size_t(j)];
    s.sun_texels.push_back(int(t));
    s.solid_angle += w;
    for (int k = 0; k < 3; ++k) ex[k] += (double(Clean(rgb[t * 3 + size_t(k)])) - double(s.fill[size_t(k)])) * w;
    const double wy = (y - fill_y) * w;
    ex_y += wy;
    dir[0] += wy * cos_e[size_t(j)] * cos_p[size_t(i)];
    dir[1] += wy * sin_e[size_t(j)];
    dir[2] += wy * cos_e[size_t(j)] * sin_p[size_t(i)];
  }
  for (size_t t : ring) {
    const double y = lum(t);
    if (y > T) ring_ex += (y - B) * dw[t / size_t(W)];
  }
  s.texels = int(s.sun_texels.size());
  s.power_fraction = ex_y / P;
  s.annulus_excess_ratio = ex_y > 0.0 ? ring_ex / ex_y : 0.0;
  const double norm = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
  if (norm > 0.0) s.map_direction = {dir[0] / norm, dir[1] / norm, dir[2] / norm};
  const double cr = std::cos(rotation_y), sr = std::sin(rotation_y);  // Environment::MapToWorld
  const auto& m = s.map_direction;
  s.world_direction = {cr * m[0] + sr * m[2], m[1], -sr * m[0] + cr * m[2]};
  for (int k = 0; k < 3; ++k) s.irradiance[size_t(k)] = std::max(0.0, ex[k]) * intensity;
  const std::string where =
      Fmt("peak %.4g at elevation %.1f deg, u %.3f; candidate ", peak_y,
          90.0 - 180.0 * (pj + 0.5) / H, (pi + 0.5) / W) +
      std::to_string(s.texels) + Fmt(" texels, %.3g sr", s.solid_angle) +
      Fmt(", power share %.4f, annulus excess ratio %.3f", s.power_fraction,
          s.annulus_excess_ratio);
  if (s.texels == 0 || !(ex_y > 0.0) || !(norm > 0.0)) {
    s.summary = "no sun: nothing above " + Fmt("%.4g", T) + " x the annulus median (" + where + ")";
    s.sun_texels.clear();
    return s;
  }
  if (s.annulus_excess_ratio > prm.max_annulus_excess) {
    s.summary = "no sun: not compact (" + where + ")";
    s.sun_texels.clear();
    return s;
  }
  if (s.power_fraction < prm.min_power_fraction) {
    s.summary = "no sun: too weak (" + where + ")";
    s.sun_texels.clear();
    return s;
  }
  // 5. The split.
  s.found = true;
  const double emax = std::max({s.irradiance[0], s.irradiance[1], s.irradiance[2]});
  s.light.type = Light::Type::kDirectional;
  s.light.name = "environment sun";
  s.light.intensity = emax;
  // The cap with the source's solid angle: cos r = 1 - Omega / (2 pi) (the horizon fade's size).
  {
    const double cos_r = std::clamp(1.0 - s.solid_angle / (2.0 * kPi), -1.0, 1.0);
    s.light.sin_angular_radius = std::sqrt(std::max(1.0 - cos_r * cos_r, 0.0));
  }
  for (int k = 0; k < 3; ++k) {
    s.light.color[size_t(k)] = emax > 0.0 ? s.irradiance[size_t(k)] / emax : 0.0;
    s.light.direction[size_t(k)] = -s.world_direction[size_t(k)];
  }
  s.summary = "sun: " + where +
              Fmt(", E = (%.4g, %.4g, %.4g), world direction", s.irradiance[0], s.irradiance[1],
                  s.irradiance[2]) +
              Fmt(" (%.4f, %.4f, %.4f)", s.world_direction[0], s.world_direction[1],
                  s.world_direction[2]);
  if (sun_free) {
    sun_free->resize(n * 3);
    for (size_t t = 0; t < n * 3; ++t) (*sun_free)[t] = Clean(rgb[t]);
    for (int t : s.sun_texels)
      for (int k = 0; k < 3; ++k) (*sun_free)[size_t(t) * 3 + size_t(k)] = s.fill[size_t(k)];
  }
  return s;
}

std::shared_ptr<const SunSplitEnvironment> SplitEnvironmentSun(const Environment& env,
                                                                SunMode mode) {
  auto unchanged = [&](const std::string& why) {
    auto r = std::make_shared<SunSplitEnvironment>();
    r->split.summary = why;
    r->summary = why;
    r->environment = std::shared_ptr<const Environment>(&env, [](const Environment*) {});
    return std::shared_ptr<const SunSplitEnvironment>(r);
  };
  if (mode == SunMode::kOff) return unchanged("no sun: off");
  // FNV-1a over the texels (the memo key; a few ms for a 1024 x 512 map).
  uint64_t h = 1469598103934665603ull;
  const auto* bytes = reinterpret_cast<const unsigned char*>(env.pixels().data());
  for (size_t k = 0, nb = env.pixels().size() * sizeof(float); k < nb; ++k)
    h = (h ^ bytes[k]) * 1099511628211ull;
  using Key = std::tuple<uint64_t, int, int, double, double, std::string, int>;
  static std::mutex mu;
  static std::map<Key, std::shared_ptr<const SunSplitEnvironment>> memo;
  const Key key{h,          env.width(),  env.height(), env.intensity(), env.rotation_y(),
                env.source(), int(mode)};
  {
    std::lock_guard<std::mutex> lock(mu);
    if (auto it = memo.find(key); it != memo.end()) {
      // Found: the memo owns the sun-free map; not found: the caller's own map.
      if (it->second->found()) return it->second;
      return unchanged(it->second->summary);
    }
  }
  auto r = std::make_shared<SunSplitEnvironment>();
  std::vector<float> free_px;
  r->split = DetectSun(env.width(), env.height(), env.pixels().data(), env.intensity(),
                       env.rotation_y(), SunDetectParams{}, &free_px);
  r->summary = r->split.summary;
  if (r->split.found) r->lights.push_back(r->split.light);
  if (mode == SunMode::kPanels) {
    // Each panel on the map with everything found so far filled (DetectSun's sun_free output).
    std::string stop;
    for (int k = 0; k < kMaxPanelLights; ++k) {
      const float* px = r->lights.empty() ? env.pixels().data() : free_px.data();
      std::vector<float> next;
      SunSplit p = DetectSun(env.width(), env.height(), px, env.intensity(), env.rotation_y(),
                             kPanelDetectParams, &next);
      if (!p.found) {
        stop = p.summary;
        break;
      }
      p.light.name = "environment panel " + std::to_string(k + 1);
      r->lights.push_back(p.light);
      r->panels.push_back(std::move(p));
      free_px = std::move(next);
    }
    r->summary += "; panels: " + std::to_string(r->panels.size());
    for (size_t k = 0; k < r->panels.size(); ++k)
      r->summary += "; panel " + std::to_string(k + 1) + ": " +  // DetectSun says "sun: ..."
                    r->panels[k].summary.substr(r->panels[k].summary.rfind("sun: ", 0) == 0 ? 5 : 0);
    if (!stop.empty() && r->panels.size() < size_t(kMaxPanelLights))
      r->summary += "; then " + stop;
  }
  // The name keys the preview's shared prefiltered chains (render/preview/preview.cpp
  // SharedPrefilter keys by source, not content): each mode its own name, or one mode's map
  // would be prefiltered for the other (review s21).
  if (r->found())
    r->environment = std::make_shared<const Environment>(Environment::FromPixels(
        env.width(), env.height(), std::move(free_px), env.intensity(), env.rotation_y(),
        env.source() + (mode == SunMode::kPanels ? "#panels-free" : "#sun-free")));
  std::shared_ptr<const SunSplitEnvironment> shared;
  {
    std::lock_guard<std::mutex> lock(mu);
    // Two threads that both missed: the first one's split is the one every caller shares.
    shared = memo.emplace(key, r).first->second;
  }
  if (!shared->found()) return unchanged(shared->summary);
  return shared;
}

}  // namespace clothfit::render
