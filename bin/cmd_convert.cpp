// clothfit convert: batch conversion of captured materials (glTF, MERL, fabric definitions,
// clothfit presets, the seed's SurfaceMaterial / TextureStack) into cloth presets and engine
// materials, by fitting in BRDF space (fit/convert/convert.h, docs/convert.md). Also `bench convert`.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <mutex>
#include <sstream>

#include "bin/commands.h"
#include "bin/progress.h"
#include "fit/convert/convert.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {
namespace {

namespace fs = std::filesystem;

// "i/N" -> (i, N); throws std::invalid_argument.
void ParseShard(const std::string& s, int& i, int& n) {
  const size_t slash = s.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument("");
    size_t a = 0, b = 0;
    i = std::stoi(s.substr(0, slash), &a);
    n = std::stoi(s.substr(slash + 1), &b);
    if (a != slash || b != s.size() - slash - 1) throw std::invalid_argument("");
  } catch (const std::exception&) {
    throw std::invalid_argument("--shard: '" + s + "' is not i/N (e.g. 0/4)");
  }
  if (n < 1 || i < 0 || i >= n)
    throw std::invalid_argument("--shard: '" + s + "' needs 0 <= i < N");
}

std::string CatalogueScript() {
  return std::string(CLOTHFIT_SOURCE_DATASETS) + "/catalogue/generate.py";
}

}  // namespace

