#include "render/scene/image_io.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <string_view>
#include <thread>
#include <tuple>

#include "render/scene/image_readers.h"
#include "render/scene/input_limits.h"
#include "render/scene/png.h"

namespace clothfit::io {
namespace fs = std::filesystem;
namespace {

std::string TempPathFor(const std::string& path) {
  // Same directory (rename is atomic only within a filesystem), unique per process and call.
  static std::atomic<unsigned> counter{0};
  const fs::path p(path);
  const std::string name = "." + p.filename().string() + ".tmp." + std::to_string(::getpid()) +
                           "." + std::to_string(counter++);
  // Keep the extension last (tools and readers that go by the name see the right format).
  return (p.parent_path() / (name + p.extension().string())).string();
}

void RenameInto(const std::string& tmp, const std::string& path) {
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw IoError(path + ": cannot move the written file into place: " + ec.message());
  }
}

// OpenEXR uses a pool of worker threads for (de)compressing blocks of scanlines, one per
// hardware thread as OpenImageIO set it up before session 16; created on the first EXR access.
void UseExrThreads() {
  static std::once_flag once;
  std::call_once(once, [] { Imf::setGlobalThreadCount(int(std::max(1u, std::thread::hardware_concurrency()))); });
}

// Writes `bytes` to the temporary file `tmp`; removes it on failure.
void WriteBytes(const std::string& path, const std::string& tmp, const std::string& bytes) {
  std::ofstream f(tmp, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open for writing");
  f.write(bytes.data(), std::streamsize(bytes.size()));
  f.flush();
  if (!f) {
    f.close();
    std::error_code ec;
    fs::remove(tmp, ec);
    throw IoError(path + ": write failed");
  }
}

// Display-referred RGB in [0, 1] (non-finite -> 0) as 8-bit codes, rounded to nearest.
std::vector<unsigned char> ToBytes(const std::vector<float>& rgb) {
  std::vector<unsigned char> bytes(rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) {
    const float v = std::isfinite(rgb[i]) ? std::min(std::max(rgb[i], 0.0f), 1.0f) : 0.0f;
    bytes[i] = static_cast<unsigned char>(std::lround(v * 255.0f));
  }
  return bytes;
}

// An sRGB-tagged 8-bit RGB PNG (render/scene/png.h). Throws IoError naming `what`.
std::string EncodePng8AsString(int width, int height, const std::vector<float>& rgb,
                               const std::string& what) {
  try {
    return EncodePng(width, height, 3, ToBytes(rgb), /*srgb_chunk=*/true);
  } catch (const std::exception& e) {
    throw IoError(what + ": PNG encoding failed: " + e.what());
  }
}

// OpenEXR reads some attribute types by their content, not by their declared size (a channel
// list runs to its empty name; fixed-size types read their own size; a preview reads width x
// height x 4 bytes), and sizes buffers from dataWindow before any pixel is read. A forged
// header whose declared sizes disagree with the content desynchronises OpenEXR's parse from
// ours, and a forged dataWindow or sampling makes it allocate line tables and buffers of up to
// gigabytes before failing (found by fuzz_image_exr). So each such attribute must hold exactly
// what its type reads, and the data window must fit the image limits. Sizes: OpenEXR file
// layout, "Header attributes" (openexr.com/en/latest/OpenEXRFileLayout.html).
// Pixels in one EXR tile at most (real files use 32x32 to 256x256): 1024 x 1024 x kMaxChannels
// float samples are 256 MiB, within kMaxImageBytes. A forged tile of 67108868 x 4 made OpenEXR
// allocate 1.6 GB for one tile's buffers (found by fuzz_image_exr in session 16; OpenImageIO
// took 3.3 GB and 17 s on the same file).
constexpr uint64_t kMaxTilePixels = uint64_t(1) << 20;

// What CheckContainer gathers from the header for the checks that combine attributes.
struct ExrHeaderSizes {
  uint64_t channels = 0, tile_x = 0, tile_y = 0, width = 0;
};

template <class Fail>
void CheckExrAttribute(std::string_view v, const std::string& name, const std::string& type,
                       const std::string& shown, const Fail& fail, ExrHeaderSizes* sizes) {
  auto i32 = [&](size_t at) {
    return int32_t(uint32_t(uint8_t(v[at])) | uint32_t(uint8_t(v[at + 1])) << 8 |
                   uint32_t(uint8_t(v[at + 2])) << 16 | uint32_t(uint8_t(v[at + 3])) << 24);
  };
  auto need = [&](size_t bytes) {
    if (v.size() != bytes)
      fail("EXR header attribute '" + shown + "' of type " + limits::EscapeForMessage(type, 32) +
           " declares " + std::to_string(v.size()) + " bytes but its type holds " +
           std::to_string(bytes));
  };
  static const std::pair<const char*, size_t> kFixed[] = {
      {"box2i", 16}, {"box2f", 16}, {"chromaticities", 32}, {"compression", 1}, {"double", 8},
      {"envmap", 1}, {"float", 4}, {"int", 4}, {"keycode", 28}, {"lineOrder", 1}, {"m33f", 36},
      {"m33d", 72}, {"m44f", 64}, {"m44d", 128}, {"rational", 8}, {"tiledesc", 9},
      {"timecode", 8}, {"v2i", 8}, {"v2f", 8}, {"v2d", 16}, {"v3i", 12}, {"v3f", 12},
      {"v3d", 24}, {"deepImageState", 1}};
  for (const auto& [t, bytes] : kFixed)
    if (type == t) need(bytes);
  if (type == "chlist") {  // (name \0, int32 type, u8 pLinear, 3 reserved, int32 xs, int32 ys)* \0
    size_t p = 0;
    uint64_t count = 0;
    for (;;) {
      const size_t end = v.find('\0', p);
      if (end == std::string_view::npos) fail("EXR channel list '" + shown + "' has no end");
      if (end == p) { p = end + 1; break; }
      p = end + 1;
      if (p + 16 > v.size()) fail("EXR channel list '" + shown + "' is truncated");
      const int32_t pixel_type = i32(p), xs = i32(p + 8), ys = i32(p + 12);
      if (pixel_type < 0 || pixel_type > 2 || xs < 1 || ys < 1 || xs > kMaxDimension ||
          ys > kMaxDimension)
        fail("EXR channel list '" + shown + "' has a channel with pixel type " +
             std::to_string(pixel_type) + " and sampling " + std::to_string(xs) + "x" +
             std::to_string(ys) + " (types 0-2, sampling 1-" + std::to_string(kMaxDimension) + ")");
      p += 16;
      // Refused here, before OpenEXR (whose channel lookups and per-pixel buffers grow with the
      // count) or our own channel ordering see the list.
      sizes->channels = std::max(sizes->channels, ++count);
      if (count > uint64_t(kMaxChannels))
        fail("EXR channel list '" + shown + "' has more than " + std::to_string(kMaxChannels) +
             " channels (kMaxChannels)");
    }
    need(p);
  }
  if (type == "preview") {
    if (v.size() < 8) need(8);
    const uint64_t w = uint32_t(i32(0)), h = uint32_t(i32(4));
    if (w != 0 && h > (v.size() - 8) / 4 / w)  // 8 + 4 w h would exceed the declared size
      fail("EXR preview '" + shown + "' claims " + std::to_string(w) + "x" + std::to_string(h) +
           " pixels in " + std::to_string(v.size()) + " bytes");
    need(size_t(8 + 4 * w * h));
  }
  if (type == "tiledesc") {  // uint32 xSize, ySize, u8 mode: OpenEXR sizes its tile buffers by them
    const uint64_t tx = uint32_t(i32(0)), ty = uint32_t(i32(4));
    if (tx < 1 || ty < 1 || tx > uint64_t(kMaxDimension) || ty > uint64_t(kMaxDimension) ||
        tx * ty > kMaxTilePixels)
      fail("EXR tile size " + std::to_string(tx) + "x" + std::to_string(ty) + " is outside 1-" +
           std::to_string(kMaxDimension) + " per side and " + std::to_string(kMaxTilePixels) +
           " pixels per tile");
    sizes->tile_x = tx;
    sizes->tile_y = ty;
  }
  if (name == "dataWindow" && type == "box2i") {
    const int64_t w = int64_t(i32(8)) - i32(0) + 1, h = int64_t(i32(12)) - i32(4) + 1;
    if (w < 1 || h < 1 || w > kMaxDimension || h > kMaxDimension)
      fail("EXR " + name + " is " + std::to_string(w) + "x" + std::to_string(h) +
           " (limit 1-" + std::to_string(kMaxDimension) + " per side)");
    sizes->width = uint64_t(w);
  }
}

// Validate before the decoder allocates (docs/reliability.md): libpng and OpenEXR allocate a
// chunk's or header attribute's *declared* length (up to 2 GiB) before reading it, so a few
// hundred forged bytes requested 1.7 GB (found by fuzz_image_png / fuzz_image_exr). Every
// declared length must fit in what remains of the real file. Returns the format of the file's
// magic bytes ("openexr", "png", "hdr"); anything but EXR, PNG and Radiance HDR (the formats
// clothfit reads) is refused.
std::string CheckContainer(const std::string& path, const std::string& shown, size_t file_bytes) {
  std::ifstream f(path, std::ios::binary);
  unsigned char head[8] = {};
  if (!f.read(reinterpret_cast<char*>(head), std::min<std::streamsize>(8, std::streamsize(file_bytes))))
    f.clear();
  auto fail = [&](const std::string& what) {
    throw IoError(shown + ": " + what + " (truncated or forged; docs/reliability.md)");
  };
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (file_bytes >= 8 && std::equal(head, head + 8, kPng)) {
    // Chunks: 4-byte big-endian length, 4-byte type, data, 4-byte CRC; IEND ends the list.
    size_t pos = 8;
    for (size_t n = 0; pos + 12 <= file_bytes; ++n) {
      unsigned char c[8];
      f.seekg(std::streamoff(pos));
      if (!f.read(reinterpret_cast<char*>(c), 8)) break;
      const size_t len = (size_t(c[0]) << 24) | (size_t(c[1]) << 16) | (size_t(c[2]) << 8) | c[3];
      const std::string type = limits::EscapeForMessage(
          std::string_view(reinterpret_cast<const char*>(c + 4), 4), 16);
      if (len > file_bytes - pos - 12)
        fail("PNG chunk '" + type + "' at byte " + std::to_string(pos) + " claims " +
             std::to_string(len) + " bytes but only " + std::to_string(file_bytes - pos - 12) +
             " remain");
      if (n > (size_t(1) << 20)) fail("PNG has over 2^20 chunks");
      if (std::memcmp(c + 4, "IEND", 4) == 0) break;
      pos += 12 + len;
    }
    return "png";
  }
  if (file_bytes >= 8 && head[0] == 0x76 && head[1] == 0x2f && head[2] == 0x31 && head[3] == 0x01) {
    // Header(s): attributes "name\0type\0" + int32 little-endian size + value, an empty name
    // ends a header; a multi-part file (version flag 0x1000) ends its header list with an
    // empty header. Only the first 16 MiB are checked (real headers are a few KB).
    const bool multipart = (head[5] & 0x10) != 0;
    const size_t window = std::min(file_bytes, size_t(16) << 20);
    std::string buf(window, '\0');
    f.seekg(0);
    f.read(buf.data(), std::streamsize(window));
    buf.resize(size_t(f.gcount()));
    size_t pos = 8;
    auto cstr = [&](std::string* out) {  // false when the string runs past the window
      const size_t end = buf.find('\0', pos);
      if (end == std::string::npos || end - pos > 255) return false;
      *out = buf.substr(pos, end - pos);
      pos = end + 1;
      return true;
    };
    // The whole header must lie in the window: an attribute or string that runs past it would
    // let a padded header (a 16 MiB comment, then a forged tile size or channel list) skip the
    // checks below.
    const std::string past = "EXR header does not end within the first " +
                             std::to_string(window) + " bytes of the file";
    ExrHeaderSizes sizes;
    for (bool first = true;; first = false) {
      size_t attributes = 0;
      std::string name, type;
      for (;;) {
        if (!cstr(&name)) fail(past);
        if (name.empty()) break;
        if (!cstr(&type) || pos + 4 > buf.size()) fail(past);
        const uint32_t u = uint32_t(uint8_t(buf[pos])) | uint32_t(uint8_t(buf[pos + 1])) << 8 |
                           uint32_t(uint8_t(buf[pos + 2])) << 16 | uint32_t(uint8_t(buf[pos + 3])) << 24;
        pos += 4;
        const std::string shown_name = limits::EscapeForMessage(name, 64);
        if (u > file_bytes - pos)
          fail("EXR header attribute '" + shown_name + "' claims " +
               std::to_string(int32_t(u)) + " bytes but only " + std::to_string(file_bytes - pos) +
               " remain");
        if (u > buf.size() - pos) fail(past);
        CheckExrAttribute(std::string_view(buf).substr(pos, u), name, type, shown_name, fail,
                          &sizes);
        pos += u;
        ++attributes;
      }
      if (!multipart || (attributes == 0 && !first)) break;
    }
    // OpenEXR's tiled reader keeps two tile buffers per thread and, for a scanline frame buffer,
    // a cache of width x tile height samples per channel: bound both in samples (4 bytes each).
    // Real files: 64 x 64 tiles x 4 channels = 2^14 samples per tile.
    constexpr uint64_t kMaxTileSamples = uint64_t(1) << 22;  // 16 MiB of floats per tile
    const uint64_t ch = std::max<uint64_t>(sizes.channels, 1);
    if (sizes.tile_x > 0 && (sizes.tile_x * sizes.tile_y * ch > kMaxTileSamples ||
                             sizes.width * sizes.tile_y * ch > uint64_t(limits::kMaxImageBytes) / 4))
      fail("EXR tiles of " + std::to_string(sizes.tile_x) + "x" + std::to_string(sizes.tile_y) +
           " with " + std::to_string(ch) + " channels and width " + std::to_string(sizes.width) +
           " exceed the tile budget (" + std::to_string(kMaxTileSamples) +
           " samples per tile, width x tile height x channels <= kMaxImageBytes / 4)");
    return "openexr";
  }
  if (file_bytes >= 2 && head[0] == '#' && head[1] == '?') return "hdr";
  throw IoError(shown + ": not an EXR, PNG or Radiance HDR file (the image formats clothfit reads)");
}

}  // namespace

// ---- EXR input (OpenEXR) --------------------------------------------------------------------
//
// As OpenImageIO 2.4 presented EXRs (the reader clothfit used before session 16):
//  - the first part of a multi-part file; its data window is the image (top row = min y);
//  - channels HALF and FLOAT as float (exact), UINT as code * (1/4294967295) in float
//    arithmetic (float_source = false);
//  - channels in OpenImageIO's canonical order, not the file's alphabetical one: grouped by
//    layer (the name up to and including its last '.', "" first, byte order), within a layer
//    the reserved names first in the order R Red G Green B Blue Y real imag A Alpha AR RA AG GA
//    AB BA Z Depth Zback (case-insensitive), or, when the layer has an X and a Y or Z,
//    R Red G Green B Blue X Y Z real imag A Alpha AR RA AG GA AB BA Depth Zback; then the
//    others by name. E.g. A B G R fabric half.B half.G half.R -> R G B A fabric half.R half.G
//    half.B, and N.X N.Y N.Z stays X Y Z;
//  - source_format: "half" or "float" or "uint" when all channels agree, else "float";
//  - metadata: every attribute of type string or int (as decimal text), under its name in the
//    file (clothfit:*) or OpenImageIO's for it (kRenamed: capDate is DateTime). Attributes of
//    other types are not copied: no consumer reads them (clothfit writes strings only).
// Subsampled channels are refused, as OpenImageIO refused them.
namespace internal {
namespace {

struct ExrChannel {
  std::string name, layer, suffix;
  Imf::PixelType type = Imf::FLOAT;
  int rank = 10000;  // position among the reserved names of its layer (10000: not reserved)
};

bool EqualIgnoringCase(const std::string& a, std::string_view b) {
  return a.size() == b.size() &&
         std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

int ReservedRank(const std::string& suffix, bool xyz_layer) {
  static constexpr std::string_view kUsual[] = {
      "R", "Red", "G", "Green", "B", "Blue", "Y", "real", "imag", "A", "Alpha", "AR", "RA", "AG",
      "GA", "AB", "BA", "Z", "Depth", "Zback"};
  static constexpr std::string_view kXyz[] = {
      "R", "Red", "G", "Green", "B", "Blue", "X", "Y", "Z", "real", "imag", "A", "Alpha", "AR",
      "RA", "AG", "GA", "AB", "BA", "Depth", "Zback"};
  const auto* begin = xyz_layer ? std::begin(kXyz) : std::begin(kUsual);
  const auto* end = xyz_layer ? std::end(kXyz) : std::end(kUsual);
  for (const auto* r = begin; r != end; ++r)
    if (EqualIgnoringCase(suffix, *r)) return int(r - begin);
  return 10000;
}

// EXR attribute names OpenImageIO gave other names to ("" = not metadata: the part's type).
// WriteExr maps the first three back, as OpenImageIO's writer did.
constexpr std::pair<std::string_view, std::string_view> kRenamed[] = {
    {"capDate", "DateTime"},
    {"comments", "ImageDescription"},
    {"owner", "Copyright"},
    {"name", "oiio:subimagename"},
    {"chunkCount", "openexr:chunkCount"},
    {"maxSamplesPerPixel", "openexr:maxSamplesPerPixel"},
    {"type", ""}};

std::string MetadataName(const std::string& exr_name) {
  for (const auto& [exr, ours] : kRenamed)
    if (exr_name == exr) return std::string(ours);
  return exr_name;
}

std::string ExrAttributeName(const std::string& metadata_name) {
  for (size_t k = 0; k < 3; ++k)
    if (metadata_name == kRenamed[k].second) return std::string(kRenamed[k].first);
  return metadata_name;
}

std::vector<ExrChannel> CanonicalOrder(const Imf::ChannelList& list) {
  std::vector<ExrChannel> ch;
  for (auto it = list.begin(); it != list.end(); ++it) {
    ExrChannel c;
    c.name = it.name();
    const size_t dot = c.name.find_last_of('.');
    c.layer = dot == std::string::npos ? std::string() : c.name.substr(0, dot + 1);
    c.suffix = dot == std::string::npos ? c.name : c.name.substr(dot + 1);
    c.type = it.channel().type;
    ch.push_back(std::move(c));
  }
  auto has = [&](const std::string& layer, std::string_view suffix) {
    for (const ExrChannel& c : ch)
      if (c.layer == layer && EqualIgnoringCase(c.suffix, suffix)) return true;
    return false;
  };
  for (ExrChannel& c : ch) {
    const bool xyz = has(c.layer, "X") && (has(c.layer, "Y") || has(c.layer, "Z"));
    c.rank = ReservedRank(c.suffix, xyz);
  }
  std::sort(ch.begin(), ch.end(), [](const ExrChannel& a, const ExrChannel& b) {
    return std::tie(a.layer, a.rank, a.suffix) < std::tie(b.layer, b.rank, b.suffix);
  });
  return ch;
}

class ExrReader : public ImageReader {
 public:
  ExrReader(const std::string& path, const std::string& shown) : shown_(shown) {
    UseExrThreads();
    try {
      file_ = std::make_unique<Imf::InputFile>(path.c_str());
    } catch (const std::exception& e) {
      throw IoError(shown_ + ": cannot read image: " + limits::EscapeForMessage(e.what(), 400));
    }
    const Imf::Header& header = file_->header();
    window_ = header.dataWindow();
    width = int(std::min<int64_t>(int64_t(window_.max.x) - window_.min.x + 1, std::numeric_limits<int>::max()));
    height = int(std::min<int64_t>(int64_t(window_.max.y) - window_.min.y + 1, std::numeric_limits<int>::max()));
    channels_ = CanonicalOrder(header.channels());
    if (channels_.empty()) throw IoError(shown_ + ": cannot read image: no channels");
    bool all_half = true, all_uint = true;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it)
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
        throw IoError(shown_ + ": cannot read image: channel '" +
                      limits::EscapeForMessage(it.name(), 64) + "' is subsampled (" +
                      std::to_string(it.channel().xSampling) + "x" +
                      std::to_string(it.channel().ySampling) + "), which clothfit does not read");
    for (const ExrChannel& c : channels_) {
      channel_names.push_back(c.name);
      sample_bytes.push_back(c.type == Imf::HALF ? 2 : 4);
      all_half = all_half && c.type == Imf::HALF;
      all_uint = all_uint && c.type == Imf::UINT;
      if (c.type == Imf::UINT) float_source = false;
    }
    source_format = all_half ? "half" : all_uint ? "uint" : "float";
    file_format = "openexr";
    for (auto it = header.begin(); it != header.end(); ++it) {
      const std::string name = MetadataName(it.name());
      if (name.empty()) continue;
      if (const auto* a = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
        metadata[name] = a->value();
      else if (const auto* i = dynamic_cast<const Imf::IntAttribute*>(&it.attribute()))
        metadata[name] = std::to_string(i->value());
    }
  }

  void Read(float* out) override {
    const size_t w = size_t(width), h = size_t(height), nc = channels_.size();
    std::vector<uint32_t> codes;  // UINT channels, converted below
    size_t uint_channels = 0;
    for (const ExrChannel& c : channels_) uint_channels += c.type == Imf::UINT;
    try {
      codes.resize(w * h * uint_channels);
      Imf::FrameBuffer fb;
      size_t u = 0;
      for (size_t k = 0; k < nc; ++k) {
        if (channels_[k].type == Imf::UINT)
          fb.insert(channels_[k].name, Imf::Slice::Make(Imf::UINT, codes.data() + u++, window_,
                                                        sizeof(uint32_t) * uint_channels,
                                                        sizeof(uint32_t) * uint_channels * w));
        else
          fb.insert(channels_[k].name, Imf::Slice::Make(Imf::FLOAT, out + k, window_,
                                                        sizeof(float) * nc, sizeof(float) * nc * w));
      }
      file_->setFrameBuffer(fb);
      file_->readPixels(window_.min.y, window_.max.y);
    } catch (const std::bad_alloc&) {
      throw;
    } catch (const std::exception& e) {
      throw IoError(shown_ + ": corrupt or truncated image: " + limits::EscapeForMessage(e.what(), 400));
    }
    if (uint_channels == 0) return;
    // OpenImageIO's integer-to-float rule: the full range maps to [0, 1].
    const float scale = 1.0f / float(std::numeric_limits<uint32_t>::max());
    for (size_t k = 0, u = 0; k < nc; ++k) {
      if (channels_[k].type != Imf::UINT) continue;
      for (size_t p = 0; p < w * h; ++p)
        out[p * nc + k] = float(codes[p * uint_channels + u]) * scale;
      ++u;
    }
  }

 private:
  std::string shown_;
  std::unique_ptr<Imf::InputFile> file_;
  Imath::Box2i window_;
  std::vector<ExrChannel> channels_;
};

}  // namespace

std::unique_ptr<ImageReader> OpenExr(const std::string& path, const std::string& shown) {
  return std::make_unique<ExrReader>(path, shown);
}

}  // namespace internal

// ---- public ---------------------------------------------------------------------------------

void WriteExr(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 || image.channels() <= 0 ||
      image.pixels.size() != size_t(image.width) * image.height * image.channels()) {
    throw IoError(path + ": refusing to write an image with inconsistent size");
  }
  RequireOutputDirectory(path);
  UseExrThreads();
  const std::string tmp = TempPathFor(path);
  // The header OpenImageIO wrote before session 16: FLOAT channels, ZIP (16 scanlines, zlib
  // level 4), increasing Y, the default windows and aspect, capDate (local time, "YYYY:MM:DD
  // HH:MM:SS"), and the metadata as string attributes.
  try {
    Imf::Header header(image.width, image.height);
    header.compression() = Imf::ZIP_COMPRESSION;
    header.zipCompressionLevel() = 4;
    header.lineOrder() = Imf::INCREASING_Y;
    const size_t nc = size_t(image.channels());
    for (const std::string& name : image.channel_names)
      header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    size_t distinct = 0;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) ++distinct;
    if (distinct != nc)
      throw IoError(path + ": refusing to write an EXR with repeated channel names");
    std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    char date[64];
    std::snprintf(date, sizeof date, "%4d:%02d:%02d %02d:%02d:%02d", local.tm_year + 1900,
                  local.tm_mon + 1, local.tm_mday, local.tm_hour, local.tm_min, local.tm_sec);
    header.insert("capDate", Imf::StringAttribute(date));  // replaced by a DateTime entry
    for (const auto& [k, v] : image.metadata)
      header.insert(internal::ExrAttributeName(k), Imf::StringAttribute(v));
    Imf::FrameBuffer fb;
    const size_t w = size_t(image.width);
    for (size_t k = 0; k < nc; ++k)
      fb.insert(image.channel_names[k],
                Imf::Slice(Imf::FLOAT, const_cast<char*>(reinterpret_cast<const char*>(image.pixels.data() + k)),
                           sizeof(float) * nc, sizeof(float) * nc * w));
    Imf::OutputFile out(tmp.c_str(), header);
    out.setFrameBuffer(fb);
    out.writePixels(image.height);
  } catch (const std::exception& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    if (dynamic_cast<const IoError*>(&e)) throw;
    throw IoError(path + ": write failed: " + e.what());
  }
  RenameInto(tmp, path);
}

