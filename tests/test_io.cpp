// Image input/output: round trip with metadata, atomic writes, clear errors naming the file;
// what the readers return (render/scene/image_readers.h): OpenImageIO's EXR channel order, PNG
// codes with premultiplied alpha, Radiance HDR flat and run-length encoded scanlines.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "brdf/lut.h"
#include "render/scene/image_io.h"
#include "render/scene/png.h"

namespace clothfit {
namespace {
namespace fs = std::filesystem;

fs::path TempDir() {
  fs::path d = fs::temp_directory_path() / ("clothfit_test_io_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

TEST(ImageIo, TableRoundTripKeepsValuesAndAxisMetadata) {
  const fs::path dir = TempDir();
  Table2D t = lut::ComputeDfg({8});
  io::Image img = io::TableToImage(t, {"R", "G", "B"});
  const std::string path = (dir / "dfg.exr").string();
  io::WriteExr(path, img);
  const io::Image back = io::ReadImage(path);
  ASSERT_EQ(back.width, 8);
  ASSERT_EQ(back.height, 8);
  ASSERT_EQ(back.channels(), 3);
  EXPECT_EQ(back.pixels, img.pixels);
  EXPECT_NE(back.metadata.at("clothfit:u_axis").find("NoV"), std::string::npos);
  EXPECT_NE(back.metadata.at("clothfit:texel_centres").find("(i + 0.5)"), std::string::npos);
  // no temporary file left behind
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
  fs::remove_all(dir);
}

TEST(ImageIo, MissingFileErrorNamesTheFile) {
  try {
    io::ReadImage("/nonexistent/dir/ref.exr");
    FAIL() << "expected an error";
  } catch (const io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/dir/ref.exr"), std::string::npos);
  }
}

TEST(ImageIo, CorruptAndTruncatedFilesGiveErrorsNotCrashes) {
  const fs::path dir = TempDir();
  const std::string junk = (dir / "junk.exr").string();
  {
    std::ofstream f(junk, std::ios::binary);
    f << "this is not an EXR file at all";
  }
  EXPECT_THROW(io::ReadImage(junk), io::IoError);

  // A valid EXR cut in half.
  io::Image img = io::TableToImage(lut::ComputeDfg({32}), {"R", "G", "B"});
  const std::string good = (dir / "good.exr").string();
  io::WriteExr(good, img);
  const auto size = fs::file_size(good);
  const std::string cut = (dir / "cut.exr").string();
  fs::copy_file(good, cut);
  fs::resize_file(cut, size / 2);
  try {
    io::ReadImage(cut);
    FAIL() << "expected an error";
  } catch (const io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.exr"), std::string::npos);
  }
  fs::remove_all(dir);
}

// Forged EXR headers (session 16 review): each is refused by CheckContainer, by name, before
// OpenEXR or the channel ordering sees it. Built here byte by byte (OpenEXR file layout,
// "Header attributes": name \0 type \0 int32 size value, an empty name ends the header).
std::string ExrAttr(const std::string& name, const std::string& type, const std::string& v) {
  std::string a = name + '\0' + type + '\0';
  const uint32_t n = uint32_t(v.size());
  for (int i = 0; i < 4; ++i) a += char((n >> (8 * i)) & 0xff);
  return a + v;
}
std::string Le32(uint32_t x) {
  std::string s;
  for (int i = 0; i < 4; ++i) s += char((x >> (8 * i)) & 0xff);
  return s;
}
std::string ForgedExr(int channels, int width, uint32_t tile_x, uint32_t tile_y, size_t pad) {
  std::string f = Le32(20000630) + Le32(tile_x ? 2 | 0x200 : 2);
  if (pad) f += ExrAttr("comments", "string", std::string(pad, 'x'));
  std::string ch;
  for (int i = 0; i < channels; ++i)
    ch += "c" + std::to_string(i) + '\0' + Le32(2) + std::string(4, '\0') + Le32(1) + Le32(1);
  f += ExrAttr("channels", "chlist", ch + '\0');
  f += ExrAttr("compression", "compression", std::string(1, '\0'));
  const std::string box = Le32(0) + Le32(0) + Le32(uint32_t(width - 1)) + Le32(0);
  f += ExrAttr("dataWindow", "box2i", box) + ExrAttr("displayWindow", "box2i", box);
  f += ExrAttr("lineOrder", "lineOrder", std::string(1, '\0'));
  if (tile_x) f += ExrAttr("tiles", "tiledesc", Le32(tile_x) + Le32(tile_y) + std::string(1, '\0'));
  return f + '\0' + std::string(64, '\0');
}

TEST(ImageIo, ForgedExrHeadersAreRefusedBeforeOpenExr) {
  const fs::path dir = TempDir();
  auto refused = [&](const std::string& file, const std::string& bytes, const std::string& why) {
    const std::string path = (dir / file).string();
    std::ofstream(path, std::ios::binary) << bytes;
    try {
      io::ReadImage(path);
      ADD_FAILURE() << file << ": expected an error";
    } catch (const io::IoError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(file), std::string::npos) << m;
      EXPECT_NE(m.find(why), std::string::npos) << m;
    }
  };
  // 65 channels: over kMaxChannels, refused in the channel list itself.
  refused("channels.exr", ForgedExr(io::kMaxChannels + 1, 4, 0, 0, 0), "more than 64 channels");
  // A 17 MiB comment hides a forged tile size past the 16 MiB the check reads.
  refused("padded.exr", ForgedExr(3, 4, 67108868, 4, size_t(17) << 20), "does not end within");
  // Legal tile sides, but width x tile height x channels would be 64 GiB of OpenEXR's cache.
  refused("wide_tile.exr", ForgedExr(64, 16384, 64, 16384, 0), "tile budget");
  // The same shapes within the limits pass the header check (and fail later only because the
  // forged files carry no pixel data), so the limits are not what refuses the files above.
  for (const auto& [file, bytes] :
       {std::pair<std::string, std::string>{"ok64.exr", ForgedExr(io::kMaxChannels, 4, 0, 0, 0)},
        {"ok_tile.exr", ForgedExr(4, 64, 64, 64, 0)}}) {
    const std::string path = (dir / file).string();
    std::ofstream(path, std::ios::binary) << bytes;
    try {
      io::ReadImage(path);
    } catch (const io::IoError& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find("more than"), std::string::npos) << m;
      EXPECT_EQ(m.find("does not end"), std::string::npos) << m;
      EXPECT_EQ(m.find("tile budget"), std::string::npos) << m;
    }
  }
  fs::remove_all(dir);
}

TEST(ImageIo, WriteIntoMissingDirectoryFailsAndNamesIt) {
  io::Image img = io::TableToImage(lut::ComputeDfg({4}), {"R", "G", "B"});
  try {
    io::WriteExr("/nonexistent/dir/out.exr", img);
    FAIL() << "expected an error";
  } catch (const io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/dir"), std::string::npos);
  }
}

TEST(ImageIo, InconsistentImageIsRefused) {
  io::Image img;
  img.width = 4;
  img.height = 4;
  img.channel_names = {"R"};
  img.pixels.resize(3);
  EXPECT_THROW(io::WriteExr((fs::temp_directory_path() / "x.exr").string(), img), io::IoError);
}

TEST(ImageIo, ExrChannelsComeInOpenImageIoOrder) {
  // The file stores channels sorted by name; the reader lists them by layer, reserved names
  // first (R G B A ... Z), X Y Z kept in a layer that has them.
  const fs::path dir = TempDir();
  io::Image img;
  img.width = 3;
  img.height = 2;
  img.channel_names = {"uv.U", "half.R", "B", "A", "fabric", "R", "G", "N.Z", "N.X", "N.Y", "Z"};
  const size_t nc = img.channel_names.size();
  img.pixels.resize(6 * nc);
  for (size_t p = 0; p < 6; ++p)
    for (size_t c = 0; c < nc; ++c) img.pixels[p * nc + c] = float(100 * c + p);
  const std::string path = (dir / "order.exr").string();
  io::WriteExr(path, img);
  const io::Image back = io::ReadImage(path);
  const std::vector<std::string> want = {"R", "G", "B", "A", "Z", "fabric", "N.X", "N.Y", "N.Z",
                                         "half.R", "uv.U"};
  ASSERT_EQ(back.channel_names, want);
  for (size_t k = 0; k < nc; ++k) {
    const size_t c = size_t(std::find(img.channel_names.begin(), img.channel_names.end(), want[k]) -
                            img.channel_names.begin());
    for (size_t p = 0; p < 6; ++p) EXPECT_EQ(back.pixels[p * nc + k], float(100 * c + p)) << want[k];
  }
  EXPECT_TRUE(back.float_source);
  EXPECT_EQ(back.source_format, "float");
  EXPECT_EQ(back.file_format, "openexr");
  fs::remove_all(dir);
}

TEST(ImageIo, PngCodesAreReadWithAlphaPremultiplied) {
  const fs::path dir = TempDir();
  const std::string path = (dir / "rgba.png").string();
  // Two pixels: (200, 100, 50, a = 128), (255, 7, 0, a = 255); top row first.
  const std::string png = io::EncodePng(1, 2, 4, {200, 100, 50, 128, 255, 7, 0, 255}, false);
  std::ofstream(path, std::ios::binary) << png;
  const io::Image img = io::ReadImage(path);
  ASSERT_EQ(img.channel_names, (std::vector<std::string>{"R", "G", "B", "A"}));
  EXPECT_FALSE(img.float_source);
  EXPECT_EQ(img.source_format, "uint8");
  EXPECT_EQ(img.file_format, "png");
  // floor(c a / 255) in the codes, then code * (1 / 255) in float.
  const int want[8] = {100, 50, 25, 128, 255, 7, 0, 255};
  for (size_t k = 0; k < 8; ++k) EXPECT_EQ(img.pixels[k], float(want[k]) * (1.0f / 255.0f)) << k;
  const std::string grey = (dir / "grey.png").string();
  std::ofstream(grey, std::ios::binary) << io::EncodePng(2, 1, 1, {0, 255}, false);
  const io::Image g = io::ReadImage(grey);
  ASSERT_EQ(g.channel_names, (std::vector<std::string>{"Y"}));
  EXPECT_EQ(g.pixels, (std::vector<float>{0.0f, 255.0f * (1.0f / 255.0f)}));
  fs::remove_all(dir);
}

TEST(ImageIo, RadianceHdrFlatAndRunLengthScanlines) {
  const fs::path dir = TempDir();
  const std::string path = (dir / "sky.hdr").string();
  // 8 x 2: row 0 run-length encoded (R: a run of 8 x 64; G: 8 literals; B: run of 8 x 0;
  // E: run of 8 x 129, i.e. value m * 2^(129 - 136) = m / 128), row 1 flat (8 x (1 2 3 136)).
  std::string f = "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=1\n\n-Y 2 +X 8\n";
  f += std::string("\x02\x02\x00\x08", 4);
  f += std::string("\x88\x40", 2);
  f += std::string("\x08", 1) + std::string("\x00\x01\x02\x03\x04\x05\x06\x07", 8);
  f += std::string("\x88\x00", 2);
  f += std::string("\x88\x81", 2);
  for (int x = 0; x < 8; ++x) f += std::string("\x01\x02\x03\x88", 4);
  std::ofstream(path, std::ios::binary) << f;
  const io::Image img = io::ReadImage(path);
  ASSERT_EQ(img.width, 8);
  ASSERT_EQ(img.height, 2);
  ASSERT_EQ(img.channel_names, (std::vector<std::string>{"R", "G", "B"}));
  EXPECT_TRUE(img.float_source);
  EXPECT_EQ(img.file_format, "hdr");
  for (int x = 0; x < 8; ++x) {
    EXPECT_EQ(img.pixels[size_t(3 * x)], 0.5f);
    EXPECT_EQ(img.pixels[size_t(3 * x + 1)], float(x) / 128.0f);
    EXPECT_EQ(img.pixels[size_t(3 * x + 2)], 0.0f);
    EXPECT_EQ(img.pixels[size_t(24 + 3 * x)], 1.0f);
    EXPECT_EQ(img.pixels[size_t(24 + 3 * x + 2)], 3.0f);
  }
  // The same file without its last scanline: refused before allocating, naming the file.
  std::ofstream(path, std::ios::binary | std::ios::trunc) << f.substr(0, f.size() - 32);
  try {
    io::ReadImage(path);
    FAIL() << "a truncated HDR was read";
  } catch (const io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("sky.hdr"), std::string::npos) << e.what();
  }
  // Another orientation (bottom-up rows): refused by name rather than read upside down.
  std::string up = f;
  up.replace(up.find("-Y 2 +X 8"), 9, "+Y 2 +X 8");
  std::ofstream(path, std::ios::binary | std::ios::trunc) << up;
  try {
    io::ReadImage(path);
    FAIL() << "a bottom-up HDR was read";
  } catch (const io::IoError& e) {
    EXPECT_NE(std::string(e.what()).find("orientation '+Y H +X W'"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace clothfit
