#include "fit/woven_fit.h"

#include <algorithm>
#include <string>

namespace clothfit::fit {
namespace {

std::vector<std::string> Union(std::vector<std::string> a, const std::vector<std::string>& b) {
  for (const std::string& s : b)
    if (std::find(a.begin(), a.end(), s) == a.end()) a.push_back(s);
  return a;
}

}  // namespace

FitResult FitWovenImages(const std::vector<SceneInput>& inputs, const FitOptions& options) {
  if (options.start.model != render::ModelKind::kWoven)
    throw FitError("FitWovenImages: the start preset is not a woven preset");
  FitOptions yarn = options;
  yarn.locked = Union(options.locked, {"anisotropy", "twist", "sheen_color", "sheen_roughness"});
  FitResult r1 = FitImages(inputs, yarn);
  if (!r1.usable) return r1;

  FitOptions sheen = options;
  sheen.start = r1.preset;
  sheen.init_from_reference = false;
  sheen.start_roughness = {0.0};  // unused without init_from_reference: one start
  const int off = sheen.start.Offset("sheen_color");
  for (int c = 0; c < 3; ++c)
    sheen.start.values[size_t(off + c)] = std::max(sheen.start.values[size_t(off + c)], 0.02);
  sheen.locked = Union(options.locked, {"roughness", "anisotropy", "twist", "warp_share",
                                        "specular_f0", "forward_scattering"});
  FitResult r2 = FitImages(inputs, sheen);
  const double seconds = r1.seconds + r2.seconds, setup = r1.setup_seconds + r2.setup_seconds;
  const int iterations = r1.iterations + r2.iterations, starts = r1.starts + r2.starts;
  FitResult best = (r2.usable && r2.rmse < r1.rmse) ? std::move(r2) : std::move(r1);
  best.seconds = seconds;
  best.setup_seconds = setup;
  best.iterations = iterations;
  best.starts = starts;
  return best;
}

}  // namespace clothfit::fit
