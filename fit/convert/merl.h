// fit/convert/merl.h: measured isotropic BRDFs in the MERL binary format (Matusik, Pfister, Brand,
// McMillan 2003, "A Data-Driven Reflectance Model"; the public MERL BRDF database), written
// from the format's description:
//   header  3 x int32 (little endian): n_theta_h, n_theta_d, n_phi_d  (database: 90, 90, 180)
//   data    3 * n_theta_h * n_theta_d * n_phi_d float64, channel-major (all R, then G, then B);
//           within a channel index = (i_theta_h * n_theta_d + i_theta_d) * n_phi_d + i_phi_d
//   scales  stored value * (1/1500, 1.15/1500, 1.66/1500) for R, G, B = BRDF (1/sr, no cosine)
//   cells   Rusinkiewicz half/difference angles: theta_h in [0, pi/2] with a square-root
//           mapping i_theta_h = floor(sqrt(theta_h / (pi/2)) * n_theta_h); theta_d in
//           [0, pi/2] linear; phi_d in [0, pi) linear (reciprocity folds phi_d + pi onto phi_d)
//   negative stored values mean "not measured" (below the horizon).
// Lookups are nearest-cell, as the format's reference reader does. Other dimensions than the
// database's are accepted (the catalogue's small synthetic tables use them); the file size must
// match the header exactly.
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "brdf/math.h"
#include "fit/brdf_fit.h"

namespace clothfit::fit {

inline constexpr double kMerlScale[3] = {1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0};

struct MerlTable {
  int n_theta_h = 90, n_theta_d = 90, n_phi_d = 180;
  std::vector<double> data;  // stored (unscaled) values, channel-major as in the file

  size_t Cells() const { return size_t(n_theta_h) * size_t(n_theta_d) * size_t(n_phi_d); }
  // BRDF value (scaled, no cosine) for directions in the local frame; false if not measured or
  // either direction is below the horizon.
  bool Lookup(const Vec3<double>& wi, const Vec3<double>& wo, Rgb<double>& f) const;
};

// Throws std::runtime_error "<path>: <field>: <reason>" on a missing, short, oversized or
// malformed file (dimensions non-positive or above 1024, size mismatch, NaN values).
MerlTable ReadMerl(const std::string& path);
// The same on bytes in memory (`path` names them in messages). The file must be exactly the
// header's size; ReadMerl refuses files over kMaxMerlBytes before reading them.
MerlTable ParseMerl(std::string_view bytes, const std::string& path);
// Atomic write (render/scene/image_io.h WriteTextAtomic on the binary bytes).
void WriteMerl(const std::string& path, const MerlTable& t);
// Fills a table from f(wi, wo) (BRDF, no cosine) at the cell centres.
template <typename F>
MerlTable TabulateMerl(int n_theta_h, int n_theta_d, int n_phi_d, F&& brdf);

// The table sampled on the canonical direction set (value = f * n.l).
BrdfSamples SampleMerl(const MerlTable& t);

// Directions (wi, wo) of a cell centre; false when one is below the horizon.
bool MerlCellDirections(const MerlTable& t, int ih, int id, int ip, Vec3<double>& wi,
                        Vec3<double>& wo);

template <typename F>
MerlTable TabulateMerl(int n_theta_h, int n_theta_d, int n_phi_d, F&& brdf) {
  MerlTable t;
  t.n_theta_h = n_theta_h;
  t.n_theta_d = n_theta_d;
  t.n_phi_d = n_phi_d;
  const size_t n = t.Cells();
  t.data.assign(3 * n, -1.0);
  size_t idx = 0;
  for (int ih = 0; ih < n_theta_h; ++ih)
    for (int id = 0; id < n_theta_d; ++id)
      for (int ip = 0; ip < n_phi_d; ++ip, ++idx) {
        Vec3<double> wi, wo;
        if (!MerlCellDirections(t, ih, id, ip, wi, wo)) continue;
        const Rgb<double> f = brdf(wi, wo);
        for (int c = 0; c < 3; ++c) t.data[size_t(c) * n + idx] = f[c] / kMerlScale[c];
      }
  return t;
}

}  // namespace clothfit::fit
