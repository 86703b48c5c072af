// render/scene/input_limits.h: the resource budget for untrusted input files and the small
// helpers every reader uses to keep to it (docs/reliability.md lists the limits and what each
// reader promises).
//
// The rules these helpers implement:
//   - validate before allocating: sizes come from the real file (fstat on the open
//     descriptor), never from a header alone, and every size product is checked;
//   - no unbounded recursion: JSON nesting is measured on the raw bytes before any DOM or
//     tinygltf parse (nlohmann's copy/dump/compare and tinygltf's value conversion recurse once
//     per level);
//   - untrusted bytes are never echoed raw: messages escape control bytes and invalid UTF-8,
//     and every JSON the tool writes replaces invalid UTF-8 instead of throwing;
//   - paths named inside a file stay inside the input tree unless the user allows otherwise.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace clothfit::limits {

// ---- The resource budget (docs/reliability.md, "Resource budget") --------------------------
inline constexpr size_t kMaxJsonDepth = 64;                        // real files reach 6
inline constexpr size_t kMaxJsonFileBytes = size_t(16) << 20;      // cards, presets, seed JSON
inline constexpr size_t kMaxSmallTextBytes = size_t(1) << 20;      // fabric, .weave
inline constexpr size_t kMaxGltfFileBytes = size_t(256) << 20;     // .gltf/.glb file
inline constexpr size_t kMaxGltfBufferBytes = size_t(256) << 20;   // all buffers of one model
inline constexpr size_t kMaxSceneVertices = size_t(1) << 21;       // per scene
inline constexpr size_t kMaxSceneIndices = size_t(1) << 23;        // per scene
inline constexpr double kMaxWorldCoordinate = 1e6;                 // scene units
inline constexpr size_t kMaxRenderPixels = size_t(1) << 24;        // card width x height
inline constexpr size_t kMaxImageFileBytes = size_t(512) << 20;    // one image file
inline constexpr size_t kMaxImageBytes = size_t(512) << 20;        // decoded float W*H*C*4
inline constexpr size_t kMaxPngExpansion = 1032;                   // deflate's maximum ratio
inline constexpr double kMaxRadiance = 1e12;                       // texel x intensity
inline constexpr size_t kMaxMerlBytes = size_t(64) << 20;          // standard MERL: 35 MB

// "(kMaxImageBytes; docs/reliability.md)": the suffix every limit error carries.
std::string LimitRef(std::string_view constant);

// Thrown by the helpers below; the message already names the file.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// ---- Checked arithmetic ---------------------------------------------------------------------
inline std::optional<size_t> CheckedMul(size_t a, size_t b) {
  size_t r;
  if (__builtin_mul_overflow(a, b, &r)) return std::nullopt;
  return r;
}
inline std::optional<size_t> CheckedAdd(size_t a, size_t b) {
  size_t r;
  if (__builtin_add_overflow(a, b, &r)) return std::nullopt;
  return r;
}
// Product of several sizes, nullopt on overflow.
std::optional<size_t> CheckedProduct(std::initializer_list<size_t> factors);

// ---- Files ----------------------------------------------------------------------------------
// Size of a regular file, checked on the open descriptor: refuses anything that is not a
// regular file (FIFOs, devices, /proc files that report size 0), empty files and files over
// `max_bytes`. `what` names the kind of file in the message ("glTF file").
size_t CheckedFileSize(const std::string& path, size_t max_bytes, std::string_view what);

// Reads a whole regular file of at most `max_bytes` (the same checks as CheckedFileSize, done
// on the descriptor that is then read, so there is no check-then-read race). Throws InputError.
std::string ReadFileBounded(const std::string& path, size_t max_bytes, std::string_view what);

// ---- JSON -----------------------------------------------------------------------------------
// Offset of the first '[' or '{' nested deeper than `max_depth` (brackets inside strings do
// not count), or nullopt. One pass, no allocation.
std::optional<size_t> FindJsonDepthExcess(std::string_view text, size_t max_depth = kMaxJsonDepth);

// Throws InputError("<file>:L:C: JSON nested deeper than 64 levels (kMaxJsonDepth; ...)") when
// `text` nests too deep. Call it right before any nlohmann or tinygltf parse of untrusted text.
void CheckJsonDepth(std::string_view text, const std::string& file);

// The JSON chunk of a .glb (magic "glTF", chunk 0 of type JSON, length within the file), or
// an empty view if the header is not one tinygltf would accept.
std::string_view GlbJsonChunk(std::span<const unsigned char> bytes);

// dump() that never throws on invalid UTF-8 (replaces it with U+FFFD). Use it for every JSON
// the tool writes: paths and messages may carry bytes from untrusted files.
std::string DumpJson(const nlohmann::json& j, int indent = 2);

// ---- Messages -------------------------------------------------------------------------------
// Untrusted bytes made safe for a message or a terminal: valid printable UTF-8 passes through;
// control bytes (C0, DEL, C1) and every byte of an invalid, overlong or surrogate sequence
// become \xNN; '\' becomes '\\'. Cut on a character boundary at `max_bytes` with "..." added.
// The result is always valid UTF-8 without control characters.
std::string EscapeForMessage(std::string_view s, size_t max_bytes = 200);

// True when `s` is valid UTF-8 (no overlongs, no surrogates, <= U+10FFFF).
bool IsValidUtf8(std::string_view s);

// Edit distance between two short names for "did you mean" hints (a mistyped subcommand, a
// misspelt preset field): insertions, deletions, substitutions and swaps of two adjacent
// bytes each cost 1 (optimal string alignment), ASCII letters compared case-folded when
// `fold_case`. Names longer than 64 bytes are never close: returns 1000 (bounds the table).
size_t NameDistance(std::string_view a, std::string_view b, bool fold_case);

// ---- Paths ----------------------------------------------------------------------------------
struct PathPolicy {
  std::filesystem::path root;   // empty: no confinement
  bool allow_outside = false;   // --allow-outside-paths
};

// Resolves `uri` (relative to the directory of `file`) and checks it against `policy`: no
// scheme, no control bytes, not absolute and not resolving (after symlinks) outside
// `policy.root` unless allowed; must be a regular, non-empty file of at most `max_bytes`.
// Throws InputError naming `file`, `field` and the (escaped) uri.
std::filesystem::path ResolveConfined(const std::string& file, const std::string& field,
                                      const std::string& uri, const PathPolicy& policy,
                                      size_t max_bytes = kMaxImageFileBytes);

// True when `p` (already canonical) lies inside `root` (canonical).
bool IsInside(const std::filesystem::path& p, const std::filesystem::path& root);

}  // namespace clothfit::limits
