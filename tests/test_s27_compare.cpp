// Session 27: metrics::Compare on a reference whose automatic HDR-FLIP range is not finite (a
// transparent film: RGB 0 around the object, so the median luminance is 0). Every other metric
// is computed; HDR-FLIP is reported unavailable with the reason (CompareResult::
// hdr_flip_unavailable), never thrown for the whole comparison and never a silent number.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "fit/metrics/metrics.h"

namespace clothfit::metrics {
namespace {

// A w x h image, black except a centred square of side `side` with colour (r, g, b).
RgbImage SquareOnBlack(int w, int h, int side, float r, float g, float b) {
  RgbImage img(w, h);
  for (int y = (h - side) / 2; y < (h + side) / 2; ++y)
    for (int x = (w - side) / 2; x < (w + side) / 2; ++x) {
      float* p = &img.rgb[3 * (size_t(y) * size_t(w) + size_t(x))];
      p[0] = r;
      p[1] = g;
      p[2] = b;
    }
  return img;
}

bool HasMap(const CompareResult& r, const std::string& name) {
  return std::any_of(r.maps.begin(), r.maps.end(),
                     [&](const CompareResult::NamedMap& m) { return m.name == name; });
}

TEST(S27Compare, TransparentFilmReferenceGivesEveryMetricButHdrFlip) {
  const RgbImage ref = SquareOnBlack(32, 32, 8, 0.5f, 0.3f, 0.2f);
  const RgbImage test = SquareOnBlack(32, 32, 8, 0.45f, 0.3f, 0.25f);
  CompareResult r;
  ASSERT_NO_THROW(r = Compare(ref, test));
  EXPECT_NE(r.hdr_flip_unavailable.find("median luminance"), std::string::npos)
      << r.hdr_flip_unavailable;
  EXPECT_TRUE(std::isnan(r.hdr_flip));
  EXPECT_TRUE(r.hdr_range_automatic);
  EXPECT_TRUE(std::isinf(r.hdr_range.stop));
  EXPECT_EQ(r.hdr_exposures, 0);
  for (double v : {r.rmse_linear, r.psnr_linear, r.rmse_display, r.psnr_display, r.ssim, r.flip,
                   r.ciede2000_mean, r.ciede2000_p95, r.ciede2000_display_mean,
                   r.ciede2000_display_p95})
    EXPECT_TRUE(std::isfinite(v));
  EXPECT_GT(r.flip, 0.0);
  EXPECT_EQ(r.counts.counted, 32 * 32);
  EXPECT_FALSE(HasMap(r, "hdr_flip"));
  EXPECT_FALSE(HasMap(r, "hdr_flip_exposure"));
  EXPECT_TRUE(HasMap(r, "flip"));
  EXPECT_EQ(r.maps.size(), 6u);

  // An all-black reference: the maximum is 0 too, and the reason says so.
  const CompareResult black = Compare(RgbImage(16, 16), SquareOnBlack(16, 16, 4, 0.1f, 0.1f, 0.1f));
  EXPECT_NE(black.hdr_flip_unavailable.find("maximum luminance"), std::string::npos)
      << black.hdr_flip_unavailable;

  // With the range given, HDR-FLIP is computed as before (the same value HdrFlip gives).
  CompareOptions o;
  o.hdr_range = ExposureRange{-3.0, 2.0};
  const CompareResult given = Compare(ref, test, o);
  EXPECT_TRUE(given.hdr_flip_unavailable.empty());
  EXPECT_FALSE(given.hdr_range_automatic);
  EXPECT_EQ(given.hdr_flip, HdrFlip(ref, test, HdrFlipOptions{o.ppd, o.hdr_range}).value);
  EXPECT_EQ(given.flip, r.flip);  // the other metrics do not depend on HDR-FLIP's fate
  EXPECT_EQ(given.ssim, r.ssim);
  EXPECT_TRUE(HasMap(given, "hdr_flip"));
  EXPECT_EQ(given.maps.size(), 8u);
}

TEST(S27Compare, FiniteAutomaticRangeIsStillUsed) {
  // The square covers more than half of the image: median luminance > 0.
  const RgbImage ref = SquareOnBlack(16, 16, 14, 0.5f, 0.3f, 0.2f);
  const CompareResult r = Compare(ref, SquareOnBlack(16, 16, 14, 0.45f, 0.3f, 0.25f));
  EXPECT_TRUE(r.hdr_flip_unavailable.empty()) << r.hdr_flip_unavailable;
  EXPECT_TRUE(r.hdr_range_automatic);
  EXPECT_TRUE(std::isfinite(r.hdr_flip));
  EXPECT_GT(r.hdr_exposures, 1);
}

}  // namespace
}  // namespace clothfit::metrics