void AddConvertCommand(CLI::App& app, const Globals& g, int& exit_code) {
  CLI::App* cmd = app.add_subcommand(
      "convert", "convert captured materials into cloth presets and engine materials");
  auto inputs = std::make_shared<std::vector<std::string>>();
  auto to = std::make_shared<std::string>("preset");
  auto out = std::make_shared<std::string>();
  auto jobs = std::make_shared<int>(0);
  auto shard = std::make_shared<std::string>("0/1");
  auto variant = std::make_shared<std::string>("filament");
  auto allow_outside = std::make_shared<bool>(false);
  cmd->add_option("inputs", *inputs,
                  "input files (.json preset/fabric/SurfaceMaterial/TextureStack, .gltf, .glb, "
                  ".binary MERL), directories (searched recursively) or manifests (.txt)")
      ->required();
  // Every option with a default shows it in --help (CLI11's "=value" after the type).
  cmd->add_option("--to", *to, "comma-separated targets: preset, threejs, gltf, filament, preset-maps (the source "
                  "preset with its weave maps copied next to it; docs/convert.md)")
      ->capture_default_str();
  cmd->add_option("--out", *out, "output directory (created)")->required();
  // --threads: the name fit and render-* use; -j/--jobs kept.
  cmd->add_option("-j,--jobs,--threads", *jobs, "worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  cmd->add_option("--shard", *shard,
                  "i/N: convert only the i-th of N deterministic parts (0-based; 0/1: all)")
      ->capture_default_str();
  cmd->add_option("--cloth-variant", *variant, "cloth target: filament or seed-threejs")
      ->check(CLI::IsMember({"filament", "seed-threejs"}))
      ->capture_default_str();
  cmd->add_flag("--allow-outside-paths", *allow_outside,
                "let map and buffer paths inside input files point outside the input directory "
                "(refused by default; docs/reliability.md)");
  cmd->callback([=, &g, &exit_code]() {
    fit::ConvertOptions o;
    o.targets = SplitList(*to);
    o.out_dir = *out;
    o.jobs = *jobs;
    o.allow_outside_paths = *allow_outside;
    if (*variant == "seed-threejs") {
      o.cloth.variant = cloth::Variant::kSeedThreejs;
      o.cloth.sheen_default = cloth::SheenDefault::kExplicit;
    }
    try {
      fit::CheckTargets(o.targets);
      ParseShard(*shard, o.shard_index, o.shard_count);
    } catch (const std::invalid_argument& e) {
      std::fprintf(stderr, "clothfit convert: %s\n", e.what());
      exit_code = 1;
      return;
    }
    try {
      const auto files = fit::ExpandInputs(*inputs, o.out_dir);
      fs::create_directories(o.out_dir);
      ProgressBar bar("convert", g.quiet);
      o.progress = [&bar](long long done, long long total) { bar.Update(done, total); };
      const fit::ConvertReport rep = fit::RunConvert(files, o);
      std::printf("%s", fit::SummaryTable(rep).c_str());
      const std::string log = (fs::path(o.out_dir) / fit::LogName(o)).string();
      // DumpJson: paths and reasons may carry bytes from untrusted files; invalid UTF-8 is
      // replaced rather than throwing, so the log is always written.
      io::WriteTextAtomic(log, limits::DumpJson(fit::ReportJson(rep, o)) + "\n");
      std::printf("log: %s\n", log.c_str());
      // 2: an input is broken (unreadable, invalid, a fit that failed). Targets refused by
      // design (a woven preset has no glTF/three.js form) and clothfit documents that are not
      // materials (report.json) are listed in the summary and the log, and leave it 0: they
      // are properties of the source, the same on every run (docs/convert.md section 4).
      exit_code = rep.failed > 0 ? 2 : 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit convert: error: %s\n",
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

int RunBenchConvert(const std::string& catalogue_in, int count, int jobs, bool quiet) {
  std::string catalogue = catalogue_in;
  const fs::path tmp =
      fs::temp_directory_path() / ("clothfit-bench-convert-" + std::to_string(::getpid()));
  struct RemoveOnExit {  // the generated catalogue and the outputs, on every way out
    fs::path dir;
    ~RemoveOnExit() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } remove_tmp{tmp};
  if (catalogue.empty()) {
    catalogue = (tmp / "catalogue").string();
    const std::string cmd = "python3 '" + CatalogueScript() + "' --out '" + catalogue +
                            "' --count " + std::to_string(count) + (quiet ? " --quiet" : "");
    if (std::system(cmd.c_str()) != 0) {
      std::fprintf(stderr, "clothfit bench convert: error: catalogue generator failed: %s\n",
                   cmd.c_str());
      return 1;
    }
  } else {
    std::error_code ec;
    const fs::file_status st = fs::status(catalogue, ec);
    if (!fs::exists(st))
      throw std::runtime_error(catalogue + ": --catalogue: no such directory");
    if (!fs::is_directory(st))
      throw std::runtime_error(catalogue + ": --catalogue: not a directory");
  }
  struct Part {
    const char* label;
    std::vector<std::string> dirs;
    std::vector<fit::InputFile> inputs;
  };
  // The catalogue's layout (datasets/catalogue/generate.py): one subdirectory per input format.
  Part parts[] = {{"scalar (preset, glTF, SurfaceMaterial)", {"presets", "gltf", "seed"}, {}},
                  {"mapped (TextureStack with maps)", {"stacks"}, {}},
                  {"measured (MERL) and woven", {"merl", "fabrics"}, {}}};
  size_t materials = 0;
  std::string searched;
  for (Part& p : parts) {
    std::vector<std::string> args;
    for (const std::string& d : p.dirs) {
      searched += (searched.empty() ? "" : ", ") + d;
      if (fs::is_directory(fs::path(catalogue) / d))
        args.push_back((fs::path(catalogue) / d).string());
    }
    if (!args.empty()) p.inputs = fit::ExpandInputs(args);
    materials += p.inputs.size();
  }
  // Nothing to time is an error, not an empty table.
  if (materials == 0)
    throw std::runtime_error(catalogue + ": --catalogue: found no materials (looked for input "
                             "files in its subdirectories " + searched +
                             ", the layout datasets/catalogue/generate.py writes)");
  std::vector<double> errors;
  // Wall-clock rate, and CPU time per material (all threads) with the rate two fully available
  // cores would give: the machine is shared, so the wall clock alone understates it.
  std::printf(
      "| materials | count | wall s | materials/s (wall) | CPU ms / material | "
      "materials/s (2 cores, from CPU time) | median fit error |\n"
      "|---|---:|---:|---:|---:|---:|---:|\n");
  int status = 0;
  int k = 0;
  for (const Part& p : parts) {
    if (p.inputs.empty()) continue;
    fit::ConvertOptions o;
    o.targets = {"preset"};
    o.jobs = jobs;
    o.out_dir = (tmp / ("out" + std::to_string(k++))).string();
    fs::remove_all(o.out_dir);
    const std::clock_t c0 = std::clock();
    const fit::ConvertReport rep = fit::RunConvert(p.inputs, o);
    const double cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
    std::vector<double> e;
    for (const auto& i : rep.items)
      if (i.error >= 0) e.push_back(i.error);
    std::sort(e.begin(), e.end());
    errors.insert(errors.end(), e.begin(), e.end());
    std::printf("| %s | %d | %.2f | %.1f | %.2f | %.1f | %.4f |\n", p.label, rep.converted,
                rep.seconds, rep.converted / std::max(rep.seconds, 1e-9),
                1e3 * cpu / std::max(rep.converted, 1), 2.0 * rep.converted / std::max(cpu, 1e-9),
                e.empty() ? -1.0 : e[e.size() / 2]);
    if (rep.failed) {
      std::printf("(%d failed)\n", rep.failed);
      status = 1;
    }
  }
  std::sort(errors.begin(), errors.end());
  if (!errors.empty())
    std::printf("median BRDF-space fit error over all %zu materials: %.4f (square-root units)\n",
                errors.size(), errors[errors.size() / 2]);
  return status;
}

}  // namespace clothfit::cli
