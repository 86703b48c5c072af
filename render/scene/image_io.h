// render/scene/image_io.h: EXR/PNG input and output through OpenImageIO.
//
// Writes are atomic: the file is written next to its destination under a temporary name
// and renamed into place, so an interrupted run never leaves a truncated output. Reads check
// sizes against explicit limits and report errors naming the file (untrusted EXRs are a
// known attack surface; see docs/conventions.md).
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "brdf/table.h"

namespace clothfit::io {

// Error with a message that already names the file.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Image {
  int width = 0, height = 0;
  std::vector<std::string> channel_names;  // e.g. {"R", "G", "B"}
  std::vector<float> pixels;               // row-major, top row first, interleaved
  std::map<std::string, std::string> metadata;
  // Set by ReadImage: false when any channel was stored as an integer type (8/16-bit PNG):
  // such values are display-encoded (sRGB), not linear radiance.
  bool float_source = true;
  std::string source_format;  // OIIO type name of the stored data ("half", "uint8")
  std::string file_format;    // OIIO format name ("openexr", "png", "hdr")

  int channels() const { return int(channel_names.size()); }
};

// Maximum accepted image dimensions and channel count on read.
inline constexpr int kMaxDimension = 16384;
inline constexpr int kMaxChannels = 64;

// Writes a 32-bit float EXR (ZIP compression) with the given string metadata, atomically.
void WriteExr(const std::string& path, const Image& image);

// Reads any OIIO-readable image as float. Throws IoError naming the file on failure.
// Before allocating, it checks the file (regular, <= kMaxImageFileBytes), the decoded size
// (W*H*C*4 <= kMaxImageBytes) and, for PNG, that the file can hold the claimed pixels
// (docs/reliability.md).
Image ReadImage(const std::string& path);

// A Table2D as an image: row j of the table (v = (j + 0.5)/H) is image row j from the top;
// metadata records both axes' conventions and the texel-centre rule.
Image TableToImage(const Table2D& table, const std::vector<std::string>& channel_names);
Table2D ImageToTable(const Image& image);

// Writes display-referred RGB (values in [0, 1], already tone mapped and sRGB encoded) as an
// 8-bit PNG, atomically. Values are clamped and rounded to nearest.
void WritePng8(const std::string& path, int width, int height, const std::vector<float>& rgb);

// Encodes display-referred RGB (values in [0, 1], clamped, non-finite -> 0) as an 8-bit PNG
// in memory (for data URIs in reports). Throws IoError naming `what` on failure.
std::vector<unsigned char> EncodePng8(int width, int height, const std::vector<float>& rgb,
                                      const std::string& what);

// Writes text atomically (temporary file + rename). Throws IoError naming the file.
void WriteTextAtomic(const std::string& path, const std::string& text);

}  // namespace clothfit::io
