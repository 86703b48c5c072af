// clothfit bench brdf: Google Benchmark of every model, ns per evaluation of the direct
// term plus the IBL weights, in double and with a ceres::Jet of 10 parameters.
// Extra arguments go to Google Benchmark (e.g. clothfit bench brdf --benchmark_format=json).
#include <benchmark/benchmark.h>
#include <ceres/jet.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "fit/yarn_farfield.h"
#include "brdf/models.h"
#include "brdf/yarn_lobe.h"
#include "fit/bench_fit.h"
#include "render/reference/fabric.h"
#include "render/preview/preview.h"
#include "render/preview/weave_maps.h"
#include "render/scene/input_limits.h"

namespace clothfit::cli {
namespace {

using Jet10 = ceres::Jet<double, 10>;

// A fixed ring of 64 realistic view/light pairs so branch prediction sees variety.
template <typename Cos, typename FromDirections>
std::vector<Cos> ConfigurationRing(FromDirections from_directions) {
  std::vector<Cos> out;
  for (int i = 0; i < 64; ++i) {
    const double tv = 0.05 + 1.4 * ((i * 37) % 64) / 64.0;
    const double tl = 0.05 + 1.4 * ((i * 11) % 64) / 64.0;
    const double ph = 6.2831853 * ((i * 23) % 64) / 64.0;
    const Vec3<double> v(std::sin(tv), 0.0, std::cos(tv));
    const Vec3<double> l(std::sin(tl) * std::cos(ph), std::sin(tl) * std::sin(ph), std::cos(tl));
    out.push_back(from_directions(v, l));
  }
  return out;
}

// The cosines of the 64 configurations.
std::vector<Cosines<double>> Configurations() {
  return ConfigurationRing<Cosines<double>>(
      [](const Vec3<double>& v, const Vec3<double>& l) { return CosinesFromDirections(v, l); });
}

// The tangent-frame cosines of the same 64 configurations.
std::vector<TangentCosines<double>> TangentConfigurations() {
  return ConfigurationRing<TangentCosines<double>>([](const Vec3<double>& v, const Vec3<double>& l) {
    return TangentCosinesFromDirections(v, l);
  });
}

template <typename T>
void BM_Model(benchmark::State& state, ModelId m) {
  const auto configs = Configurations();
  std::vector<Cosines<T>> cs;
  for (const auto& c : configs) cs.push_back({T(c.NoV), T(c.NoL), T(c.NoH), T(c.LoH)});
  std::vector<TangentCosines<T>> ts;  // anisotropic models: the same directions' frame
  for (const auto& t : TangentConfigurations())
    ts.push_back({T(t.ToV), T(t.BoV), T(t.ToL), T(t.BoL), T(t.ToH), T(t.BoH)});
  std::array<T, kMaxModelParameters> x{};
  // Values in [0, 1] for the first 10 (every model's range); woven's last six inside theirs.
  const std::array<double, kMaxModelParameters> values{0.6, 0.4, 0.3, 0.8,  0.7, 0.6, 0.55, 0.2,
                                                       0.1, 0.05, 0.05, 2.0, 0.1, 0.1, 0.1, 0.6};
  // Each value clamped into the model's documented range (physical-aniso's
  // specular_intensity is in [0, 1]; the others' values already are).
  std::array<double, kMaxModelParameters> lo{}, hi{};
  FlatBounds(m, lo.data(), hi.data());
  for (int k = 0; k < ParameterCount(m); ++k) {
    const double v = std::clamp(values[size_t(k)], lo[size_t(k)], hi[size_t(k)]);
    if constexpr (std::is_same_v<T, double>) {
      x[size_t(k)] = v;
    } else {  // Jet10: the first 10 parameters carry derivatives (the image fit's free set)
      x[size_t(k)] = k < 10 ? T(v, k) : T(v);
    }
  }
  size_t i = 0;
  for (auto _ : state) {
    Rgb<T> direct, ibl;
    const size_t j = i++ & 63;
    EvaluateFlat<T>(m, x.data(), cs[j], direct, ibl, &ts[j]);
    benchmark::DoNotOptimize(direct);
    benchmark::DoNotOptimize(ibl);
  }
  state.SetItemsProcessed(int64_t(state.iterations()));
}

struct PreviewSet {
  std::string name;
  std::unique_ptr<render::PreviewCache> cache;
  bool sheen = false;  // woven: evaluate with a non-zero sheen colour (the full sheen path)
};

// The preset lobe `clothfit fit` writes for the fabric at `path` (an irawan fabric's far-field
// lobe with `nodes` nodes, a sadeghi fabric's microcylinder lobe), as a function of the summary's
// table_theta (0: none; the microcylinder lobe then gets the smallest table, 2).
std::function<yarn_lobe::FarField(int)> LobeDescriber(const std::string& path, int nodes = 8) {
  if (render::LoadFabric(path).model == "sadeghi")
    return [path](int theta) { return fit::MicrocylinderDescription(path, std::max(theta, 2)).lobe; };
  auto ff = std::make_shared<const fit::YarnFarField>(path);
  return [ff, nodes](int theta) { return ff->Description(nodes, theta); };
}

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
    render::IblEngine engine = render::IblEngine::kFilament;
    woven::IblMode woven_ibl = woven::IblMode::kSplit;
    int map_anisotropy = 0;  // > 0: weave maps (synthetic, below) with this max anisotropy
    const char* yarn_lobe_fabric = nullptr;  // the far-field yarn lobe of this irawan or sadeghi fabric
  };
  const Def defs[] = {{"full (direct+ibl+subsurface+shadows)", &scene, env.get(), true, true},
                      {"direct+ibl", &scene, env.get(), false, false},
                      {"direct only (no environment)", &scene, nullptr, false, false},
                      {"ibl only (no lights)", &no_lights, env.get(), false, false},
                      {"woven direct+ibl", &scene, env.get(), false, false},
                      {"woven direct+ibl, sheen on", &scene, env.get(), false, false},
                      // session 8: the engine web/ draws with (three.js PMREM); woven's yarn
                      // lobes by split sum or by FIS (default taps); frame cost vs cloth's
                      {"threejs: cloth direct+ibl", &scene, env.get(), false, false,
                       render::IblEngine::kThreejs},
                      {"threejs: woven direct+ibl, split", &scene, env.get(), false, false,
                       render::IblEngine::kThreejs},
                      {"threejs: woven direct+ibl, fis", &scene, env.get(), false, false,
                       render::IblEngine::kThreejs, woven::IblMode::kFis},
                      // session 9: weave maps, isotropic vs anisotropic filtering (16). The maps
                      // are sampled once per pixel at cache build (the build time printed above
                      // the table is where anisotropy costs); the frame evaluates the cached
                      // per-pixel weights, so the two frame costs should match.
                      {"threejs: woven direct+ibl, maps anisotropy 1", &scene, env.get(), false,
                       false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 1},
                      {"threejs: woven direct+ibl, maps anisotropy 16", &scene, env.get(), false,
                       false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 16},
                      // session 12: the far-field yarn lobe ("woven": {"yarn_lobe"}, the fit
                      // default for irawan fabrics): evaluated per light sample at cache build
                      // (printed above the table), its split sum cached per pixel: the frame
                      // evaluates cached values (web/ evaluates the quadrature per fragment)
                      {"threejs: woven direct+ibl, far-field lobe (canvas)", &scene, env.get(),
                       false, false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 0,
                       "fabrics/canvas.json"},
                      {"threejs: woven direct+ibl, far-field lobe (twill)", &scene, env.get(),
                       false, false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 0,
                       "fabrics/twill.json"},
                      // session 19: the microcylinder lobe of a sadeghi fabric (the same cached
                      // path; web/ evaluates it per fragment)
                      {"threejs: woven direct+ibl, microcylinder lobe (velvet)", &scene, env.get(),
                       false, false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 0,
                       "fabrics/velvet.json"},
                      {"threejs: woven direct+ibl, microcylinder lobe (satin)", &scene, env.get(),
                       false, false, render::IblEngine::kThreejs, woven::IblMode::kSplit, 0,
                       "fabrics/satin.json"}};
  // Synthetic maps for the map sets: 64 x 64 per period, 60 periods per uv unit (the canvas's),
  // a fixed pseudo-random pattern (the cost does not depend on the values).
  std::vector<float> level0(64 * 64 * render::WeaveMaps::kChannels);
  uint32_t h = 12345u;
  for (float& x : level0) {
    h = h * 1664525u + 1013904223u;
    x = 0.2f + float(h >> 8) / float(1u << 24);
  }
  const render::WeaveMaps base_maps = render::WeaveMaps::FromLevel0(64, 60.0, level0);
  for (const Def& d : defs) {
    render::PreviewOptions o;
    o.model = std::string_view(d.name).find("woven") != std::string_view::npos
                  ? render::ModelKind::kWoven
                  : render::ModelKind::kCloth;
    o.ibl_engine = d.engine;
    o.woven.ibl = d.woven_ibl;
    o.cloth.subsurface = d.sub;
    o.shadows = d.shadows;
    if (d.map_anisotropy > 0) {
      auto maps = std::make_shared<render::WeaveMaps>(base_maps);
      maps->anisotropy = d.map_anisotropy;
      o.weave_maps = maps;
    }
    if (d.yarn_lobe_fabric) {  // relative to the source tree's datasets/ (any working directory)
      const std::string path = std::string(CLOTHFIT_SOURCE_DATASETS) + "/" + d.yarn_lobe_fabric;
      render::MaterialPreset p = render::DefaultPreset(render::ModelKind::kWoven);
      p.yarn_lobe = std::make_shared<const yarn_lobe::FarField>(LobeDescriber(path, 16)(16));
      render::ApplyPresetYarnLobe(p, &o);
    }
    auto cache = render::PreviewCache::Build(*d.s, d.e, o);
    std::fprintf(stderr, "bench preview: cache '%s': %zu fabric pixels, %zu light samples, built in %.3f s\n",
                 d.name, cache->pixels.size(), cache->light_samples.size(), cache->build_seconds);
    PreviewSets().push_back(
        {d.name, std::move(cache), std::string_view(d.name).ends_with("sheen on")});
  }
}

