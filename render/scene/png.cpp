#include "render/scene/png.h"

#include <png.h>
#include <zlib.h>

#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "render/scene/image_io.h"
#include "render/scene/image_readers.h"
#include "render/scene/input_limits.h"

namespace clothfit::io {
namespace {

void PutU32(std::string* s, uint32_t v) {
  for (int k = 3; k >= 0; --k) s->push_back(char((v >> (8 * k)) & 0xFFu));
}

void Chunk(std::string* out, const char type[4], const std::string& data) {
  PutU32(out, uint32_t(data.size()));
  std::string td(type, 4);
  td += data;
  out->append(td);
  uLong crc = crc32(0L, Z_NULL, 0);
  crc = crc32(crc, reinterpret_cast<const Bytef*>(td.data()), uInt(td.size()));
  PutU32(out, uint32_t(crc));
}

}  // namespace

std::string EncodePng(int width, int height, int channels, const std::vector<unsigned char>& pixels,
                      bool srgb_chunk) {
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536)
    throw std::invalid_argument("EncodePng: bad size");
  if (channels != 1 && channels != 3 && channels != 4)
    throw std::invalid_argument("EncodePng: channels must be 1, 3 or 4");
  const size_t row = size_t(width) * size_t(channels);
  if (pixels.size() != row * size_t(height))
    throw std::invalid_argument("EncodePng: pixel buffer size does not match");
  // Scanlines, each with filter byte 0 (None).
  std::string raw;
  raw.reserve((row + 1) * size_t(height));
  for (int y = 0; y < height; ++y) {
    raw.push_back('\0');
    raw.append(reinterpret_cast<const char*>(&pixels[size_t(y) * row]), row);
  }
  uLongf zlen = compressBound(uLong(raw.size()));
  std::string z(zlen, '\0');
  if (compress2(reinterpret_cast<Bytef*>(z.data()), &zlen,
                reinterpret_cast<const Bytef*>(raw.data()), uLong(raw.size()),
                Z_BEST_COMPRESSION) != Z_OK)
    throw std::runtime_error("EncodePng: zlib compress2 failed");
  z.resize(zlen);

  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string ihdr;
  PutU32(&ihdr, uint32_t(width));
  PutU32(&ihdr, uint32_t(height));
  ihdr.push_back(char(8));                                                   // bit depth
  ihdr.push_back(char(channels == 1 ? 0 : channels == 3 ? 2 : 6));           // colour type
  ihdr.push_back('\0');                                                      // deflate
  ihdr.push_back('\0');                                                      // filter method 0
  ihdr.push_back('\0');                                                      // no interlace
  Chunk(&png, "IHDR", ihdr);
  if (srgb_chunk) Chunk(&png, "sRGB", std::string(1, '\0'));  // intent 0: perceptual
  Chunk(&png, "IDAT", z);
  Chunk(&png, "IEND", "");
  return png;
}

// ---- Decoding (libpng) -------------------------------------------------------------------
//
// The samples OpenImageIO 2.4's PNG reader gave, which clothfit's results were made with:
//  - palette, 1/2/4-bit grey and tRNS transparency expanded (png_set_expand): palette -> RGB,
//    tRNS -> an alpha channel; 8- or 16-bit samples after that;
//  - channels Y (grey), Y A (grey + alpha), R G B, R G B A;
//  - alpha ASSOCIATED (premultiplied) in the stored integers: c' = floor(c a / max) when the
//    file has no gAMA chunk or has an sRGB chunk, else c' = trunc(c (a/max)^g) with g the
//    file's decoding exponent 1/gAMA rounded to 0.01 (the "linear" association);
//  - float value = code * (1/max) in float arithmetic (max = 255 or 65535): display-encoded,
//    not linearised (float_source = false);
//  - no metadata (text chunks are not read: nothing in clothfit reads metadata from a PNG).
namespace internal {
namespace {

struct PngState {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::FILE* file = nullptr;
  char error[200] = {};

  PngState() = default;
  PngState(const PngState&) = delete;
  PngState& operator=(const PngState&) = delete;
  ~PngState() {
    if (png) png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    if (file) std::fclose(file);
  }
};

void OnPngError(png_structp png, png_const_charp message) {
  auto* s = static_cast<PngState*>(png_get_error_ptr(png));
  std::snprintf(s->error, sizeof s->error, "%s", message ? message : "libpng error");
  png_longjmp(png, 1);
}

// libpng's warnings (a bad CRC in an ancillary chunk, an unknown chunk) do not stop decoding;
// they are not printed either.
void OnPngWarning(png_structp, png_const_charp) {}

// libpng reports errors by longjmp back here: these two functions hold no object with a
// destructor, and every object the callers own outlives them.
bool ReadPngInfo(PngState* s) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_init_io(s->png, s->file);
  png_read_info(s->png, s->info);
  png_set_expand(s->png);  // palette -> RGB, grey < 8 bits -> 8 bits, tRNS -> alpha
  png_set_interlace_handling(s->png);
  png_read_update_info(s->png, s->info);
  return true;
}

bool ReadPngRows(PngState* s, png_bytep* rows) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_read_image(s->png, rows);
  return true;
}

