#include "fit/convergence.h"

#include <algorithm>
#include <cmath>

#include "brdf/cloth.h"

namespace clothfit::fit {

double FitLowerBound(const render::MaterialPreset& preset, const std::string& name,
                     double table_lower) {
  if (preset.model == render::ModelKind::kCloth && name == "roughness")
    return cloth::MinRoughness(preset.cloth);
  return table_lower;
}

std::vector<AtBound> ParametersAtBounds(const render::MaterialPreset& preset,
                                        const std::vector<std::string>& locked, double rel_tol) {
  std::vector<AtBound> out;
  size_t off = 0;
  for (const ParamInfo& p : render::ParameterTable(preset.model)) {
    const std::string name(p.name);
    const bool is_locked = std::find(locked.begin(), locked.end(), name) != locked.end();
    const bool ignored = preset.model == render::ModelKind::kCloth &&
                         ((name == "sheen_color" &&
                           preset.cloth.sheen_default != cloth::SheenDefault::kExplicit) ||
                          (name == "subsurface_color" && !preset.cloth.subsurface));
    const double lower = FitLowerBound(preset, name, p.lower), upper = p.upper;
    const double tol = rel_tol * std::max(upper - lower, 1e-12);
    for (int c = 0; c < p.size && !is_locked && !ignored; ++c) {
      if (off + size_t(c) >= preset.values.size()) break;
      const double v = preset.values[off + size_t(c)];
      const bool at_lower = std::abs(v - lower) <= tol, at_upper = std::abs(v - upper) <= tol;
      if (!at_lower && !at_upper) continue;
      AtBound b;
      b.name = p.size == 1 ? name : name + "[" + std::to_string(c) + "]";
      b.value = v;
      b.upper = at_upper;
      b.flagged = !(p.size == 3 && at_lower && lower == 0.0);
      out.push_back(b);
    }
    off += size_t(p.size);
  }
  return out;
}

bool Converged(const std::string& termination) {
  return termination == "CONVERGENCE" || termination == "USER_SUCCESS";
}

}  // namespace clothfit::fit