template <typename T>
void BM_Preview(benchmark::State& state, const render::PreviewCache* cache, bool sheen) {
  // cloth: 10 parameters; woven: 17 (a canvas-like fit: the stage-1 fit has the sheen off, the
  // "sheen on" set uses the fitted canvas sheen (0.08, 0.03, 0.03); diffuse_roughness 0), the
  // first 10 differentiated. Sized by the table (session 19: 16-value arrays were written past
  // their end once woven had 17 parameters, and `bench preview` crashed).
  constexpr size_t kN = size_t(woven::kParameterCount);
  static_assert(kN >= 17);
  const bool woven = cache->options.model == render::ModelKind::kWoven;
  const std::array<double, kN> cloth_values{0.6, 0.4, 0.3, 0.8, 0.7, 0.6, 0.55, 0.2, 0.1, 0.05};
  std::array<double, kN> woven_values{0.47, 0.41, 0.31, 0.54, 0.51, 0.46, 0.6, 0.75, -9.0,
                                      0.54, 0.07, 1.6,  0.0,  0.0,  0.0,  0.6,  0.0};
  if (sheen) {
    woven_values[12] = 0.08;
    woven_values[13] = 0.03;
    woven_values[14] = 0.03;
  }
  const auto& values = woven ? woven_values : cloth_values;
  const int n = woven ? woven::kParameterCount : 10;
  std::array<T, kN> x{};
  for (int k = 0; k < n; ++k) {
    if constexpr (std::is_same_v<T, double>) {
      x[size_t(k)] = values[size_t(k)];
    } else {
      x[size_t(k)] = k < 10 ? T(values[size_t(k)], k) : T(values[size_t(k)]);
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
  std::string fabrics;  // empty: canvas,twill for the sweep; canvas,twill,velvet for --models
  std::string widths = "64,128,256,512";
  std::string strides = "0,1";
  std::string starts = "1,2,3";
  int spp = 64;
  std::string csv = "out/bench-fit.csv", png = "out/bench-fit.png";
  std::string models;  // non-empty: every listed model at the fit defaults (RunModelBench)
};

// `bench fit --models all|m1,m2`: each model fitted at the defaults of `clothfit fit --fabric`
// (card resolution, auto level and stride, the default starts) on the cached references; seconds,
// iterations and the common error side by side.
void RunBenchModels(const BenchFitArgs& a, bool quiet) {
  const char* env_root = std::getenv("CLOTHFIT_DATASETS");
  const std::string root = env_root ? env_root : CLOTHFIT_SOURCE_DATASETS;
  std::vector<render::ModelKind> models;
  if (a.models == "all") {
    models = {render::ModelKind::kCloth, render::ModelKind::kStandard,
              render::ModelKind::kPhysicalSheen, render::ModelKind::kGltfSheen,
              render::ModelKind::kWoven, render::ModelKind::kPhysicalAniso};  // every model clothfit fits
  } else {
    std::stringstream ms(a.models);
    std::string m;
    while (std::getline(ms, m, ',')) models.push_back(render::ParseModelKind(m));
  }
  const std::vector<std::string> paths = CanonicalScenes();
  std::vector<fit::ModelRow> all;
  std::printf("%-8s %-15s %8s %8s %6s %6s %9s %-15s\n", "fabric", "model", "seconds", "cpu s",
              "iters", "starts", "error", "termination");
  std::stringstream ss(a.fabrics.empty() ? std::string("canvas,twill,velvet") : a.fabrics);
  std::string name;
  while (std::getline(ss, name, ',')) {
    const std::string fabric_path = root + "/fabrics/" + name + ".json";
    const double weave_period = render::LoadFabric(fabric_path).weave_period_uv;
    std::vector<render::Scene> scenes;
    std::vector<fit::Reference> refs;
    std::vector<std::unique_ptr<render::Environment>> envs;
    for (const std::string& sp : paths) {
      scenes.push_back(render::LoadScene(sp));
      envs.push_back(LoadSceneEnvironment(scenes.back(), true));
      refs.push_back(fit::ReadReference(CachedReference(sp, fabric_path, a.spp, 1, quiet)));
    }
    std::vector<fit::SceneInput> in;
    for (size_t i = 0; i < paths.size(); ++i)
      in.push_back({&scenes[i], envs[i].get(), &refs[i], nullptr, paths[i]});
    const auto rows = fit::RunModelBench(name, in, weave_period, models, [](const fit::ModelRow& r) {
      std::printf("%-8s %-15s %8.2f %8.2f %6d %6d %9.5f %-15s%s\n", r.fabric.c_str(),
                  r.model.c_str(), r.seconds, r.cpu_seconds, r.iterations, r.starts, r.error, r.termination.c_str(),
                  r.usable ? "" : "  (unusable)");
      std::fflush(stdout);
    }, fabric_path);
    all.insert(all.end(), rows.begin(), rows.end());
  }
  const std::filesystem::path dir = std::filesystem::path(a.csv).parent_path();
  if (!dir.empty()) std::filesystem::create_directories(dir);
  fit::WriteModelBench(all, a.csv);
  std::printf("bench fit --models: %zu fits -> %s\n", all.size(), a.csv.c_str());
}

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
  std::stringstream ss(a.fabrics.empty() ? std::string("canvas,twill") : a.fabrics);
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
  int jobs = 0;         // -j/--jobs/--threads, every bench kind (0: all cores)
  bool quiet = false;   // -q/--quiet given after `bench` (the global flag is read too)
  BenchReferenceArgs reference;  // `bench reference` (bin/cmd_bench_reference.cpp)
};

// Every option with a default shows it in --help: CLI11's "=value" after the type, or the
// help text where the default depends on the bench kind.
void AddBenchOptions(CLI::App* cmd, BenchArgs& a) {
  BenchFitArgs& fa = a.fit;
  cmd->add_option("what", a.what, "what to benchmark: brdf | preview | fit | convert | reference")
      ->required()
      ->check(CLI::IsMember({"brdf", "preview", "fit", "convert", "reference"}));
  // bench passes the options it does not know to Google Benchmark (allow_extras below), so it
  // does not fall through to the global options: it takes -q/--quiet itself.
  cmd->fallthrough(false);
  cmd->add_flag("-q,--quiet", a.quiet, "no progress output on stderr (as the global -q)");
  cmd->add_option("--catalogue", a.catalogue,
                  "`bench convert`: catalogue directory (default: generate one in a temporary "
                  "directory with datasets/catalogue/generate.py)");
  cmd->add_option("--count", a.count, "`bench convert`: materials per input format when generating")
      ->check(CLI::Range(1, 100000))  // session 28: 0 and negative counts were accepted
      ->capture_default_str();
  // --threads: the name fit and render-* use; -j/--jobs kept (bench reference's --threads
  // before session 27 is this option now).
  cmd->add_option("-j,--jobs,--threads", a.jobs,
                  "worker threads of every bench kind: bench convert's conversions, bench "
                  "reference's two renderers, bench fit's and bench preview's TBB work (0: all "
                  "cores)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  cmd->add_option("--fabrics", fa.fabrics,
                  "`bench fit`: comma-separated fabric names (default canvas,twill; with "
                  "--models canvas,twill,velvet)");
  cmd->add_option("--widths", fa.widths, "`bench fit`: fit resolutions (image widths, px)")
      ->capture_default_str();
  cmd->add_option("--strides", fa.strides, "`bench fit`: pixel strides (0 = auto)")
      ->capture_default_str();
  cmd->add_option("--starts", fa.starts, "`bench fit`: multi-start counts (1-3)")
      ->capture_default_str();
  cmd->add_option("--spp", fa.spp,
                  "`bench fit`: reference samples per pixel (cached); `bench reference`: samples "
                  "per pixel of both renderers")
      ->check(CLI::Range(16, 65536))
      ->capture_default_str();
  cmd->add_option("--models", fa.models,
                  "`bench fit`: all | comma-separated models: each at the fit defaults, "
                  "seconds and error side by side (instead of the settings sweep)");
  cmd->add_option("--csv", fa.csv, "`bench fit`: output CSV")->capture_default_str();
  cmd->add_option("--png", fa.png, "`bench fit`: output plot (error vs time)")
      ->capture_default_str();
  cmd->add_option("--scene", a.scene, "scene card for `bench preview` and `bench reference`")
      ->capture_default_str();
  BenchReferenceArgs& ra = a.reference;
  ra.fabric = std::string(CLOTHFIT_SOURCE_DATASETS) + "/materials/lambert.json";
  ra.cycles_script = std::string(CLOTHFIT_SOURCE_DATASETS) + "/../scripts/cycles-reference";
  cmd->add_option("--fabric", ra.fabric,
                  "`bench reference`: fabric or simple material (lambert/ggx_conductor: vs Cycles; "
                  "woven: time to --target-error)")
      ->capture_default_str();
  cmd->add_option("--max-depth", ra.max_depth, "`bench reference`: maximum path depth")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--seed", ra.seed, "`bench reference`: seed (both renderers)")
      ->capture_default_str();
  cmd->add_option("--width", ra.width, "`bench reference`: image width (0: the card's)")
      ->check(CLI::Range(0, 8192))  // as render-references --width (session 28: -5 was the card's)
      ->capture_default_str();
  cmd->add_option("--target-error", ra.target_error,
                  "`bench reference`, woven: mean standard error / mean value to reach")
      ->check(CLI::Range(1e-4, 1.0))
      ->capture_default_str();
  cmd->add_option("--cycles-script", ra.cycles_script, "`bench reference`: scripts/cycles-reference")
      ->capture_default_str();
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
  // The far-field yarn lobe a woven fit bakes (fit --yarn-lobe defaults: 8 nodes, a 16 x 32
  // environment summary; session 14 made it 2-3x faster): the whole bake, and one lobe
  // evaluation (a light's read in the preview; wo fixed, as for one pixel's lights). Session 19
  // adds the microcylinder lobe of the sadeghi fabrics (its wi grid refined for narrow lobes).
  for (const char* fabric : {"canvas", "twill", "velvet", "linen", "satin"}) {
    const std::string path = std::string(CLOTHFIT_SOURCE_DATASETS) + "/fabrics/" + fabric + ".json";
    benchmark::RegisterBenchmark(("brdf/yarn-lobe-summary-bake/" + std::string(fabric)).c_str(),
                                 [path](benchmark::State& s) {
                                   const auto describe = LobeDescriber(path);  // (fabric loaded once)
                                   for (auto _ : s) benchmark::DoNotOptimize(describe(16));
                                 })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("brdf/yarn-lobe-eval/" + std::string(fabric)).c_str(),
                                 [path](benchmark::State& s) {
                                   const yarn_lobe::Lobe lobe(LobeDescriber(path)(0));
                                   const Vec3<double> wo = Normalize(Vec3<double>(0.3, 0.1, 0.9));
                                   Vec3<double> wi = Normalize(Vec3<double>(-0.4, 0.05, 0.8));
                                   double out[2];
                                   for (auto _ : s) {
                                     benchmark::DoNotOptimize(wi);
                                     lobe.Eval(wo, wi, out);
                                     benchmark::DoNotOptimize(out);
                                   }
                                 });
  }
}

