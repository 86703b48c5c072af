// render/reference/fabric.h: fabric definitions (JSON) for the reference renderer.
//
// A fabric file names a woven-cloth model and its preset (schema in docs/woven-cloth.md):
//   {
//     "format": "clothfit-fabric", "version": 1,
//     "name": "canvas",
//     "model": "irawan" | "sadeghi",
//     "preset": "cotton_canvas",          // irawan: a weave file stem, sadeghi: a fabric name
//     "weave_file": "../weaves/x.weave",  // optional, irawan only; relative to this file;
//                                         // default "../weaves/<preset>.weave"
//     "uv_repeats": 40                    // weave tiles per UV unit, (0, 10000]
//   }
// or a simple material (render/reference/simple_bsdf.h; no preset, weave_file or uv_repeats),
// which renders identically in Blender Cycles (scripts/cycles-reference):
//   {"format": "clothfit-fabric", "version": 1, "name": "grey", "model": "lambert",
//    "albedo": [0.5, 0.5, 0.5]}
//   {"format": "clothfit-fabric", "version": 1, "name": "gold", "model": "ggx_conductor",
//    "colour": [1.0, 0.78, 0.34], "roughness": 0.4}    // roughness as Cycles' node: alpha = r^2
// Unknown fields are rejected. Errors throw FabricError naming the file and the field (JSON
// syntax errors give the line and column); weave-file errors keep their file:line.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

#include "render/reference/bsdf.h"

namespace clothfit::render {

class FabricError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Fabric {
  std::string name, model, preset;
  double uv_repeats = 1.0;  // weave repeats per UV unit (both u and v)
  std::unique_ptr<Bsdf> bsdf;
  double weave_period_uv = 1.0;  // size of one weave tile in uv units (= 1 / uv_repeats)
  // irawan: the .weave file that was read ('weave_file', else ../weaves/<preset>.weave, relative
  // to the fabric file; lexically normalised); empty for the other models. A content key of a
  // render must hash this file (session 28: the reference cache hashed ../weaves/<preset>.weave
  // even when 'weave_file' named another file, and reused references after it changed).
  std::string weave_path;
};

Fabric LoadFabric(const std::string& path);
// Parses fabric JSON text; `path` names the file in errors and anchors relative paths.
Fabric ParseFabric(const std::string& text, const std::string& path);

}  // namespace clothfit::render
