// clothfit: the command line. Thin: parse, validate, call one library function, turn
// errors into a non-zero exit status with a message naming the file or flag.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "bin/commands.h"
#include "render/scene/input_limits.h"

namespace {

// The subcommand closest to `typed`, compared with each name and with each of its endings after
// a '-' ("previwe" finds render-preview through "preview"); empty when none is within
// max(1, length / 3) edits (more would suggest unrelated names).
std::string ClosestSubcommand(const std::string& typed, const std::vector<std::string>& names) {
  if (typed.size() > 64) return {};  // (also bounds the quadratic distance table)
  std::string best;
  size_t best_distance = std::max<size_t>(1, typed.size() / 3) + 1;
  for (const std::string& name : names) {
    for (size_t start = 0; start != std::string::npos;) {
      const size_t distance = clothfit::limits::NameDistance(
          typed, std::string_view(name).substr(start), /*fold_case=*/false);
      if (distance < best_distance) {
        best_distance = distance;
        best = name;
      }
      const size_t dash = name.find('-', start);
      start = dash == std::string::npos ? dash : dash + 1;
    }
  }
  return best;
}

// CLI11's usage messages echo the user's arguments: each line goes through EscapeForMessage
// (control and invalid bytes as \xNN, cut at 300 bytes), then the help hint.
std::string UsageMessage(const CLI::App*, const CLI::Error& e) {
  std::istringstream lines(e.what());
  std::string out;
  for (std::string line; std::getline(lines, line);)
    out += clothfit::limits::EscapeForMessage(line, 300) + "\n";
  return out + "Run with --help for more information.\n";
}

// After a usage error with no subcommand parsed: "unknown subcommand 'X'" for the first word
// that is not an option (the global options take no values, so it is the one given where the
// subcommand belongs), with the closest name and the valid ones; false when there is none
// (no word at all: CLI11's "A subcommand is required" stands).
bool ReportUnknownSubcommand(CLI::App& app) {
  if (!app.get_subcommands().empty()) return false;
  const std::vector<std::string> rest = app.remaining();
  const auto word = std::find_if(rest.begin(), rest.end(),
                                 [](const std::string& w) { return !w.empty() && w[0] != '-'; });
  if (word == rest.end()) return false;
  std::vector<std::string> names;
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; }))
    names.push_back(sub->get_name());
  std::string valid;
  for (const std::string& n : names) valid += (valid.empty() ? "" : ", ") + n;
  const std::string closest = ClosestSubcommand(*word, names);
  const std::string hint = closest.empty() ? "" : " (did you mean '" + closest + "'?)";
  std::fprintf(stderr, "clothfit: error: unknown subcommand '%s'%s\nvalid subcommands: %s\n",
               clothfit::limits::EscapeForMessage(*word, 64).c_str(), hint.c_str(), valid.c_str());
  return true;
}

}  // namespace

int main(int argc, char** argv) {
#if defined(__GLIBC__)
  // The fits and the metrics allocate and free many 0.5 to 1.5 MB image planes (FLIP, SSIM
  // filters, preview frames). Above glibc's default mmap threshold each one was a fresh mmap,
  // zeroed page by page through page faults (perf: about a third of the report's CPU time).
  // Keeping them on the heap (threshold 32 MB, glibc's maximum; no trimming) reuses the pages:
  // same values (report.json and fit presets bit-identical), report 20.27 + 5.25 -> 15.75 +
  // 0.42 user + system CPU s on the 15 demo presets (docs/benchmarks.md "Session 7"). An
  // explicit GLIBC_TUNABLES wins (mallopt would override it).
  if (std::getenv("GLIBC_TUNABLES") == nullptr) {
    mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
    mallopt(M_TRIM_THRESHOLD, 1024 * 1024 * 1024);
  }
#endif
  CLI::App app{"clothfit: fit real-time cloth materials to ray-traced references"};
  app.set_version_flag("--version", "clothfit 0.1.0");
  app.require_subcommand(1);
  app.failure_message(UsageMessage);
  // Global options are accepted after the subcommand too ("clothfit fit -q ..."): an option a
  // subcommand does not define falls through to this app. Subcommands inherit the setting
  // when added; none defines -q or --quiet itself (a subcommand's own option would win).
  // `bench` is the exception: its unknown options go to Google Benchmark, so it takes
  // -q/--quiet itself (bin/cmd_bench.cpp).
  app.fallthrough();
  clothfit::cli::Globals globals;
  app.add_flag("-q,--quiet", globals.quiet,
               "no progress output on stderr (before or after the subcommand)");

  int exit_code = 0;
  clothfit::cli::AddLutCommand(app, globals, exit_code);
  clothfit::cli::AddStressCommand(app, globals, exit_code);
  clothfit::cli::AddBenchCommand(app, globals, exit_code);
  clothfit::cli::AddModelsCommand(app, globals, exit_code);
  clothfit::cli::AddRenderCommand(app, globals, exit_code);
  clothfit::cli::AddRenderReferencesCommand(app, globals, exit_code);
  clothfit::cli::AddPreviewCommand(app, globals, exit_code);
  clothfit::cli::AddFitCommand(app, globals, exit_code);
  clothfit::cli::AddCompareCommand(app, globals, exit_code);
  clothfit::cli::AddTonemapCommand(app, globals, exit_code);
  clothfit::cli::AddReportCommand(app, globals, exit_code);
  clothfit::cli::AddConvertCommand(app, globals, exit_code);
  clothfit::cli::AddEvaluateCommand(app, globals, exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Usage errors print the message and exit 1 (help and --version: 0).
    if (e.get_exit_code() != 0 && ReportUnknownSubcommand(app)) return 1;
    return app.exit(e) == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "clothfit: error: %s\n", 
                   clothfit::limits::EscapeForMessage(e.what(), 2000).c_str());
    return 1;
  }
  return exit_code;
}
