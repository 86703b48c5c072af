// render/scene/gltf_impl.cpp: the one translation unit that compiles tinygltf's implementation.
// Debian's libtinygltf-dev ships it as a header (README.Debian: define
// TINYGLTF_IMPLEMENTATION in exactly one .cpp); the configuration macros live in
// render/scene/gltf_tinygltf.h so that every includer sees the same class layout.
#define TINYGLTF_IMPLEMENTATION
#include "render/scene/gltf_tinygltf.h"

#include <cstring>
#include <filesystem>
#include <span>

#include "render/scene/input_limits.h"

namespace clothfit::render {
namespace {

// Image payloads are skipped: clothfit reads material factors and image URIs only.
bool SkipImage(tinygltf::Image*, const int, std::string*, std::string*, int, int,
               const unsigned char*, int, void*) {
  return true;
}

// External buffers: only regular files inside the policy's root (the glTF's own directory by
// default), read with the same bounded reader as everything else. tinygltf also searches the
// current directory; that candidate is refused unless it resolves inside the root.
struct FsPolicy {
  limits::PathPolicy policy;
  std::string refused;  // why the last candidate was refused (reported with the error)
};

bool PolicyFileExists(const std::string& path, void* user) {
  auto* p = static_cast<FsPolicy*>(user);
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  if (p->policy.allow_outside) return true;
  const auto canon = std::filesystem::weakly_canonical(path, ec);
  const auto root = std::filesystem::weakly_canonical(p->policy.root, ec);
  if (ec || !limits::IsInside(canon, root)) {
    p->refused = "buffer '" + limits::EscapeForMessage(path, 200) +
                 "' resolves outside the directory " +
                 limits::EscapeForMessage(p->policy.root.string(), 200);
    return false;
  }
  return true;
}

std::string IdentityExpand(const std::string& s, void*) { return s; }

bool BoundedReadWholeFile(std::vector<unsigned char>* out, std::string* err,
                          const std::string& path, void*) {
  try {
    const std::string d = limits::ReadFileBounded(path, limits::kMaxGltfBufferBytes, "glTF buffer");
    out->assign(d.begin(), d.end());
    return true;
  } catch (const std::exception& e) {
    *err += e.what();
    return false;
  }
}

bool RefuseWrite(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  *err += "clothfit never writes through tinygltf";
  return false;
}

std::string OneLine(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  for (char& c : s) c = c == '\n' ? ';' : c;
  return s;
}

}  // namespace

bool LoadGltfModelFromMemory(std::span<const unsigned char> bytes, const std::string& file,
                             const std::string& base_dir, const limits::PathPolicy* policy,
                             tinygltf::Model* model, std::string* err, std::string* warn) {
  static_cast<void>(file);  // the callers prefix `err` with the file name
  err->clear();
  warn->clear();
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  // tinygltf turns every extras/extensions value into a tinygltf::Value recursively, and
  // nlohmann copies recursively: the nesting is bounded on the bytes before either sees them.
  const std::string_view json =
      binary ? limits::GlbJsonChunk(bytes)
             : std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (const auto at = limits::FindJsonDepthExcess(json, limits::kMaxJsonDepth)) {
    *err = "JSON nested deeper than " + std::to_string(limits::kMaxJsonDepth) + " levels at byte " +
           std::to_string(*at + (binary ? 20 : 0)) + " " + limits::LimitRef("kMaxJsonDepth");
    return false;
  }
  if (bytes.size() > limits::kMaxGltfFileBytes) {
    *err = "file is " + std::to_string(bytes.size()) + " bytes, over the limit of " +
           std::to_string(limits::kMaxGltfFileBytes) + " " + limits::LimitRef("kMaxGltfFileBytes");
    return false;
  }
  FsPolicy fsp;
  fsp.policy.root = policy ? policy->root : std::filesystem::path(base_dir.empty() ? "." : base_dir);
  fsp.policy.allow_outside = policy && policy->allow_outside;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&SkipImage, nullptr);
  loader.SetFsCallbacks({&PolicyFileExists, &IdentityExpand, &BoundedReadWholeFile,
                         &RefuseWrite, &fsp});
  bool ok = false;
  try {
    ok = binary ? loader.LoadBinaryFromMemory(model, err, warn, bytes.data(),
                                              unsigned(bytes.size()), base_dir)
                : loader.LoadASCIIFromString(model, err, warn,
                                             reinterpret_cast<const char*>(bytes.data()),
                                             unsigned(bytes.size()), base_dir);
  } catch (const std::exception& e) {
    *err += e.what();
    ok = false;
  }
  if (ok) {
    size_t total = 0;
    for (size_t i = 0; i < model->buffers.size(); ++i) {
      total += model->buffers[i].data.size();  // each is at most the file or the read limit
      if (total > limits::kMaxGltfBufferBytes) {
        *err = "buffers[" + std::to_string(i) + "]: buffers hold more than " +
               std::to_string(limits::kMaxGltfBufferBytes) + " bytes in total " +
               limits::LimitRef("kMaxGltfBufferBytes");
        ok = false;
        break;
      }
    }
  }
  if (!fsp.refused.empty()) *err += (err->empty() ? "" : "; ") + fsp.refused;
  *err = limits::EscapeForMessage(OneLine(ok || !err->empty() ? *err : "unknown error"), 2000);
  *warn = limits::EscapeForMessage(OneLine(*warn), 2000);
  return ok;
}

bool LoadGltfModel(const std::string& file, tinygltf::Model* model, std::string* err,
                   std::string* warn, const limits::PathPolicy* policy) {
  std::string bytes;
  try {
    bytes = limits::ReadFileBounded(file, limits::kMaxGltfFileBytes, "glTF file");
  } catch (const limits::InputError& e) {
    *err = e.what();
    return false;
  }
  return LoadGltfModelFromMemory(
      std::span<const unsigned char>(reinterpret_cast<const unsigned char*>(bytes.data()),
                                     bytes.size()),
      file, std::filesystem::path(file).parent_path().string(), policy, model, err, warn);
}

}  // namespace clothfit::render
