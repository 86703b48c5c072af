#include "render/scene/image_io.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <random>

#include "render/scene/input_limits.h"

namespace clothfit::io {
namespace fs = std::filesystem;
namespace {

std::string TempPathFor(const std::string& path) {
  // Same directory (rename is atomic only within a filesystem), unique per process and call.
  static std::atomic<unsigned> counter{0};
  const fs::path p(path);
  const std::string name = "." + p.filename().string() + ".tmp." + std::to_string(::getpid()) +
                           "." + std::to_string(counter++);
  // Keep the extension last so OIIO picks the right writer.
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

// Writes `pixels` to the temporary file `tmp` with OpenImageIO; removes it on failure.
void WriteWithOiio(const std::string& path, const std::string& tmp, const OIIO::ImageSpec& spec,
                   OIIO::TypeDesc type, const void* pixels) {
  auto out = OIIO::ImageOutput::create(tmp);
  if (!out) throw IoError(path + ": cannot create an image writer: " + OIIO::geterror());
  if (!out->open(tmp, spec)) throw IoError(path + ": cannot open for writing: " + out->geterror());
  const bool ok = out->write_image(type, pixels);
  const bool closed = out->close();
  if (!ok || !closed) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw IoError(path + ": write failed: " + out->geterror());
  }
}

}  // namespace

void WriteExr(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 || image.channels() <= 0 ||
      image.pixels.size() != size_t(image.width) * image.height * image.channels()) {
    throw IoError(path + ": refusing to write an image with inconsistent size");
  }
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent)) {
    throw IoError(path + ": output directory " + parent.string() + " does not exist");
  }
  const std::string tmp = TempPathFor(path);
  OIIO::ImageSpec spec(image.width, image.height, image.channels(), OIIO::TypeDesc::FLOAT);
  spec.channelnames = image.channel_names;
  spec.attribute("compression", "zip");
  for (const auto& [k, v] : image.metadata) spec.attribute(k, v);
  WriteWithOiio(path, tmp, spec, OIIO::TypeDesc::FLOAT, image.pixels.data());
  RenameInto(tmp, path);
}

Image ReadImage(const std::string& path) {
  const std::string shown = limits::EscapeForMessage(path, 400);
  // The real file first: a regular, non-empty file within the byte budget (this also refuses
  // /proc files, FIFOs and devices, which OIIO would read without end).
  size_t file_bytes = 0;
  try {
    file_bytes = limits::CheckedFileSize(path, limits::kMaxImageFileBytes, "image file");
  } catch (const limits::InputError& e) {
    throw IoError(e.what());
  }
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw IoError(shown + ": cannot read image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.width > kMaxDimension ||
      spec.height > kMaxDimension || spec.nchannels <= 0 || spec.nchannels > kMaxChannels ||
      spec.depth != 1) {
    throw IoError(shown + ": unsupported image size " + std::to_string(spec.width) + "x" +
                  std::to_string(spec.height) + "x" + std::to_string(spec.nchannels) + " (limits " +
                  std::to_string(kMaxDimension) + " per side, " + std::to_string(kMaxChannels) +
                  " channels)");
  }
  // Validate before allocating: the decoded float image must fit the per-image budget...
  const size_t w = size_t(spec.width), h = size_t(spec.height), c = size_t(spec.nchannels);
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
  if (std::string(in->format_name()) == "png") {
    size_t sample_bytes = 0;
    for (int k = 0; k < spec.nchannels; ++k) sample_bytes += spec.channelformat(k).size();
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
  img.width = spec.width;
  img.height = spec.height;
  img.channel_names = spec.channelnames;
  img.float_source = true;
  for (int k = 0; k < spec.nchannels; ++k)
    if (!spec.channelformat(k).is_floating_point()) img.float_source = false;
  img.source_format = spec.format.c_str();
  img.file_format = in->format_name();
  for (const auto& p : spec.extra_attribs) img.metadata[p.name().string()] = p.get_string();
  try {
    img.pixels.resize(w * h * c);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, img.pixels.data()))
      throw IoError(shown + ": corrupt or truncated image: " +
                    limits::EscapeForMessage(in->geterror(), 400));
  } catch (const std::bad_alloc&) {
    throw IoError(shown + ": out of memory decoding a " + std::to_string(w) + "x" +
                  std::to_string(h) + "x" + std::to_string(c) + " image " +
                  limits::LimitRef("kMaxImageBytes"));
  }
  in->close();
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
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent))
    throw IoError(path + ": output directory " + parent.string() + " does not exist");
  std::vector<unsigned char> bytes(rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) {
    const float v = std::isfinite(rgb[i]) ? std::min(std::max(rgb[i], 0.0f), 1.0f) : 0.0f;
    bytes[i] = static_cast<unsigned char>(std::lround(v * 255.0f));
  }
  const std::string tmp = TempPathFor(path);
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  WriteWithOiio(path, tmp, spec, OIIO::TypeDesc::UINT8, bytes.data());
  RenameInto(tmp, path);
}

std::vector<unsigned char> EncodePng8(int width, int height, const std::vector<float>& rgb,
                                      const std::string& what) {
  if (width <= 0 || height <= 0 || rgb.size() != size_t(width) * size_t(height) * 3)
    throw IoError(what + ": refusing to encode a PNG with inconsistent size");
  std::vector<unsigned char> bytes(rgb.size());
  for (size_t i = 0; i < rgb.size(); ++i) {
    const float v = std::isfinite(rgb[i]) ? std::min(std::max(rgb[i], 0.0f), 1.0f) : 0.0f;
    bytes[i] = static_cast<unsigned char>(std::lround(v * 255.0f));
  }
  std::vector<unsigned char> png;
  OIIO::Filesystem::IOVecOutput proxy(png);
  auto out = OIIO::ImageOutput::create("memory.png");
  if (!out) throw IoError(what + ": cannot create a PNG writer: " + OIIO::geterror());
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  if (!out->set_ioproxy(&proxy) || !out->open("memory.png", spec) ||
      !out->write_image(OIIO::TypeDesc::UINT8, bytes.data()) || !out->close())
    throw IoError(what + ": PNG encoding failed: " + out->geterror());
  if (png.empty()) throw IoError(what + ": PNG encoding produced no data");
  return png;
}

void WriteTextAtomic(const std::string& path, const std::string& text) {
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

}  // namespace clothfit::io
