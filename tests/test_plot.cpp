// The benchmark plotter: tick choice, text, and the bench-fit CSV/PNG writer.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fit/bench_fit.h"
#include "fit/metrics/plot.h"
#include "render/scene/image_io.h"

namespace clothfit {
namespace {

TEST(Plot, LinearTicksAreRoundAndCoverTheRange) {
  const auto t = fit::LinearTicks(0.0213, 0.0687, 6);
  ASSERT_GE(t.size(), 3u);
  EXPECT_GE(t.front(), 0.0213);
  EXPECT_LE(t.back(), 0.0687);
  const double step = t[1] - t[0];
  // 1-2-5 steps: step / 10^floor(log10 step) is 1, 2 or 5.
  const double m = step / std::pow(10.0, std::floor(std::log10(step)));
  EXPECT_TRUE(std::abs(m - 1) < 1e-9 || std::abs(m - 2) < 1e-9 || std::abs(m - 5) < 1e-9) << m;
  for (size_t i = 1; i < t.size(); ++i) EXPECT_NEAR(t[i] - t[i - 1], step, 1e-12);
  EXPECT_TRUE(fit::LinearTicks(1.0, 1.0, 5).empty());
}

TEST(Plot, LogTicksFollowOneTwoFive) {
  const auto t = fit::LogTicks(0.3, 60.0);
  const std::vector<double> want{0.5, 1, 2, 5, 10, 20, 50};
  ASSERT_EQ(t.size(), want.size());
  for (size_t i = 0; i < t.size(); ++i) EXPECT_NEAR(t[i], want[i], 1e-12);
  EXPECT_TRUE(fit::LogTicks(0.0, 1.0).empty());
}

TEST(Plot, TextDrawsInkWhenAFontIsInstalled) {
  if (fit::PlotFontPath().empty()) GTEST_SKIP() << "no TrueType font installed (fonts-dejavu-core)";
  const std::string path = (std::filesystem::temp_directory_path() / "clothfit_plot_text.png").string();
  fit::Canvas c(120, 40);
  ASSERT_TRUE(c.Text(5, 25, "0.0123", 16, {0, 0, 0}));
  c.WritePng(path);
  const io::Image img = io::ReadImage(path);
  int dark = 0;
  for (size_t i = 0; i < img.pixels.size(); ++i) dark += img.pixels[i] < 0.5f;
  EXPECT_GT(dark, 30);  // glyphs were drawn
  std::filesystem::remove(path);
}

TEST(BenchFit, WritesOneCsvRowPerSettingAndAPlot) {
  std::vector<fit::BenchRow> rows;
  for (int w : {64, 128, 256})
    for (int starts : {1, 2}) {
      fit::BenchRow r;
      r.fabric = "canvas";
      r.setting = {w, -1, 0, starts};
      r.width = w;
      r.level = w == 64 ? 2 : 3;
      r.seconds = 0.01 * w;
      r.error = 0.05 + 1.0 / w;
      r.usable = true;
      rows.push_back(r);
    }
  rows.back().usable = false;
  rows.back().error = std::nan("");
  const auto dir = std::filesystem::temp_directory_path();
  const std::string csv = (dir / "clothfit_bench_fit.csv").string();
  const std::string png = (dir / "clothfit_bench_fit.png").string();
  fit::WriteFitBench(rows, csv, png);
  std::ifstream in(csv);
  std::string header, line;
  std::getline(in, header);
  EXPECT_EQ(header, "fabric,width,level,stride,starts,seconds,error,usable");
  int n = 0;
  while (std::getline(in, line)) ++n;
  EXPECT_EQ(n, 6);
  const io::Image img = io::ReadImage(png);
  EXPECT_GT(img.width, 400);
  std::filesystem::remove(csv);
  std::filesystem::remove(png);
}

}  // namespace
}  // namespace clothfit
