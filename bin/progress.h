// bin/progress.h: a one-line progress bar on stderr (when stderr is a terminal, unless
// CLOTHFIT_PROGRESS=0; always with CLOTHFIT_PROGRESS=1), with rate and ETA. Silent under --quiet.
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace clothfit::cli {

class ProgressBar {
 public:
  ProgressBar(std::string label, bool quiet)
      : label_(std::move(label)),
        enabled_(!quiet && Wanted()),
        start_(std::chrono::steady_clock::now()) {}

  void Update(long long done, long long total) {
    if (!enabled_ || total <= 0) return;
    const auto now = std::chrono::steady_clock::now();
    if (done < total && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    const double secs = std::chrono::duration<double>(now - start_).count();
    const double frac = double(done) / double(total);
    const double rate = secs > 0 ? double(done) / secs : 0.0;
    const double eta = rate > 0 ? double(total - done) / rate : 0.0;
    const int width = 30;
    const int filled = int(frac * width);
    std::fprintf(stderr, "\r%s [%.*s%*s] %5.1f%%  %.3g/s  ETA %.0fs ", label_.c_str(), filled,
                 "##############################", width - filled, "", 100.0 * frac, rate, eta);
    if (done >= total) std::fprintf(stderr, "\n");
    std::fflush(stderr);
  }

 private:
  // CLOTHFIT_PROGRESS=1 forces the bar, =0 (or empty) turns it off even on a terminal; unset:
  // on a terminal only. (Before session 28 any value, "0" included, turned it on.)
  static bool Wanted() {
    const char* env = std::getenv("CLOTHFIT_PROGRESS");
    if (env == nullptr) return isatty(2) != 0;
    return std::string(env) != "0" && *env != '\0';
  }

  std::string label_;
  bool enabled_;
  std::chrono::steady_clock::time_point start_, last_{};
};

}  // namespace clothfit::cli
