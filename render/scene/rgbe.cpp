// Radiance HDR (RGBE) input for io::ReadImage: header, flat and run-length encoded scanlines.
//
// Format: Greg Ward, "Real Pixels" (Graphics Gems II, 1991) and the Radiance file format notes
// (radsite.lbl.gov/radiance/refer/filefmts.pdf): text header lines up to an empty line, a
// resolution line, then one scanline after another. A pixel is 4 bytes R G B E with value
// m * 2^(E - 136) (E = 0: black). A scanline of 8..32767 pixels may be "new RLE": bytes 2 2 and
// its width (big-endian, 15 bits), then the four components one after another, each as
// (count > 128: a run of count - 128 copies of the next byte; else count literal bytes).
//
// Accepted as OpenImageIO 2.4 accepted them (the reader clothfit used before session 16): the
// header must contain the line FORMAT=32-bit_rle_rgbe (XYZE is refused), lines are read 128
// bytes at most at a time, at most 100 header lines; the resolution line must be the standard
// "-Y H +X W" (top-down rows, left to right). The seven other forms are refused by name since
// the session-16 review: OpenImageIO returned them in stored order, i.e. upside down or
// transposed, without a word. Channels R G B, linear (float_source), values as OpenImageIO
// computed them (ToFloat).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <string_view>

#include "render/scene/image_io.h"
#include "render/scene/image_readers.h"
#include "render/scene/input_limits.h"

namespace clothfit::io::internal {
namespace {

constexpr size_t kLineChunk = 128;   // bytes read per header "line"
constexpr int kMaxHeaderLines = 100;

class RgbeReader : public ImageReader {
 public:
  RgbeReader(const std::string& path, const std::string& shown, size_t file_bytes)
      : path_(path), shown_(shown), file_bytes_(file_bytes) {
    auto fail = [&](const std::string& what) {
      throw IoError(shown_ + ": cannot read image: " + what);
    };
    std::ifstream f(path, std::ios::binary);
    std::string head(std::min(file_bytes, (kMaxHeaderLines + 3) * kLineChunk), '\0');
    f.read(head.data(), std::streamsize(head.size()));
    head.resize(size_t(f.gcount()));
    size_t pos = 0;
    // The next header line: up to and including '\n', at most kLineChunk bytes.
    auto line = [&]() -> std::string_view {
      const std::string_view rest = std::string_view(head).substr(std::min(pos, head.size()));
      if (rest.empty()) fail("Radiance HDR header ends early");
      const std::string_view chunk = rest.substr(0, kLineChunk);
      const size_t nl = chunk.find('\n');
      const std::string_view l = nl == std::string_view::npos ? chunk : chunk.substr(0, nl + 1);
      pos += l.size();
      return l;
    };
    line();  // "#?RADIANCE" (or another program type)
    std::string_view l = line();
    bool format_found = false;
    for (int n = 0; n < kMaxHeaderLines; ++n) {
      if (l.empty() || l[0] == '\n') break;
      if (l == "FORMAT=32-bit_rle_rgbe\n") format_found = true;
      l = line();
    }
    if (!format_found) fail("no FORMAT=32-bit_rle_rgbe line in the Radiance HDR header");
    if (l != "\n") fail("missing blank line after the Radiance HDR header");
    const std::string_view res = line();
    int h = 0, w = 0;
    static const char* const kForms[8][2] = {{"-Y", "+X"}, {"-Y", "-X"}, {"+Y", "-X"},
                                             {"+Y", "+X"}, {"+X", "-Y"}, {"+X", "+Y"},
                                             {"-X", "+Y"}, {"-X", "-Y"}};
    int form_found = -1;
    for (int k = 0; k < 8; ++k)
      if (ParseResolution(res, kForms[k][0], kForms[k][1], &h, &w)) {
        form_found = k;
        break;
      }
    if (form_found < 0) fail("missing image size line in the Radiance HDR header");
    // Only the standard top-down, left-to-right form: OpenImageIO (before session 16) returned
    // the other seven in stored order, so a "+Y" environment loaded upside down without a word.
    if (form_found != 0)
      fail(std::string("Radiance HDR orientation '") + kForms[form_found][0] + " H " +
           kForms[form_found][1] + " W' is not supported (only '-Y H +X W', top-down rows)");
    width = w;
    height = h;
    data_begin_ = pos;
    channel_names = {"R", "G", "B"};
    sample_bytes.assign(3, 4);  // as OpenImageIO declared them: float
    float_source = true;
    source_format = "float";
    file_format = "hdr";
    // Validate before allocating: the smallest encoding of a scanline is new RLE with runs of
    // 127 (4 + 4 x 2 ceil(W / 127) bytes); widths outside 8..32767 are stored flat (4 W).
    if (w > 0 && h > 0 && w <= kMaxDimension && h <= kMaxDimension) {
      const size_t W = size_t(w);
      const size_t per_row = (W < 8 || W > 0x7fff) ? 4 * W : 4 + 8 * ((W + 126) / 127);
      if (data_begin_ + per_row * size_t(h) > file_bytes_)
        throw IoError(shown_ + ": Radiance HDR header claims " + std::to_string(w) + "x" +
                      std::to_string(h) + " but the file has only " + std::to_string(file_bytes_) +
                      " bytes, fewer than the smallest encoding of that many scanlines "
                      "(truncated or forged; docs/reliability.md)");
    }
  }

