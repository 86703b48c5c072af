// render/reference/weave_pattern.h: weave patterns for the Irawan-Marschner woven-cloth BSDF.
//
// A weave pattern is one tile of a woven fabric drawn as a weave draft: tile_width columns
// (warp ends) by tile_height rows (weft picks), each cell holding the 1-based id of the yarn
// segment visible there. Warp yarns run along the draft's columns (vertically in the
// drawing), weft yarns along its rows. Rows are listed top to bottom as drawn; the draft's
// coordinates (X to the right, Y up) put (0, 0) at the LOWER left corner, so row r of the
// file covers Y in [H-1-r, H-r) (Irawan's and Mitsuba's published presets use this layout;
// the published polyester centres are reproduced by DeriveSegmentCentres, see the tests).
//
// Segment centres are DERIVED, never read: each id's cells must form one axis-aligned
// rectangle (one segment) and its centre is the centre of that rectangle, in tile units
// ((X, Y) / (W, H)). A float cut by the tile edge is two ids, each its own segment.
//
// The text format (".weave", documented in docs/woven-cloth.md) is line based:
//   clothfit-weave 1
//   name <free text>
//   alpha <a>   beta <b>   ss <s>   hWidth <h>   warpArea <a>   weftArea <a>
//   fineness <f>   dWarpUmaxOverDWarp <deg> ... period <p>     (each on its own line)
//   tile <W> <H>
//   pattern            (followed by H lines of W integers)
//   yarn <id> warp|weft psi <deg> umax <deg> kappa <k> width <w> length <l>
//        kd <r> <g> <b> ks <r> <g> <b> [center <u> <v>]            (one line per id)
// Errors throw WeavePatternError with "file:line: message".
#pragma once

#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "brdf/math.h"

namespace clothfit::render {

class WeavePatternError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class YarnType { kWarp, kWeft };

struct Yarn {
  YarnType type = YarnType::kWarp;
  double psi = 0.0;     // fibre twist angle, degrees; 0 = filament yarn, else staple yarn
  double umax = 30.0;   // maximum inclination of the yarn, degrees, in (0, 90)
  double kappa = 0.0;   // cross-section/spine curvature shape, >= -1
  double width = 1.0;   // yarn width w, in cells
  double length = 1.0;  // segment length l, in cells
  double center_u = 0.0, center_v = 0.0;  // segment centre in tile units (derived)
  Rgb<double> kd, ks;                     // linear RGB
};

struct WeavePattern {
  std::string name;
  double alpha = 0.0;    // uniform scattering
  double beta = 0.0;     // forward scattering (von Mises concentration)
  double ss = 0.0;       // filament smoothing, 0 <= ss < 1
  double h_width = 0.5;  // highlight width, (0, 1]
  double warp_area = 1.0, weft_area = 1.0;
  double fineness = 0.0;  // intensity variation; 0 = off
  double d_warp_umax_over_d_warp = 0.0, d_warp_umax_over_d_weft = 0.0;  // degrees
  double d_weft_umax_over_d_warp = 0.0, d_weft_umax_over_d_weft = 0.0;  // degrees
  double period = 0.0;  // umax noise period in cells; 0 = off
  int tile_width = 0, tile_height = 0;
  std::vector<int> pattern;  // row-major, row 0 = top row of the draft, 1-based ids
  std::vector<Yarn> yarns;   // yarns[id - 1]

  // Id at draft column `col`, file row `row` (0 = top).
  int IdAt(int col, int row) const {
    return pattern[size_t(row) * size_t(tile_width) + size_t(col)];
  }
};

// The rectangle of cells an id occupies: columns [col0, col1], file rows [row0, row1].
struct SegmentCells {
  int col0 = 0, col1 = 0, row0 = 0, row1 = 0;
};

// Derives every yarn's centre from the pattern (see the header comment) and returns each
// id's rectangle. Throws WeavePatternError prefixed with `context` if an id's cells do not
// form one rectangle or an id is unused.
std::vector<SegmentCells> DeriveSegmentCentres(WeavePattern* pattern, const std::string& context);

// Checks every documented range (w sin(umax) < l, kappa >= -1, 0 <= ss < 1, ids in range,
// every id used, ...). Throws WeavePatternError prefixed with `context`.
void ValidateWeave(const WeavePattern& pattern, const std::string& context);

// Parses the text format; `source` names the file in error messages. Derives the centres
// (a `center` given in the file must agree with the derived one within 1e-9) and validates.
WeavePattern ParseWeave(std::string_view text, const std::string& source);
WeavePattern LoadWeave(const std::string& path);

// Writes the text format (shortest round-trip numbers, derived centres included as
// `center`), so ParseWeave(WriteWeave(p)) == p.
std::string WriteWeave(const WeavePattern& pattern);

bool operator==(const Yarn& a, const Yarn& b);
bool operator==(const WeavePattern& a, const WeavePattern& b);

}  // namespace clothfit::render
