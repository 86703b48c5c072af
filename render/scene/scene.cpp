// render/scene/scene.cpp: scene cards (JSON, docs/scene-card.md) and glTF 2.0 scenes (tinygltf).
//
// Card: parsed with nlohmann::json; every field is type- and range-checked, unknown fields are
// rejected (a typo must not silently fall back to a default), and every error names the card
// file and the field (JSON syntax errors: file, line and column).
//
// glTF: the default scene's node hierarchy is flattened into world space (TRS or matrix);
// every triangle primitive becomes one Mesh. Repairs, each reported in Scene::warnings:
//   - no NORMAL: smooth normals, the area-weighted average of the adjacent face normals over
//     shared vertex indices (an unindexed mesh therefore gets flat normals);
//   - no TANGENT: per-vertex accumulation of each triangle's dP/du and dP/dv (the same idea as
//     MikkTSpace without its vertex splitting): t = normalize(Gram-Schmidt(sum dP/du)),
//     w = sign(dot(cross(n, t), -sum dP/dv)), so cross(n, t) * w points towards decreasing
//     glTF v (the texture's "up", what MikkTSpace yields for glTF's v-down UVs);
//   - no TEXCOORD_0 on a non-fabric mesh: UVs (0, 0) (tangents then any unit vector
//     orthogonal to n). On the fabric mesh a missing TEXCOORD_0 is an error.
// A negative-determinant node transform flips the triangle winding (glTF 2.0 3.7.4), so the
// indices are reordered to keep counter-clockwise front faces in world space.
#include "render/scene/scene.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "render/scene/gltf_tinygltf.h"
#include "render/scene/input_limits.h"

namespace clothfit::render {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;
using V3 = std::array<double, 3>;

constexpr int kSchemaVersion = 1;
constexpr int kMaxImageSize = 16384;
constexpr const char* kToneMappings[] = {"Linear",     "Reinhard", "Cineon",
                                         "ACESFilmic", "AgX",      "Neutral"};

// ---------------------------------------------------------------------------------------------
// Small vector helpers.

V3 Add(const V3& a, const V3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
V3 Sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 Scale(const V3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
double Dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 Cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double Length(const V3& a) { return std::sqrt(Dot(a, a)); }
bool Finite(const V3& a) {
  return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]);
}
// Unit vector, or `fallback` when `a` is (nearly) zero or not finite.
V3 NormalizeOr(const V3& a, const V3& fallback) {
  const double len = Length(a);
  if (!(len > 1e-30) || !std::isfinite(len)) return fallback;
  return Scale(a, 1.0 / len);
}
// Any unit vector orthogonal to the unit vector n.
V3 AnyOrthogonal(const V3& n) {
  const V3 h = std::abs(n[0]) < 0.9 ? V3{1, 0, 0} : V3{0, 1, 0};
  return NormalizeOr(Sub(h, Scale(n, Dot(n, h))), {0, 0, 1});
}
std::array<float, 3> ToFloat(const V3& a) {
  return {static_cast<float>(a[0]), static_cast<float>(a[1]), static_cast<float>(a[2])};
}
V3 ToDouble(const std::array<float, 3>& a) { return {double(a[0]), double(a[1]), double(a[2])}; }

// Column-major 4x4 affine transform (glTF's layout).
struct Mat4 {
  std::array<double, 16> m{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  double& operator()(int row, int col) { return m[col * 4 + row]; }
  double operator()(int row, int col) const { return m[col * 4 + row]; }
};

Mat4 Mul(const Mat4& a, const Mat4& b) {
  Mat4 r;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a(i, k) * b(k, j);
      r(i, j) = s;
    }
  }
  return r;
}
V3 TransformPoint(const Mat4& a, const V3& p) {
  V3 r;
  for (int i = 0; i < 3; ++i) r[i] = a(i, 0) * p[0] + a(i, 1) * p[1] + a(i, 2) * p[2] + a(i, 3);
  return r;
}
V3 TransformVector(const Mat4& a, const V3& v) {
  V3 r;
  for (int i = 0; i < 3; ++i) r[i] = a(i, 0) * v[0] + a(i, 1) * v[1] + a(i, 2) * v[2];
  return r;
}
double Det3(const Mat4& a) {
  return a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)) -
         a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0)) +
         a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0));
}
// Cofactor matrix of the linear part: cof(A) = det(A) A^-T, so cof(A) n has the direction of
// the correctly transformed normal up to the sign of det(A).
Mat4 Cofactor3(const Mat4& a) {
  Mat4 c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      c(i, j) = a(i1, j1) * a(i2, j2) - a(i1, j2) * a(i2, j1);
    }
  }
  return c;
}

// ---------------------------------------------------------------------------------------------
// Errors.

[[noreturn]] void Fail(const std::string& file, const std::string& where, const std::string& msg) {
  throw SceneError(file + ": " + where + ": " + msg);
}

std::string Quote(const std::string& s) { return "'" + limits::EscapeForMessage(s, 80) + "'"; }

