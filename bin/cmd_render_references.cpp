// clothfit render-references: fill the content-addressed reference cache for a catalogue of
// fabrics on the canonical scenes, optionally one shard of it (--shard i/N), so that several
// machines (a Slurm array, docs/reference-renderer.md "Sharding") share one cache directory.
// Every reference is a pure function of its cache key, so shards never coordinate: shard i
// renders the tasks whose index is i modulo N in a fixed enumeration (fabric, scene, seed).
#include <tbb/global_control.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "bin/commands.h"
#include "render/reference/fabric.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {
namespace fs = std::filesystem;

double TargetErrorFor(const std::string& spec, const std::string& fabric_path,
                      const std::string& scene_path) {
  if (spec.empty()) return 0.0;
  auto parse = [&](const std::string& text) {
    size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != text.size() || !(v >= 0.0 && v < 1.0))
      throw std::invalid_argument("--target-error: '" + text +
                                  "' is not a number in [0, 1) (a fraction: 0.02 = 2 %)");
    return v;
  };
  if (spec.find('=') == std::string::npos) return parse(spec);
  const std::string stem = fs::path(scene_path).stem().string();
  const std::string pair = fs::path(fabric_path).stem().string() + "/" + stem;
  double by_scene = -1.0;
  for (const std::string& item : SplitList(spec)) {
    const size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("--target-error: item '" + item +
                                  "' is not scene=E or fabric/scene=E");
    const std::string key = item.substr(0, eq);
    if (key == pair) return parse(item.substr(eq + 1));
    if (key == stem) by_scene = parse(item.substr(eq + 1));
  }
  if (by_scene >= 0.0) return by_scene;
  throw std::invalid_argument("--target-error: no target for '" + pair + "' in '" + spec + "'");
}

std::pair<int, int> ParseShard(const std::string& spec) {
  const size_t slash = spec.find('/');
  int i = -1, n = 0;
  try {
    size_t a = 0, b = 0;
    if (slash != std::string::npos) {
      i = std::stoi(spec.substr(0, slash), &a);
      n = std::stoi(spec.substr(slash + 1), &b);
      if (a != slash || b != spec.size() - slash - 1) n = 0;
    }
  } catch (const std::exception&) {
    n = 0;
  }
  if (!(n >= 1 && i >= 0 && i < n))
    throw std::invalid_argument("--shard: '" + spec +
                                "' is not i/N with 0 <= i < N (e.g. $SLURM_ARRAY_TASK_ID/8)");
  return {i, n};
}

namespace {

// One fabric JSON path per line; blank lines and '#' comments skipped; relative paths are
// relative to the list file's directory.
std::vector<std::string> ReadFabricList(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec))  // a directory opened and read as empty (session 28)
    throw std::invalid_argument(path + ": the fabric list (--fabric-list) is not a file");
  std::ifstream in(path);
  if (!in) throw std::invalid_argument(path + ": cannot read the fabric list (--fabric-list)");
  std::vector<std::string> out;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    // A UTF-8 byte order mark (Windows editors) is not part of the first path (session 28).
    if (line_no == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    const size_t b = line.find_first_not_of(" \t\r"), e = line.find_last_not_of(" \t\r");
    if (b == std::string::npos) continue;
    fs::path p(line.substr(b, e - b + 1));
    if (p.is_relative()) p = fs::path(path).parent_path() / p;
    if (!fs::exists(p))
      throw std::invalid_argument(path + ":" + std::to_string(line_no) + ": fabric file '" +
                                  p.string() + "' does not exist");
    out.push_back(p.string());
  }
  if (out.empty()) throw std::invalid_argument(path + ": the fabric list is empty");
  return out;
}

// --seeds: comma-separated decimal integers in [0, 2^64) (the renderer's uint64_t seed).
// Before session 28 std::stoull took "-1" as 2^64 - 1, "1.5" and "1abc" as 1, failed "x" with
// the bare message "stoull", and an empty list rendered nothing with status 0.
std::vector<uint64_t> ParseSeeds(const std::string& spec) {
  std::vector<uint64_t> seeds;
  for (const std::string& s : SplitList(spec)) {
    uint64_t v = 0;
    bool ok =
        !s.empty() && s.size() <= 20 && s.find_first_not_of("0123456789") == std::string::npos;
    if (ok) {
      try {
        v = std::stoull(s);
      } catch (const std::exception&) {
        ok = false;  // above 2^64 - 1
      }
    }
    if (!ok)
      throw std::invalid_argument("--seeds: '" + s +
                                  "' is not a seed (a non-negative integer below 2^64)");
    seeds.push_back(v);
  }
  if (seeds.empty()) throw std::invalid_argument("--seeds: '" + spec + "' lists no seed");
  return seeds;
}