Image ReadImage(const std::string& path) {
  const std::string shown = limits::EscapeForMessage(path, 400);
  // The real file first: a regular, non-empty file within the byte budget (this also refuses
  // /proc files, FIFOs and devices, which a decoder would read without end).
  size_t file_bytes = 0;
  try {
    file_bytes = limits::CheckedFileSize(path, limits::kMaxImageFileBytes, "image file");
  } catch (const limits::InputError& e) {
    throw IoError(e.what());
  }
  // The decoder for the file's magic bytes only, after the container's declared lengths were
  // checked against the file; it reads the header, nothing is allocated for pixels yet.
  const std::string format = CheckContainer(path, shown, file_bytes);
  const std::unique_ptr<internal::ImageReader> in =
      format == "openexr" ? internal::OpenExr(path, shown)
      : format == "png"   ? internal::OpenPng(path, shown)
                          : internal::OpenRgbe(path, shown, file_bytes);
  const int nchannels = int(in->channel_names.size());
  if (in->width <= 0 || in->height <= 0 || in->width > kMaxDimension ||
      in->height > kMaxDimension || nchannels <= 0 || nchannels > kMaxChannels) {
    throw IoError(shown + ": unsupported image size " + std::to_string(in->width) + "x" +
                  std::to_string(in->height) + "x" + std::to_string(nchannels) + " (limits " +
                  std::to_string(kMaxDimension) + " per side, " + std::to_string(kMaxChannels) +
                  " channels)");
  }
  // Validate before allocating: the decoded float image must fit the per-image budget...
  const size_t w = size_t(in->width), h = size_t(in->height), c = size_t(nchannels);
  const auto bytes = limits::CheckedProduct({w, h, c, sizeof(float)});
  if (!bytes || *bytes > limits::kMaxImageBytes) {
    throw IoError(shown + ": image " + std::to_string(w) + "x" + std::to_string(h) + "x" +
                  std::to_string(c) + " needs " +
                  std::to_string(bytes ? *bytes >> 20 : std::numeric_limits<size_t>::max() >> 20) +
                  " MiB as float, over the limit of " +
                  std::to_string(limits::kMaxImageBytes >> 20) + " MiB per image " +
                  limits::LimitRef("kMaxImageBytes"));
  }
  // ...and a PNG cannot hold more than deflate's maximum expansion of its file: a forged header
  // on a few bytes of data is refused here instead of costing a zero-filled giant buffer.
  if (in->file_format == "png") {
    size_t sample_bytes = 0;
    for (size_t b : in->sample_bytes) sample_bytes += b;
    const auto raw = limits::CheckedMul(h, 1 + w * sample_bytes);  // filter byte per row
    const size_t can_hold = limits::kMaxPngExpansion * file_bytes + (size_t(64) << 10);
    if (!raw || *raw > can_hold)
      throw IoError(shown + ": PNG header claims " + std::to_string(w) + "x" + std::to_string(h) +
                    "x" + std::to_string(c) + " but the file has only " +
                    std::to_string(file_bytes) +
                    " bytes (truncated or forged; deflate expands at most " +
                    std::to_string(limits::kMaxPngExpansion) + ":1) " +
                    limits::LimitRef("kMaxPngExpansion"));
  }
  Image img;
  img.width = in->width;
  img.height = in->height;
  img.channel_names = in->channel_names;
  img.float_source = in->float_source;
  img.source_format = in->source_format;
  img.file_format = in->file_format;
  img.metadata = in->metadata;
  try {
    img.pixels.resize(w * h * c);
    in->Read(img.pixels.data());
  } catch (const std::bad_alloc&) {
    throw IoError(shown + ": out of memory decoding a " + std::to_string(w) + "x" +
                  std::to_string(h) + "x" + std::to_string(c) + " image " +
                  limits::LimitRef("kMaxImageBytes"));
  }
  return img;
}