// A world-space point must lie within +-kMaxWorldCoordinate (this also refuses NaN): beyond
// it float conversion overflows and Embree rejects the rays (docs/reliability.md).
void CheckWorldPoint(const std::string& file, const std::string& where, const V3& p) {
  for (double x : p) {
    if (!(std::abs(x) <= limits::kMaxWorldCoordinate)) {
      std::ostringstream s;
      s << "is at (" << p[0] << ", " << p[1] << ", " << p[2]
        << ") in world space, outside +-1e+06 scene units " << limits::LimitRef("kMaxWorldCoordinate");
      Fail(file, where, s.str());
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Scene card.

std::string ReadText(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw SceneError(path + ": " + what + " not found");
  if (!fs::is_regular_file(path, ec)) throw SceneError(path + ": " + what + " is not a file");
  try {  // size checked on the open descriptor before reading (docs/reliability.md)
    return limits::ReadFileBounded(path, limits::kMaxJsonFileBytes, what);
  } catch (const limits::InputError& e) {
    throw SceneError(e.what());
  }
}

// Validates the fields of one JSON object; `prefix` is the dotted path of the object.
class FieldReader {
 public:
  FieldReader(const std::string& file, const Json& object, std::string prefix)
      : file_(file), object_(object), prefix_(std::move(prefix)) {}

  bool Has(const char* key) const { return object_.contains(key) && !object_[key].is_null(); }

  std::string Name(const char* key) const { return "field " + Quote(prefix_ + key); }

  [[noreturn]] void Bad(const char* key, const std::string& msg) const {
    Fail(file_, Name(key), msg);
  }

  // A short description of an untrusted value: never recursive (a deep value would overflow
  // the stack in dump()), never raw bytes.
  static std::string Show(const Json& v) {
    if (v.is_object()) return "an object (" + std::to_string(v.size()) + " keys)";
    if (v.is_array()) return "an array (" + std::to_string(v.size()) + " elements)";
    if (v.is_string())
      return "a string \"" + limits::EscapeForMessage(v.get_ref<const std::string&>(), 40) + "\"";
    return v.dump();  // a number, boolean or null: flat and ASCII
  }

  std::string String(const char* key, const std::string& fallback, bool required) const {
    if (!Has(key)) {
      if (required) Bad(key, "missing (required string)");
      return fallback;
    }
    const Json& v = object_[key];
    if (!v.is_string()) Bad(key, "expected a string, got " + Show(v));
    return v.get<std::string>();
  }

  int Int(const char* key, int fallback, int lo, int hi, bool required = false) const {
    if (!Has(key)) {
      if (required) Bad(key, "missing (required integer)");
      return fallback;
    }
    const Json& v = object_[key];
    if (!v.is_number_integer()) Bad(key, "expected an integer, got " + Show(v));
    const bool in_range = v.is_number_unsigned() ? v.get<uint64_t>() <= static_cast<uint64_t>(hi)
                                                 : v.get<int64_t>() >= lo && v.get<int64_t>() <= hi;
    if (!in_range || v.get<int64_t>() < lo) {
      Bad(key,
          "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " + Show(v));
    }
    return static_cast<int>(v.get<int64_t>());
  }

  // A finite number in [lo, hi] (lo excluded when lo_open).
  double Number(const char* key, double fallback, double lo, double hi, bool lo_open,
                const char* range_text) const {
    if (!Has(key)) return fallback;
    return CheckNumber(object_[key], key, lo, hi, lo_open, range_text);
  }

  double CheckNumber(const Json& v, const char* key, double lo, double hi, bool lo_open,
                     const char* range_text) const {
    if (!v.is_number()) Bad(key, "expected a number, got " + Show(v));
    const double x = v.get<double>();
    if (!std::isfinite(x) || x < lo || x > hi || (lo_open && x == lo)) {
      Bad(key, std::string("must be a finite number ") + range_text + ", got " + Show(v));
    }
    return x;
  }

  // Rejects any key not in `known`, listing the valid ones.
  void RejectUnknown(std::initializer_list<const char*> known) const {
    for (const auto& item : object_.items()) {
      const std::string& key = item.key();
      const bool ok =
          std::any_of(known.begin(), known.end(), [&](const char* k) { return key == k; });
      if (!ok) {
        std::string list;
        for (const char* k : known) list += std::string(list.empty() ? "" : ", ") + k;
        Fail(file_, "field " + Quote(prefix_ + key),
             "unknown field (schema version " + std::to_string(kSchemaVersion) +
                 " fields: " + list + ")");
      }
    }
  }

  const Json& object() const { return object_; }
  const std::string& file() const { return file_; }

 private:
  const std::string& file_;
  const Json& object_;
  std::string prefix_;
};

// Line and column (1-based) of the character at 0-based `offset` in `text`.
std::pair<size_t, size_t> LineColumn(const std::string& text, size_t offset) {
  offset = std::min(offset, text.size());
  size_t line = 1, column = 1;
  for (size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return {line, column};
}

// The data cache root: $CLOTHFIT_DATA, else ~/.cache/clothfit.
fs::path DataRoot() {
  if (const char* env = std::getenv("CLOTHFIT_DATA"); env != nullptr && *env != '\0') {
    return fs::path(env);
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    return fs::path(home) / ".cache" / "clothfit";
  }
  return fs::path("~") / ".cache" / "clothfit";
}

// Resolves the card's environment "path" (docs/scene-card.md, "Environment").
void ResolveEnvironment(const std::string& file, const fs::path& card_dir, EnvironmentSpec& env) {
  const std::string& name = env.name;
  if (name.empty()) Fail(file, "field 'environment.path'", "must not be empty");
  if (name == "procedural-sky") {
    env.path = name;
    env.found = true;
    return;
  }
  std::error_code ec;
  const bool is_name = name.find('/') == std::string::npos && !fs::path(name).has_extension();
  if (!is_name) {
    fs::path p = fs::path(name);
    if (p.is_relative()) p = card_dir / p;
    env.path = p.lexically_normal().string();
    env.found = fs::is_regular_file(env.path, ec);
    env.is_file = true;
    return;
  }
  const fs::path dir = DataRoot() / "hdri";
  for (const char* ext : {".exr", ".hdr"}) {
    const fs::path p = dir / (name + ext);
    if (fs::is_regular_file(p, ec)) {
      env.path = p.lexically_normal().string();
      env.found = true;
      return;
    }
  }
  env.path = (dir / (name + ".exr")).lexically_normal().string();
  env.found = false;
}

// ---------------------------------------------------------------------------------------------
// glTF.

struct GltfContext {
  const std::string& file;  // the glTF path, for messages
  const tinygltf::Model& model;
};

// Validates an accessor's bufferView and buffer bounds for elements of `elem` bytes and
// returns the address of its first element and its stride (the caller handles
// acc.bufferView < 0, which glTF defines as all zeros).
const unsigned char* AccessorData(const GltfContext& g, const tinygltf::Model& model,
                                  const tinygltf::Accessor& acc, size_t elem,
                                  const std::string& where, const std::string& what,
                                  size_t* stride_out) {
  if (acc.bufferView < 0 || acc.bufferView >= static_cast<int>(model.bufferViews.size())) {
    Fail(g.file, where, what + ": bufferView index out of range");
  }
  const std::string vw = "bufferViews[" + std::to_string(acc.bufferView) + "]";
  const tinygltf::BufferView& view = model.bufferViews[static_cast<size_t>(acc.bufferView)];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) {
    Fail(g.file, vw, "buffer index out of range");
  }
  const std::vector<unsigned char>& data = model.buffers[static_cast<size_t>(view.buffer)].data;
  // Every sum and product is checked: offsets near 2^64 must not wrap past the tests.
  const size_t size = data.size();
  if (view.byteOffset > size || view.byteLength > size - view.byteOffset) {
    Fail(g.file, vw,
         "byteOffset " + std::to_string(view.byteOffset) + " + byteLength " +
             std::to_string(view.byteLength) + " runs past the end of buffers[" +
             std::to_string(view.buffer) + "] (" + std::to_string(size) + " bytes)");
  }
  const size_t stride = view.byteStride != 0 ? view.byteStride : elem;
  if (stride < elem) {
    Fail(g.file, where, what + ": byteStride " + std::to_string(stride) +
                            " is smaller than one element (" + std::to_string(elem) + " bytes)");
  }
  if (acc.count > 0) {
    auto need = limits::CheckedMul(stride, acc.count - 1);
    if (need) need = limits::CheckedAdd(*need, elem);
    if (need) need = limits::CheckedAdd(*need, acc.byteOffset);
    if (!need || *need > view.byteLength) {
      Fail(g.file, where,
           what + ": count " + std::to_string(acc.count) + " x stride " + std::to_string(stride) +
               " from byteOffset " + std::to_string(acc.byteOffset) + " runs past the end of " +
               vw + " (" + std::to_string(view.byteLength) + " bytes)");
    }
  } else if (acc.byteOffset > view.byteLength) {
    Fail(g.file, where, what + ": byteOffset past the end of " + vw);
  }
  *stride_out = stride;
  return data.data() + view.byteOffset + acc.byteOffset;
}

std::string MeshWhere(const tinygltf::Model& model, int mesh, int prim) {
  const std::string& name = model.meshes[mesh].name;
  return "mesh " + Quote(name.empty() ? "mesh" + std::to_string(mesh) : name) + " (meshes[" +
         std::to_string(mesh) + "].primitives[" + std::to_string(prim) + "])";
}

// Reads accessor `index` as floats, `comps` per element. FLOAT data always; with
// `allow_normalized`, also normalized (U)BYTE/(U)SHORT (glTF allows them for TEXCOORD_n).
// `max_count`: the element budget (the vertex limit for POSITION); with `exact`, the count must
// equal it (NORMAL, TEXCOORD_0, TANGENT against POSITION). Checked before allocating.
std::vector<float> ReadFloats(const GltfContext& g, const std::string& where, const char* attr,
                              int index, int comps, bool allow_normalized, size_t max_count,
                              bool exact) {
  const auto& model = g.model;
  const std::string what = std::string(attr) + " (accessors[" + std::to_string(index) + "])";
  if (index < 0 || index >= static_cast<int>(model.accessors.size())) {
    Fail(g.file, where,
         std::string(attr) + ": accessor index " + std::to_string(index) + " out of range");
  }
  const tinygltf::Accessor& acc = model.accessors[index];
  if (acc.sparse.isSparse) Fail(g.file, where, what + ": sparse accessors are not supported");
  if (tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc.type)) != comps) {
    Fail(g.file, where, what + ": expected " + std::to_string(comps) + " components per element");
  }
  const int ct = acc.componentType;
  const bool is_float = ct == TINYGLTF_COMPONENT_TYPE_FLOAT;
  const bool is_norm = allow_normalized && acc.normalized &&
                       (ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                        ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
                        ct == TINYGLTF_COMPONENT_TYPE_BYTE || ct == TINYGLTF_COMPONENT_TYPE_SHORT);
  if (!is_float && !is_norm) {
    Fail(g.file, where,
         what + ": unsupported component type " + std::to_string(ct) +
             (allow_normalized ? " (expected FLOAT or normalized integers)" : " (expected FLOAT)"));
  }
  const size_t csize =
      static_cast<size_t>(tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(ct)));
  const size_t elem = csize * static_cast<size_t>(comps);
  if (exact && acc.count != max_count) {
    Fail(g.file, where,
         what + ": count " + std::to_string(acc.count) + " differs from POSITION's " +
             std::to_string(max_count));
  }
  if (acc.count > max_count) {
    Fail(g.file, where,
         what + ": count " + std::to_string(acc.count) + " exceeds the limit of " +
             std::to_string(max_count) + " vertices per scene " +
             limits::LimitRef("kMaxSceneVertices"));
  }
  if (acc.bufferView < -1) Fail(g.file, where, what + ": bufferView index out of range");
  const unsigned char* base = nullptr;
  size_t stride = 0;
  if (acc.bufferView >= 0) base = AccessorData(g, model, acc, elem, where, what, &stride);
  std::vector<float> out(acc.count * static_cast<size_t>(comps), 0.0f);  // count bounded above
  if (base == nullptr) return out;  // glTF: no bufferView means all zeros
  for (size_t i = 0; i < acc.count; ++i) {
    const unsigned char* src = base + i * stride;
    for (int c = 0; c < comps; ++c) {
      const unsigned char* p = src + static_cast<size_t>(c) * csize;
      float v = 0.0f;
      switch (ct) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: std::memcpy(&v, p, 4); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: v = static_cast<float>(*p) / 255.0f; break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          uint16_t u;
          std::memcpy(&u, p, 2);
          v = static_cast<float>(u) / 65535.0f;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          int8_t s;
          std::memcpy(&s, p, 1);
          v = std::max(static_cast<float>(s) / 127.0f, -1.0f);
          break;
        }
        default: {  // SHORT
          int16_t s;
          std::memcpy(&s, p, 2);
          v = std::max(static_cast<float>(s) / 32767.0f, -1.0f);
          break;
        }
      }
      if (!std::isfinite(v)) Fail(g.file, where, what + ": non-finite value");
      out[i * static_cast<size_t>(comps) + static_cast<size_t>(c)] = v;
    }
  }
  return out;
}

