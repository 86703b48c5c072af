#include "fit/metrics/plot.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "render/scene/image_io.h"

namespace clothfit::fit {

Canvas::Canvas(int width, int height)
    : width_(width), height_(height), rgb_(size_t(width) * size_t(height) * 3, 1.0f) {}

void Canvas::Dot(int x, int y, const Colour& c, int radius) {
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx) {
      const int px = x + dx, py = y + dy;
      if (px < 0 || py < 0 || px >= width_ || py >= height_) continue;
      for (int k = 0; k < 3; ++k) rgb_[(size_t(py) * size_t(width_) + size_t(px)) * 3 + size_t(k)] = c[size_t(k)];
    }
}

void Canvas::Line(int x0, int y0, int x1, int y1, const Colour& c) {
  const int steps = std::max(std::abs(x1 - x0), std::abs(y1 - y0)) + 1;
  for (int i = 0; i <= steps; ++i) {
    const double t = double(i) / steps;
    Dot(int(std::lround(x0 + t * (x1 - x0))), int(std::lround(y0 + t * (y1 - y0))), c, 0);
  }
}

std::string PlotFontPath() {
  if (const char* f = std::getenv("CLOTHFIT_FONT"); f && std::filesystem::exists(f)) return f;
  for (const char* f : {"/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
                        "/usr/share/fonts/TTF/DejaVuSans.ttf"})
    if (std::filesystem::exists(f)) return f;
  return "";
}

bool Canvas::Text(int x, int y, const std::string& text, int size, const Colour& c) {
  static const std::string font = PlotFontPath();
  if (font.empty() || text.empty()) return false;
  OIIO::ImageSpec spec(width_, height_, 3, OIIO::TypeDesc::FLOAT);
  OIIO::ImageBuf buf(spec, rgb_.data());  // wraps our pixels: text is drawn in place
  const float col[3] = {c[0], c[1], c[2]};
  return OIIO::ImageBufAlgo::render_text(buf, x, y, text, size, font, col);
}

void Canvas::WritePng(const std::string& path) const { io::WritePng8(path, width_, height_, rgb_); }

std::vector<double> LinearTicks(double lo, double hi, int count) {
  std::vector<double> ticks;
  if (!(hi > lo) || count < 1) return ticks;
  const double raw = (hi - lo) / count;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * mag >= raw) {
      step = m * mag;
      break;
    }
  for (double v = std::ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step)
    ticks.push_back(std::abs(v) < 1e-12 * step ? 0.0 : v);
  return ticks;
}

std::vector<double> LogTicks(double lo, double hi) {
  std::vector<double> ticks;
  if (!(lo > 0) || !(hi > lo)) return ticks;
  for (double decade = std::pow(10.0, std::floor(std::log10(lo))); decade <= hi; decade *= 10.0)
    for (double m : {1.0, 2.0, 5.0})
      if (m * decade >= lo && m * decade <= hi) ticks.push_back(m * decade);
  return ticks;
}

}  // namespace clothfit::fit