// Needs BuildPreviewSets first.
void RegisterPreviewBenchmarks() {
  for (const PreviewSet& set : PreviewSets()) {
    const render::PreviewCache* c = set.cache.get();
    const bool sh = set.sheen;
    benchmark::RegisterBenchmark(("preview/" + set.name + "/double").c_str(),
                                 [c, sh](benchmark::State& s) { BM_Preview<double>(s, c, sh); })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("preview/" + set.name + "/jet10").c_str(),
                                 [c, sh](benchmark::State& s) { BM_Preview<Jet10>(s, c, sh); })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
  }
}

// Runs the registered benchmarks with the command's extra arguments; returns the exit status
// (1 when no benchmark matches --benchmark_filter: nothing timed is not a result).
int RunRegisteredBenchmarks(CLI::App* cmd) {
  std::vector<std::string> extras = cmd->remaining();
  std::vector<char*> argv{const_cast<char*>("clothfit-bench")};
  for (auto& e : extras) argv.push_back(e.data());
  int argc = int(argv.size());
  benchmark::Initialize(&argc, argv.data());
  if (benchmark::ReportUnrecognizedArguments(argc, argv.data())) return 1;
  // Debian's libbenchmark is built without NDEBUG, so its context block ends with "***WARNING***
  // Library was built as DEBUG. Timings may be affected." No flag or context entry turns that
  // line off (it is compiled into BenchmarkReporter::PrintBasicContext). This context entry,
  // printed just above it, says what it concerns: the timed loops are clothfit code compiled
  // into this binary (inline benchmark::State iteration included), with clothfit's flags.
#ifdef NDEBUG
  benchmark::AddCustomContext(
      "clothfit", "built Release (NDEBUG); a DEBUG warning below is about the system "
                  "libbenchmark's own build, not the timed clothfit code");
#else
  benchmark::AddCustomContext("clothfit", "built without NDEBUG (not Release): timings are not "
                                          "representative");
#endif
  const size_t ran = benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  if (ran == 0) {
    std::fprintf(stderr, "clothfit bench: error: no benchmark was run (--benchmark_filter "
                         "matches none; --benchmark_list_tests lists them)\n");
    return 1;
  }
  return 0;
}

