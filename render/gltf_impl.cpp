// render/gltf_impl.cpp: the one translation unit that compiles tinygltf's implementation.
// Debian's libtinygltf-dev ships it as a header (README.Debian: define
// TINYGLTF_IMPLEMENTATION in exactly one .cpp); the configuration macros live in
// render/gltf_tinygltf.h so that every includer sees the same class layout.
#define TINYGLTF_IMPLEMENTATION
#include "render/gltf_tinygltf.h"