std::vector<uint32_t> ReadIndices(const GltfContext& g, const std::string& where, int index) {
  const auto& model = g.model;
  const std::string what = "indices (accessors[" + std::to_string(index) + "])";
  if (index < 0 || index >= static_cast<int>(model.accessors.size())) {
    Fail(g.file, where, what + ": accessor index out of range");
  }
  const tinygltf::Accessor& acc = model.accessors[index];
  if (acc.sparse.isSparse) Fail(g.file, where, what + ": sparse accessors are not supported");
  if (acc.type != TINYGLTF_TYPE_SCALAR) Fail(g.file, where, what + ": expected SCALAR");
  const int ct = acc.componentType;
  size_t csize = 0;
  if (ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) csize = 1;
  if (ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) csize = 2;
  if (ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) csize = 4;
  if (csize == 0) Fail(g.file, where, what + ": component type must be an unsigned integer");
  if (acc.count > limits::kMaxSceneIndices) {
    Fail(g.file, where,
         what + ": count " + std::to_string(acc.count) + " exceeds the limit of " +
             std::to_string(limits::kMaxSceneIndices) + " indices per scene " +
             limits::LimitRef("kMaxSceneIndices"));
  }
  if (acc.count % 3 != 0) {
    Fail(g.file, where,
         "index count " + std::to_string(acc.count) + " is not a multiple of 3");
  }
  if (acc.bufferView < -1) Fail(g.file, where, what + ": bufferView index out of range");
  const unsigned char* base = nullptr;
  size_t stride = 0;
  if (acc.bufferView >= 0) base = AccessorData(g, model, acc, csize, where, what, &stride);
  std::vector<uint32_t> out(acc.count, 0);  // count bounded above
  if (base == nullptr) return out;
  for (size_t i = 0; i < acc.count; ++i) {
    const unsigned char* p = base + i * stride;
    if (csize == 1) {
      out[i] = *p;
    } else if (csize == 2) {
      uint16_t u;
      std::memcpy(&u, p, 2);
      out[i] = u;
    } else {
      std::memcpy(&out[i], p, 4);
    }
  }
  return out;
}

// Area-weighted smooth normals over shared indices (docs/scene-card.md, "Repairs").
std::vector<std::array<float, 3>> SmoothNormals(const Mesh& m) {
  std::vector<V3> acc(m.positions.size(), V3{0, 0, 0});
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    const uint32_t a = m.indices[t], b = m.indices[t + 1], c = m.indices[t + 2];
    const V3 pa = ToDouble(m.positions[a]);
    const V3 n = Cross(Sub(ToDouble(m.positions[b]), pa), Sub(ToDouble(m.positions[c]), pa));
    for (uint32_t k : {a, b, c}) acc[k] = Add(acc[k], n);
  }
  std::vector<std::array<float, 3>> out(acc.size());
  // A vertex in no triangle (or only degenerate ones) gets +Y: it is never shaded anyway.
  for (size_t i = 0; i < acc.size(); ++i) out[i] = ToFloat(NormalizeOr(acc[i], {0, 1, 0}));
  return out;
}

