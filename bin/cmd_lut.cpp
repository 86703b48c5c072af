// clothfit lut: the DFG LUT and the glTF sheen albedo table, as EXR.
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>

#include "bin/commands.h"
#include "bin/progress.h"
#include "brdf/lut.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {
namespace {
template <typename A>
std::string Integrator(const A& a) {
  return "half-vector quadrature: Gauss-Legendre order " + std::to_string(a.order) +
         " per theta_h panel (breakpoints every pi/8 + 8 at the lobe scale), " +
         std::to_string(a.azimuth) + " azimuth midpoints over the arc where n.l > 0";
}
}  // namespace

void AddLutCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    int size = 128;
    int order = 8;
    int azimuth = 32;
    std::string out;
    std::string sheen_out;
    int sheen_size = 32;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "lut",
      "compute the DFG LUT (R,G = GGX scale/bias, B = cloth sheen albedo) and the glTF "
      "sheen albedo table");
  // --help shows each default ("=64"), as bench does (session 28: it showed none).
  cmd->option_defaults()->always_capture_default();
  cmd->add_option("--size", args->size, "DFG texels per axis")->check(CLI::Range(2, 4096));
  cmd->add_option("--gl-order", args->order, "Gauss-Legendre nodes per theta_h panel")
      ->check(CLI::Range(2, 64));
  cmd->add_option("--azimuth", args->azimuth, "azimuth midpoints over the valid half arc")
      ->check(CLI::Range(4, 4096));
  cmd->add_option("--out", args->out, "output EXR for the DFG LUT")->required();
  cmd->add_option("--sheen-out", args->sheen_out,
                  "also write the glTF sheen albedo table E(NoV, r_s) to this EXR");
  cmd->add_option("--sheen-size", args->sheen_size, "sheen table texels per axis")
      ->check(CLI::Range(2, 4096));
  cmd->callback([args, &g, &exit_code]() {
    try {
      io::RequireOutputDirectory(args->out);  // both, before any table is computed
      if (!args->sheen_out.empty()) io::RequireOutputDirectory(args->sheen_out);
      // EXRs by name as by content, two different files, directories that take them (session
      // 28: before, `--sheen-out` equal to `--out` replaced the DFG LUT with the sheen table,
      // and `--out dfg.png` received EXR bytes).
      using Output = std::pair<const char*, const std::string&>;
      for (const auto& [flag, path] :
           {Output{"--out", args->out}, Output{"--sheen-out", args->sheen_out}}) {
        if (path.empty()) continue;
        std::string ext = std::filesystem::path(path).extension().string();
        for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
        if (ext != ".exr")
          throw std::invalid_argument(std::string(flag) + ": '" + path +
                                      "' must end in .exr (lut writes float EXR tables)");
        RequireWritableOutput(path, flag);
      }
      if (!args->sheen_out.empty())
        RefuseOutputOverInput({"--sheen-out", args->sheen_out},
                              std::vector<NamedPath>{NamedPath{"--out", args->out}});
      lut::Settings s{args->size, args->order, args->azimuth};
      ProgressBar bar("lut dfg", g.quiet);
      const Table2D dfg = lut::ComputeDfg(s, [&](int d, int t) { bar.Update(d, t); });
      io::Image img = io::TableToImage(dfg, {"R", "G", "B"});
      img.metadata["clothfit:table"] = "DFG";
      img.metadata["clothfit:channels"] =
          "R = GGX split-sum scale A, G = bias B (albedo for F0: F0 A + B); B = cloth sheen "
          "albedo int D_Charlie V_Neubelt cos (no sheen colour)";
      img.metadata["clothfit:integrator"] = Integrator(*args);
      io::WriteExr(args->out, img);
      std::printf("wrote %s (%dx%d; %s)\n", args->out.c_str(), args->size, args->size,
                  Integrator(*args).c_str());
      if (!args->sheen_out.empty()) {
        lut::Settings ss{args->sheen_size, args->order, args->azimuth};
        ProgressBar bar2("lut sheen", g.quiet);
        const Table2D e = lut::ComputeSheenAlbedo(ss, [&](int d, int t) { bar2.Update(d, t); });
        io::Image simg = io::TableToImage(e, {"Y"});
        simg.metadata["clothfit:table"] = "sheen albedo E (glTF KHR_materials_sheen)";
        simg.metadata["clothfit:channels"] = "Y = int D_Charlie V_Charlie cos (Charlie Lambda)";
        simg.metadata["clothfit:integrator"] = Integrator(*args);
        io::WriteExr(args->sheen_out, simg);
        std::printf("wrote %s (%dx%d)\n", args->sheen_out.c_str(), args->sheen_size,
                    args->sheen_size);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit lut: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
