// clothfit: the command line. Thin: parse, validate, call one library function, turn
// errors into a non-zero exit status with a message naming the file or flag.
#include <cstdio>
#include <cstdlib>
#include <exception>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "bin/commands.h"
#include "render/scene/input_limits.h"

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
  clothfit::cli::Globals globals;
  app.add_flag("-q,--quiet", globals.quiet, "no progress output on stderr");

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
    return app.exit(e) == 0 ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "clothfit: error: %s\n", 
                   clothfit::limits::EscapeForMessage(e.what(), 2000).c_str());
    return 1;
  }
  return exit_code;
}
