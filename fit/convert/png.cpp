#include "fit/convert/png.h"

#include <zlib.h>

#include <cstdint>
#include <stdexcept>

namespace clothfit::fit {
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

}  // namespace clothfit::fit