// Per-vertex tangents from UV gradients (docs/scene-card.md, "Repairs").
std::vector<std::array<float, 4>> GenerateTangents(const Mesh& m) {
  std::vector<V3> su(m.positions.size(), V3{0, 0, 0}), sv(m.positions.size(), V3{0, 0, 0});
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    const uint32_t a = m.indices[t], b = m.indices[t + 1], c = m.indices[t + 2];
    const V3 pa = ToDouble(m.positions[a]);
    const V3 e1 = Sub(ToDouble(m.positions[b]), pa), e2 = Sub(ToDouble(m.positions[c]), pa);
    const double du1 = double(m.uvs[b][0]) - double(m.uvs[a][0]);
    const double dv1 = double(m.uvs[b][1]) - double(m.uvs[a][1]);
    const double du2 = double(m.uvs[c][0]) - double(m.uvs[a][0]);
    const double dv2 = double(m.uvs[c][1]) - double(m.uvs[a][1]);
    const double det = du1 * dv2 - du2 * dv1;
    if (!(std::abs(det) > 1e-20)) continue;  // no UV parameterisation on this triangle
    const double r = 1.0 / det;
    const V3 sdir = Scale(Sub(Scale(e1, dv2), Scale(e2, dv1)), r);  // dP/du
    const V3 tdir = Scale(Sub(Scale(e2, du1), Scale(e1, du2)), r);  // dP/dv
    for (uint32_t k : {a, b, c}) {
      su[k] = Add(su[k], sdir);
      sv[k] = Add(sv[k], tdir);
    }
  }
  std::vector<std::array<float, 4>> out(m.positions.size());
  for (size_t k = 0; k < out.size(); ++k) {
    const V3 n = ToDouble(m.normals[k]);
    V3 t = Sub(su[k], Scale(n, Dot(n, su[k])));
    t = Length(t) > 1e-12 * (Length(su[k]) + 1e-30) ? NormalizeOr(t, AnyOrthogonal(n))
                                                    : AnyOrthogonal(n);
    const double w = Dot(Cross(n, t), Scale(sv[k], -1.0)) >= 0 ? 1.0 : -1.0;
    out[k] = {static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2]),
              static_cast<float>(w)};
  }
  return out;
}

// What the readers of one primitive's attributes share.
struct PrimitiveInput {
  const GltfContext& g;
  const tinygltf::Primitive& prim;
  const std::string& where;  // MeshWhere(...), for messages
  size_t n;                  // vertex count (of POSITION)
  const Mat4& world;
  bool mirrored;  // det(world) < 0: winding flipped, normals and tangent signs negated
};

// Accessor index of attribute `name`, or -1.
int AttributeIndex(const tinygltf::Primitive& prim, const char* name) {
  const auto it = prim.attributes.find(name);
  return it == prim.attributes.end() ? -1 : it->second;
}

void CheckCount(const PrimitiveInput& in, const char* name, size_t count) {
  if (count != in.n) {
    Fail(in.g.file, in.where,
         std::string(name) + " has " + std::to_string(count) + " elements, POSITION has " +
             std::to_string(in.n));
  }
}

// Name, material index, fabric flag and base colour of a primitive's mesh.
void ReadMeshMaterial(const GltfContext& g, const SceneCard& card, int mesh_index, int prim_index,
                      const std::string& where, Mesh* mesh) {
  const tinygltf::Model& model = g.model;
  const tinygltf::Primitive& prim = model.meshes[mesh_index].primitives[prim_index];
  const std::string& mesh_name = model.meshes[mesh_index].name;
  mesh->name = mesh_name.empty() ? "mesh" + std::to_string(mesh_index) : mesh_name;
  if (model.meshes[mesh_index].primitives.size() > 1)
    mesh->name += "/" + std::to_string(prim_index);
  mesh->material = prim.material;
  if (mesh->material >= static_cast<int>(model.materials.size())) {
    Fail(g.file, where, "material index " + std::to_string(mesh->material) + " out of range");
  }
  // A glTF without any material (docs/scenes.md, "A glTF without materials"): every primitive
  // has the glTF default material, and with fabric_material 0 that default slot is the fabric
  // (clothfit's fabric material applies, as for any fabric slot). With materials present, a
  // primitive without one is a non-fabric mesh with the glTF default material (below).
  const bool default_is_fabric = model.materials.empty() && card.fabric_material == 0;
  mesh->is_fabric = mesh->material >= 0 ? mesh->material == card.fabric_material
                                        : default_is_fabric;
  if (mesh->material >= 0) {
    mesh->double_sided = model.materials[mesh->material].doubleSided;
    const auto& f = model.materials[mesh->material].pbrMetallicRoughness.baseColorFactor;
    if (f.size() >= 3) {
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(f[c]) || f[c] < 0) {
          Fail(g.file, "materials[" + std::to_string(mesh->material) + "]",
               "baseColorFactor must be finite and >= 0");
        }
        mesh->base_color[c] = static_cast<float>(f[c]);
      }
    }
  } else {
    mesh->double_sided = false;             // glTF default material: single-sided
    mesh->base_color = {1.0f, 1.0f, 1.0f};  // glTF default material
  }
}

// Indices (non-indexed: 0, 1, 2, ...), checked against the vertex count n.
std::vector<uint32_t> ReadTriangleIndices(const GltfContext& g, const tinygltf::Primitive& prim,
                                          const std::string& where, size_t n) {
  std::vector<uint32_t> indices;
  if (prim.indices >= 0) {
    indices = ReadIndices(g, where, prim.indices);
  } else {
    indices.resize(n);
    for (size_t i = 0; i < n; ++i) indices[i] = static_cast<uint32_t>(i);
  }
  if (indices.size() % 3 != 0) {
    Fail(g.file, where,
         "index count " + std::to_string(indices.size()) + " is not a multiple of 3");
  }
  for (uint32_t i : indices) {
    if (i >= n) {
      Fail(g.file, where, "index " + std::to_string(i) + " >= vertex count " + std::to_string(n));
    }
  }
  return indices;
}

// NORMAL through the cofactor matrix; zero-length values, or all when NORMAL is absent,
// replaced by smooth normals (needs mesh->positions and mesh->indices).
void ReadNormals(const PrimitiveInput& in, Mesh* mesh, std::vector<std::string>& warnings) {
  const GltfContext& g = in.g;
  const size_t n = in.n;
  std::vector<std::array<float, 3>> smooth;  // computed on demand
  if (AttributeIndex(in.prim, "NORMAL") >= 0) {
    const std::vector<float> nrm =
        ReadFloats(g, in.where, "NORMAL", AttributeIndex(in.prim, "NORMAL"), 3, false, in.n, true);
    CheckCount(in, "NORMAL", nrm.size() / 3);
    const Mat4 cof = Cofactor3(in.world);
    const double sign = in.mirrored ? -1.0 : 1.0;
    mesh->normals.resize(n);
    size_t repaired = 0;
    for (size_t i = 0; i < n; ++i) {
      const V3 n_in{double(nrm[3 * i]), double(nrm[3 * i + 1]), double(nrm[3 * i + 2])};
      const V3 v = Scale(TransformVector(cof, n_in), sign);
      if (Length(v) > 1e-20 && Finite(v)) {
        mesh->normals[i] = ToFloat(NormalizeOr(v, {0, 1, 0}));
      } else {
        if (smooth.empty()) smooth = SmoothNormals(*mesh);
        mesh->normals[i] = smooth[i];
        ++repaired;
      }
    }
    if (repaired > 0) {
      warnings.push_back(g.file + ": " + in.where + ": " + std::to_string(repaired) +
                         " zero-length NORMAL values replaced by computed smooth normals");
    }
  } else {
    mesh->normals = SmoothNormals(*mesh);
    warnings.push_back(g.file + ": " + in.where +
                       ": no NORMAL attribute; computed smooth (area-weighted) normals");
  }
}