Image TableToImage(const Table2D& t, const std::vector<std::string>& names) {
  Image img;
  img.width = t.width;
  img.height = t.height;
  img.channel_names = names;
  img.pixels = t.data;
  img.metadata["clothfit:u_axis"] = "x (columns, left to right): " + t.u_axis;
  img.metadata["clothfit:v_axis"] = "y (rows, top to bottom): " + t.v_axis;
  img.metadata["clothfit:texel_centres"] = "texel i holds the value at (i + 0.5) / N";
  img.metadata["clothfit:filtering"] = "bilinear, clamp to edge";
  return img;
}

Table2D ImageToTable(const Image& img) {
  Table2D t(img.width, img.height, img.channels());
  t.data = img.pixels;
  auto get = [&](const char* k) {
    auto it = img.metadata.find(k);
    return it == img.metadata.end() ? std::string() : it->second;
  };
  t.u_axis = get("clothfit:u_axis");
  t.v_axis = get("clothfit:v_axis");
  return t;
}

void WritePng8(const std::string& path, int width, int height, const std::vector<float>& rgb) {
  if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * size_t(height) * 3)
    throw IoError(path + ": refusing to write a PNG with inconsistent size");
  RequireOutputDirectory(path);
  const std::string png = EncodePng8AsString(width, height, rgb, path);
  const std::string tmp = TempPathFor(path);
  WriteBytes(path, tmp, png);
  RenameInto(tmp, path);
}

