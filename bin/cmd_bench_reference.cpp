// bin/cmd_bench_reference.cpp: `clothfit bench reference`.
//
// Simple materials (datasets/materials: lambert, ggx_conductor): clothfit and Blender Cycles
// (scripts/cycles-reference) render the same card and material at the same size, spp, depth,
// seed and thread count, back to back, and the time ratio is printed. Timed on each side: what
// a render costs once the scene is in memory - clothfit: environment load + BVH build +
// render; Cycles: the bpy render call (scene sync, BVH, environment map, render). Start-up
// (Blender's, the glTF import) is excluded on both sides and printed separately for Cycles.
//
// Woven fabrics (no Cycles equivalent): the time clothfit needs to reach a mean standard error
// of `target_error` x the mean pixel value (the measure of docs/reference-renderer.md): a pilot
// render gives the error at its spp; the standard error falls as spp^(-1/2), so the spp for the
// target is pilot spp x (pilot error / target)^2 (rounded up to a multiple of 16); that render
// is then made and its own seconds and error are printed (not a projection).
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "bin/commands.h"
#include "render/reference/fabric.h"
#include "render/reference/path_tracer.h"
#include "render/scene/image_io.h"

namespace clothfit::cli {
namespace {

namespace fs = std::filesystem;

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a.empty() ? "?" : a + " " + b + " " + c;
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct ClothfitRun {
  render::RenderResult result;
  double seconds = 0.0;  // environment load + BVH + render
};

ClothfitRun RenderClothfit(const render::Scene& scene, const render::Bsdf& bsdf,
                           const render::RenderSettings& st, bool quiet) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto env = LoadSceneEnvironment(scene, quiet);
  render::PathTracer tracer(scene, bsdf, env.get());
  ClothfitRun run;
  run.result = tracer.Render(st);
  run.seconds = Seconds(t0);
  return run;
}

double RelativeError(const render::RenderResult& r) {
  return r.mean_value > 0.0 ? r.mean_std_error / r.mean_value : 0.0;
}

}  // namespace

int RunBenchReference(const BenchReferenceArgs& a, bool quiet) {
  std::unique_ptr<tbb::global_control> limit;
  if (a.threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  size_t(a.threads));
  }
  const int threads = a.threads > 0 ? a.threads
                                    : int(tbb::global_control::active_value(
                                          tbb::global_control::max_allowed_parallelism));
  const render::Scene scene = LoadSceneAtWidth(a.scene, a.width);
  const render::Fabric fabric = render::LoadFabric(a.fabric);
  render::RenderSettings st;
  st.spp = a.spp;
  st.max_depth = a.max_depth;
  st.seed = a.seed;
  const int W = scene.card.width, H = scene.card.height;
  std::printf("bench reference: %s, %s (%s), %dx%d, max depth %d, seed %llu, %d threads\n",
              fs::path(a.scene).filename().string().c_str(), fabric.name.c_str(),
              fabric.model.c_str(), W, H, a.max_depth, (unsigned long long)a.seed, threads);
  std::printf("  load average at start: %s\n", LoadAverage().c_str());

  if (fabric.model != "lambert" && fabric.model != "ggx_conductor") {
    // Woven: time to the target mean standard error.
    const ClothfitRun pilot = RenderClothfit(scene, *fabric.bsdf, st, quiet);
    const double e0 = RelativeError(pilot.result);
    int spp = int(std::ceil(a.spp * (e0 / a.target_error) * (e0 / a.target_error) / 16.0)) * 16;
    spp = std::max(spp, 32);
    std::printf("  pilot: %d spp, %.2f s, mean std error %.2f %% of mean -> %d spp for %.1f %%\n",
                a.spp, pilot.seconds, 100.0 * e0, spp, 100.0 * a.target_error);
    st.spp = spp;
    const ClothfitRun run = RenderClothfit(scene, *fabric.bsdf, st, quiet);
    std::printf("  clothfit: %d spp, %.2f s, %.2f Mrays/s, mean std error %.2f %% of mean\n", spp,
                run.seconds, double(run.result.rays) / run.result.seconds * 1e-6,
                100.0 * RelativeError(run.result));
    std::printf("  time to %.1f %% mean standard error: %.2f s\n", 100.0 * a.target_error,
                run.seconds);
    std::printf("  load average at end: %s\n", LoadAverage().c_str());
    return 0;
  }

  // Simple material: clothfit, then Cycles, back to back.
  const ClothfitRun run = RenderClothfit(scene, *fabric.bsdf, st, quiet);
  std::printf("  clothfit: %d spp, %.2f s, %.2f Mrays/s, mean std error %.2f %% of mean\n", a.spp,
              run.seconds, double(run.result.rays) / run.result.seconds * 1e-6,
              100.0 * RelativeError(run.result));
  const fs::path out = fs::temp_directory_path() /
                       ("clothfit_bench_cycles_" + std::to_string(::getpid()) + ".exr");
  const std::string cmd = "'" + a.cycles_script + "' --scene '" + a.scene + "' --fabric '" +
                          a.fabric + "' --spp " + std::to_string(a.spp) + " --max-depth " +
                          std::to_string(a.max_depth) + " --seed " + std::to_string(a.seed) +
                          " --threads " + std::to_string(threads) + " --width " +
                          std::to_string(W) + " --height " + std::to_string(H) + " --out '" +
                          out.string() + "' 2>&1";
  const auto t0 = std::chrono::steady_clock::now();
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) throw std::runtime_error("cannot run " + a.cycles_script);
  std::string line, info;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), int(buf.size()), pipe)) {
    line = buf.data();
    if (line.rfind("cycles-reference: ", 0) == 0) info = line.substr(18);
  }
  const int status = pclose(pipe);
  const double wall = Seconds(t0);
  if (status != 0 || info.empty()) {
    std::fprintf(stderr, "clothfit bench reference: Cycles failed (%s); last line: %s\n",
                 cmd.c_str(), line.c_str());
    return 1;
  }
  const double cycles_s = nlohmann::json::parse(info).at("seconds").get<double>();
  std::printf("  cycles:   %d spp, %.2f s (bpy render call; %.2f s with Blender start-up and glTF "
              "import)\n",
              a.spp, cycles_s, wall);
  std::printf("  time ratio clothfit / cycles = %.3f\n", run.seconds / cycles_s);
  // Image means over pixels covered in both (a consistency check, not the agreement test).
  try {
    const io::Image img = io::ReadImage(out.string());
    const size_t nc = img.channel_names.size();
    double sc[3] = {0, 0, 0}, sy[3] = {0, 0, 0};
    for (size_t p = 0; p < size_t(W) * size_t(H) && nc >= 4; ++p) {
      if (!(run.result.coverage[p] >= 1.0f && img.pixels[p * nc + 3] >= 0.999f)) continue;
      for (size_t c = 0; c < 3; ++c) {
        sc[c] += double(run.result.rgb[p * 3 + c]);
        sy[c] += double(img.pixels[p * nc + c]);
      }
    }
    std::printf("  covered-pixel means clothfit / cycles - 1: %+.4f %+.4f %+.4f\n",
                sy[0] > 0 ? sc[0] / sy[0] - 1 : 0.0, sy[1] > 0 ? sc[1] / sy[1] - 1 : 0.0,
                sy[2] > 0 ? sc[2] / sy[2] - 1 : 0.0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "clothfit bench reference: cannot read %s: %s\n", out.c_str(), e.what());
  }
  fs::remove(out);
  std::printf("  load average at end: %s\n", LoadAverage().c_str());
  return 0;
}

}  // namespace clothfit::cli
