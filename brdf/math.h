// brdf/math.h: the small, Jet-safe math every BRDF header shares.
//
// Everything here is templated on the scalar T (float, double, ceres::Jet<double, N>).
// Rules (CODE_STYLE.md): call math through ADL (`using std::sqrt; sqrt(x)`) so the Jet
// overloads are found; compare with `<` (Jets compare their scalar parts); never call
// std::max/std::min on T.
#pragma once

#include <cmath>
#include <type_traits>

namespace clothfit {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kInvPi = 1.0 / kPi;

// Scalar part of a value: the value itself for float/double, `.a` for a ceres::Jet.
// Used only for control flow (table indices, branch selection), never for results.
template <typename T>
inline double ScalarPart(const T& x) {
  if constexpr (std::is_arithmetic_v<T>) {
    return static_cast<double>(x);
  } else {
    return static_cast<double>(x.a);
  }
}

// Constant of type T from a double literal (float gets an explicit narrowing cast).
template <typename T>
inline T Const(double v) {
  if constexpr (std::is_arithmetic_v<T>) {
    return static_cast<T>(v);
  } else {
    return T(v);
  }
}

template <typename T>
inline T Max(const T& a, const T& b) {
  return (a < b) ? b : a;
}
template <typename T>
inline T Min(const T& a, const T& b) {
  return (b < a) ? b : a;
}
template <typename T>
inline T Clamp(const T& x, const T& lo, const T& hi) {
  return Min(Max(x, lo), hi);
}
// GLSL saturate: clamp to [0, 1].
template <typename T>
inline T Saturate(const T& x) {
  return Clamp(x, Const<T>(0.0), Const<T>(1.0));
}
template <typename T>
inline T Mix(const T& a, const T& b, const T& t) {
  return a + (b - a) * t;
}
template <typename T>
inline T Sq(const T& x) {
  return x * x;
}
template <typename T>
inline T Pow5(const T& x) {
  const T x2 = x * x;
  return x2 * x2 * x;
}

// sqrt with a finite derivative at 0: below `eps` (a value, not a derivative scale) the
// argument is clamped, so d/dx stays bounded by 1 / (2 sqrt(eps)).
template <typename T>
inline T SafeSqrt(const T& x, double eps = 1e-12) {
  using std::sqrt;
  return sqrt(Max(x, Const<T>(eps)));
}

// Linear RGB triple. Plain aggregate: arithmetic is component-wise.
template <typename T>
struct Rgb {
  T r{}, g{}, b{};

  Rgb() = default;
  Rgb(T r_, T g_, T b_) : r(r_), g(g_), b(b_) {}
  static Rgb Splat(T v) { return Rgb(v, v, v); }

  T& operator[](int i) { return i == 0 ? r : (i == 1 ? g : b); }
  const T& operator[](int i) const { return i == 0 ? r : (i == 1 ? g : b); }

  friend Rgb operator+(const Rgb& a, const Rgb& c) { return {a.r + c.r, a.g + c.g, a.b + c.b}; }
  friend Rgb operator-(const Rgb& a, const Rgb& c) { return {a.r - c.r, a.g - c.g, a.b - c.b}; }
  friend Rgb operator*(const Rgb& a, const Rgb& c) { return {a.r * c.r, a.g * c.g, a.b * c.b}; }
  friend Rgb operator*(const Rgb& a, const T& s) { return {a.r * s, a.g * s, a.b * s}; }
  friend Rgb operator*(const T& s, const Rgb& a) { return {a.r * s, a.g * s, a.b * s}; }
  Rgb& operator+=(const Rgb& c) {
    r += c.r;
    g += c.g;
    b += c.b;
    return *this;
  }
};

template <typename T>
inline T Max3(const Rgb<T>& c) {
  return Max(Max(c.r, c.g), c.b);
}
template <typename T>
inline Rgb<T> Saturate(const Rgb<T>& c) {
  return {Saturate(c.r), Saturate(c.g), Saturate(c.b)};
}
template <typename T>
inline Rgb<T> Sqrt(const Rgb<T>& c, double eps = 1e-12) {
  return {SafeSqrt(c.r, eps), SafeSqrt(c.g, eps), SafeSqrt(c.b, eps)};
}

// Convert an Rgb<double> (a default, a table value) to Rgb<T>.
template <typename T, typename U>
inline Rgb<T> CastRgb(const Rgb<U>& c) {
  return {Const<T>(static_cast<double>(c.r)), Const<T>(static_cast<double>(c.g)),
          Const<T>(static_cast<double>(c.b))};
}

// 3-vector for directions in the shading frame (z = normal).
template <typename T>
struct Vec3 {
  T x{}, y{}, z{};
  Vec3() = default;
  Vec3(T x_, T y_, T z_) : x(x_), y(y_), z(z_) {}
  friend Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
  friend Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
  friend Vec3 operator*(const Vec3& a, const T& s) { return {a.x * s, a.y * s, a.z * s}; }
  friend Vec3 operator*(const T& s, const Vec3& a) { return {a.x * s, a.y * s, a.z * s}; }
};

template <typename T>
inline T Dot(const Vec3<T>& a, const Vec3<T>& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <typename T>
inline Vec3<T> Cross(const Vec3<T>& a, const Vec3<T>& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <typename T>
inline T Length(const Vec3<T>& a) {
  using std::sqrt;
  return sqrt(Dot(a, a));
}
// Normalise; a zero vector stays zero instead of becoming NaN.
template <typename T>
inline Vec3<T> Normalize(const Vec3<T>& a) {
  const T len2 = Dot(a, a);
  if (!(Const<T>(0.0) < len2)) return Vec3<T>(Const<T>(0.0), Const<T>(0.0), Const<T>(0.0));
  using std::sqrt;
  return a * (Const<T>(1.0) / sqrt(len2));
}

// Direction from spherical angles in the shading frame (z = normal).
template <typename T>
inline Vec3<T> SphericalDirection(T cos_theta, T phi) {
  using std::cos;
  using std::sin;
  const T sin_theta = SafeSqrt(Const<T>(1.0) - cos_theta * cos_theta);
  return {sin_theta * cos(phi), sin_theta * sin(phi), cos_theta};
}

}  // namespace clothfit