// TEXCOORD_0; required on the fabric, (0, 0) elsewhere when absent.
void ReadUvs(const PrimitiveInput& in, const SceneCard& card, Mesh* mesh) {
  if (AttributeIndex(in.prim, "TEXCOORD_0") >= 0) {
    const std::vector<float> uv =
        ReadFloats(in.g, in.where, "TEXCOORD_0", AttributeIndex(in.prim, "TEXCOORD_0"), 2, true,
                   in.n, true);
    CheckCount(in, "TEXCOORD_0", uv.size() / 2);
    mesh->uvs.resize(in.n);
    for (size_t i = 0; i < in.n; ++i) mesh->uvs[i] = {uv[2 * i], uv[2 * i + 1]};
  } else if (mesh->is_fabric) {
    Fail(in.g.file, in.where,
         "no TEXCOORD_0 attribute, but its material " +
             (mesh->material >= 0 ? std::to_string(mesh->material) : std::string("(default)")) +
             " is the fabric (scene card " + card.path +
             ", field 'fabric_material'); the weave needs UVs");
  } else {
    mesh->uvs.assign(in.n, {0.0f, 0.0f});
  }
}

// TANGENT, orthogonalised against the normal; degenerate values, or all when TANGENT is
// absent, replaced by generated tangents (needs the mesh's positions, indices, normals, uvs).
void ReadTangents(const PrimitiveInput& in, Mesh* mesh, std::vector<std::string>& warnings) {
  const GltfContext& g = in.g;
  const size_t n = in.n;
  if (AttributeIndex(in.prim, "TANGENT") >= 0) {
    const std::vector<float> tan =
        ReadFloats(g, in.where, "TANGENT", AttributeIndex(in.prim, "TANGENT"), 4, false, in.n, true);
    CheckCount(in, "TANGENT", tan.size() / 4);
    std::vector<std::array<float, 4>> generated;
    size_t repaired = 0;
    mesh->tangents.resize(n);
    for (size_t i = 0; i < n; ++i) {
      const V3 nn = ToDouble(mesh->normals[i]);
      V3 t = TransformVector(in.world,
                             {double(tan[4 * i]), double(tan[4 * i + 1]), double(tan[4 * i + 2])});
      t = Sub(t, Scale(nn, Dot(nn, t)));
      if (Length(t) > 1e-12 && Finite(t)) {
        t = NormalizeOr(t, AnyOrthogonal(nn));
        const double w = (tan[4 * i + 3] < 0 ? -1.0 : 1.0) * (in.mirrored ? -1.0 : 1.0);
        mesh->tangents[i] = {static_cast<float>(t[0]), static_cast<float>(t[1]),
                             static_cast<float>(t[2]), static_cast<float>(w)};
      } else {
        if (generated.empty()) generated = GenerateTangents(*mesh);
        mesh->tangents[i] = generated[i];
        ++repaired;
      }
    }
    if (repaired > 0) {
      warnings.push_back(g.file + ": " + in.where + ": " + std::to_string(repaired) +
                         " degenerate TANGENT values replaced by generated tangents");
    }
  } else {
    mesh->tangents = GenerateTangents(*mesh);
    if (AttributeIndex(in.prim, "TEXCOORD_0") >= 0) {
      warnings.push_back(g.file + ": " + in.where +
                         ": no TANGENT attribute; generated tangents from TEXCOORD_0");
    }
  }
}

Mesh BuildMesh(const GltfContext& g, const SceneCard& card, int mesh_index, int prim_index,
               const Mat4& world, std::vector<std::string>& warnings) {
  const tinygltf::Model& model = g.model;
  const tinygltf::Primitive& prim = model.meshes[mesh_index].primitives[prim_index];
  const std::string where = MeshWhere(model, mesh_index, prim_index);
  const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
  if (mode != TINYGLTF_MODE_TRIANGLES) {
    Fail(g.file, where,
         "primitive mode " + std::to_string(mode) + " is not supported (triangles only, mode 4)");
  }
  Mesh mesh;
  ReadMeshMaterial(g, card, mesh_index, prim_index, where, &mesh);

  if (AttributeIndex(prim, "POSITION") < 0) Fail(g.file, where, "no POSITION attribute");
  const std::vector<float> pos =
      ReadFloats(g, where, "POSITION", AttributeIndex(prim, "POSITION"), 3, false,
                 limits::kMaxSceneVertices, false);
  const size_t n = pos.size() / 3;
  if (n == 0) Fail(g.file, where, "POSITION is empty");
  if (n > std::numeric_limits<uint32_t>::max()) Fail(g.file, where, "too many vertices");

  // Indices, winding fixed for mirroring transforms.
  mesh.indices = ReadTriangleIndices(g, prim, where, n);
  const double det = Det3(world);
  if (!std::isfinite(det) || std::abs(det) < 1e-30) {
    Fail(g.file, where, "node transform is singular or not finite");
  }
  const bool mirrored = det < 0;
  if (mirrored) {
    for (size_t t = 0; t < mesh.indices.size(); t += 3) {
      std::swap(mesh.indices[t + 1], mesh.indices[t + 2]);
    }
  }

  mesh.positions.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const V3 p =
        TransformPoint(world, {double(pos[3 * i]), double(pos[3 * i + 1]), double(pos[3 * i + 2])});
    CheckWorldPoint(g.file, where + ": POSITION[" + std::to_string(i) + "]", p);
    mesh.positions[i] = ToFloat(p);
  }

  // In this order: the repairs of each read the attributes before it.
  const PrimitiveInput in{g, prim, where, n, world, mirrored};
  ReadNormals(in, &mesh, warnings);
  ReadUvs(in, card, &mesh);
  ReadTangents(in, &mesh, warnings);
  return mesh;
}

