// fit/convert/convert.h: batch conversion of captured materials into cloth presets and engine
// materials (`clothfit convert`, docs/convert.md).
//
// Inputs: files, directories (searched recursively for .json, .gltf, .glb, .binary, .merl;
// sorted) and manifests (a .txt file: one input path per line, relative to the manifest, '#'
// comments). Work is split by input file; `--shard i/N` keeps the files whose position in the
// sorted, de-duplicated list is congruent to i mod N (0-based i), so N array tasks over the
// same manifest partition it exactly.
//
// Per material: the source BRDF on the canonical directions (fit/brdf_fit.h), one fit per
// target model (cloth always; physical-sheen for threejs; gltf-sheen for gltf), the outputs
// written atomically, then a resume record `.clothfit-convert/<stem>.json` holding the content
// hash. The hash (64-bit FNV-1a, change detection, not security) covers the tool version and
// the fit's revision (fit/brdf_fit.h kFitRevision), the options that change outputs (targets, cloth variant), the material name, the input file's
// bytes and every file it depends on (maps, weave files). A material whose record hash matches
// and whose outputs all exist is skipped. A bad input is reported (file and reason) and
// skipped; the others complete.
#pragma once

#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "brdf/cloth.h"

namespace clothfit::fit {

inline constexpr const char* kToolVersion = "clothfit 0.1.0";

struct ConvertOptions {
  std::vector<std::string> targets = {"preset"};  // preset, threejs, gltf, filament
  std::string out_dir;
  int jobs = 0;  // 0: TBB default
  int shard_index = 0, shard_count = 1;
  cloth::Options cloth;  // target cloth variant
  // Map and glTF buffer paths may leave the input tree (--allow-outside-paths).
  bool allow_outside_paths = false;
  // Called with (materials done, materials known so far) from worker threads (serialised).
  std::function<void(long long, long long)> progress;
};

struct ItemResult {
  std::string file, material, stem, kind;
  // converted; skipped (up to date); failed (a broken input: reason); refused (every requested
  // target refused by design: `refused`); ignored (not a material: notes)
  std::string status;
  std::string reason;   // failures
  double error = -1.0;  // cloth fit error (square-root units); -1 when not fitted
  double seconds = 0.0;
  std::vector<std::string> outputs;
  std::vector<std::string> notes;
  // Requested targets this source cannot be written to by design (target, reason), e.g. a
  // woven preset for threejs/gltf; the other targets are written (docs/convert.md section 4).
  std::vector<std::pair<std::string, std::string>> refused;
};

struct ConvertReport {
  std::vector<ItemResult> items;
  int converted = 0, skipped = 0, failed = 0, refused = 0, ignored = 0, files = 0;
  int refused_targets = 0;  // (material, target) pairs refused by design, over all items
  double seconds = 0.0;
};

// Files, directories and manifests -> sorted, unique input files paired with their output stem
// (the path relative to the directory or manifest it came from, extension dropped, '/' -> '_').
// Throws ConvertError for a missing argument path or a bad manifest line (file:line).
struct InputFile {
  std::string path, stem;
  // The input tree the file came from (a directory argument, a manifest entry's directory, or
  // the file's own directory): the paths it names must stay inside it (docs/reliability.md).
  std::string root;
};
// Files under `exclude` (the output directory, when it sits inside an input directory) are
// left out of directory scans.
std::vector<InputFile> ExpandInputs(const std::vector<std::string>& args,
                                    const std::string& exclude = "");

// Validates targets (throws std::invalid_argument listing the valid names).
void CheckTargets(const std::vector<std::string>& targets);

ConvertReport RunConvert(const std::vector<InputFile>& inputs, const ConvertOptions& options);

// The summary table (text) and the JSON log.
std::string SummaryTable(const ConvertReport& r);
nlohmann::json ReportJson(const ConvertReport& r, const ConvertOptions& o);
// Log file name in the output directory: convert-log.json or convert-log.shard-i-of-N.json.
std::string LogName(const ConvertOptions& o);

}  // namespace clothfit::fit
