// render/preview/sheen_tilt.h: a nap for the sheen lobe (session 10 prototype, s10-velvet;
// measurement, opt-in: PreviewOptions::sheen_tilt_degrees, default 0 = the untouched paths).
//
// Velvet's pile leans along the mesh tangent (the Sadeghi "velvet" preset's thread 1 has the
// asymmetric tangent offsets {-90, -50}: docs/velvet.md), which no model symmetric under
// t -> -t can show. The prototype gives the sheen lobe (Charlie + Neubelt, direct and IBL) its
// own normal, tilted by a fixed angle theta towards +t (the mesh tangent, +u, Gram-Schmidt'd
// against the shading normal n, so |n_s| = 1):
//
//   n_s = cos(theta) n + sin(theta) t
//
// as three.js / glTF give the clearcoat lobe its own normal: the lobe's cosines (NoV, NoL, NoH)
// and its IBL lookup (reflect(-v, n_s), dominant direction about n_s) use n_s, including its
// own n_s.l cosine factor; LoH does not involve the normal. Everything else (diffuse, yarn
// lobes, SH / PMREM irradiance) keeps n. A light with n.l <= 0 stays culled (light from below
// the surface never reaches the pile). Since theta is fixed, the tilted cosines are geometry
// only and come from the cached ones and the tangent cosines:
//
//   n_s.x = cos(theta) n.x + sin(theta) t.x,   x in {v, l, h}
//
// Layering (woven): the sheen albedo scaling S uses the sheen lobe's own cosines:
//   direct  out = f_s(n_s) (n_s.l)+ + min(S(n_s.v), S(n_s.l)) (f_y + y f_d) (n.l)+
//   IBL     sheen Es(n_s.v) L_pref(n_s) + S(n_s.v) [yarn L_pref(n) + diffuse E_d]
// cloth (Filament or seed, no subsurface):
//   direct  out = c/pi (n.l)+ + sheen D(n_s.h) V(n_s.v, n_s.l) (n_s.l)+
//   IBL     E_s = sheen DFG.z(n_s.v, r): E_s L_pref(n_s) + c (1 - E_s) E_d
// At theta = 0 these are the models' own expressions regrouped (equal to rounding; the
// preview does not take this path at 0: bit-identical). Mirroring the tangent (t -> -t)
// at +theta equals the original tangent at -theta (tests/test_s10_velvet.cpp).
#pragma once

#include "brdf/cloth.h"
#include "brdf/woven.h"

namespace clothfit::render::sheen_tilt {

// The tilted cosines of one pixel and light (raw, unclamped; the models clamp as usual).
template <typename T>
struct TiltedCosines {
  T NoV, NoL, NoH;
};

// cloth, direct light per unit light colour (cosine included). Throws nothing; the caller
// rejects subsurface (the wrap has no tilted form here).
template <typename T>
inline Rgb<T> ClothDirect(const cloth::Params<T>& p, const cloth::Options& o, const Cosines<T>& c,
                          const TiltedCosines<T>& s) {
  const T r = cloth::ClampedRoughness(p.roughness, o);
  const T NoL = Saturate(c.NoL);
  const T NoV_s = cloth::ShadingNoV(s.NoV, o);
  const T NoL_s = Saturate(s.NoL);
  const Rgb<T> sheen = cloth::EffectiveSheen(p, o);
  const Rgb<T> Fr = sheen * cloth::SheenDV(r, NoV_s, NoL_s, s.NoH, o);
  return p.base_color * (Fd_Lambert<T>() * NoL) + Fr * NoL_s;
}

// cloth, split-sum weights: specular (= E_s) multiplies the radiance table looked up about n_s,
// diffuse c (1 - E_s) the irradiance about n.
template <typename T>
inline IblWeights<T> ClothIbl(const cloth::Params<T>& p, const cloth::Options& o, const T& NoV_s,
                              const Table2D& dfg) {
  return cloth::EvalIbl(p, o, NoV_s, dfg);  // no subsurface: {E(n_s.v), c (1 - E(n_s.v)), 0}
}

// woven, direct light per unit light colour (cosine included).
template <typename T>
inline Rgb<T> WovenDirect(const woven::Params<T>& p, const woven::Options& o,
                          const woven::Lobes<T>& lb, const Cosines<T>& c,
                          const TiltedCosines<T>& s, const TangentCosines<T>& tc,
                          const woven::WeaveSample<T>& ws, const Table2D& dfg,
                          const Table2D& phase) {
  woven::Params<T> p0 = p;  // the lobes below the sheen: sheen off -> S = 1 exactly
  p0.sheen_color = Rgb<T>::Splat(Const<T>(0.0));
  const Rgb<T> inner = woven::EvalDirect(p0, o, lb, c, tc, ws, dfg, phase);  // (f_y + y f_d) NoL
  const T NoV_s = Clamp(s.NoV, Const<T>(kMinNoV), Const<T>(1.0));
  const T NoL_s = Saturate(s.NoL);
  const T NoH_s = Saturate(s.NoH);
  const T sc = Min(woven::SheenScaling(p, lb, dfg, NoV_s), woven::SheenScaling(p, lb, dfg, NoL_s));
  const T dv = D_Charlie(lb.r_s * lb.r_s, NoH_s) * V_Neubelt(NoV_s, NoL_s);
  return p.sheen_color * (dv * NoL_s) + inner * sc;
}

// woven, split-sum weights: sheen multiplies the table about n_s, the rest as woven::EvalIbl.
template <typename T>
inline woven::WovenIblWeights<T> WovenIbl(const woven::Params<T>& p, const woven::Options& o,
                                          const woven::Lobes<T>& lb, const T& NoV,
                                          const T& NoV_s_raw, const woven::WeaveSample<T>& ws,
                                          const Table2D& dfg, const Table2D& phase) {
  woven::Params<T> p0 = p;
  p0.sheen_color = Rgb<T>::Splat(Const<T>(0.0));
  woven::WovenIblWeights<T> w = woven::EvalIbl(p0, o, lb, NoV, ws, dfg, phase);  // S = 1
  const T NoV_s = Clamp(NoV_s_raw, Const<T>(kMinNoV), Const<T>(1.0));
  const T sc = woven::SheenScaling(p, lb, dfg, NoV_s);
  w.warp = w.warp * sc;
  w.weft = w.weft * sc;
  w.diffuse = w.diffuse * sc;
  w.sheen = p.sheen_color * dfg.Sample(NoV_s, lb.r_s, 2);
  return w;
}

}  // namespace clothfit::render::sheen_tilt
