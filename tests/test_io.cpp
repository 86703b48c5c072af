// EXR input/output: round trip with metadata, atomic writes, clear errors naming the file.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "brdf/lut.h"
#include "render/scene/image_io.h"

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

}  // namespace
}  // namespace clothfit
