// render/scene/gltf_impl.cpp: the one translation unit that compiles tinygltf's implementation.
// Debian's libtinygltf-dev ships it as a header (README.Debian: define
// TINYGLTF_IMPLEMENTATION in exactly one .cpp); the configuration macros live in
// render/scene/gltf_tinygltf.h so that every includer sees the same class layout.
#define TINYGLTF_IMPLEMENTATION
#include "render/scene/gltf_tinygltf.h"

#include <cstring>
#include <fstream>

namespace clothfit::render {
namespace {

// Image payloads are skipped: clothfit reads material factors and image URIs only.
bool SkipImage(tinygltf::Image*, const int, std::string*, std::string*, int, int,
               const unsigned char*, int, void*) {
  return true;
}

std::string OneLine(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  for (char& c : s) c = c == '\n' ? ';' : c;
  return s;
}

}  // namespace

bool LoadGltfModel(const std::string& file, tinygltf::Model* model, std::string* err,
                   std::string* warn) {
  bool binary = false;
  {
    std::ifstream in(file, std::ios::binary);
    if (!in) {
      *err = "cannot open " + file;
      return false;
    }
    char magic[4] = {0, 0, 0, 0};
    in.read(magic, 4);
    binary = in.gcount() == 4 && std::memcmp(magic, "glTF", 4) == 0;
  }
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&SkipImage, nullptr);
  bool ok = false;
  try {
    ok = binary ? loader.LoadBinaryFromFile(model, err, warn, file)
                : loader.LoadASCIIFromFile(model, err, warn, file);
  } catch (const std::exception& e) {
    *err += e.what();
    ok = false;
  }
  *err = OneLine(ok || !err->empty() ? *err : "unknown error");
  *warn = OneLine(*warn);
  return ok;
}

}  // namespace clothfit::render
