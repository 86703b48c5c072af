// clothfit render-reference: path-traced reference of a fabric on a scene.
#include <tbb/global_control.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>

#include "bin/commands.h"
#include "bin/progress.h"
#include "render/reference/fabric.h"
#include "render/reference/path_tracer.h"
#include "render/scene/environment.h"
#include "render/scene/image_io.h"
#include "render/scene/input_limits.h"
#include "render/scene/scene.h"

namespace clothfit::cli {

// Resolves the scene's environment: the card's map, or the procedural sky (with a warning)
// when the map is not installed. Returns null when the card has no environment.
std::unique_ptr<render::Environment> LoadSceneEnvironment(const render::Scene& scene,
                                                          bool quiet) {
  if (!scene.card.environment) return nullptr;
  const render::EnvironmentSpec& e = *scene.card.environment;
  // Each distinct warning is printed once per process (fit and bench load the same map for
  // every reference they render).
  auto warn = [quiet](const std::string& msg) {
    static std::mutex mutex;
    static std::set<std::string> said;
    std::lock_guard<std::mutex> lock(mutex);
    if (!quiet && said.insert(msg).second) std::fprintf(stderr, "clothfit: warning: %s\n", msg.c_str());
  };
  if (e.path != "procedural-sky" && std::filesystem::exists(e.path)) {
    // One load (decode, CDF build) per map and process: render-references and fit render
    // several references under the same map; later ones get a copy (a memcpy of the texels and
    // CDFs, milliseconds instead of the decode's fraction of a second). Keyed by path, size
    // and modification time, intensity and rotation.
    static std::mutex memo_mutex;
    static std::map<std::string, std::shared_ptr<const render::Environment>> memo;
    std::error_code ec;
    const auto mtime = std::filesystem::last_write_time(e.path, ec);
    char key_tail[96];
    std::snprintf(key_tail, sizeof key_tail, "|%.17g|%.17g|%lld|%lld", e.intensity, e.rotation_y,
                  (long long)(ec ? 0 : mtime.time_since_epoch().count()),
                  (long long)std::filesystem::file_size(e.path, ec));
    const std::string key = e.path + key_tail;
    std::lock_guard<std::mutex> lock(memo_mutex);
    auto it = memo.find(key);
    if (it == memo.end()) {
      try {
        it =
            memo.emplace(key, std::make_shared<const render::Environment>(render::Environment::Load(
                                  e.path, e.intensity, e.rotation_y, warn)))
                .first;
      } catch (const io::IoError& error) {  // the map's own message, with the card and field
        throw io::IoError(scene.card.path + ": field 'environment.path': " + error.what());
      }
    }
    return std::make_unique<render::Environment>(*it->second);
  }
  // A file the card names is the user's own map, not one scripts/fetch-data installs: a typo
  // there rendered the procedural sky with status 0 (session 28).
  if (e.is_file)
    throw io::IoError(scene.card.path + ": field 'environment.path': '" + e.name +
                      "': no such file " + e.path +
                      " (a path with '/' or an extension is a "
                      "file, relative to the card's directory; only a map name such as "
                      "\"studio\" may be missing, until scripts/fetch-data installs it)");
  if (e.path != "procedural-sky") {
    warn(scene.card.path + ": environment '" + e.path +
         "' is not installed (run scripts/fetch-data); using the procedural sky");
  }
  return std::make_unique<render::Environment>(
      render::Environment::ProceduralSky(e.intensity, e.rotation_y));
}

bool ParseAovs(const std::string& list, render::AovSet& aovs, std::string& bad) {
  std::stringstream ss(list);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item == "normal") aovs.normal = true;
    else if (item == "position") aovs.position = true;
    else if (item == "uv") aovs.uv = true;
    else if (item == "tangent") aovs.tangent = true;
    else if (item == "depth") aovs.depth = true;
    else if (item == "all") aovs = {true, true, true, true, true};
    else if (!item.empty()) {
      bad = item;
      return false;
    }
  }
  return true;
}

void AddRenderCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    std::string scene, fabric, out, aov;
    int spp = 64, threads = 0, max_depth = 8, env_samples = -1;
    uint64_t seed = 1;
    double target_error = 0.0;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("render-reference",
                                     "path-trace a reference image of a fabric on a scene");
  // --help shows each default ("=64"), as bench does (session 28: it showed none).
  cmd->option_defaults()->always_capture_default();
  cmd->add_option("--scene", args->scene, "scene card (JSON)")->required();
  cmd->add_option("--fabric", args->fabric, "fabric definition (JSON)")->required();
  cmd->add_option("--out", args->out, "output EXR")->required();
  cmd->add_option("--spp", args->spp, "samples per pixel")->check(CLI::Range(1, 1 << 20));
  cmd->add_option("--seed", args->seed, "random seed (same seed: bit-identical image)");
  cmd->add_option("--threads", args->threads, "worker threads (0 = all cores)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--max-depth", args->max_depth, "maximum path depth")->check(CLI::Range(1, 64));
  cmd->add_option("--env-samples", args->env_samples,
                  "environment samples at each camera ray's hit (default: the renderer's; with "
                  "--target-error: chosen among 2, 4, 8 by a pilot)")
      ->check(CLI::Range(1, 16))
      ->default_str("");  // -1, "not given", is no value to show
  cmd->add_option("--target-error", args->target_error,
                  "adaptive sampling: target mean standard error / mean value (0.02 = 2 %); "
                  "--spp is then the per-pixel budget (a multiple of 16 >= 32)")
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--aov", args->aov,
                  "comma-separated AOVs: normal,position,uv,tangent,depth,all");
  cmd->callback([args, &g, &exit_code]() {
    try {
      io::RequireOutputDirectory(args->out);  // before minutes of rendering
      // An EXR by name as by content, not one of the inputs, in a directory that takes the file
      // (session 28: before, `--out canvas.json` replaced the fabric with the image after the
      // render, and `--out x.png` received EXR bytes).
      std::string ext = std::filesystem::path(args->out).extension().string();
      for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
      if (ext != ".exr")
        throw std::invalid_argument("--out: '" + args->out +
                                    "' must end in .exr (render-reference "
                                    "writes a linear EXR; clothfit tonemap makes a PNG of it)");
      RefuseOutputOverInput({"--out", args->out},
                            {{"--scene", args->scene}, {"--fabric", args->fabric}});
      RequireWritableOutput(args->out, "--out");
      render::RenderSettings st;
      st.spp = args->spp;
      st.seed = args->seed;
      st.max_depth = args->max_depth;
      if (args->env_samples > 0) {
        st.first_env_samples = args->env_samples;
        st.choose_env_samples = false;  // adaptive mode otherwise chooses among 2, 4, 8
      }
      st.target_error = args->target_error;
      if (st.target_error > 0.0 && (args->spp < 32 || args->spp % 16 != 0)) {
        std::fprintf(stderr,
                     "clothfit render-reference: error: --spp: with --target-error the budget "
                     "must be a multiple of 16 >= 32, got %d\n", args->spp);
        exit_code = 1;
        return;
      }
      std::string bad;
      if (!ParseAovs(args->aov, st.aovs, bad)) {
        std::fprintf(stderr, "clothfit render-reference: error: --aov: unknown AOV '%s'\n",
                     bad.c_str());
        exit_code = 1;
        return;
      }
      std::unique_ptr<tbb::global_control> limit;
      if (args->threads > 0) {
        limit = std::make_unique<tbb::global_control>(
            tbb::global_control::max_allowed_parallelism, size_t(args->threads));
      }
      const render::Scene scene = render::LoadScene(args->scene);
      const render::Fabric fabric = render::LoadFabric(args->fabric);
      // The files the card names are inputs too (its glTF, its environment map).
      RefuseOutputOverInput(
          {"--out", args->out},
          {{"--scene's gltf", scene.card.gltf},
           {"--scene's environment.path", scene.card.environment && scene.card.environment->found &&
                                                  scene.card.environment->path != "procedural-sky"
                                              ? scene.card.environment->path
                                              : std::string()}});
      // The loader's repairs (computed normals, tangents) and a missing map, as render-preview
      // prints them (session 28: render-reference repaired silently).
      for (const std::string& w : scene.warnings)
        if (!g.quiet)
          std::fprintf(stderr, "clothfit: warning: %s\n",
                       limits::EscapeForMessage(w, 2000).c_str());
      const auto env = LoadSceneEnvironment(scene, g.quiet);
      render::PathTracer tracer(scene, *fabric.bsdf, env.get());
      ProgressBar bar("render " + fabric.name, g.quiet);
      const render::RenderResult r =
          tracer.Render(st, [&](int d, int t) { bar.Update(d, t); });
      render::WriteRenderExr(
          args->out, r,
          {{"clothfit:scene", args->scene},
           {"clothfit:fabric", args->fabric},
           {"clothfit:fabric_name", fabric.name},
           {"clothfit:spp", std::to_string(args->spp)},
           {"clothfit:seed", std::to_string(args->seed)},
           {"clothfit:max_depth", std::to_string(args->max_depth)},
           {"clothfit:env_samples", std::to_string(r.env_samples)},
           {"clothfit:target_error", std::to_string(st.target_error)},
           {"clothfit:mean_spp", std::to_string(r.mean_spp)},
           {"clothfit:environment", env ? env->source() : std::string("none")},
           {"clothfit:renderer", "clothfit reference path tracer (NEE + env MIS, power heuristic)"},
           {"clothfit:renderer_version", std::to_string(render::kReferenceRendererVersion)}});
      const double mrays = double(r.rays) / r.seconds * 1e-6;
      std::printf(
          "render-reference: %s on %s: %dx%d, %d spp, %.2f s, %.2f Mrays/s, mean value %.4g, "
          "mean std error %.4g (%.2f%% of mean; per covered pixel %.2f%%) -> %s\n",
          fabric.name.c_str(), args->scene.c_str(), r.width, r.height, args->spp, r.seconds,
          mrays, r.mean_value, r.mean_std_error,
          r.mean_value > 0 ? 100.0 * r.mean_std_error / r.mean_value : 0.0,
          100.0 * r.mean_relative_std_error, args->out.c_str());
      if (st.target_error > 0.0) {
        const auto [lo, hi] = std::minmax_element(r.tile_spp.begin(), r.tile_spp.end());
        std::printf("render-reference: adaptive: target %.2f%%, mean %.1f spp (pilot included; "
                    "tiles %d..%d spp), pilot %.2f s\n",
                    100.0 * st.target_error, r.mean_spp, *lo, *hi, r.pilot_seconds);
        std::printf("render-reference: adaptive: predicted %.2f%%, achieved %.2f%% (ratio "
                    "%.3f); rate gamma %.2f; first-vertex env samples %d; candidates",
                    100.0 * r.predicted_error,
                    r.mean_value > 0 ? 100.0 * r.mean_std_error / r.mean_value : 0.0,
                    r.predicted_error > 0 && r.mean_value > 0
                        ? r.mean_std_error / r.mean_value / r.predicted_error
                        : 0.0,
                    r.error_rate, r.env_samples);
        for (const auto& c : r.env_candidates)
          std::printf(" %d: %.2f%% x %.1f rays", c.env_samples, 100.0 * c.relative_error, c.cost);
        std::printf("\n");
      }
      exit_code = 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit render-reference: error: %s\n", 
                   limits::EscapeForMessage(e.what(), 2000).c_str());
      exit_code = 1;
    }
  });
}

}  // namespace clothfit::cli
