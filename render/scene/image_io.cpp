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
#include <memory>
#include <random>

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
  if (!fs::exists(path)) throw IoError(path + ": no such file");
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw IoError(path + ": cannot read image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.width > kMaxDimension ||
      spec.height > kMaxDimension || spec.nchannels <= 0 || spec.nchannels > kMaxChannels ||
      spec.depth != 1) {
    throw IoError(path + ": unsupported image size " + std::to_string(spec.width) + "x" +
                  std::to_string(spec.height) + "x" + std::to_string(spec.nchannels) + " (limits " +
                  std::to_string(kMaxDimension) + " per side, " + std::to_string(kMaxChannels) +
                  " channels)");
  }
  Image img;
  img.width = spec.width;
  img.height = spec.height;
  img.channel_names = spec.channelnames;
  for (const auto& p : spec.extra_attribs) img.metadata[p.name().string()] = p.get_string();
  img.pixels.resize(size_t(img.width) * img.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, img.pixels.data())) {
    throw IoError(path + ": corrupt or truncated image: " + in->geterror());
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
