// render/scene/image_readers.h: the three decoders behind io::ReadImage (internal to
// render/scene/): OpenEXR (image_io.cpp), PNG through libpng (png.cpp) and Radiance RGBE
// (rgbe.cpp). Each opens a file whose container io::ReadImage has already checked, reads its
// header only, and decodes on Read() into a buffer io::ReadImage allocated after checking the
// header's size against the limits (docs/reliability.md: validate before allocating).
//
// The results are those OpenImageIO 2.4 gave for the same files (clothfit read images through
// it until session 16; docs/conventions.md "Image files"): the same channel names in the same
// order, the same float value for every stored sample, the same float_source / source_format /
// file_format. Every decoder's output is row-major, top row (the first stored row) first,
// channels interleaved.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace clothfit::io::internal {

class ImageReader {
 public:
  virtual ~ImageReader() = default;
  // Decodes every pixel into `out` (width x height x channels floats). Throws IoError.
  virtual void Read(float* out) = 0;

  int width = 0, height = 0;
  std::vector<std::string> channel_names;
  std::vector<size_t> sample_bytes;  // bytes of one stored sample, per channel
  bool float_source = true;
  std::string source_format;  // "half", "float", "uint", "uint8", "uint16"
  std::string file_format;    // "openexr", "png", "hdr"
  std::map<std::string, std::string> metadata;
};

// `path` is opened, `shown` (escaped) names it in errors. Throw IoError("<shown>: cannot read
// image: ...") when the header cannot be read.
std::unique_ptr<ImageReader> OpenExr(const std::string& path, const std::string& shown);
std::unique_ptr<ImageReader> OpenPng(const std::string& path, const std::string& shown);
std::unique_ptr<ImageReader> OpenRgbe(const std::string& path, const std::string& shown,
                                      size_t file_bytes);

}  // namespace clothfit::io::internal