std::vector<unsigned char> EncodePng8(int width, int height, const std::vector<float>& rgb,
                                      const std::string& what) {
  if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * size_t(height) * 3)
    throw IoError(what + ": refusing to encode a PNG with inconsistent size");
  const std::string png = EncodePng8AsString(width, height, rgb, what);
  return std::vector<unsigned char>(png.begin(), png.end());
}

void RequireOutputDirectory(const std::string& path) {
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent))
    throw IoError(path + ": output directory " + parent.string() + " does not exist");
}

void WriteTextAtomic(const std::string& path, const std::string& text) {
  RequireOutputDirectory(path);
  const std::string tmp = TempPathFor(path);
  {
    std::ofstream f(tmp, std::ios::binary);
    if (!f) throw IoError(path + ": cannot open for writing");
    f << text;
    f.flush();
    if (!f) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw IoError(path + ": write failed");
    }
  }
  RenameInto(tmp, path);
}


ReferenceHalves ReferenceHalvesFromImage(const Image& image, const std::string& what) {
  auto channel = [&](const std::string& name) {
    for (size_t i = 0; i < image.channel_names.size(); ++i)
      if (image.channel_names[i] == name) return int(i);
    throw IoError(what + ": no channel '" + name +
                  "' (half images need a reference rendered by renderer version >= 4)");
  };
  auto field = [&](const std::string& key) {
    const auto it = image.metadata.find(key);
    if (it == image.metadata.end()) throw IoError(what + ": no metadata '" + key + "'");
    size_t used = 0;
    int v = 0;
    try {
      v = std::stoi(it->second, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != it->second.size())
      throw IoError(what + ": metadata '" + key + "' = '" + limits::EscapeForMessage(it->second, 64) +
                    "' is not an integer");
    return v;
  };
  ReferenceHalves h;
  h.width = image.width;
  h.height = image.height;
  h.batches = field("clothfit:batches");
  h.half_batches = field("clothfit:half_batches");
  if (!(h.half_batches >= 1 && h.batches - h.half_batches >= 1))
    throw IoError(what + ": metadata clothfit:half_batches = " + std::to_string(h.half_batches) +
                  " and clothfit:batches = " + std::to_string(h.batches) +
                  " do not give two non-empty halves");
  const int mean[3] = {channel("R"), channel("G"), channel("B")};
  const int half[3] = {channel("half.R"), channel("half.G"), channel("half.B")};
  const size_t np = size_t(image.width) * size_t(image.height), nc = image.channel_names.size();
  h.a.resize(np * 3);
  h.b.resize(np * 3);
  const double K = h.batches, kA = h.half_batches;
  for (size_t p = 0; p < np; ++p)
    for (size_t c = 0; c < 3; ++c) {
      const double m = double(image.pixels[p * nc + size_t(mean[c])]);
      const double a = double(image.pixels[p * nc + size_t(half[c])]);
      h.a[p * 3 + c] = float(a);
      h.b[p * 3 + c] = float((K * m - kA * a) / (K - kA));
    }
  return h;
}

}  // namespace clothfit::io
