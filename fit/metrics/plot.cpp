#include "fit/metrics/plot.h"

#include <ft2build.h>
#include FT_FREETYPE_H

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <mutex>

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

namespace {

// Code points of UTF-8 `text`; a byte that does not start a well-formed sequence stands for
// itself (Latin-1).
std::vector<uint32_t> CodePoints(const std::string& text) {
  std::vector<uint32_t> out;
  for (size_t i = 0; i < text.size();) {
    const auto b = static_cast<unsigned char>(text[i]);
    const size_t extra = b >= 0xF0 ? 3 : b >= 0xE0 ? 2 : b >= 0xC0 ? 1 : 0;
    uint32_t cp = extra == 0 ? b : uint32_t(b & (0x3Fu >> extra));
    bool ok = b < 0x80 || (extra > 0 && i + extra < text.size());
    for (size_t k = 1; ok && k <= extra; ++k) {
      const auto cont = static_cast<unsigned char>(text[i + k]);
      ok = (cont & 0xC0) == 0x80;
      cp = (cp << 6) | (cont & 0x3Fu);
    }
    out.push_back(ok ? cp : b);
    i += ok ? extra + 1 : 1;
  }
  return out;
}

}  // namespace

// FreeType, as OpenImageIO's ImageBufAlgo::render_text drew the plots before session 16: the
// face at `size` pixels per em, each glyph's 8-bit coverage bitmap placed at the pen position
// + (bitmap_left, -bitmap_top) with the baseline at y (image rows grow downwards), the pen
// advanced by the glyph's advance (no kerning), a later glyph's coverage replacing an earlier
// one where they overlap; then "over": pixel = colour a + pixel (1 - a), a = coverage / 255.
bool Canvas::Text(int x, int y, const std::string& text, int size, const Colour& c) {
  static const std::string font = PlotFontPath();
  if (font.empty() || text.empty() || size <= 0) return false;
  static FT_Library library = nullptr;
  static std::once_flag once;
  std::call_once(once, [] {
    if (FT_Init_FreeType(&library)) library = nullptr;
  });
  if (!library) return false;
  static std::mutex mutex;  // one FT_Library serves every canvas; FreeType faces are not shared
  const std::lock_guard<std::mutex> lock(mutex);
  FT_Face face = nullptr;
  if (FT_New_Face(library, font.c_str(), 0, &face)) return false;
  if (FT_Set_Pixel_Sizes(face, 0, FT_UInt(size))) {
    FT_Done_Face(face);
    return false;
  }
  std::vector<float> coverage(size_t(width_) * size_t(height_), -1.0f);  // -1: untouched
  int pen = x, line = y;
  for (const uint32_t ch : CodePoints(text)) {
    if (ch == '\n') {
      pen = x;
      line += size;
      continue;
    }
    if (FT_Load_Char(face, ch, FT_LOAD_RENDER)) continue;  // a missing glyph is skipped
    const FT_GlyphSlot g = face->glyph;
    for (int j = 0; j < int(g->bitmap.rows); ++j) {
      const int py = line + j - g->bitmap_top;
      if (py < 0 || py >= height_) continue;
      for (int i = 0; i < int(g->bitmap.width); ++i) {
        const int px = pen + i + g->bitmap_left;
        if (px < 0 || px >= width_) continue;
        coverage[size_t(py) * size_t(width_) + size_t(px)] =
            float(g->bitmap.buffer[g->bitmap.pitch * j + i]) / 255.0f;
      }
    }
    pen += int(g->advance.x >> 6);
  }
  FT_Done_Face(face);
  for (size_t p = 0; p < coverage.size(); ++p) {
    const float a = coverage[p];
    if (a <= 0.0f) continue;
    for (size_t k = 0; k < 3; ++k) rgb_[p * 3 + k] = c[k] * a + rgb_[p * 3 + k] * (1.0f - a);
  }
  return true;
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
