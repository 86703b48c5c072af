// fit/bench_fit.h: speed against error for the image fit (`clothfit bench fit`).
//
// For each fabric, every setting (block level x pixel stride x number of starts) is fitted on
// the same cached references, timed, and scored with ONE common measure so settings compare:
// the display-space RMSE of the fitted preset's full preview against the reference over the
// 16 x 16 blocks that are fabric in both (level 4, every pixel), averaged over the scenes.
#pragma once

#include <string>
#include <vector>

#include "fit/image_fit.h"

namespace clothfit::fit {

struct BenchSetting {
  int level = 4;
  int stride = 0;  // 0 = auto
  int starts = 2;
};

struct BenchRow {
  std::string fabric;
  BenchSetting setting;
  double seconds = 0.0;      // FitImages wall time (caches included)
  double error = 0.0;        // the common measure
  bool usable = false;
};

// Common error measure of a preset on the inputs (see above).
double CommonError(const std::vector<SceneInput>& inputs, const render::MaterialPreset& preset);

// Runs every setting on `inputs` (one fabric). `log` gets one line per finished setting.
std::vector<BenchRow> RunFitBench(const std::string& fabric, const std::vector<SceneInput>& inputs,
                                  const FitOptions& base, const std::vector<BenchSetting>& settings,
                                  const std::function<void(const BenchRow&)>& log = {});

// Writes rows as CSV (atomically) and an error-vs-time scatter plot as PNG: x = seconds (log
// scale), y = error; one polyline per (stride, starts) curve across levels, colour by curve.
void WriteFitBench(const std::vector<BenchRow>& rows, const std::string& csv_path,
                   const std::string& png_path);

}  // namespace clothfit::fit
