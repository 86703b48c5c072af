// fit/bench_fit.h: speed against error for the image fit (`clothfit bench fit`).
//
// For each fabric, every setting (block level x pixel stride x number of starts) is fitted on
// the same cached references, timed, and scored with ONE common measure so settings compare:
// the display-space RMSE of the fitted preset's full preview against the reference over the
// 16 x 16 blocks that are fabric in both (level 4, every pixel), averaged over the scenes.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "fit/image_fit.h"

namespace clothfit::fit {

struct BenchSetting {
  int width = 0;    // fit resolution: image width in pixels (0 = the scene card's)
  int level = -1;   // block level; -1 = auto (from the weave scale at this resolution)
  int stride = 0;   // pixel stride per block axis; 0 = auto (at most 4 x 4 per block)
  int starts = 2;   // multi-start count (nested sets: {0.6}, {0.6, 0.9}, {0.6, 0.9, 0.3})
};

struct BenchRow {
  std::string fabric;
  BenchSetting setting;
  int width = 0, level = 0;  // the resolution and block level actually used
  double seconds = 0.0;      // FitImages wall time (caches included)
  double error = 0.0;        // the common measure
  bool usable = false;
};

// Common error measure of a preset on the inputs (see above).
double CommonError(const std::vector<SceneInput>& inputs, const render::MaterialPreset& preset);

// Runs every setting for one fabric. `inputs_at(width)` returns the fit inputs (scenes and
// references) at a resolution (0 = the cards'); `common` are the card-resolution inputs the
// common measure is taken on. `log` gets one line per finished setting.
std::vector<BenchRow> RunFitBench(const std::string& fabric,
                                  const std::function<std::vector<SceneInput>(int width)>& inputs_at,
                                  const std::vector<SceneInput>& common, double weave_period_uv,
                                  const FitOptions& base, const std::vector<BenchSetting>& settings,
                                  const std::function<void(const BenchRow&)>& log = {});

// `clothfit bench fit --models`: every model fitted at the fit defaults (card resolution,
// auto level and stride, the default starts) on the same inputs, timed and scored with the
// common measure. The baselines lock metalness to 0, as `clothfit fit` does.
struct ModelRow {
  std::string fabric, model;
  double seconds = 0.0;  // FitImages wall time (preview caches included)
  double cpu_seconds = 0.0;  // process CPU time over the fit, all threads (std::clock): less
                             // sensitive than wall time to other processes on a shared machine
  double error = 0.0;    // the common measure
  double fit_rmse = 0.0; // the fit's own error (fit space, its blocks)
  int iterations = 0, starts = 0;
  std::string termination;
  bool usable = false;
};
// woven: as `clothfit fit --model woven --fabric F` (weave maps baked from `fabric_path`
// into a temporary file when it is an Irawan fabric, inside the timed span; the two stages
// of fit/woven_fit.h; one start).
std::vector<ModelRow> RunModelBench(const std::string& fabric,
                                    const std::vector<SceneInput>& inputs,
                                    double weave_period_uv,
                                    const std::vector<render::ModelKind>& models,
                                    const std::function<void(const ModelRow&)>& log = {},
                                    const std::string& fabric_path = "");
void WriteModelBench(const std::vector<ModelRow>& rows, const std::string& csv_path);

// Writes rows as CSV (atomically) and an error-vs-time plot as PNG: x = seconds (log scale),
// y = error; one polyline per (fabric, stride, starts) across resolutions, with axis ticks and a
// legend when a TrueType font is installed (DejaVu Sans; without it the plot has no text).
void WriteFitBench(const std::vector<BenchRow>& rows, const std::string& csv_path,
                   const std::string& png_path);

}  // namespace clothfit::fit