// Local transform of a node: its matrix, or T * R * S.
Mat4 NodeTransform(const std::string& file, const tinygltf::Node& node, int index) {
  const std::string where = "nodes[" + std::to_string(index) + "]";
  Mat4 m;
  if (!node.matrix.empty()) {
    if (node.matrix.size() != 16) Fail(file, where, "matrix must have 16 numbers");
    for (int i = 0; i < 16; ++i) m.m[i] = node.matrix[i];
  } else {
    V3 t{0, 0, 0}, s{1, 1, 1};
    std::array<double, 4> q{0, 0, 0, 1};
    if (!node.translation.empty()) {
      if (node.translation.size() != 3) Fail(file, where, "translation must have 3 numbers");
      t = {node.translation[0], node.translation[1], node.translation[2]};
    }
    if (!node.scale.empty()) {
      if (node.scale.size() != 3) Fail(file, where, "scale must have 3 numbers");
      s = {node.scale[0], node.scale[1], node.scale[2]};
    }
    if (!node.rotation.empty()) {
      if (node.rotation.size() != 4) Fail(file, where, "rotation must have 4 numbers");
      q = {node.rotation[0], node.rotation[1], node.rotation[2], node.rotation[3]};
      const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      if (!(len > 1e-12) || !std::isfinite(len))
        Fail(file, where, "rotation is not a unit quaternion");
      for (double& c : q) c /= len;
    }
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                            {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                            {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) m(i, j) = r[i][j] * s[j];
      m(i, 3) = t[i];
    }
  }
  for (double v : m.m) {
    if (!std::isfinite(v)) Fail(file, where, "transform is not finite");
  }
  return m;
}

struct Placed {
  int index;  // camera or light index
  Mat4 world;
};

struct Flattened {
  std::vector<std::pair<int, Mat4>> mesh_nodes;  // (mesh index, world)
  std::vector<Placed> cameras;
  std::vector<Placed> lights;
};

void Visit(const std::string& file, const tinygltf::Model& model, int index, const Mat4& parent,
           std::vector<char>& on_path, int depth, Flattened& out) {
  if (index < 0 || index >= static_cast<int>(model.nodes.size())) {
    Fail(file, "nodes", "node index " + std::to_string(index) + " out of range");
  }
  if (on_path[index] || depth > 1000) {
    Fail(file, "nodes[" + std::to_string(index) + "]", "the node hierarchy has a cycle");
  }
  on_path[index] = 1;
  const tinygltf::Node& node = model.nodes[index];
  const Mat4 world = Mul(parent, NodeTransform(file, node, index));
  const std::string where = "nodes[" + std::to_string(index) + "]";
  for (double v : world.m) {
    if (!std::isfinite(v)) Fail(file, where, "world transform overflows (not finite)");
  }
  if (node.mesh >= 0) {
    if (node.mesh >= static_cast<int>(model.meshes.size())) {
      Fail(file, where, "mesh index " + std::to_string(node.mesh) + " out of range");
    }
    out.mesh_nodes.emplace_back(node.mesh, world);
  }
  if (node.camera >= 0) out.cameras.push_back({node.camera, world});
  const auto ext = node.extensions.find("KHR_lights_punctual");
  if (ext != node.extensions.end()) {
    const tinygltf::Value& light = ext->second.Get("light");
    if (!light.IsNumber()) {
      Fail(file, where + ".extensions.KHR_lights_punctual.light", "expected a light index");
    }
    const int li = light.GetNumberAsInt();
    if (li < 0 || li >= static_cast<int>(model.lights.size())) {
      Fail(file, where + ".extensions.KHR_lights_punctual.light",
           "light index " + std::to_string(li) + " out of range (" +
               std::to_string(model.lights.size()) + " lights)");
    }
    out.lights.push_back({li, world});
  }
  for (int child : node.children) Visit(file, model, child, world, on_path, depth + 1, out);
  on_path[index] = 0;
}

Light BuildLight(const std::string& file, const SceneCard& card, const tinygltf::Model& model,
                 const Placed& placed) {
  const tinygltf::Light& src = model.lights[placed.index];
  const std::string where =
      "extensions.KHR_lights_punctual.lights[" + std::to_string(placed.index) + "]";
  Light light;
  light.name = src.name.empty() ? "light" + std::to_string(placed.index) : src.name;
  if (src.type == "directional") {
    light.type = Light::Type::kDirectional;
  } else if (src.type == "point") {
    light.type = Light::Type::kPoint;
  } else if (src.type == "spot") {
    light.type = Light::Type::kSpot;
  } else {
    Fail(file, where + ".type",
         "unknown light type " + Quote(src.type) + " (directional, point or spot)");
  }
  if (!src.color.empty()) {
    if (src.color.size() != 3) Fail(file, where + ".color", "expected 3 numbers");
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(src.color[c]) || src.color[c] < 0) {
        Fail(file, where + ".color", "components must be finite and >= 0");
      }
      light.color[c] = src.color[c];
    }
  }
  if (!std::isfinite(src.intensity) || src.intensity < 0) {
    Fail(file, where + ".intensity", "must be finite and >= 0");
  }
  light.intensity = src.intensity * card.light_scale;
  if (!(light.intensity <= limits::kMaxRadiance)) {
    Fail(file, where + ".intensity",
         "intensity x the card's light_scale is above the limit 1e+12 " +
             limits::LimitRef("kMaxRadiance"));
  }
  if (!std::isfinite(src.range) || src.range < 0) {
    Fail(file, where + ".range", "must be finite and > 0 when present");
  }
  light.range = src.range;
  if (light.type == Light::Type::kSpot) {
    const double inner = src.spot.innerConeAngle, outer = src.spot.outerConeAngle;
    if (!(outer > 0 && outer <= kPi / 2 + 1e-9)) {
      Fail(file, where + ".spot.outerConeAngle", "must be in (0, pi/2]");
    }
    if (!(inner >= 0 && inner < outer)) {
      Fail(file, where + ".spot.innerConeAngle", "must be in [0, outerConeAngle)");
    }
    light.inner_cone = inner;
    light.outer_cone = outer;
  }
  light.position = TransformPoint(placed.world, {0, 0, 0});
  if (light.type != Light::Type::kDirectional) CheckWorldPoint(file, where, light.position);
  const V3 d = TransformVector(placed.world, {0, 0, -1});
  if (!(Length(d) > 1e-12)) Fail(file, where, "its node transform collapses the -Z axis");
  light.direction = Scale(d, 1.0 / Length(d));
  return light;
}

Camera BuildCamera(const std::string& file, const SceneCard& card, const tinygltf::Model& model,
                   const Flattened& flat) {
  const int n = static_cast<int>(model.cameras.size());
  if (card.camera >= n) {
    Fail(card.path, "field 'camera'",
         std::to_string(card.camera) + " is out of range: " + file + " has " + std::to_string(n) +
             " camera" + (n == 1 ? "" : "s"));
  }
  const tinygltf::Camera& src = model.cameras[card.camera];
  const std::string where = "cameras[" + std::to_string(card.camera) + "]";
  if (src.type != "perspective") {
    Fail(file, where, "type " + Quote(src.type) + " is not supported (perspective only)");
  }
  const double yfov = src.perspective.yfov;
  if (!(yfov > 0 && yfov < kPi)) Fail(file, where + ".perspective.yfov", "must be in (0, pi)");
  const auto it = std::find_if(flat.cameras.begin(), flat.cameras.end(),
                               [&](const Placed& p) { return p.index == card.camera; });
  if (it == flat.cameras.end()) {
    Fail(file, where, "no node of the scene places this camera");
  }
  Camera cam;
  cam.yfov = yfov;
  cam.position = TransformPoint(it->world, {0, 0, 0});
  CheckWorldPoint(file, where + " (placed by its node)", cam.position);
  const V3 f = TransformVector(it->world, {0, 0, -1});
  const V3 u = TransformVector(it->world, {0, 1, 0});
  cam.forward = NormalizeOr(f, {0, 0, 0});
  const V3 up = Sub(u, Scale(cam.forward, Dot(cam.forward, u)));
  cam.up = NormalizeOr(up, {0, 0, 0});
  if (Length(cam.forward) == 0 || Length(cam.up) == 0) {
    Fail(file, where, "the camera node's transform is degenerate");
  }
  cam.right = Cross(cam.forward, cam.up);
  return cam;
}

