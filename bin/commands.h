// bin/commands.h: one function per subcommand; each registers its flags on the CLI11 app
// and returns the callback result as an exit code. Library code never exits (style.md 10).
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "render/scene/environment.h"
#include "render/scene/scene.h"
#include "render/scene/tonemap.h"

namespace clothfit::cli {

struct Globals {
  bool quiet = false;
};

void AddLutCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddStressCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddBenchCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddModelsCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddRenderCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddRenderReferencesCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddPreviewCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddFitCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddCompareCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddTonemapCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddReportCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddConvertCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddEvaluateCommand(CLI::App& app, const Globals& g, int& exit_code);  // cmd_evaluate.cpp

// `clothfit bench convert`: converts a catalogue (generated into a temporary directory by
// datasets/catalogue/generate.py when `catalogue` is empty) and prints materials/s per kind and
// the median BRDF-space fit error. Returns the exit status.
int RunBenchConvert(const std::string& catalogue, int count, int jobs, bool quiet);

// `clothfit bench reference` (bin/cmd_bench_reference.cpp): clothfit vs Blender Cycles on a
// simple material (time ratio), or a woven fabric's time to a target mean standard error.
struct BenchReferenceArgs {
  std::string scene, fabric, cycles_script;
  int spp = 64, max_depth = 8, width = 0, threads = 0;
  uint64_t seed = 1;
  double target_error = 0.02;
};
int RunBenchReference(const BenchReferenceArgs& args, bool quiet);

// The scene's environment: the card's map, or the procedural sky (warning on stderr unless
// quiet) when the map is not installed; null when the card has no environment.
std::unique_ptr<render::Environment> LoadSceneEnvironment(const render::Scene& scene, bool quiet);
// Renders (or reuses from the content-keyed cache) a reference; returns its path. `width` > 0
// overrides the card's image width (height scaled to keep the aspect ratio; same camera).
// target_error > 0: adaptive sampling to that relative mean standard error (spp = budget);
// it is part of the cache key.
std::string CachedReference(const std::string& scene_path, const std::string& fabric_path,
                            int spp, uint64_t seed, bool quiet, int width = 0,
                            double target_error = 0.0);
// --target-error of fit / render-references: "E" (every reference) or a list of items
// "scene=E" or "fabric/scene=E" by file stem ("canvas/sphere=0.0178,drape=0.019"; the
// fabric/scene item wins); 0 = fixed spp. Throws std::invalid_argument naming the option.
double TargetErrorFor(const std::string& spec, const std::string& fabric_path,
                      const std::string& scene_path);
// "i/N" with 0 <= i < N -> {i, N}; throws std::invalid_argument naming --shard.
std::pair<int, int> ParseShard(const std::string& spec);
// The scene card with its image width overridden as above (width <= 0: unchanged).
render::Scene LoadSceneAtWidth(const std::string& scene_path, int width);
// "a,b,,c" -> {"a", "b", "c"} (empty items dropped).
std::vector<std::string> SplitList(const std::string& s);
// The canonical scene cards (datasets/scenes/{sphere,drape,swatch}.json).
std::vector<std::string> CanonicalScenes();
// Linear RGB frame -> display RGB in [0, 1] (tone mapping + sRGB).
std::vector<float> ToDisplayImage(const std::vector<float>& linear, render::ToneMapping op,
                                  double exposure);

// Output checks before any work (bin/cmd_preview.cpp; fit, render-preview, tonemap).
// A command-line path and the flag (or positional) that gave it, for messages.
struct NamedPath {
  std::string flag, path;
};
// Throws std::invalid_argument "<flag> <path> is the same file as <flag> <path>: refusing to
// overwrite an input" when `out` names the same file as one of `inputs`: equivalent files when
// both exist (symbolic and hard links), else equal weakly canonical paths.
void RefuseOutputOverInput(const NamedPath& out, const std::vector<NamedPath>& inputs);
// The writers replace a file atomically, by a temporary file in its directory and a rename
// (render/scene/image_io.h), so an output needs a directory that takes new files; the old
// file's own mode does not matter. Throws io::IoError "<flag>: <path>: output directory <dir> is
// not writable (<reason>)" unless a file can be created in the directory of `path` (the
// nearest existing one when the command creates it, as fit --images does), or "... is a
// directory" when `path` is one. Probed by creating and removing a file: nothing is left
// behind. The directory's existence is io::RequireOutputDirectory's, called first.
void RequireWritableOutput(const std::string& path, const std::string& flag);
// The same for a directory the command creates or writes into (fit --images): the directory
// if it exists, else its nearest existing ancestor, must take new files.
void RequireWritableDirectory(const std::string& dir, const std::string& flag);
// A CLI11 check: a finite number > 0 (CLI::PositiveNumber accepts inf and prints DBL_MAX in its
// message); compare's and tonemap's --exposure and the like.
const CLI::Validator& PositiveFinite();

}  // namespace clothfit::cli
