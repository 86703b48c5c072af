// clothfit: the command line. Thin: parse, validate, call one library function, turn
// errors into a non-zero exit status with a message naming the file or flag.
#include <cstdio>
#include <exception>

#include "bin/commands.h"
#include "render/scene/input_limits.h"

int main(int argc, char** argv) {
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
