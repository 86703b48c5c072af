// fit/convergence.h: is a fitted preset a converged, interior solution? (docs/references.md,
// "Convergence"; issue #15: non-converged fits used to look like successes.)
#pragma once

#include <string>
#include <vector>

#include "render/scene/material.h"

namespace clothfit::fit {

// A free parameter component at one of its bounds.
struct AtBound {
  std::string name;    // "roughness" or "sheen_color[1]"
  double value = 0.0;  // the fitted value (= the bound)
  bool upper = false;  // at the upper bound
  // A colour at 0 means "none of this term" (no sheen, no subsurface): a legitimate fit,
  // reported but not flagged. Every other bound (a colour saturated at 1, a roughness at its
  // clamp) is where the solver stopped because it could not go further: flagged.
  bool flagged = true;
};

// Free parameter components of `preset` within `rel_tol` x (upper - lower) of a bound.
// `locked` (held constant) and the parameters the model ignores (cloth's sheen_color under a
// non-explicit sheen default, subsurface_color without subsurface) are never reported.
std::vector<AtBound> ParametersAtBounds(const render::MaterialPreset& preset,
                                        const std::vector<std::string>& locked,
                                        double rel_tol = 1e-6);

// The lower bound the fit uses for a parameter (the table's, or the cloth variant's roughness
// clamp).
double FitLowerBound(const render::MaterialPreset& preset, const std::string& name,
                     double table_lower);

// True unless the Ceres termination says the solver stopped early (NO_CONVERGENCE: iteration
// or time cap; FAILURE; USER_FAILURE).
bool Converged(const std::string& termination);

}  // namespace clothfit::fit
