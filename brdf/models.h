// brdf/models.h: the closed set of models, for code that iterates over all of them
// (stress test, benchmarks, CLI listings). Dispatch happens here, once, outside pixel loops.
#pragma once

#include <array>
#include <span>
#include <string_view>

#include "brdf/cloth.h"
#include "brdf/gltf_sheen.h"
#include "brdf/lut.h"
#include "brdf/physical_aniso.h"
#include "brdf/physical_sheen.h"
#include "brdf/standard.h"
#include "brdf/woven.h"

namespace clothfit {

enum class ModelId {
  kClothFilament,            // cloth, Filament desktop, no subsurface
  kClothFilamentSubsurface,  // cloth, Filament desktop, subsurface colour
  kClothFilamentMobile,      // cloth, Filament mobile clamps
  kClothSeed,                // cloth, seed MeshClothMaterial, sheen = sqrt(base)
  kClothSeedSubsurface,      // cloth, seed MeshClothMaterial with SUBSURFACE, sqrt(base)
  kStandard,                 // three.js r187 MeshStandardMaterial
  kPhysicalSheen,            // three.js r187 MeshPhysicalMaterial sheen
  kGltfSheen,                // glTF KHR_materials_sheen
  kWoven,                    // clothfit woven (yarn lobes + sheen + Lambert), uniform
  kPhysicalAniso,            // three.js r187 MeshPhysicalMaterial sheen + anisotropy + specular
};

inline constexpr std::array<ModelId, 10> kAllModels{
    ModelId::kClothFilament,       ModelId::kClothFilamentSubsurface,
    ModelId::kClothFilamentMobile, ModelId::kClothSeed,
    ModelId::kClothSeedSubsurface, ModelId::kStandard,
    ModelId::kPhysicalSheen,       ModelId::kGltfSheen,
    ModelId::kWoven,               ModelId::kPhysicalAniso};

// Largest ParameterCount over kAllModels (array sizes of flat-vector callers).
inline constexpr int kMaxModelParameters = woven::kParameterCount;
static_assert(physical_aniso::kParameterCount <= kMaxModelParameters);

inline std::string_view ModelName(ModelId m) {
  switch (m) {
    case ModelId::kClothFilament: return "cloth/filament";
    case ModelId::kClothFilamentSubsurface: return "cloth/filament+subsurface";
    case ModelId::kClothFilamentMobile: return "cloth/filament-mobile";
    case ModelId::kClothSeed: return "cloth/seed";
    case ModelId::kClothSeedSubsurface: return "cloth/seed+subsurface";
    case ModelId::kStandard: return "standard";
    case ModelId::kPhysicalSheen: return "physical-sheen";
    case ModelId::kGltfSheen: return "gltf-sheen";
    case ModelId::kWoven: return "woven";
    case ModelId::kPhysicalAniso: return "physical-aniso";
  }
  return "?";
}

inline cloth::Options ClothOptionsFor(ModelId m) {
  cloth::Options o;
  switch (m) {
    case ModelId::kClothFilamentSubsurface: o.subsurface = true; break;
    case ModelId::kClothFilamentMobile: o.platform = Platform::kMobile; break;
    case ModelId::kClothSeed:
      o.variant = cloth::Variant::kSeedThreejs;
      o.sheen_default = cloth::SheenDefault::kSqrtBaseColor;
      break;
    case ModelId::kClothSeedSubsurface:
      o.variant = cloth::Variant::kSeedThreejs;
      o.sheen_default = cloth::SheenDefault::kSqrtBaseColor;
      o.subsurface = true;
      break;
    default: break;
  }
  return o;
}

// Number of scalar parameters of a model (colours count 3).
inline int ParameterCount(ModelId m) {
  switch (m) {
    case ModelId::kStandard: return 5;
    case ModelId::kPhysicalSheen:
    case ModelId::kGltfSheen: return 9;
    case ModelId::kWoven: return woven::kParameterCount;
    case ModelId::kPhysicalAniso: return physical_aniso::kParameterCount;
    default: return 10;
  }
}

// Evaluate a model from a flat parameter vector x (layout = the model's parameter table
// order). Writes the direct reflectance (per unit light, cosine included) and the IBL
// response to a uniform white environment (spec + diffuse + sheen weights: L = E_d = 1).
// `tc`: tangent-frame cosines for anisotropic models (woven); null = derived from `c` with v
// in the tangent-normal plane (woven::TangentCosinesInPlane).
template <typename T>
inline void EvaluateFlat(ModelId m, const T* x, const Cosines<T>& c, Rgb<T>& direct,
                         Rgb<T>& ibl_uniform, const TangentCosines<T>* tc = nullptr) {
  const Table2D& dfg = lut::DefaultDfg();
  auto rgb = [&](int k) { return Rgb<T>(x[k], x[k + 1], x[k + 2]); };
  auto sum = [](const IblWeights<T>& w) { return w.specular + w.diffuse + w.sheen; };
  switch (m) {
    case ModelId::kStandard: {
      standard::Params<T> p{rgb(0), x[3], x[4]};
      direct = standard::EvalDirect(p, {}, c, dfg);
      ibl_uniform = sum(standard::EvalIbl(p, {}, c.NoV, dfg));
      return;
    }
    case ModelId::kPhysicalSheen: {
      physical_sheen::Params<T> p{rgb(0), x[3], x[4], rgb(5), x[8]};
      direct = physical_sheen::EvalDirect(p, {}, c, dfg);
      ibl_uniform = sum(physical_sheen::EvalIbl(p, {}, c.NoV, dfg));
      return;
    }
    case ModelId::kGltfSheen: {
      const Table2D& e = lut::DefaultSheenAlbedo();
      gltf_sheen::Params<T> p{rgb(0), x[3], x[4], rgb(5), x[8]};
      direct = gltf_sheen::EvalDirect(p, {}, c, e);
      ibl_uniform = sum(gltf_sheen::EvalIbl(p, {}, c.NoV, dfg, e));
      return;
    }
    case ModelId::kWoven: {
      const Table2D& phase = lut::DefaultWovenPhase();
      const woven::Params<T> p = woven::FromFlat(x);
      const woven::Lobes<T> lb = woven::PrepareLobes(p);
      const TangentCosines<T> t = tc ? *tc : woven::TangentCosinesInPlane(c);
      direct = woven::EvalDirect(p, {}, lb, c, t, {}, dfg, phase);
      const woven::WovenIblWeights<T> w = woven::EvalIbl(p, {}, lb, c.NoV, {}, dfg, phase);
      ibl_uniform = w.warp + w.weft + w.diffuse + w.sheen;
      return;
    }
    case ModelId::kPhysicalAniso: {
      // No map: anisotropy along the tangent, rotated by anisotropy_rotation.
      const physical_aniso::Params<T> p = physical_aniso::FromFlat(x);
      const TangentCosines<T> t = tc ? *tc : woven::TangentCosinesInPlane(c);
      direct = physical_aniso::EvalDirect(p, {}, c, t, {}, dfg);
      ibl_uniform = sum(physical_aniso::EvalIbl(p, {}, c.NoV, dfg));
      return;
    }
    default: {
      const cloth::Options o = ClothOptionsFor(m);
      cloth::Params<T> p{rgb(0), rgb(3), x[6], rgb(7)};
      direct = cloth::EvalDirect(p, o, c);
      ibl_uniform = sum(cloth::EvalIbl(p, o, c.NoV, dfg));
      return;
    }
  }
}

// Documented parameter bounds in flat layout (lower, upper), used to draw stress inputs.
inline void FlatBounds(ModelId m, double* lo, double* hi) {
  auto fill = [&](std::span<const ParamInfo> table) {
    int k = 0;
    for (const ParamInfo& p : table)
      for (int c = 0; c < p.size; ++c, ++k) {
        lo[k] = p.lower;
        hi[k] = p.upper;
      }
  };
  switch (m) {
    case ModelId::kStandard: fill(standard::kParameterTable); return;
    case ModelId::kPhysicalSheen: fill(physical_sheen::kParameterTable); return;
    case ModelId::kGltfSheen: fill(gltf_sheen::kParameterTable); return;
    case ModelId::kWoven: fill(woven::kParameterTable); return;
    case ModelId::kPhysicalAniso: fill(physical_aniso::kParameterTable); return;
    default:
      fill(cloth::kParameterTable);
      lo[6] = cloth::MinRoughness(ClothOptionsFor(m));
      return;
  }
}

}  // namespace clothfit
