#include "render/preview/sh.h"

#include <cmath>
#include <vector>

namespace clothfit::render {
namespace {

// Closed-form integrals over one texel cell of the equirect map.
//
// A cell is phi in [phi0, phi1] x elevation E in [e0, e1] (map space), with
//   x = cos E cos phi,  y = sin E,  z = cos E sin phi,  dw = cos E dE dphi
// (Environment::UvToDirection: phi = 2 pi (u - 1/2), E = pi (v - 1/2)). Every monomial of
// degree <= 2 separates into a phi factor and an E factor:
//   1 = P0 Q1,   x = Pc Qc,    y = P0 Qs,    z = Ps Qc,
//   xx = Pcc Qcc, yy = P0 Qss, zz = Pss Qcc, xy = Pc Qcs, yz = Ps Qcs, xz = Pcs Qcc,
// with P* = int (1, cos, sin, cos^2, sin^2, cos sin)(phi) dphi and
//      Q* = int (cos, cos^2, sin cos, cos^3, sin^2 cos, cos^2 sin)(E) dE.
struct PhiIntegrals {
  double p0, pc, ps, pcc, pss, pcs;
};
struct ElevationIntegrals {
  double q1, qc, qs, qcc, qss, qcs;
};

PhiIntegrals IntegratePhi(double a, double b) {
  const double sa = std::sin(a), sb = std::sin(b), ca = std::cos(a), cb = std::cos(b);
  const double d = b - a;
  const double sin2 = (std::sin(2.0 * b) - std::sin(2.0 * a)) / 4.0;
  return {d, sb - sa, ca - cb, d / 2.0 + sin2, d / 2.0 - sin2, (sb * sb - sa * sa) / 2.0};
}

ElevationIntegrals IntegrateElevation(double a, double b) {
  const double sa = std::sin(a), sb = std::sin(b), ca = std::cos(a), cb = std::cos(b);
  return {sb - sa,
          (b - a) / 2.0 + (std::sin(2.0 * b) - std::sin(2.0 * a)) / 4.0,
          (sb * sb - sa * sa) / 2.0,
          (sb - sb * sb * sb / 3.0) - (sa - sa * sa * sa / 3.0),
          (sb * sb * sb - sa * sa * sa) / 3.0,
          (ca * ca * ca - cb * cb * cb) / 3.0};
}

}  // namespace

Sh9 ProjectEnvironment(const Environment& env) {
  const int w = env.width(), h = env.height();
  const std::vector<float>& px = env.pixels();
  std::vector<PhiIntegrals> cols(static_cast<size_t>(w));
  for (int i = 0; i < w; ++i) {
    const double phi0 = (double(i) / w - 0.5) * 2.0 * kPi;
    const double phi1 = (double(i + 1) / w - 0.5) * 2.0 * kPi;
    cols[static_cast<size_t>(i)] = IntegratePhi(phi0, phi1);
  }
  // Map-space moments int L m dw for the ten monomials, per channel.
  enum { k1, kX, kY, kZ, kXX, kYY, kZZ, kXY, kYZ, kXZ, kMoments };
  std::array<Rgb<double>, kMoments> m{};
  for (int j = 0; j < h; ++j) {
    // Row j (top first) covers v in [1 - (j+1)/H, 1 - j/H), E = pi (v - 1/2).
    const double e0 = (0.5 - double(j + 1) / h) * kPi;
    const double e1 = (0.5 - double(j) / h) * kPi;
    const ElevationIntegrals q = IntegrateElevation(e0, e1);
    // Row sums of L times each phi integral.
    Rgb<double> s0, sc, ss, scc, sss, scs;
    for (int i = 0; i < w; ++i) {
      const size_t p = (static_cast<size_t>(j) * static_cast<size_t>(w) + size_t(i)) * 3;
      const Rgb<double> l(static_cast<double>(px[p]), static_cast<double>(px[p + 1]),
                          static_cast<double>(px[p + 2]));
      const PhiIntegrals& c = cols[static_cast<size_t>(i)];
      s0 += l * c.p0;
      sc += l * c.pc;
      ss += l * c.ps;
      scc += l * c.pcc;
      sss += l * c.pss;
      scs += l * c.pcs;
    }
    m[k1] += s0 * q.q1;
    m[kX] += sc * q.qc;
    m[kY] += s0 * q.qs;
    m[kZ] += ss * q.qc;
    m[kXX] += scc * q.qcc;
    m[kYY] += s0 * q.qss;
    m[kZZ] += sss * q.qcc;
    m[kXY] += sc * q.qcs;
    m[kYZ] += ss * q.qcs;
    m[kXZ] += scs * q.qcc;
  }
  const double s = env.intensity();
  Sh9 sh;
  sh.c[0] = m[k1] * (kShY00 * s);
  sh.c[1] = m[kY] * (kShY1 * s);
  sh.c[2] = m[kZ] * (kShY1 * s);
  sh.c[3] = m[kX] * (kShY1 * s);
  sh.c[4] = m[kXY] * (kShY2a * s);
  sh.c[5] = m[kYZ] * (kShY2a * s);
  sh.c[6] = (m[kZZ] * 3.0 - m[k1]) * (kShY20 * s);
  sh.c[7] = m[kXZ] * (kShY2a * s);
  sh.c[8] = (m[kXX] - m[kYY]) * (kShY22 * s);
  // The map is rotated by +rotation_y into the world (environment.h).
  return env.rotation_y() == 0.0 ? sh : RotateY(sh, env.rotation_y());
}

// L'_k = int L(R^-1 w) Y_k(w) dw = int L(m) Y_k(R m) dm, and Y_k(R m) is a combination of the
// same band's Y_k'(m). With R = R_y(a): x' = c x + s z, y' = y, z' = -s x + c z (c = cos a,
// s = sin a). Substituting and re-expanding (x^2 + y^2 + z^2 = 1 eliminates the constant):
//   band 1:  Y_y -> Y_y;  Y_z -> c Y_z - s Y_x;  Y_x -> c Y_x + s Y_z
//   band 2:  Y_xy -> c Y_xy + s Y_yz;  Y_yz -> c Y_yz - s Y_xy
//            Y_20 -> (c^2 - s^2/2) Y_20 - sqrt3 c s Y_xz + (sqrt3/2) s^2 Y_22
//            Y_xz -> sqrt3 c s Y_20 + (c^2 - s^2) Y_xz - c s Y_22
//            Y_22 -> (sqrt3/2) s^2 Y_20 + c s Y_xz + (1 + c^2)/2 Y_22
Sh9 RotateY(const Sh9& sh, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  const double r3 = std::sqrt(3.0);
  const auto& l = sh.c;
  Sh9 out;
  out.c[0] = l[0];
  out.c[1] = l[1];
  out.c[2] = l[2] * c - l[3] * s;
  out.c[3] = l[3] * c + l[2] * s;
  out.c[4] = l[4] * c + l[5] * s;
  out.c[5] = l[5] * c - l[4] * s;
  out.c[6] = l[6] * (c * c - s * s / 2.0) - l[7] * (r3 * c * s) + l[8] * (r3 / 2.0 * s * s);
  out.c[7] = l[6] * (r3 * c * s) + l[7] * (c * c - s * s) - l[8] * (c * s);
  out.c[8] = l[6] * (r3 / 2.0 * s * s) + l[7] * (c * s) + l[8] * ((1.0 + c * c) / 2.0);
  return out;
}

}  // namespace clothfit::render
