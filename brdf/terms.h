// brdf/terms.h: the microfacet and diffuse terms shared by every model, named as in the
// literature (D_, V_, F_, Fd_) and as in Filament's brdf.fs / three.js bsdfs.glsl.js.
//
// All functions take the *inside-the-formula* roughness alpha (not the perceptual r);
// the models convert r -> alpha = r^2 and apply their engine's clamps. Each term guards its
// singular points so that values AND ceres::Jet derivatives stay finite for inputs inside
// the documented domain (cloth-models.md section 8); every guard is written next to the term.
#pragma once

#include <cmath>

#include "brdf/math.h"

namespace clothfit {

// Filament / three.js clamp of sin^2(theta_h) in the Charlie distribution: 2^-7, so that
// sin2h^2 > 0 in fp16.
inline constexpr double kCharlieMinSin2h = 0.0078125;

// Smallest alpha any term accepts; below it 1/alpha overflows the exponent of pow().
inline constexpr double kMinAlpha = 1e-8;

// D_Charlie: Estevez & Kulla 2017, "Production Friendly Microfacet Sheen BRDF".
//   D(h) = (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi),  sin^2 = 1 - NoH^2.
// `engine_clamp` applies the engines' sin2h >= 2^-7 clamp (Filament, three.js). Without it
// sin2h is still floored at 1e-12 so that pow(0, g) (infinite derivative in the base,
// NaN in g through log 0) never occurs; the value
// changes by at most (1e-12)^(1/(2 alpha)) <= 1e-6 relative to the peak. alpha is floored
// at kMinAlpha = 1e-8 (three.js r187's smallest sheen alpha, (1e-4)^2).
template <typename T>
inline T D_Charlie(const T& alpha_in, const T& NoH, bool engine_clamp = true) {
  using std::pow;
  const T alpha = Max(alpha_in, Const<T>(kMinAlpha));
  const T inv_alpha = Const<T>(1.0) / alpha;
  const T sin2h = Max(Const<T>(1.0) - NoH * NoH, Const<T>(engine_clamp ? kCharlieMinSin2h : 1e-12));
  return (Const<T>(2.0) + inv_alpha) * pow(sin2h, inv_alpha * Const<T>(0.5)) *
         Const<T>(0.5 * kInvPi);
}

// How the Neubelt visibility is bounded (it is unbounded as NoV, NoL -> 0).
enum class NeubeltClamp {
  kNone,    // Filament desktop: 1 / (4 (NoL + NoV - NoL NoV)), NoV already >= 1e-4
  kMobile,  // Filament mobile: saturateMediump, V <= 65504
  kOne,     // three.js and the seed: saturate(V), V <= 1
};

// V_Neubelt: Neubelt & Pettineo 2013, "Crafting a Next-gen Material Pipeline for The
// Order: 1886" (the "Ashikhmin" visibility).  V = 1 / (4 (NoL + NoV - NoL NoV)).
// Guard: the denominator is floored at 1e-12 before the division (it is exactly 0 at
// NoV = NoL = 0, where three.js's saturate(1/0) = 1 and our kOne result is also 1).
template <typename T>
inline T V_Neubelt(const T& NoV, const T& NoL, NeubeltClamp clamp = NeubeltClamp::kNone) {
  const T den = Max(Const<T>(4.0) * (NoL + NoV - NoL * NoV), Const<T>(1e-12));
  const T v = Const<T>(1.0) / den;
  switch (clamp) {
    case NeubeltClamp::kOne: return Min(v, Const<T>(1.0));
    case NeubeltClamp::kMobile: return Min(v, Const<T>(65504.0));
    case NeubeltClamp::kNone: break;
  }
  return v;
}

// Charlie Lambda: glTF KHR_materials_sheen specification, from Conty & Kulla 2017
// ("Production Friendly Microfacet Sheen BRDF", the fitted shadowing term).
//   t = (1 - alpha)^2; a..e lerp between the two fitted rows;
//   L(x) = a / (1 + b x^c) + d x + e
//   Lambda(cos) = exp(L(cos)) if |cos| < 0.5, else exp(2 L(0.5) - L(1 - cos)).
// Guard: x is floored at 1e-9 inside L, so x^c (0 < c < 1) keeps a finite derivative in c
// (changes Lambda(1) by less than 1e-7, negligible against 1 in the visibility).
template <typename T>
inline T L_CharlieLambda(const T& x_in, const T& alpha) {
  using std::pow;
  const T t = Sq(Const<T>(1.0) - alpha);
  const T a = Mix(Const<T>(21.5473), Const<T>(25.3245), t);
  const T b = Mix(Const<T>(3.82987), Const<T>(3.32435), t);
  const T c = Mix(Const<T>(0.19823), Const<T>(0.16801), t);
  const T d = Mix(Const<T>(-1.97760), Const<T>(-1.27393), t);
  const T e = Mix(Const<T>(-4.32054), Const<T>(-4.85967), t);
  const T x = Max(x_in, Const<T>(1e-9));
  return a / (Const<T>(1.0) + b * pow(x, c)) + d * x + e;
}

template <typename T>
inline T Lambda_Charlie(const T& cos_theta, const T& alpha) {
  using std::abs;
  using std::exp;
  if (abs(cos_theta) < Const<T>(0.5)) return exp(L_CharlieLambda(abs(cos_theta), alpha));
  return exp(Const<T>(2.0) * L_CharlieLambda(Const<T>(0.5), alpha) -
             L_CharlieLambda(Const<T>(1.0) - abs(cos_theta), alpha));
}

// V_Charlie (glTF sheen visibility): V = 1 / ((1 + Lambda(NoV) + Lambda(NoL)) 4 NoV NoL),
// clamped to [0, 1] as the Khronos sample viewer does. Guard: the denominator is floored at
// 1e-12 (it vanishes at grazing angles, where the sample viewer's clamp gives 1).
template <typename T>
inline T V_Charlie(const T& NoV, const T& NoL, const T& alpha) {
  const T den = (Const<T>(1.0) + Lambda_Charlie(NoV, alpha) + Lambda_Charlie(NoL, alpha)) *
                Const<T>(4.0) * NoV * NoL;
  return Saturate(Const<T>(1.0) / Max(den, Const<T>(1e-12)));
}

// D_GGX: Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces"
// (Trowbridge-Reitz). D = alpha^2 / (pi (NoH^2 (alpha^2 - 1) + 1)^2). three.js form.
// Guard: the denominator is floored at 1e-12 (it is >= alpha^2 for NoH in [0, 1], so the
// floor only acts when alpha < 1e-6, i.e. glTF roughness below 1e-3).
template <typename T>
inline T D_GGX(const T& alpha_in, const T& NoH) {
  const T alpha = Max(alpha_in, Const<T>(kMinAlpha));
  const T a2 = alpha * alpha;
  const T den = Max(NoH * NoH * (a2 - Const<T>(1.0)) + Const<T>(1.0), Const<T>(1e-12));
  return Const<T>(kInvPi) * a2 / (den * den);
}

// V_SmithGGXCorrelated: Heitz 2014, "Understanding the Masking-Shadowing Function in
// Microfacet-Based BRDFs" (height-correlated Smith, visibility form G / (4 NoL NoV)).
// three.js V_GGX_SmithCorrelated: 0.5 / max(gv + gl, EPSILON = 1e-6).
template <typename T>
inline T V_SmithGGXCorrelated(const T& alpha_in, const T& NoV, const T& NoL) {
  using std::sqrt;
  const T alpha = Max(alpha_in, Const<T>(kMinAlpha));
  const T a2 = alpha * alpha;
  const T one = Const<T>(1.0);
  const T gv = NoL * sqrt(a2 + (one - a2) * NoV * NoV);
  const T gl = NoV * sqrt(a2 + (one - a2) * NoL * NoL);
  return Const<T>(0.5) / Max(gv + gl, Const<T>(1e-6));
}

// Schlick 1994, "An Inexpensive BRDF Model for Physically-based Rendering".
enum class FresnelForm {
  kPow5,               // F0 + (F90 - F0) (1 - VoH)^5
  kSphericalGaussian,  // three.js: fresnel = 2^((-5.55473 VoH - 6.98316) VoH)
};

template <typename T>
inline T F_SchlickWeight(const T& VoH_in, FresnelForm form) {
  using std::exp2;
  const T VoH = Saturate(VoH_in);
  if (form == FresnelForm::kSphericalGaussian) {
    return exp2((Const<T>(-5.55473) * VoH - Const<T>(6.98316)) * VoH);
  }
  return Pow5(Const<T>(1.0) - VoH);
}

template <typename T>
inline Rgb<T> F_Schlick(const Rgb<T>& f0, const T& f90, const T& VoH, FresnelForm form) {
  const T w = F_SchlickWeight(VoH, form);
  return f0 * (Const<T>(1.0) - w) + Rgb<T>::Splat(f90 * w);
}

// D_GGX_Anisotropic: Burley 2012 ("Physically-Based Shading at Disney", appendix B) / Walter
// et al. 2007, written as three.js r187 D_GGX_Anisotropic (bsdfs, lights_physical_pars):
//   D = (1/pi) a2 (a2 / |q|^2)^2,  a2 = alpha_t alpha_b,
//   q = (alpha_b (t.h), alpha_t (b.h), a2 (n.h))
// alpha_t is the roughness along the axis t, alpha_b along b (raw cosines t.h, b.h, n.h).
// Guard: |q|^2 is floored at 1e-12 (it is >= a2^2 NoH^2 + ... > 0 except for alpha -> 0 with
// h in the tangent plane, where D -> 0 anyway); alphas are floored at kMinAlpha.
template <typename T>
inline T D_GGX_Anisotropic(const T& alpha_t_in, const T& alpha_b_in, const T& NoH, const T& ToH,
                           const T& BoH) {
  const T alpha_t = Max(alpha_t_in, Const<T>(kMinAlpha));
  const T alpha_b = Max(alpha_b_in, Const<T>(kMinAlpha));
  const T a2 = alpha_t * alpha_b;
  const T q2 = Max(Sq(alpha_b * ToH) + Sq(alpha_t * BoH) + Sq(a2 * NoH), Const<T>(1e-12));
  return Const<T>(kInvPi) * a2 * Sq(a2 / q2);
}

// V_SmithGGXCorrelated_Anisotropic: Heitz 2014 (height-correlated Smith, anisotropic Lambda),
// three.js r187 V_GGX_SmithCorrelated_Anisotropic without its final saturate (the isotropic
// V_SmithGGXCorrelated above is unsaturated too):
//   V = 0.5 / (NoL |(alpha_t t.v, alpha_b b.v, NoV)| + NoV |(alpha_t t.l, alpha_b b.l, NoL)|)
// Guard: the denominator is floored at 1e-6 (three.js EPSILON), which only acts when both
// NoV and NoL are ~0 (grazing), where the NoL factor of the caller makes the product vanish.
template <typename T>
inline T V_SmithGGXCorrelated_Anisotropic(const T& alpha_t, const T& alpha_b, const T& NoV,
                                          const T& NoL, const T& ToV, const T& BoV,
                                          const T& ToL, const T& BoL) {
  using std::sqrt;
  const T lv = sqrt(Sq(alpha_t * ToV) + Sq(alpha_b * BoV) + Sq(NoV) + Const<T>(1e-20));
  const T ll = sqrt(Sq(alpha_t * ToL) + Sq(alpha_b * BoL) + Sq(NoL) + Const<T>(1e-20));
  return Const<T>(0.5) / Max(NoL * lv + NoV * ll, Const<T>(1e-6));
}

// Fp: the "phase Fresnel" of the woven model: Irawan & Marschner 2012 (the von Mises forward
// scattering of their yarn model, exp(beta (-l.v)) / normalisation), rewritten in the half
// vector with -l.v = 1 - 2 (l.h)^2 and blended with a floor f0:
//   Fp(LoH) = f0 + (1 - f0) exp(-2 beta LoH^2)     (Fp(0) = 1, Fp(1) = f0 + (1 - f0) e^(-2 beta))
// beta >= 0 keeps exp() in (0, 1]; no guard needed.
template <typename T>
inline T F_Phase(const T& f0, const T& beta, const T& LoH) {
  using std::exp;
  return f0 + (Const<T>(1.0) - f0) * exp(Const<T>(-2.0) * beta * Sq(LoH));
}

// Fd_Lambert: 1 / pi.
template <typename T>
inline T Fd_Lambert() {
  return Const<T>(kInvPi);
}

// Fd_Wrap: wrapped diffuse (Filament; Green 2004, "Real-Time Approximations to Subsurface
// Scattering", GPU Gems ch. 16). Energy-conserving wrap without the 1/pi:
//   W(x, w) = saturate((x + w) / (1 + w)^2).
template <typename T>
inline T Fd_Wrap(const T& x, const T& w) {
  return Saturate((x + w) / Sq(Const<T>(1.0) + w));
}

}  // namespace clothfit