// `clothfit bench` after parsing: returns the exit status.
int RunBench(CLI::App* cmd, const BenchArgs& a, const Globals& g) {
  const bool quiet = g.quiet || a.quiet;
  std::unique_ptr<tbb::global_control> limit;  // -j/--jobs/--threads for every kind
  if (a.jobs > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  size_t(a.jobs));
  (void)lut::DefaultDfg();  // tables are built once, outside the timed loops
  (void)lut::DefaultSheenAlbedo();
  // Errors name the file or flag; user paths in them are escaped.
  auto fail = [&a](const std::exception& e) {
    std::fprintf(stderr, "clothfit bench %s: error: %s\n", a.what.c_str(),
                 limits::EscapeForMessage(e.what(), 2000).c_str());
    return 1;
  };
  if (a.what == "convert") {
    try {
      return RunBenchConvert(a.catalogue, a.count, a.jobs, quiet);
    } catch (const std::exception& e) {
      return fail(e);
    }
  }
  if (a.what == "reference") {
    BenchReferenceArgs r = a.reference;
    r.scene = a.scene;
    if (cmd->count("--spp")) r.spp = a.fit.spp;  // else BenchReferenceArgs' (64, as bench fit's)
    r.threads = a.jobs;
    try {
      return RunBenchReference(r, quiet);
    } catch (const std::exception& e) {
      return fail(e);
    }
  }
  if (a.what == "fit") {
    try {
      if (!a.fit.models.empty())
        RunBenchModels(a.fit, quiet);
      else
        RunBenchFit(a.fit, quiet);
      return 0;
    } catch (const std::exception& e) {
      return fail(e);
    }
  }
  if (a.what == "brdf") {
    RegisterBrdfBenchmarks();
  } else {
    try {
      BuildPreviewSets(a.scene, quiet);
    } catch (const std::exception& e) {
      return fail(e);
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