  void Read(float* out) override {
    std::ifstream f(path_, std::ios::binary);
    std::string bytes(file_bytes_ - std::min(file_bytes_, data_begin_), '\0');
    f.seekg(std::streamoff(data_begin_));
    f.read(bytes.data(), std::streamsize(bytes.size()));
    bytes.resize(size_t(f.gcount()));
    const auto* data = reinterpret_cast<const unsigned char*>(bytes.data());
    const size_t size = bytes.size(), W = size_t(width);
    size_t pos = 0;
    auto fail = [&](size_t y, const char* what) {
      throw IoError(shown_ + ": corrupt or truncated image: Radiance HDR scanline " +
                    std::to_string(y) + ": " + what);
    };
    std::vector<unsigned char> line(4 * W);
    for (size_t y = 0; y < size_t(height); ++y) {
      float* row = out + y * W * 3;
      // Flat pixels [from, W) of this scanline, RGBE interleaved.
      auto flat = [&](size_t from) {
        if (size - pos < 4 * (W - from)) fail(y, "ends early");
        for (size_t x = from; x < W; ++x, pos += 4) ToFloat(data + pos, row + 3 * x);
      };
      if (W < 8 || W > 0x7fff) {  // run-length encoding cannot describe this width
        flat(0);
        continue;
      }
      if (size - pos < 4) fail(y, "ends early");
      const unsigned char* p = data + pos;
      if (p[0] != 2 || p[1] != 2 || (p[2] & 0x80)) {  // a flat scanline
        flat(0);
        continue;
      }
      if (((size_t(p[2]) << 8) | p[3]) != W) fail(y, "wrong scanline width");
      pos += 4;
      for (size_t c = 0; c < 4; ++c) {
        unsigned char* q = &line[c * W];
        unsigned char* const end = q + W;
        while (q < end) {
          if (size - pos < 2) fail(y, "ends early");
          const unsigned char count_byte = data[pos], value = data[pos + 1];
          pos += 2;
          if (count_byte > 128) {  // a run
            const size_t count = count_byte - 128u;
            if (count > size_t(end - q)) fail(y, "run past the end of the scanline");
            std::memset(q, value, count);
            q += count;
          } else {  // literal bytes: `value` and count - 1 more
            const size_t count = count_byte;
            if (count == 0 || count > size_t(end - q)) fail(y, "bad literal count");
            *q++ = value;
            if (size - pos < count - 1) fail(y, "ends early");
            std::memcpy(q, data + pos, count - 1);
            q += count - 1;
            pos += count - 1;
          }
        }
      }
      for (size_t x = 0; x < W; ++x) {
        const unsigned char px[4] = {line[x], line[W + x], line[2 * W + x], line[3 * W + x]};
        ToFloat(px, row + 3 * x);
      }
    }
  }

 private:
  // "<a> <int> <b> <int>" with optional blanks before each part (the resolution line).
  static bool ParseResolution(std::string_view s, std::string_view a, std::string_view b, int* first,
                              int* second) {
    size_t i = 0;
    auto blanks = [&] {
      while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r' ||
                              s[i] == '\v' || s[i] == '\f'))
        ++i;
    };
    auto word = [&](std::string_view w) {
      blanks();
      if (s.substr(i, w.size()) != w) return false;
      i += w.size();
      return true;
    };
    auto number = [&](int* v) {
      blanks();
      const bool negative = i < s.size() && s[i] == '-';
      if (i < s.size() && (s[i] == '-' || s[i] == '+')) ++i;
      long long x = 0;
      const size_t start = i;
      for (; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) {
        x = x * 10 + (s[i] - '0');
        if (x > (1LL << 31)) return false;
      }
      if (i == start) return false;
      x = negative ? -x : x;
      if (x > std::numeric_limits<int>::max() || x < std::numeric_limits<int>::min()) return false;
      *v = int(x);
      return true;
    };
    return word(a) && number(first) && word(b) && number(second);
  }

  // value = m * scale(e) per component in float arithmetic (e = 0: black), scale(e) =
  // 2^(e - 136) written to 8 significant digits and read back as a float: the rounded table
  // OpenImageIO 2.4 used, one float ulp off the power of two for some exponents (e.g. 40); kept
  // so that every texel has the value it had before session 16.
  static void ToFloat(const unsigned char* rgbe, float* rgb) {
    static const std::array<float, 256> kScale = [] {
      std::array<float, 256> t{};
      for (int e = 0; e < 256; ++e) {
        char text[32];
        std::snprintf(text, sizeof text, "%.8g", std::ldexp(1.0, e - 136));
        t[size_t(e)] = std::strtof(text, nullptr);
      }
      return t;
    }();
    if (rgbe[3] == 0) {
      rgb[0] = rgb[1] = rgb[2] = 0.0f;
      return;
    }
    const float f = kScale[rgbe[3]];
    for (int c = 0; c < 3; ++c) rgb[c] = float(rgbe[c]) * f;
  }

  std::string path_, shown_;
  size_t file_bytes_ = 0, data_begin_ = 0;
};

}  // namespace

std::unique_ptr<ImageReader> OpenRgbe(const std::string& path, const std::string& shown,
                                      size_t file_bytes) {
  return std::make_unique<RgbeReader>(path, shown, file_bytes);
}

}  // namespace clothfit::io::internal