// Every "key=E" item of --target-error names a scene or a fabric/scene of these tasks (session
// 28: a misspelt override, "canvas/drap=0.01" next to "drape=0.02", was ignored silently and
// the references were rendered at the other target).
void RequireEveryTargetUsed(const std::string& spec, const std::vector<std::string>& fabrics,
                            const std::vector<std::string>& scenes) {
  if (spec.find('=') == std::string::npos) return;
  std::vector<std::string> keys;
  for (const std::string& scene : scenes) keys.push_back(fs::path(scene).stem().string());
  for (const std::string& fabric : fabrics)
    for (const std::string& scene : scenes)
      keys.push_back(fs::path(fabric).stem().string() + "/" + fs::path(scene).stem().string());
  for (const std::string& item : SplitList(spec)) {
    const std::string key = item.substr(0, item.find('='));
    if (std::find(keys.begin(), keys.end(), key) != keys.end()) continue;
    std::string valid;
    for (const std::string& k : keys) valid += (valid.empty() ? "" : ", ") + k;
    throw std::invalid_argument("--target-error: item '" + item + "' names no task of this run (" +
                                valid + ")");
  }
}

}  // namespace

void AddRenderReferencesCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    std::string fabric_list, fabrics, shard = "0/1", target_error, seeds = "1,2";
    int spp = 128, threads = 0, width = 0;
    bool dry_run = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "render-references",
      "render (or reuse) the cached references of fabrics on the canonical scenes, one shard");
  // --help shows each default ("=64"), as bench does (session 28: it showed none).
  cmd->option_defaults()->always_capture_default();
  cmd->add_option("--fabric-list", a->fabric_list, "file: one fabric JSON per line");
  cmd->add_option("--fabrics", a->fabrics, "comma-separated fabric JSON files");
  cmd->add_option("--shard", a->shard, "i/N: render task indices equal to i modulo N (0-based)");
  cmd->add_option("--spp", a->spp, "samples per pixel (the budget with --target-error)")
      ->check(CLI::Range(16, 65536));
  cmd->add_option("--target-error", a->target_error,
                  "adaptive sampling: 'E' or 'sphere=E,drape=E,swatch=E' (as clothfit fit)");
  cmd->add_option("--seeds", a->seeds, "comma-separated seeds (fit uses 1 and 2)");
  cmd->add_option("--threads", a->threads, "worker threads (0 = all cores)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--width", a->width, "override the cards' image width (0 = the card's)")
      ->check(CLI::Range(0, 8192));
  cmd->add_flag("--dry-run", a->dry_run, "list this shard's tasks, render nothing");
  cmd->callback([a, &g, &exit_code]() {
    try {
      std::vector<std::string> fabrics;
      if (!a->fabric_list.empty()) fabrics = ReadFabricList(a->fabric_list);
      for (const std::string& f : SplitList(a->fabrics)) fabrics.push_back(f);
      if (fabrics.empty()) throw std::invalid_argument("give --fabric-list or --fabrics");
      const auto [shard, shards] = ParseShard(a->shard);
      const std::vector<uint64_t> seeds = ParseSeeds(a->seeds);
      const std::vector<std::string> scenes = CanonicalScenes();
      // Every input before the first render (session 28: a broken second fabric, or a bad
      // --target-error item for the last scene, failed only after the earlier references had
      // been rendered, minutes each): the cards (their warnings once), the fabrics, each
      // task's target and the budget adaptive sampling needs.
      for (const std::string& scene : scenes)
        for (const std::string& w : LoadSceneAtWidth(scene, a->width).warnings)
          if (!g.quiet)
            std::fprintf(stderr, "clothfit: warning: %s\n",
                         limits::EscapeForMessage(w, 2000).c_str());
      std::vector<std::vector<double>> targets;  // [fabric][scene]
      for (const std::string& fabric : fabrics) {
        render::LoadFabric(fabric);
        targets.emplace_back();
        for (const std::string& scene : scenes) {
          targets.back().push_back(TargetErrorFor(a->target_error, fabric, scene));
          if (targets.back().back() > 0.0 && (a->spp < 32 || a->spp % 16 != 0))
            throw std::invalid_argument(
                "--spp: with --target-error the budget must be a "
                "multiple of 16 >= 32, got " +
                std::to_string(a->spp));
        }
      }
      RequireEveryTargetUsed(a->target_error, fabrics, scenes);
      std::unique_ptr<tbb::global_control> limit;
      if (a->threads > 0)
        limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      size_t(a->threads));
      int task = 0;
      for (size_t fi = 0; fi < fabrics.size(); ++fi) {
        const std::string& fabric = fabrics[fi];
        for (size_t si = 0; si < scenes.size(); ++si) {
          const std::string& scene = scenes[si];
          const double te = targets[fi][si];
          for (uint64_t seed : seeds) {
            if (task++ % shards != shard) continue;
            if (a->dry_run) {
              std::printf("%s %s seed %llu\n", fabric.c_str(), scene.c_str(),
                          (unsigned long long)seed);
              continue;
            }
            std::printf("%s\n", CachedReference(scene, fabric, a->spp, seed, g.quiet, a->width, te).c_str());
            std::fflush(stdout);
          }
        }
      }
      exit_code = 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit render-references: error: %s\n",
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
