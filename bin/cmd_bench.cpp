// clothfit bench brdf: Google Benchmark of every model, ns per evaluation of the direct
// term plus the IBL weights, in double and with a ceres::Jet of 10 parameters.
// Extra arguments go to Google Benchmark (e.g. clothfit bench brdf --benchmark_format=json).
#include <benchmark/benchmark.h>
#include <ceres/jet.h>

#include <array>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "brdf/models.h"
#include "fit/bench_fit.h"
#include "render/reference/fabric.h"
#include "render/preview/preview.h"

namespace clothfit::cli {
namespace {

using Jet10 = ceres::Jet<double, 10>;

// A fixed ring of 64 realistic configurations so branch prediction sees variety.
std::vector<Cosines<double>> Configurations() {
  std::vector<Cosines<double>> out;
  for (int i = 0; i < 64; ++i) {
    const double tv = 0.05 + 1.4 * ((i * 37) % 64) / 64.0;
    const double tl = 0.05 + 1.4 * ((i * 11) % 64) / 64.0;
    const double ph = 6.2831853 * ((i * 23) % 64) / 64.0;
    const Vec3<double> v(std::sin(tv), 0.0, std::cos(tv));
    const Vec3<double> l(std::sin(tl) * std::cos(ph), std::sin(tl) * std::sin(ph), std::cos(tl));
    out.push_back(CosinesFromDirections(v, l));
  }
  return out;
}

template <typename T>
void BM_Model(benchmark::State& state, ModelId m) {
  const auto configs = Configurations();
  std::vector<Cosines<T>> cs;
  for (const auto& c : configs) cs.push_back({T(c.NoV), T(c.NoL), T(c.NoH), T(c.LoH)});
  std::array<T, 10> x{};
  const std::array<double, 10> values{0.6, 0.4, 0.3, 0.8, 0.7, 0.6, 0.55, 0.2, 0.1, 0.05};
  for (int k = 0; k < ParameterCount(m); ++k) {
    if constexpr (std::is_same_v<T, double>) {
      x[size_t(k)] = values[size_t(k)];
    } else {
      x[size_t(k)] = T(values[size_t(k)], k);
    }
  }
  size_t i = 0;
  for (auto _ : state) {
    Rgb<T> direct, ibl;
    EvaluateFlat<T>(m, x.data(), cs[i++ & 63], direct, ibl);
    benchmark::DoNotOptimize(direct);
    benchmark::DoNotOptimize(ibl);
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
}

struct PreviewSet {
  std::string name;
  std::unique_ptr<render::PreviewCache> cache;
};

std::vector<PreviewSet>& PreviewSets() {
  static std::vector<PreviewSet> sets;
  return sets;
}

// Builds the preview caches for the feature sets, outside any timing.
void BuildPreviewSets(const std::string& scene_path, bool quiet) {
  const render::Scene scene = render::LoadScene(scene_path);
  const auto env = LoadSceneEnvironment(scene, quiet);
  if (!env) throw std::runtime_error(scene_path + ": bench preview needs a scene with an environment");
  if (scene.lights.empty()) throw std::runtime_error(scene_path + ": bench preview needs a light");
  render::Scene no_lights = scene;
  no_lights.lights.clear();
  struct Def {
    const char* name;
    const render::Scene* s;
    const render::Environment* e;
    bool sub, shadows;
  };
  const Def defs[] = {{"full (direct+ibl+subsurface+shadows)", &scene, env.get(), true, true},
                      {"direct+ibl", &scene, env.get(), false, false},
                      {"direct only (no environment)", &scene, nullptr, false, false},
                      {"ibl only (no lights)", &no_lights, env.get(), false, false}};
  for (const Def& d : defs) {
    render::PreviewOptions o;
    o.model = render::ModelKind::kCloth;
    o.cloth.subsurface = d.sub;
    o.shadows = d.shadows;
    auto cache = render::PreviewCache::Build(*d.s, d.e, o);
    std::fprintf(stderr, "bench preview: cache '%s': %zu fabric pixels, %zu light samples, built in %.3f s\n",
                 d.name, cache->pixels.size(), cache->light_samples.size(), cache->build_seconds);
    PreviewSets().push_back({d.name, std::move(cache)});
  }
}

template <typename T>
void BM_Preview(benchmark::State& state, const render::PreviewCache* cache) {
  const std::array<double, 10> values{0.6, 0.4, 0.3, 0.8, 0.7, 0.6, 0.55, 0.2, 0.1, 0.05};
  std::array<T, 10> x{};
  for (int k = 0; k < 10; ++k) {
    if constexpr (std::is_same_v<T, double>) {
      x[size_t(k)] = values[size_t(k)];
    } else {
      x[size_t(k)] = T(values[size_t(k)], k);
    }
  }
  std::vector<Rgb<T>> out;
  for (auto _ : state) {
    render::EvaluatePreview(*cache, x.data(), out);
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["pixels"] = double(cache->pixels.size());
}

struct BenchFitArgs {
  std::string fabrics = "canvas,twill";
  std::string widths = "64,128,256,512";
  std::string strides = "0,1";
  std::string starts = "1,2,3";
  int spp = 64;
  std::string csv = "out/bench-fit.csv", png = "out/bench-fit.png";
};

std::vector<int> IntList(const std::string& text, const char* flag, int lo, int hi) {
  std::vector<int> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    size_t used = 0;
    int v = 0;
    try {
      v = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || v < lo || v > hi)
      throw std::invalid_argument(std::string(flag) + ": '" + item + "' is not an integer in [" +
                                  std::to_string(lo) + ", " + std::to_string(hi) + "]");
    out.push_back(v);
  }
  if (out.empty()) throw std::invalid_argument(std::string(flag) + ": empty list");
  return out;
}

void RunBenchFit(const BenchFitArgs& a, bool quiet) {
  const char* env_root = std::getenv("CLOTHFIT_DATASETS");
  const std::string root = env_root ? env_root : CLOTHFIT_SOURCE_DATASETS;
  std::vector<fit::BenchSetting> settings;
  for (int width : IntList(a.widths, "--widths", 16, 4096))
    for (int stride : IntList(a.strides, "--strides", 0, 16))
      for (int starts : IntList(a.starts, "--starts", 1, 3)) settings.push_back({width, -1, stride, starts});
  std::vector<fit::BenchRow> all;
  std::stringstream ss(a.fabrics);
  std::string name;
  std::printf("%-8s %5s %5s %6s %6s %8s %9s\n", "fabric", "width", "level", "stride", "starts",
              "seconds", "error");
  const std::vector<std::string> paths = CanonicalScenes();
  while (std::getline(ss, name, ',')) {
    const std::string fabric_path = root + "/fabrics/" + name + ".json";
    const double weave_period = render::LoadFabric(fabric_path).weave_period_uv;
    // Everything loaded here outlives the bench: scenes, environments and references per width.
    std::map<int, std::vector<render::Scene>> scenes;
    std::map<int, std::vector<fit::Reference>> refs;
    std::vector<std::unique_ptr<render::Environment>> envs;
    for (const std::string& sp : paths) envs.push_back(LoadSceneEnvironment(render::LoadScene(sp), true));
    auto inputs_at = [&](int width) {
      auto& sc = scenes[width];
      auto& rr = refs[width];
      sc.clear();
      rr.clear();
      for (const std::string& sp : paths) {
        sc.push_back(LoadSceneAtWidth(sp, width));
        rr.push_back(fit::ReadReference(CachedReference(sp, fabric_path, a.spp, 1, quiet, width)));
      }
      std::vector<fit::SceneInput> in;
      for (size_t i = 0; i < paths.size(); ++i) in.push_back({&sc[i], envs[i].get(), &rr[i], nullptr, paths[i]});
      return in;
    };
    // The common measure is taken at the cards' own resolution (key -1 keeps it apart from a
    // bench width equal to the card's).
    std::vector<render::Scene> common_scenes;
    std::vector<fit::Reference> common_refs;
    for (const std::string& sp : paths) {
      common_scenes.push_back(render::LoadScene(sp));
      common_refs.push_back(fit::ReadReference(CachedReference(sp, fabric_path, a.spp, 1, quiet)));
    }
    std::vector<fit::SceneInput> common;
    for (size_t i = 0; i < paths.size(); ++i)
      common.push_back({&common_scenes[i], envs[i].get(), &common_refs[i], nullptr, paths[i]});
    fit::FitOptions base;
    base.start = render::DefaultPreset(render::ModelKind::kCloth);
    const auto rows = fit::RunFitBench(name, inputs_at, common, weave_period, base, settings,
                                       [](const fit::BenchRow& r) {
      std::printf("%-8s %5d %5d %6s %6d %8.2f %9.5f%s\n", r.fabric.c_str(), r.width, r.level,
                  r.setting.stride == 0 ? "auto" : std::to_string(r.setting.stride).c_str(),
                  r.setting.starts, r.seconds, r.error, r.usable ? "" : "  (unusable)");
      std::fflush(stdout);
    });
    all.insert(all.end(), rows.begin(), rows.end());
  }
  const std::string& csv = a.csv;
  const std::string& png = a.png;
  std::filesystem::create_directories(std::filesystem::path(csv).parent_path().empty()
                                          ? std::filesystem::path(".")
                                          : std::filesystem::path(csv).parent_path());
  std::filesystem::create_directories(std::filesystem::path(png).parent_path().empty()
                                          ? std::filesystem::path(".")
                                          : std::filesystem::path(png).parent_path());
  fit::WriteFitBench(all, csv, png);
  std::printf("bench fit: %zu fits -> %s, %s\n", all.size(), csv.c_str(), png.c_str());
}

// What `clothfit bench` was asked for.
struct BenchArgs {
  std::string what;
  std::string scene = std::string(CLOTHFIT_SOURCE_DATASETS) + "/scenes/sphere.json";
  BenchFitArgs fit;
  std::string catalogue;
  int count = 200;
  int jobs = 0;
};

void AddBenchOptions(CLI::App* cmd, BenchArgs& a) {
  BenchFitArgs& fa = a.fit;
  cmd->add_option("what", a.what, "what to benchmark: brdf | preview | fit | convert")
      ->required()
      ->check(CLI::IsMember({"brdf", "preview", "fit", "convert"}));
  cmd->add_option("--catalogue", a.catalogue,
                  "`bench convert`: catalogue directory (default: generate one in a temporary "
                  "directory with datasets/catalogue/generate.py)");
  cmd->add_option("--count", a.count,
                  "`bench convert`: materials per input format when generating");
  cmd->add_option("-j,--jobs", a.jobs, "`bench convert`: worker threads (0: all cores)");
  cmd->add_option("--fabrics", fa.fabrics, "`bench fit`: comma-separated fabric names");
  cmd->add_option("--widths", fa.widths, "`bench fit`: fit resolutions (image widths, px)");
  cmd->add_option("--strides", fa.strides, "`bench fit`: pixel strides (0 = auto)");
  cmd->add_option("--starts", fa.starts, "`bench fit`: multi-start counts (1-3)");
  cmd->add_option("--spp", fa.spp, "`bench fit`: reference samples per pixel (cached)")
      ->check(CLI::Range(16, 65536));
  cmd->add_option("--csv", fa.csv, "`bench fit`: output CSV");
  cmd->add_option("--png", fa.png, "`bench fit`: output plot (error vs time)");
  cmd->add_option("--scene", a.scene, "scene card for `bench preview`");
  cmd->allow_extras();
}

void RegisterBrdfBenchmarks() {
  for (ModelId m : kAllModels) {
    const std::string name(ModelName(m));
    benchmark::RegisterBenchmark(("brdf/" + name + "/double").c_str(),
                                 [m](benchmark::State& s) { BM_Model<double>(s, m); });
    benchmark::RegisterBenchmark(("brdf/" + name + "/jet10").c_str(),
                                 [m](benchmark::State& s) { BM_Model<Jet10>(s, m); });
  }
}

// Needs BuildPreviewSets first.
void RegisterPreviewBenchmarks() {
  for (const PreviewSet& set : PreviewSets()) {
    const render::PreviewCache* c = set.cache.get();
    benchmark::RegisterBenchmark(("preview/" + set.name + "/double").c_str(),
                                 [c](benchmark::State& s) { BM_Preview<double>(s, c); })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("preview/" + set.name + "/jet10").c_str(),
                                 [c](benchmark::State& s) { BM_Preview<Jet10>(s, c); })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
  }
}

// Runs the registered benchmarks with the command's extra arguments; returns the exit status.
int RunRegisteredBenchmarks(CLI::App* cmd) {
  std::vector<std::string> extras = cmd->remaining();
  std::vector<char*> argv{const_cast<char*>("clothfit-bench")};
  for (auto& e : extras) argv.push_back(e.data());
  int argc = int(argv.size());
  benchmark::Initialize(&argc, argv.data());
  if (benchmark::ReportUnrecognizedArguments(argc, argv.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

// `clothfit bench` after parsing: returns the exit status.
int RunBench(CLI::App* cmd, const BenchArgs& a, const Globals& g) {
  (void)lut::DefaultDfg();  // tables are built once, outside the timed loops
  (void)lut::DefaultSheenAlbedo();
  if (a.what == "convert") {
    try {
      return RunBenchConvert(a.catalogue, a.count, a.jobs, g.quiet);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit bench convert: error: %s\n", e.what());
      return 1;
    }
  }
  if (a.what == "fit") {
    try {
      RunBenchFit(a.fit, g.quiet);
      return 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit bench fit: error: %s\n", e.what());
      return 1;
    }
  }
  if (a.what == "brdf") {
    RegisterBrdfBenchmarks();
  } else {
    try {
      BuildPreviewSets(a.scene, g.quiet);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "clothfit bench preview: error: %s\n", e.what());
      return 1;
    }
    RegisterPreviewBenchmarks();
  }
  return RunRegisteredBenchmarks(cmd);
}

}  // namespace

void AddBenchCommand(CLI::App& app, const Globals& g, int& exit_code) {
  CLI::App* cmd = app.add_subcommand("bench", "benchmarks (Google Benchmark)");
  auto a = std::make_shared<BenchArgs>();
  AddBenchOptions(cmd, *a);
  cmd->callback([cmd, a, &g, &exit_code]() { exit_code = RunBench(cmd, *a, g); });
}

}  // namespace clothfit::cli
