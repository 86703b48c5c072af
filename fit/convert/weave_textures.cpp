#include "fit/convert/weave_textures.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace clothfit::fit {
namespace {

double SrgbDecode(double s) {  // IEC 61966-2-1
  return s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
}

// The 8-bit sRGB code whose decoded value is nearest to the linear value x in [0, 1].
int NearestSrgbCode(double x) {
  const auto& dec = SrgbDecodeTable();
  const auto it = std::lower_bound(dec.begin(), dec.end(), x);  // first code with dec >= x
  if (it == dec.begin()) return 0;
  if (it == dec.end()) return 255;
  const int hi = int(it - dec.begin()), lo = hi - 1;
  return (x - dec[size_t(lo)] <= dec[size_t(hi)] - x) ? lo : hi;
}

// The smallest 8-bit sRGB code whose decoded value is >= x (x in [0, 1]).
int CeilSrgbCode(double x) {
  const auto& dec = SrgbDecodeTable();
  const auto it = std::lower_bound(dec.begin(), dec.end(), x);
  return it == dec.end() ? 255 : int(it - dec.begin());
}

double WrapAngle(double a) {
  while (a > kPi) a -= 2.0 * kPi;
  while (a < -kPi) a += 2.0 * kPi;
  return a;
}

}  // namespace

const std::array<double, 256>& SrgbDecodeTable() {
  static const std::array<double, 256> table = [] {
    std::array<double, 256> t{};
    for (int q = 0; q < 256; ++q) t[size_t(q)] = SrgbDecode(double(q) / 255.0);
    return t;
  }();
  return table;
}

WeaveTextures BakePhysicalAnisoTextures(const render::MaterialPreset& p,
                                        const render::WeaveMaps& maps) {
  if (p.model != render::ModelKind::kPhysicalAniso)
    throw std::invalid_argument("BakePhysicalAnisoTextures: the preset is not physical-aniso");
  if (maps.levels.empty() || maps.size <= 0)
    throw std::invalid_argument("BakePhysicalAnisoTextures: empty weave maps");
  constexpr int C = render::WeaveMaps::kChannels;
  const std::vector<float>& l0 = maps.levels[0];
  const size_t n = size_t(maps.size) * size_t(maps.size);
  const auto& dec = SrgbDecodeTable();
  WeaveTextures w;
  w.size = maps.size;
  w.uv_repeats = maps.uv_repeats;
  w.max_anisotropy = maps.anisotropy;
  w.base_color.assign(n * 3, 0);
  w.anisotropy.assign(n * 3, 0);

  // ---- base colour: factor f_c (an exact 8-bit sRGB value) x texel = b_c k_c(t) ----
  const int ob = p.Offset("base_color");
  for (int c = 0; c < 3; ++c) {
    const double b = p.values[size_t(ob + c)];
    double K = 0.0;
    for (size_t t = 0; t < n; ++t) K = std::max(K, double(l0[t * C + 2 + size_t(c)]));
    w.kd_max[c] = K;
    const double f = b * K >= 1.0 ? 1.0 : dec[size_t(CeilSrgbCode(b * K))];
    w.base_factor[c] = f;
    for (size_t t = 0; t < n; ++t) {
      const double exact = b * double(l0[t * C + 2 + size_t(c)]);
      if (exact > 1.0) ++w.clipped_texels;
      const int q = f > 0.0 ? NearestSrgbCode(std::min(exact / f, 1.0)) : 0;
      w.base_color[t * 3 + size_t(c)] = static_cast<unsigned char>(q);
      const double err = std::abs(f * dec[size_t(q)] - exact);
      w.base_max_abs_error = std::max(w.base_max_abs_error, err);
      if (exact > 1e-3) w.base_max_rel_error = std::max(w.base_max_rel_error, err / exact);
    }
  }

  // ---- anisotropy: direction (warp -> t, weft -> b), strength s / S ----
  const double a = p.values[size_t(p.Offset("anisotropy_strength"))];
  const double rot = p.values[size_t(p.Offset("anisotropy_rotation"))];
  std::vector<double> s(n);
  for (size_t t = 0; t < n; ++t) {
    const double wa = double(l0[t * C]), wb = double(l0[t * C + 1]);
    s[t] = wa + wb > 0.0 ? std::abs(wa - wb) / (wa + wb) : 0.0;
    w.strength_max = std::max(w.strength_max, s[t]);
  }
  const double S = w.strength_max;
  w.anisotropy_strength = a * S;
  const double e = std::atan(1.0 / 255.0);  // the stored axes are turned by -e (header)
  w.anisotropy_rotation = WrapAngle(rot + e);
  for (size_t t = 0; t < n; ++t) {
    const bool warp = l0[t * C] >= l0[t * C + 1];
    unsigned char* px = &w.anisotropy[t * 3];
    px[0] = warp ? 255 : 128;
    px[1] = warp ? 127 : 255;
    const int qb = S > 0.0 ? int(std::lround(255.0 * s[t] / S)) : 0;
    px[2] = static_cast<unsigned char>(std::clamp(qb, 0, 255));
    // Measured: decode as the shader does, rotate by the written rotation, compare.
    double dx = 2.0 * px[0] / 255.0 - 1.0, dy = 2.0 * px[1] / 255.0 - 1.0;
    const double len = std::hypot(dx, dy);
    dx /= len;
    dy /= len;
    const double cr = std::cos(w.anisotropy_rotation), sr = std::sin(w.anisotropy_rotation);
    const double ux = cr * dx - sr * dy, uy = sr * dx + cr * dy;
    const double want = rot + (warp ? 0.0 : 0.5 * kPi);
    const double ang = std::abs(WrapAngle(std::atan2(uy, ux) - want));
    w.direction_max_angle_error = std::max(w.direction_max_angle_error, ang);
    w.strength_max_abs_error = std::max(
        w.strength_max_abs_error, std::abs(w.anisotropy_strength * px[2] / 255.0 - a * s[t]));
  }
  return w;
}

}  // namespace clothfit::fit
