// bin/commands.h: one function per subcommand; each registers its flags on the CLI11 app
// and returns the callback result as an exit code. Library code never exits (style.md 10).
#pragma once

#include <CLI/CLI.hpp>

namespace clothfit::cli {

struct Globals {
  bool quiet = false;
};

void AddLutCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddStressCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddBenchCommand(CLI::App& app, const Globals& g, int& exit_code);
void AddModelsCommand(CLI::App& app, const Globals& g, int& exit_code);

}  // namespace clothfit::cli
