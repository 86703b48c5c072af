// clothfit report: per-fabric HTML reports, an index page, JSON and CSV from fit presets.
#include <cstdio>
#if defined(__GLIBC__)
#endif
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "fit/metrics/report.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {

void AddReportCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    std::vector<std::string> presets;
    std::string out;
    double ppd = 67.0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "report",
      "per-fabric HTML reports (images embedded), an index page with a sortable summary, "
      "report.json and report.csv, from presets written by `clothfit fit --images` "
      "(docs/report.md)");
  cmd->add_option("presets", a->presets,
                  "fit presets (JSON); grouped by fabric, one per model and fabric")
      ->required();
  cmd->add_option("--out", a->out, "output directory (index.html, <fabric>.html, report.*)")
      ->required();
  cmd->add_option("--ppd", a->ppd, "FLIP pixels per degree")->check(CLI::Range(1.0, 1000.0));
  cmd->callback([a, &g, &exit_code]() {
    try {
      const std::vector<report::FabricSpec> specs = report::FabricsFromPresets(a->presets);
      std::vector<report::FabricReport> reports;
      report::ReportOptions o;
      o.ppd = a->ppd;
      for (const report::FabricSpec& s : specs) {
        if (!g.quiet) std::fprintf(stderr, "clothfit report: %s\n", s.name.c_str());
        reports.push_back(report::BuildFabricReport(s, o));
      }
      const std::string index = report::WriteReport(reports, a->out);
      std::printf("%s", report::TerminalTable(reports).c_str());
      std::printf("report: %s\n", std::filesystem::absolute(index).lexically_normal().c_str());
      exit_code = 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit report: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
