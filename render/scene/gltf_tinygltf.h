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

#include <string>

namespace clothfit::render {

// Loads a .gltf or .glb (chosen by content: the 4-byte magic "glTF", not the extension) with
// image payloads skipped. Returns false with `err` set on failure; `warn` gets tinygltf's
// warnings. Newlines in both are replaced by ';'. Never throws.
bool LoadGltfModel(const std::string& file, tinygltf::Model* model, std::string* err,
                   std::string* warn);

}  // namespace clothfit::render
