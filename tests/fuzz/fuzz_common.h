// tests/fuzz/fuzz_common.h: what every libFuzzer harness checks (docs/reliability.md).
//
// A reader given arbitrary bytes may succeed or throw one of the project's documented error
// types (all std::runtime_error or std::invalid_argument with a message naming the file). It must
// not crash, hang or exhaust memory (libFuzzer's -timeout/-rss_limit_mb/-malloc_limit_mb and
// ASan/UBSan catch those), and these oracles trap on:
//   - std::bad_alloc, std::length_error, nlohmann::json::exception escaping a reader: the
//     input reached an allocation or a JSON accessor that should have been validated first;
//   - an error message that is not valid UTF-8 or carries control bytes (untrusted bytes
//     echoed raw).
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <new>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>

#include "render/scene/input_limits.h"

namespace clothfit::fuzz {

[[noreturn]] inline void Bug(const char* kind, const std::string& what) {
  std::fprintf(stderr, "fuzz oracle: %s: %s\n", kind,
               clothfit::limits::EscapeForMessage(what, 2000).c_str());
  std::abort();
}

inline void CheckMessage(const char* what) {
  const std::string_view m(what);
  if (!clothfit::limits::IsValidUtf8(m)) Bug("message is not valid UTF-8", std::string(m));
  for (unsigned char c : m)
    if ((c < 0x20 && c != '\n' && c != '\t') || c == 0x7F)
      Bug("message carries a control byte", std::string(m));
}

// Runs `f`, accepting success or a documented error; traps on anything else.
template <class F>
void Run(F&& f) {
  try {
    f();
  } catch (const std::bad_alloc& e) {
    Bug("std::bad_alloc escaped (allocation before validation)", e.what());
  } catch (const std::length_error& e) {
    Bug("std::length_error escaped", e.what());
  } catch (const nlohmann::json::exception& e) {
    Bug("nlohmann::json exception escaped (unchecked JSON access)", e.what());
  } catch (const std::exception& e) {
    CheckMessage(e.what());
  }
}

// A private scratch directory for this process (inputs are written to files because the
// readers' public entry points take paths).
inline const std::filesystem::path& Scratch() {
  static const std::filesystem::path d = [] {
    const char* base = std::getenv("CLOTHFIT_FUZZ_TMP");
    std::filesystem::path p = std::filesystem::path(base ? base : "/tmp") /
                              ("clothfit-fuzz-" + std::to_string(::getpid()));
    std::filesystem::create_directories(p);
    return p;
  }();
  return d;
}

inline std::string WriteInput(const std::string& name, const uint8_t* data, size_t size) {
  const std::string path = (Scratch() / name).string();
  std::ofstream o(path, std::ios::binary | std::ios::trunc);
  o.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return path;
}

inline std::string DatasetsDir() { return CLOTHFIT_FUZZ_DATASETS; }

}  // namespace clothfit::fuzz
