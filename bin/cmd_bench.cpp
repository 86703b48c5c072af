// clothfit bench brdf: Google Benchmark of every model, ns per evaluation of the direct
// term plus the IBL weights, in double and with a ceres::Jet of 10 parameters.
// Extra arguments go to Google Benchmark (e.g. clothfit bench brdf --benchmark_format=json).
#include <benchmark/benchmark.h>
#include <ceres/jet.h>

#include <array>
#include <cstdio>
#include <string>
#include <vector>

#include "bin/commands.h"
#include "brdf/models.h"

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

}  // namespace

void AddBenchCommand(CLI::App& app, const Globals&, int& exit_code) {
  auto what = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand("bench", "benchmarks (Google Benchmark)");
  cmd->add_option("what", *what, "what to benchmark: brdf")
      ->required()
      ->check(CLI::IsMember({"brdf"}));
  cmd->allow_extras();
  cmd->callback([cmd, what, &exit_code]() {
    (void)lut::DefaultDfg();  // tables are built once, outside the timed loops
    (void)lut::DefaultSheenAlbedo();
    for (ModelId m : kAllModels) {
      const std::string name(ModelName(m));
      benchmark::RegisterBenchmark(("brdf/" + name + "/double").c_str(),
                                   [m](benchmark::State& s) { BM_Model<double>(s, m); });
      benchmark::RegisterBenchmark(("brdf/" + name + "/jet10").c_str(),
                                   [m](benchmark::State& s) { BM_Model<Jet10>(s, m); });
    }
    std::vector<std::string> extras = cmd->remaining();
    std::vector<char*> argv{const_cast<char*>("clothfit-bench")};
    for (auto& e : extras) argv.push_back(e.data());
    int argc = int(argv.size());
    benchmark::Initialize(&argc, argv.data());
    if (benchmark::ReportUnrecognizedArguments(argc, argv.data())) {
      exit_code = 1;
      return;
    }
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    exit_code = 0;
  });
}

}  // namespace clothfit::cli
