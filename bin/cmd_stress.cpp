// clothfit stress: values and Jet derivatives of every model over random and adversarial
// inputs; exit status 1 when anything is non-finite or negative.
#include <cstdio>

#include "bin/commands.h"
#include "bin/progress.h"
#include "brdf/stress.h"

namespace clothfit::cli {

void AddStressCommand(CLI::App& app, const Globals& g, int& exit_code) {
  struct Args {
    long long evals = 1000000;
    unsigned long long seed = 1;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "stress", "evaluate every model (double, float, Jet) on random and adversarial inputs");
  // --help shows each default ("=64"), as bench does (session 28: it showed none).
  cmd->option_defaults()->always_capture_default();
  cmd->add_option("--evals", args->evals, "total evaluations, split across models")
      ->check(CLI::Range(1LL, 10000000000LL));
  cmd->add_option("--seed", args->seed, "random seed (results are deterministic per seed)");
  cmd->callback([args, &g, &exit_code]() {
    ProgressBar bar("stress", g.quiet);
    const stress::Report r =
        stress::Run(args->evals, args->seed, [&](int64_t d, int64_t t) { bar.Update(d, t); });
    std::printf("%-28s %12s %10s %10s %14s\n", "model", "evaluations", "non-finite", "negative",
                "max rel f-dev");
    for (const auto& m : r.models) {
      std::printf("%-28s %12lld %10lld %10lld %14.3g\n", m.model.c_str(), (long long)m.evaluations,
                  (long long)m.non_finite, (long long)m.negative, m.max_rel_float_dev);
      if (m.max_rel_float_dev > 1e-3) std::printf("  %s\n", m.worst_float_deviation.c_str());
      if (!m.first_failure.empty()) std::printf("  first failure: %s\n", m.first_failure.c_str());
    }
    std::printf("stress: %lld evaluations, %lld non-finite, %lld negative\n",
                (long long)r.evaluations, (long long)r.non_finite, (long long)r.negative);
    exit_code = (r.non_finite > 0 || r.negative > 0) ? 1 : 0;
  });
}

}  // namespace clothfit::cli