// ---------------------------------------------------------------------------------------------
// LoadSceneCard's steps.

// The card's JSON; a syntax error names the card's line and column.
Json ParseCardJson(const std::string& text, const std::string& card_path) {
  try {  // the nesting limit first: FieldReader copies and compares values recursively
    limits::CheckJsonDepth(text, card_path);
  } catch (const limits::InputError& e) {
    throw SceneError(e.what());
  }
  try {
    return Json::parse(text);
  } catch (const Json::parse_error& e) {
    const size_t offset = e.byte > 0 ? e.byte - 1 : 0;
    const auto [line, column] = LineColumn(text, offset);
    std::string msg = e.what();
    // nlohmann's message repeats the position; keep its description only.
    if (const size_t colon = msg.find(": "); colon != std::string::npos) {
      msg = msg.substr(colon + 2);
    }
    throw SceneError(card_path + ":" + std::to_string(line) + ":" + std::to_string(column) +
                     ": malformed JSON: " + limits::EscapeForMessage(msg, 400));
  } catch (const Json::out_of_range& e) {  // 406: a number beyond double (1e400) while parsing
    throw SceneError(card_path + ": malformed JSON: " + limits::EscapeForMessage(e.what(), 400));
  }
}

// "environment": {path, intensity, rotation_y_degrees, sun}, its path resolved.
EnvironmentSpec ReadCardEnvironment(const FieldReader& r, const fs::path& card_dir) {
  const Json& env_json = r.object()["environment"];
  if (!env_json.is_object()) {
    r.Bad("environment",
          "expected an object {path, intensity, rotation_y_degrees} or null, "
          "got " +
              FieldReader::Show(env_json));
  }
  const FieldReader e(r.file(), env_json, "environment.");
  e.RejectUnknown({"path", "intensity", "rotation_y_degrees", "sun"});
  EnvironmentSpec env;
  env.name = e.String("path", "", true);
  env.intensity = e.Number("intensity", 1.0, 0.0, 1e30, false, ">= 0");
  const double degrees =
      e.Number("rotation_y_degrees", 0.0, -1e6, 1e6, false, "in [-1e6, 1e6] degrees");
  env.rotation_y = degrees * kPi / 180.0;
  if (e.Has("sun")) {  // the preview's sun split (render/scene/sun.h, docs/sun.md)
    const std::string sun = e.String("sun", "", true);
    if (sun == "auto") env.sun = SunMode::kAuto;
    else if (sun == "off") env.sun = SunMode::kOff;
    else if (sun == "panels") env.sun = SunMode::kPanels;
    else e.Bad("sun", "expected \"auto\", \"off\" or \"panels\", got " + Quote(sun));
  }
  ResolveEnvironment(r.file(), card_dir, env);
  return env;
}

// "visibility": {"shadows": bool, "light_map": false | {"size", "samples", "hit_samples",
// "bounces"}} (session 13).
CardVisibility ReadCardVisibility(const FieldReader& r) {
  const Json& j = r.object()["visibility"];
  if (!j.is_object())
    r.Bad("visibility", "expected an object {shadows, light_map}, got " + FieldReader::Show(j));
  const FieldReader v(r.file(), j, "visibility.");
  v.RejectUnknown({"shadows", "light_map"});
  CardVisibility out;
  if (v.Has("shadows")) {
    if (!j["shadows"].is_boolean())
      v.Bad("shadows", "expected true or false, got " + FieldReader::Show(j["shadows"]));
    out.shadows = j["shadows"].get<bool>();
  }
  if (v.Has("light_map")) {
    const Json& lm = j["light_map"];
    if (lm.is_boolean()) {
      out.light_map = lm.get<bool>();
    } else if (lm.is_object()) {
      const FieldReader l(r.file(), lm, "visibility.light_map.");
      l.RejectUnknown({"size", "samples", "hit_samples", "bounces"});
      out.light_map = true;
      out.size = l.Int("size", out.size, 1, 2048);
      out.samples = l.Int("samples", out.samples, 1, 65536);
      out.hit_samples = l.Int("hit_samples", out.hit_samples, 0, 4096);
      out.bounces = l.Int("bounces", out.bounces, 1, 4);
    } else {
      v.Bad("light_map", "expected true, false or an object {size, samples, hit_samples, "
                         "bounces}, got " + FieldReader::Show(lm));
    }
  }
  return out;
}

// Tone mapping, exposure, fabric material, light scale, camera and background.
void ReadCardLook(const FieldReader& r, SceneCard* card) {
  card->tone_mapping = r.String("tone_mapping", card->tone_mapping, false);
  if (std::none_of(std::begin(kToneMappings), std::end(kToneMappings),
                   [&](const char* t) { return card->tone_mapping == t; })) {
    std::string list;
    for (const char* t : kToneMappings) list += std::string(list.empty() ? "" : ", ") + t;
    r.Bad("tone_mapping",
          "unknown tone mapping " + Quote(card->tone_mapping) + " (valid: " + list + ")");
  }
  card->exposure = r.Number("exposure", card->exposure, 0.0, 1e30, true, "> 0");
  card->fabric_material =
      r.Int("fabric_material", card->fabric_material, 0, std::numeric_limits<int>::max());
  card->light_scale = r.Number("light_scale", card->light_scale, 0.0, 1e30, false, ">= 0");
  card->camera = r.Int("camera", card->camera, 0, std::numeric_limits<int>::max());
  if (r.Has("background")) {
    const Json& bg = r.object()["background"];
    if (!bg.is_array() || bg.size() != 3) {
      r.Bad("background",
            "expected an array of 3 numbers (linear RGB), got " + FieldReader::Show(bg));
    }
    for (int c = 0; c < 3; ++c) {
      card->background[c] = r.CheckNumber(bg[static_cast<size_t>(c)], "background", 0.0, 1e30,
                                          false, ">= 0 in every channel");
    }
  }
}

}  // namespace

// -------------------------------------------------------------------------------------------------

