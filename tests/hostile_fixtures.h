// tests/hostile_fixtures.h: the reproducers of issue 14 (tests/fuzz/regressions/
// fuzz-crashers.tar.gz), unpacked once per test process into a temporary directory.
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace clothfit::testing {

inline std::filesystem::path SourceDir() { return CLOTHFIT_TEST_SOURCE_DIR; }

// Directory holding the unpacked reproducer folders (one per defect find).
inline const std::filesystem::path& Reproducers() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = std::filesystem::temp_directory_path() /
                                    ("clothfit_repro_" + std::to_string(::getpid()));
    std::filesystem::remove_all(d);
    std::filesystem::create_directories(d);
    const std::string cmd = "tar xzf '" +
                            (SourceDir() / "tests/fuzz/regressions/fuzz-crashers.tar.gz").string() +
                            "' -C '" + d.string() + "'";
    if (std::system(cmd.c_str()) != 0) throw std::runtime_error("cannot unpack: " + cmd);
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(std::filesystem::temp_directory_path() /
                                      ("clothfit_repro_" + std::to_string(::getpid())),
                                  ec);
    });
    return d;
  }();
  return dir;
}

inline std::string Repro(const std::string& rel) { return (Reproducers() / rel).string(); }

// A fresh scratch directory for one test.
inline std::filesystem::path Scratch(const std::string& name) {
  const std::filesystem::path d = std::filesystem::temp_directory_path() /
                                  ("clothfit_hostile_" + std::to_string(::getpid()) + "_" + name);
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

}  // namespace clothfit::testing
