// render/gltf_tinygltf.h: includes tinygltf with this project's configuration. Every file
// that uses tinygltf includes this header (never <tiny_gltf.h> directly) so the macros below,
// which change the TinyGLTF class, agree in every translation unit.
//   TINYGLTF_NO_STB_IMAGE / _WRITE: no image codecs (stb is not a dependency); scenes use
//     material factors only, and the loader installs a callback that skips image payloads.
//   TINYGLTF_NO_EXTERNAL_IMAGE: external image files are not read.
// The implementation is compiled once, in render/gltf_impl.cpp.
#pragma once

#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>