SceneCard LoadSceneCard(const std::string& card_path) {
  const std::string text = ReadText(card_path, "scene card");
  const Json root = ParseCardJson(text, card_path);
  if (!root.is_object()) Fail(card_path, "top level", "the scene card must be a JSON object");

  SceneCard card;
  card.path = card_path;
  const fs::path dir = fs::absolute(fs::path(card_path)).parent_path();
  const FieldReader r(card.path, root, "");
  // A glTF given where a card is expected (every command's --scene/--scenes): say so, rather
  // than failing on its first field ("unknown field 'accessors'").
  if (root.contains("asset") && root["asset"].is_object() && !root.contains("gltf"))
    Fail(card_path, "top level",
         "this is a glTF file, not a clothfit scene card (docs/scene-card.md): a card names its "
         "glTF in the `gltf` field (e.g. datasets/scenes/sphere.json)");
  r.RejectUnknown({"version", "description", "gltf", "width", "height", "environment",
                   "tone_mapping", "exposure", "fabric_material", "light_scale", "camera",
                   "background", "uv_metres_per_unit", "visibility"});

  if (!r.Has("version")) r.Bad("version", "missing (required; this build reads version 1)");
  const int version = r.Int("version", 0, 0, std::numeric_limits<int>::max(), true);
  if (version != kSchemaVersion) {
    r.Bad("version", "schema version " + std::to_string(version) + " is not supported (this " +
                         "build reads version " + std::to_string(kSchemaVersion) + ")");
  }
  card.description = r.String("description", "", false);

  const std::string gltf = r.String("gltf", "", true);
  if (gltf.empty()) r.Bad("gltf", "must not be empty");
  fs::path gltf_path(gltf);
  if (gltf_path.is_relative()) gltf_path = dir / gltf_path;
  card.gltf = gltf_path.lexically_normal().string();

  card.width = r.Int("width", card.width, 1, kMaxImageSize);
  card.height = r.Int("height", card.height, 1, kMaxImageSize);
  if (size_t(card.width) * size_t(card.height) > limits::kMaxRenderPixels) {
    r.Bad("height", std::to_string(card.width) + " x " + std::to_string(card.height) +
                        " pixels is over the limit of " + std::to_string(limits::kMaxRenderPixels) +
                        " per render " + limits::LimitRef("kMaxRenderPixels"));
  }
  if (r.Has("environment")) card.environment = ReadCardEnvironment(r, dir);
  ReadCardLook(r, &card);
  card.uv_metres_per_unit =
      r.Number("uv_metres_per_unit", card.uv_metres_per_unit, 0.0, 1e6, true, "> 0");
  if (r.Has("visibility")) card.visibility = ReadCardVisibility(r);
  return card;
}

Scene LoadScene(const std::string& card_path) {
  Scene scene;
  scene.card = LoadSceneCard(card_path);
  const SceneCard& card = scene.card;
  const std::string& file = card.gltf;
  std::error_code ec;
  if (!fs::exists(file, ec)) Fail(card.path, "field 'gltf'", "glTF file not found: " + file);
  if (!fs::is_regular_file(file, ec)) Fail(card.path, "field 'gltf'", "not a file: " + file);

  tinygltf::Model model;
  {
    std::string err, warn;
    if (!LoadGltfModel(file, &model, &err, &warn))
      throw SceneError(file + ": cannot load glTF: " + err);
    if (!warn.empty()) scene.warnings.push_back(file + ": tinygltf: " + warn);
  }
  const GltfContext g{file, model};

  // Flatten the hierarchy of the default scene (or of every root node when there is none).
  std::vector<int> roots;
  if (!model.scenes.empty()) {
    const int s = model.defaultScene >= 0 ? model.defaultScene : 0;
    if (s >= static_cast<int>(model.scenes.size())) Fail(file, "scene", "index out of range");
    roots = model.scenes[s].nodes;
  } else {
    std::vector<char> is_child(model.nodes.size(), 0);
    for (const auto& node : model.nodes) {
      for (int c : node.children) {
        if (c >= 0 && c < static_cast<int>(is_child.size())) is_child[c] = 1;
      }
    }
    for (size_t i = 0; i < model.nodes.size(); ++i) {
      if (!is_child[i]) roots.push_back(static_cast<int>(i));
    }
  }
  Flattened flat;
  std::vector<char> on_path(model.nodes.size(), 0);
  for (int root : roots) Visit(file, model, root, Mat4{}, on_path, 0, flat);

  const int n_materials = static_cast<int>(model.materials.size());
  if (card.fabric_material >= n_materials && !(n_materials == 0 && card.fabric_material == 0)) {
    Fail(card.path, "field 'fabric_material'",
         std::to_string(card.fabric_material) + " is out of range: " + file + " has " +
             std::to_string(n_materials) + " material" + (n_materials == 1 ? "" : "s"));
  }

  size_t total_vertices = 0, total_indices = 0;
  for (const auto& [mesh_index, world] : flat.mesh_nodes) {
    const auto& prims = model.meshes[mesh_index].primitives;
    for (size_t p = 0; p < prims.size(); ++p) {
      scene.meshes.push_back(
          BuildMesh(g, card, mesh_index, static_cast<int>(p), world, scene.warnings));
      total_vertices += scene.meshes.back().positions.size();
      total_indices += scene.meshes.back().indices.size();
      if (total_vertices > limits::kMaxSceneVertices || total_indices > limits::kMaxSceneIndices)
        Fail(file, "meshes",
             "the scene holds more than " + std::to_string(limits::kMaxSceneVertices) +
                 " vertices or " + std::to_string(limits::kMaxSceneIndices) + " indices " +
                 limits::LimitRef("kMaxSceneVertices"));
    }
  }
  if (scene.meshes.empty()) Fail(file, "meshes", "the scene has no triangle meshes");
  if (n_materials == 0)
    scene.warnings.push_back(file + " has no materials: every primitive has the glTF default "
                             "material, which is the fabric (fabric_material 0)");
  if (std::none_of(scene.meshes.begin(), scene.meshes.end(),
                   [](const Mesh& m) { return m.is_fabric; })) {
    Fail(card.path, "field 'fabric_material'",
         "no mesh of " + file + " uses material " + std::to_string(card.fabric_material));
  }

  scene.camera = BuildCamera(file, card, model, flat);
  for (const Placed& placed : flat.lights) {
    scene.lights.push_back(BuildLight(file, card, model, placed));
  }
  if (card.environment && !card.environment->found) {
    // A missing file (not a cache name) is an error of the renderers (bin/cmd_render.cpp
    // LoadSceneEnvironment), not a fallback to the sky.
    scene.warnings.push_back(card.environment->is_file
                                 ? card.path + ": field 'environment.path': no such file " +
                                       card.environment->path + " (the renderers refuse it)"
                                 : card.path + ": field 'environment.path': map " +
                                       Quote(card.environment->name) +
                                       " is not installed (looked for " + card.environment->path +
                                       "); renderers use the procedural sky");
  }
  return scene;
}

void Scene::CameraRay(double px, double py, std::array<double, 3>& origin,
                      std::array<double, 3>& dir) const {
  const double tan_half = std::tan(0.5 * camera.yfov);
  const double aspect = static_cast<double>(card.width) / static_cast<double>(card.height);
  const double sx = (2.0 * px / card.width - 1.0) * tan_half * aspect;
  const double sy = (1.0 - 2.0 * py / card.height) * tan_half;
  const V3 d = Add(camera.forward, Add(Scale(camera.right, sx), Scale(camera.up, sy)));
  origin = camera.position;
  dir = Scale(d, 1.0 / Length(d));
}

}  // namespace clothfit::render
