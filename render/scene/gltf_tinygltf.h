// render/scene/gltf_tinygltf.h: includes tinygltf with this project's configuration. Every file
// that uses tinygltf includes this header (never <tiny_gltf.h> directly) so the macros below,
// which change the TinyGLTF class, agree in every translation unit.
//   TINYGLTF_NO_STB_IMAGE / _WRITE: no image codecs (stb is not a dependency); scenes use
//     material factors only, and the loader installs a callback that skips image payloads.
//   TINYGLTF_NO_EXTERNAL_IMAGE: external image files are not read.
// The implementation is compiled once, in render/scene/gltf_impl.cpp.
#pragma once

#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <span>
#include <string>

#include "render/scene/input_limits.h"

namespace clothfit::render {

// Loads a .gltf or .glb (chosen by content: the 4-byte magic "glTF", not the extension) with
// image payloads skipped. Returns false with `err` set on failure; `warn` gets tinygltf's
// warnings. Newlines in both are replaced by ';'. Never throws.
// Loads a .gltf or .glb (picked by the magic) with the input limits of docs/reliability.md:
// the file is read once with a size cap, JSON nesting is bounded before tinygltf parses it,
// external buffers are read only from inside `policy->root` (default: the glTF's directory)
// with a size cap, and the buffers' total is capped. `err` never holds raw untrusted bytes.
bool LoadGltfModel(const std::string& file, tinygltf::Model* model, std::string* err,
                   std::string* warn, const limits::PathPolicy* policy = nullptr);

// The same on bytes already in memory (`file` names them in messages; fuzz harnesses).
bool LoadGltfModelFromMemory(std::span<const unsigned char> bytes, const std::string& file,
                             const std::string& base_dir, const limits::PathPolicy* policy,
                             tinygltf::Model* model, std::string* err, std::string* warn);

}  // namespace clothfit::render
