// clothfit lut: the DFG LUT and the glTF sheen albedo table, as EXR.
#include <cstdio>
#include <filesystem>
#include <string>

#include "bin/commands.h"
#include "bin/progress.h"
#include "brdf/lut.h"
#include "render/image_io.h"

namespace clothfit::cli {

void AddLutCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    int size = 128;
    int samples = 64;
    std::string out;
    std::string sheen_out;
    int sheen_size = 32;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "lut", "compute the DFG LUT (R,G = GGX scale/bias, B = cloth sheen albedo) and the glTF "
             "sheen albedo table");
  cmd->add_option("--size", args->size, "DFG texels per axis")->check(CLI::Range(2, 4096));
  cmd->add_option("--samples", args->samples,
                  "importance samples per axis per texel (S x S strata)")
      ->check(CLI::Range(4, 1024));
  cmd->add_option("--out", args->out, "output EXR for the DFG LUT")->required();
  cmd->add_option("--sheen-out", args->sheen_out,
                  "also write the glTF sheen albedo table E(NoV, r_s) to this EXR");
  cmd->add_option("--sheen-size", args->sheen_size, "sheen table texels per axis")
      ->check(CLI::Range(2, 4096));
  cmd->callback([args, &g, &exit_code]() {
    try {
      lut::Settings s{args->size, args->samples};
      ProgressBar bar("lut dfg", g.quiet);
      const Table2D dfg = lut::ComputeDfg(s, [&](int d, int t) { bar.Update(d, t); });
      io::Image img = io::TableToImage(dfg, {"R", "G", "B"});
      img.metadata["clothfit:table"] = "DFG";
      img.metadata["clothfit:channels"] =
          "R = GGX split-sum scale A, G = bias B (albedo for F0: F0 A + B); B = cloth sheen "
          "albedo int D_Charlie V_Neubelt cos (no sheen colour)";
      img.metadata["clothfit:samples_per_texel"] = std::to_string(args->samples * args->samples);
      img.metadata["clothfit:integrator"] =
          "stratified importance sampling of h (GGX D cos / Charlie D cos), midpoint strata";
      io::WriteExr(args->out, img);
      std::printf("wrote %s (%dx%d, %d samples per texel)\n", args->out.c_str(), args->size,
                  args->size, args->samples * args->samples);
      if (!args->sheen_out.empty()) {
        lut::Settings ss{args->sheen_size, args->samples};
        ProgressBar bar2("lut sheen", g.quiet);
        const Table2D e = lut::ComputeSheenAlbedo(ss, [&](int d, int t) { bar2.Update(d, t); });
        io::Image simg = io::TableToImage(e, {"Y"});
        simg.metadata["clothfit:table"] = "sheen albedo E (glTF KHR_materials_sheen)";
        simg.metadata["clothfit:channels"] = "Y = int D_Charlie V_Charlie cos (Charlie Lambda)";
        simg.metadata["clothfit:samples_per_texel"] =
            std::to_string(args->samples * args->samples);
        io::WriteExr(args->sheen_out, simg);
        std::printf("wrote %s (%dx%d)\n", args->sheen_out.c_str(), args->sheen_size,
                    args->sheen_size);
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit lut: error: %s\n", e.what());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
