// fit/metrics/plot.h: a small raster plotter for benchmark figures (error against time).
//
// Linear RGB in [0, 1] on a white canvas, written as an 8-bit PNG through render/scene/image_io.h.
// Text is rasterised by FreeType (as OpenImageIO's render_text did) with a TrueType font found at
// $CLOTHFIT_FONT or the Debian fonts-dejavu-core path; when no font is found, Text() returns
// false and the plot carries marks without text (the CSV next to it has every number).
#pragma once

#include <array>
#include <string>
#include <vector>

namespace clothfit::fit {

using Colour = std::array<float, 3>;

class Canvas {
 public:
  Canvas(int width, int height);
  int width() const { return width_; }
  int height() const { return height_; }

  void Dot(int x, int y, const Colour& c, int radius);
  void Line(int x0, int y0, int x1, int y1, const Colour& c);
  // Draws `text` with its baseline starting at (x, y), `size` pixels high. Returns false (and
  // draws nothing) when no font is available.
  bool Text(int x, int y, const std::string& text, int size, const Colour& c);
  void WritePng(const std::string& path) const;

 private:
  int width_, height_;
  std::vector<float> rgb_;
};

// Path of the TrueType font the canvas uses ("" when none is installed).
std::string PlotFontPath();

// A "nice" set of tick values covering [lo, hi] (at most about `count` ticks), for linear axes;
// for log axes, the 1-2-5 sequence within [lo, hi].
std::vector<double> LinearTicks(double lo, double hi, int count);
std::vector<double> LogTicks(double lo, double hi);

}  // namespace clothfit::fit
