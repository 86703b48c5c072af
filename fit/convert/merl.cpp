#include "fit/convert/merl.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>

#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"

namespace clothfit::fit {
namespace {

[[noreturn]] void Fail(const std::string& path, const std::string& field, const std::string& msg) {
  throw std::runtime_error(path + ": " + field + ": " + msg);
}

// Rotation of v about the axis (0,0,1) or (0,1,0) by angle a.
Vec3<double> RotZ(const Vec3<double>& v, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x - s * v.y, s * v.x + c * v.y, v.z};
}
Vec3<double> RotY(const Vec3<double>& v, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c * v.x + s * v.z, v.y, -s * v.x + c * v.z};
}

}  // namespace

bool MerlTable::Lookup(const Vec3<double>& wi_in, const Vec3<double>& wo_in, Rgb<double>& f) const {
  if (wi_in.z <= 0.0 || wo_in.z <= 0.0) return false;
  const Vec3<double> wi = Normalize(wi_in), wo = Normalize(wo_in);
  const Vec3<double> h = Normalize(wi + wo);
  const double theta_h = std::acos(std::clamp(h.z, -1.0, 1.0));
  const double phi_h = std::atan2(h.y, h.x);
  // Difference vector: wi in the frame where h is the pole (rotate by -phi_h, then -theta_h).
  const Vec3<double> d = RotY(RotZ(wi, -phi_h), -theta_h);
  const double theta_d = std::acos(std::clamp(d.z, -1.0, 1.0));
  double phi_d = std::atan2(d.y, d.x);
  if (phi_d < 0.0) phi_d += kPi;
  const int ih = std::clamp(int(std::sqrt(theta_h / (0.5 * kPi)) * n_theta_h), 0, n_theta_h - 1);
  const int id = std::clamp(int(theta_d / (0.5 * kPi) * n_theta_d), 0, n_theta_d - 1);
  const int ip = std::clamp(int(phi_d / kPi * n_phi_d), 0, n_phi_d - 1);
  const size_t idx = (size_t(ih) * size_t(n_theta_d) + size_t(id)) * size_t(n_phi_d) + size_t(ip);
  const size_t n = Cells();
  for (int c = 0; c < 3; ++c) {
    const double v = data[size_t(c) * n + idx];
    if (v < 0.0) return false;
    f[c] = v * kMerlScale[c];
  }
  return true;
}

bool MerlCellDirections(const MerlTable& t, int ih, int id, int ip, Vec3<double>& wi,
                        Vec3<double>& wo) {
  const double u = (ih + 0.5) / t.n_theta_h;
  const double theta_h = u * u * 0.5 * kPi;
  const double theta_d = (id + 0.5) / t.n_theta_d * 0.5 * kPi;
  const double phi_d = (ip + 0.5) / t.n_phi_d * kPi;
  const Vec3<double> d(std::sin(theta_d) * std::cos(phi_d), std::sin(theta_d) * std::sin(phi_d),
                       std::cos(theta_d));
  wi = RotY(d, theta_h);  // phi_h = 0 (isotropic)
  const Vec3<double> h(std::sin(theta_h), 0.0, std::cos(theta_h));
  wo = h * (2.0 * Dot(wi, h)) - wi;
  return wi.z > 1e-6 && wo.z > 1e-6;
}

MerlTable ReadMerl(const std::string& path) {
  std::string bytes;
  try {  // size checked on the descriptor first: a 1024^3 header cannot make us read 24 GiB
    bytes = limits::ReadFileBounded(path, limits::kMaxMerlBytes, "MERL file");
  } catch (const limits::InputError& e) {
    Fail(path, "file", e.what());
  }
  return ParseMerl(bytes, path);
}

MerlTable ParseMerl(std::string_view bytes, const std::string& path) {
  if (bytes.size() < 12) Fail(path, "header", "file shorter than the 12-byte header");
  int32_t dims[3];
  std::memcpy(dims, bytes.data(), 12);
  const char* names[3] = {"header.n_theta_h", "header.n_theta_d", "header.n_phi_d"};
  for (int k = 0; k < 3; ++k)
    if (dims[k] <= 0 || dims[k] > 1024)
      Fail(path, names[k], std::to_string(dims[k]) + " outside [1, 1024]");
  MerlTable t;
  t.n_theta_h = dims[0];
  t.n_theta_d = dims[1];
  t.n_phi_d = dims[2];
  const auto cells = limits::CheckedProduct({size_t(dims[0]), size_t(dims[1]), size_t(dims[2]),
                                             3, sizeof(double)});
  const size_t expect = cells ? 12 + *cells : 0;
  if (bytes.size() != expect)
    Fail(path, "data",
         "file has " + std::to_string(bytes.size()) + " bytes, header " + std::to_string(dims[0]) +
             "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " needs " +
             std::to_string(expect));
  t.data.resize(3 * t.Cells());
  std::memcpy(t.data.data(), bytes.data() + 12, t.data.size() * sizeof(double));
  for (size_t i = 0; i < t.data.size(); ++i)
    if (!std::isfinite(t.data[i]))
      Fail(path, "data[" + std::to_string(i) + "]", "non-finite value");
  return t;
}

void WriteMerl(const std::string& path, const MerlTable& t) {
  std::string bytes(12 + t.data.size() * sizeof(double), '\0');
  const int32_t dims[3] = {t.n_theta_h, t.n_theta_d, t.n_phi_d};
  std::memcpy(bytes.data(), dims, 12);
  std::memcpy(bytes.data() + 12, t.data.data(), t.data.size() * sizeof(double));
  io::WriteTextAtomic(path, bytes);
}

BrdfSamples SampleMerl(const MerlTable& t) {
  BrdfSamples s;
  for (const DirectionPair& d : CanonicalDirections()) {
    Rgb<double> f(0, 0, 0);
    const bool ok = t.Lookup(d.l, d.v, f);
    s.value.push_back(f * d.l.z);
    s.valid.push_back(ok);
  }
  return s;
}

}  // namespace clothfit::fit