class PngReader : public ImageReader {
 public:
  // The state is a member: it closes the file and frees libpng's structures also when the
  // constructor throws.
  PngReader(const std::string& path, const std::string& shown) : shown_(shown) {
    state_.file = std::fopen(path.c_str(), "rb");
    if (!state_.file) throw IoError(shown_ + ": cannot read image: cannot open the file");
    state_.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state_, OnPngError, OnPngWarning);
    if (state_.png) state_.info = png_create_info_struct(state_.png);
    if (!state_.png || !state_.info) throw IoError(shown_ + ": cannot read image: out of memory");
    if (!ReadPngInfo(&state_))
      throw IoError(shown_ + ": cannot read image: " + limits::EscapeForMessage(state_.error, 200));
    width = int(png_get_image_width(state_.png, state_.info));
    height = int(png_get_image_height(state_.png, state_.info));
    const int bit_depth = png_get_bit_depth(state_.png, state_.info);
    const int channels = png_get_channels(state_.png, state_.info);
    if ((bit_depth != 8 && bit_depth != 16) || channels < 1 || channels > 4)
      throw IoError(shown_ + ": cannot read image: unsupported PNG layout (" +
                    std::to_string(bit_depth) + "-bit, " + std::to_string(channels) + " channels)");
    wide_ = bit_depth == 16;
    static const char* const kNames[4][4] = {
        {"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
    channel_names.assign(kNames[channels - 1], kNames[channels - 1] + channels);
    alpha_ = channels == 2 ? 1 : channels == 4 ? 3 : -1;
    sample_bytes.assign(size_t(channels), wide_ ? 2 : 1);
    float_source = false;
    source_format = wide_ ? "uint16" : "uint8";
    file_format = "png";
    // The exponent of the alpha association: only a gAMA chunk without an sRGB chunk sets one.
    double file_gamma = 0.0;
    if (!png_get_valid(state_.png, state_.info, PNG_INFO_sRGB) &&
        png_get_gAMA(state_.png, state_.info, &file_gamma) && file_gamma > 0.0) {
      const float g = float(1.0 / file_gamma);
      gamma_ = std::round(float(100.0 * double(g))) / 100.0f;
    }
  }
  void Read(float* out) override {
    const size_t w = size_t(width), h = size_t(height), nc = channel_names.size();
    const size_t row_bytes = png_get_rowbytes(state_.png, state_.info);
    if (row_bytes != w * nc * (wide_ ? 2 : 1))
      throw IoError(shown_ + ": corrupt or truncated image: unexpected PNG row size");
    std::vector<unsigned char> raw(row_bytes * h);
    std::vector<png_bytep> rows(h);
    for (size_t y = 0; y < h; ++y) rows[y] = raw.data() + y * row_bytes;
    if (!ReadPngRows(&state_, rows.data()))
      throw IoError(shown_ + ": corrupt or truncated image: " +
                    limits::EscapeForMessage(state_.error, 200));
    if (wide_)
      Convert<uint16_t>(raw, out);
    else
      Convert<uint8_t>(raw, out);
  }

 private:
  template <class T>
  void Convert(const std::vector<unsigned char>& raw, float* out) const {
    const size_t n = size_t(width) * size_t(height), nc = channel_names.size();
    const unsigned max = std::numeric_limits<T>::max();
    const float scale = 1.0f / float(max);
    std::vector<T> px(nc);
    for (size_t p = 0; p < n; ++p) {
      for (size_t c = 0; c < nc; ++c) {
        const unsigned char* b = &raw[(p * nc + c) * sizeof(T)];
        px[c] = sizeof(T) == 2 ? T((unsigned(b[0]) << 8) | b[1]) : T(b[0]);  // big-endian
      }
      if (alpha_ >= 0) {
        const unsigned a = px[size_t(alpha_)];
        if (gamma_ == 1.0f) {
          for (size_t c = 0; c < nc; ++c)
            if (int(c) != alpha_) px[c] = T(unsigned(px[c]) * a / max);
        } else {
          const float inv_max = float(1.0 / double(max));
          const float k = float(std::pow(double(float(a) * inv_max), double(gamma_)));
          for (size_t c = 0; c < nc; ++c)
            if (int(c) != alpha_) px[c] = T(float(px[c]) * k);
        }
      }
      for (size_t c = 0; c < nc; ++c) out[p * nc + c] = float(px[c]) * scale;
    }
  }

  std::string shown_;
  PngState state_;
  bool wide_ = false;
  int alpha_ = -1;
  float gamma_ = 1.0f;
};

}  // namespace

std::unique_ptr<ImageReader> OpenPng(const std::string& path, const std::string& shown) {
  return std::make_unique<PngReader>(path, shown);
}

}  // namespace internal
}  // namespace clothfit::io
