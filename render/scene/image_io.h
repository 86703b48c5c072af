// render/scene/image_io.h: image input (EXR through OpenEXR, PNG through libpng, Radiance HDR)
// and output (float EXR, 8-bit sRGB PNG). render/scene/image_readers.h describes what a read
// returns: the same as OpenImageIO 2.4, which clothfit used until session 16.
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
  // The stored data type ("half", "float", "uint", "uint8", "uint16"; "float" for mixed EXR
  // channels) and the format ("openexr", "png", "hdr"): OpenImageIO's names.
  std::string source_format;
  std::string file_format;

  int channels() const { return int(channel_names.size()); }
};

// Maximum accepted image dimensions and channel count on read.
inline constexpr int kMaxDimension = 16384;
inline constexpr int kMaxChannels = 64;

// Writes a 32-bit float EXR (ZIP compression) with the given metadata as string attributes,
// atomically.
void WriteExr(const std::string& path, const Image& image);

// Reads an EXR, PNG or Radiance HDR image as float. Throws IoError naming the file on failure.
// EXR: the first part's data window, channels in OpenImageIO's canonical order (R G B A first;
// image_readers.h), string attributes as metadata. PNG: 8/16-bit codes / (2^n - 1), not
// linearised, alpha premultiplied. HDR: RGB as stored.
// Before allocating, it checks the file (regular, <= kMaxImageFileBytes), the decoded size
// (W*H*C*4 <= kMaxImageBytes) and, for PNG, that the file can hold the claimed pixels
// (docs/reliability.md).
Image ReadImage(const std::string& path);

// A Table2D as an image: row j of the table (v = (j + 0.5)/H) is image row j from the top;
// metadata records both axes' conventions and the texel-centre rule.
Image TableToImage(const Table2D& table, const std::vector<std::string>& channel_names);
Table2D ImageToTable(const Image& image);

// Writes display-referred RGB (values in [0, 1], already tone mapped and sRGB encoded) as an
// 8-bit PNG with an sRGB chunk, atomically. Values are clamped and rounded to nearest.
void WritePng8(const std::string& path, int width, int height, const std::vector<float>& rgb);

// Encodes display-referred RGB (values in [0, 1], clamped, non-finite -> 0) as an 8-bit PNG
// in memory (for data URIs in reports). Throws IoError naming `what` on failure.
std::vector<unsigned char> EncodePng8(int width, int height, const std::vector<float>& rgb,
                                      const std::string& what);

// The two half images of a reference EXR written by the path tracer (render/reference/
// path_tracer.h, docs/reference-renderer.md "Half images"): of each pixel's K i.i.d. batch
// means, a = half.R/G/B is the mean of the first kA (metadata clothfit:half_batches) and
// b = (K mean - kA a) / (K - kA) the mean of the other K - kA (K = clothfit:batches, the same
// in every pixel), 3 floats per pixel, top row first. a and b are independent unbiased
// estimates of the pixel: E (a - b)^2 = sigma^2 (1/kA + 1/(K - kA)) with sigma^2 the variance
// of one batch mean, i.e. K stderr^2 (1/kA + 1/(K - kA)) (= 4 stderr^2 for K = 16, kA = 8).
struct ReferenceHalves {
  int width = 0, height = 0;
  int batches = 0, half_batches = 0;  // K, kA
  std::vector<float> a, b;
};
// Throws IoError naming the file `what` and the missing channel or bad metadata field.
ReferenceHalves ReferenceHalvesFromImage(const Image& image, const std::string& what);

// Writes text atomically (temporary file + rename). Throws IoError naming the file.
void WriteTextAtomic(const std::string& path, const std::string& text);

// Throws IoError "<path>: output directory <dir> does not exist" unless the directory `path`
// would be written into exists (a bare file name: the working directory). The writers above
// call it; commands that work for seconds or minutes before they write call it first, so a
// mistyped --out fails before the work and not after it.
void RequireOutputDirectory(const std::string& path);

}  // namespace clothfit::io
