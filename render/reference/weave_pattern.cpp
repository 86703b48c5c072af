// render/reference/weave_pattern.cpp: parser, validator and writer of the ".weave" text format.
#include "render/reference/weave_pattern.h"

#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "render/scene/input_limits.h"

namespace clothfit::render {
namespace {

constexpr double kDegToRad = kPi / 180.0;

[[noreturn]] void Fail(const std::string& context, const std::string& message) {
  // Tokens from the file are quoted in messages: escape control bytes and invalid UTF-8
  // (docs/reliability.md), so no raw byte from the input reaches a terminal or a log.
  throw WeavePatternError(limits::EscapeForMessage(context + ": " + message, 1000));
}

std::string Located(const std::string& source, int line) {
  return source + ":" + std::to_string(line);
}

// Splits on blanks and commas; '#' starts a comment.
std::vector<std::string_view> Tokens(std::string_view line) {
  const size_t hash = line.find('#');
  if (hash != std::string_view::npos) line = line.substr(0, hash);
  std::vector<std::string_view> out;
  size_t i = 0;
  auto is_sep = [](char c) { return c == ' ' || c == '\t' || c == ',' || c == '\r'; };
  while (i < line.size()) {
    while (i < line.size() && is_sep(line[i])) ++i;
    const size_t start = i;
    while (i < line.size() && !is_sep(line[i])) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

double ParseDouble(std::string_view token, const std::string& where, const std::string& what) {
  double value = 0.0;
  const char* end = token.data() + token.size();
  auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec != std::errc() || ptr != end || !std::isfinite(value)) {
    Fail(where, "expected a finite number for " + what + ", got '" + std::string(token) + "'");
  }
  return value;
}

int ParseInt(std::string_view token, const std::string& where, const std::string& what) {
  long value = 0;
  const char* end = token.data() + token.size();
  auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec != std::errc() || ptr != end || value < -1000000 || value > 1000000) {
    Fail(where, "expected an integer for " + what + ", got '" + std::string(token) + "'");
  }
  return int(value);
}

std::string Num(double v) {
  char buf[64];
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, ptr);
}

// The scalar weave constants, by their file keyword.
std::vector<std::pair<const char*, double WeavePattern::*>> ScalarFields() {
  return {{"alpha", &WeavePattern::alpha},
          {"beta", &WeavePattern::beta},
          {"ss", &WeavePattern::ss},
          {"hWidth", &WeavePattern::h_width},
          {"warpArea", &WeavePattern::warp_area},
          {"weftArea", &WeavePattern::weft_area},
          {"fineness", &WeavePattern::fineness},
          {"dWarpUmaxOverDWarp", &WeavePattern::d_warp_umax_over_d_warp},
          {"dWarpUmaxOverDWeft", &WeavePattern::d_warp_umax_over_d_weft},
          {"dWeftUmaxOverDWarp", &WeavePattern::d_weft_umax_over_d_warp},
          {"dWeftUmaxOverDWeft", &WeavePattern::d_weft_umax_over_d_weft},
          {"period", &WeavePattern::period}};
}
// Keys that must appear; the others default to 0 (noise and fineness off).
bool Required(const std::string& key) {
  return key == "alpha" || key == "beta" || key == "ss" || key == "hWidth" || key == "warpArea" ||
         key == "weftArea";
}

void ValidateYarn(const Yarn& y, const std::string& where) {
  if (!(std::abs(y.psi) < 90.0)) Fail(where, "psi must be in (-90, 90) degrees");
  if (!(y.umax > 0.0 && y.umax < 90.0)) Fail(where, "umax must be in (0, 90) degrees");
  if (!(y.kappa >= -1.0)) Fail(where, "kappa must be >= -1");
  if (!(y.width > 0.0)) Fail(where, "width must be > 0");
  if (!(y.length > 0.0)) Fail(where, "length must be > 0");
  if (!(y.width * std::sin(y.umax * kDegToRad) < y.length)) {
    Fail(where, "w sin(umax) must be < l (width " + Num(y.width) + ", umax " + Num(y.umax) +
                    ", length " + Num(y.length) + ")");
  }
  for (int c = 0; c < 3; ++c) {
    if (!(y.kd[c] >= 0.0) || !std::isfinite(y.kd[c])) Fail(where, "kd must be finite, >= 0");
    if (!(y.ks[c] >= 0.0) || !std::isfinite(y.ks[c])) Fail(where, "ks must be finite, >= 0");
  }
}

}  // namespace

std::vector<SegmentCells> DeriveSegmentCentres(WeavePattern* p, const std::string& context) {
  const int n = int(p->yarns.size());
  const int W = p->tile_width, H = p->tile_height;
  if (W <= 0 || H <= 0 || p->pattern.size() != size_t(W) * size_t(H)) {
    Fail(context, "pattern size does not match the tile");
  }
  std::vector<SegmentCells> cells(size_t(n), SegmentCells{W, -1, H, -1});
  std::vector<int> count(size_t(n), 0);
  for (int r = 0; r < H; ++r) {
    for (int c = 0; c < W; ++c) {
      const int id = p->IdAt(c, r);
      if (id < 1 || id > n) {
        Fail(context, "pattern id " + std::to_string(id) + " at row " + std::to_string(r + 1) +
                          ", column " + std::to_string(c + 1) + " is not in [1, " +
                          std::to_string(n) + "]");
      }
      SegmentCells& s = cells[size_t(id - 1)];
      s.col0 = std::min(s.col0, c);
      s.col1 = std::max(s.col1, c);
      s.row0 = std::min(s.row0, r);
      s.row1 = std::max(s.row1, r);
      ++count[size_t(id - 1)];
    }
  }
  for (int i = 0; i < n; ++i) {
    const SegmentCells& s = cells[size_t(i)];
    if (count[size_t(i)] == 0) Fail(context, "yarn id " + std::to_string(i + 1) + " is unused");
    const int area = (s.col1 - s.col0 + 1) * (s.row1 - s.row0 + 1);
    if (area != count[size_t(i)]) {
      Fail(context, "the cells of yarn id " + std::to_string(i + 1) +
                        " do not form one rectangle (one segment)");
    }
    // Centre of the rectangle in draft coordinates (Y up: file row r covers [H-1-r, H-r)).
    const double x = 0.5 * (s.col0 + s.col1 + 1);
    const double y = double(H) - 0.5 * (s.row0 + s.row1 + 1);
    p->yarns[size_t(i)].center_u = x / W;
    p->yarns[size_t(i)].center_v = y / H;
  }
  return cells;
}

void ValidateWeave(const WeavePattern& p, const std::string& context) {
  if (p.tile_width < 1 || p.tile_height < 1 || p.tile_width > 256 || p.tile_height > 256) {
    Fail(context, "tile size must be in [1, 256] x [1, 256]");
  }
  if (p.yarns.empty()) Fail(context, "no yarns");
  if (!(p.alpha >= 0.0)) Fail(context, "alpha must be >= 0");
  if (!std::isfinite(p.beta) || std::abs(p.beta) > 100.0)
    Fail(context, "beta must be in [-100, 100]");
  if (!(p.ss >= 0.0 && p.ss < 1.0)) Fail(context, "ss must satisfy 0 <= ss < 1");
  if (!(p.h_width > 0.0 && p.h_width <= 1.0)) Fail(context, "hWidth must be in (0, 1]");
  if (!(p.fineness >= 0.0) || !std::isfinite(p.fineness)) Fail(context, "fineness must be >= 0");
  if (!(p.period >= 0.0) || !std::isfinite(p.period)) Fail(context, "period must be >= 0");
  bool has_warp = false, has_weft = false;
  for (size_t i = 0; i < p.yarns.size(); ++i) {
    ValidateYarn(p.yarns[i], context + ": yarn " + std::to_string(i + 1));
    (p.yarns[i].type == YarnType::kWarp ? has_warp : has_weft) = true;
  }
  if (has_warp && !(p.warp_area > 0.0)) Fail(context, "warpArea must be > 0");
  if (has_weft && !(p.weft_area > 0.0)) Fail(context, "weftArea must be > 0");
  WeavePattern copy = p;
  DeriveSegmentCentres(&copy, context);
}

namespace {

// ---------------------------------------------------------------------------------------------
// ParseWeave's steps: one function per keyword, then the checks after the last line.

std::vector<std::string_view> SplitLines(std::string_view text) {
  std::vector<std::string_view> lines;
  for (size_t start = 0; start <= text.size();) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    lines.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return lines;
}

// What ParseWeave has gathered so far, line by line.
struct WeaveDraft {
  WeavePattern p;
  std::map<std::string, int> seen;            // keyword -> line
  std::map<int, std::pair<Yarn, int>> yarns;  // id -> (yarn, line)
  std::map<int, std::pair<double, double>> given_centres;
  bool header = false;
  int pattern_line = 0;
};

// "name <text>": the rest of the line, blanks trimmed (the name may contain blanks).
void ParseNameLine(std::string_view line, const std::string& where, WeavePattern* p) {
  std::string_view rest = line.substr(line.find("name") + 4);
  while (!rest.empty() && (rest.front() == ' ' || rest.front() == '\t')) rest.remove_prefix(1);
  while (!rest.empty() && (rest.back() == ' ' || rest.back() == '\r')) rest.remove_suffix(1);
  p->name = std::string(rest);
  if (p->name.find('#') != std::string::npos) Fail(where, "name must not contain '#'");
}

// "tile <width> <height>".
void ParseTileLine(const std::vector<std::string_view>& tok, const std::string& where,
                   WeavePattern* p) {
  if (tok.size() != 3) Fail(where, "expected 'tile <width> <height>'");
  p->tile_width = ParseInt(tok[1], where, "tile width");
  p->tile_height = ParseInt(tok[2], where, "tile height");
  if (p->tile_width < 1 || p->tile_height < 1 || p->tile_width > 256 || p->tile_height > 256) {
    Fail(where, "tile size must be in [1, 256] x [1, 256]");
  }
}

// "pattern" and the tile_height non-blank rows after it; *li ends on the last row read.
void ParsePatternBlock(const std::vector<std::string_view>& lines, const std::string& source,
                       const std::vector<std::string_view>& tok, const std::string& where,
                       size_t* li, WeaveDraft* d) {
  WeavePattern& p = d->p;
  if (tok.size() != 1) Fail(where, "'pattern' takes no values; rows follow on the next lines");
  if (p.tile_width == 0) Fail(where, "'tile' must come before 'pattern'");
  d->pattern_line = int(*li) + 1;
  int rows = 0;
  while (rows < p.tile_height) {
    ++*li;
    if (*li >= lines.size()) {
      Fail(Located(source, int(*li)), "pattern ends after " + std::to_string(rows) +
                                          " rows; expected " + std::to_string(p.tile_height));
    }
    const std::string row_where = Located(source, int(*li) + 1);
    const auto row = Tokens(lines[*li]);
    if (row.empty()) continue;
    // A keyword where a row belongs: the pattern is shorter than the tile says (session 28:
    // before, the keyword's line was reported as a row with the wrong number of ids).
    if (row[0].find_first_not_of("+-0123456789") == 0) {
      Fail(row_where, "pattern has " + std::to_string(rows) + " rows, but 'tile " +
                          std::to_string(p.tile_width) + " " + std::to_string(p.tile_height) +
                          "' (line " + std::to_string(d->seen.at("tile")) + ") declares " +
                          std::to_string(p.tile_height) + "; this line starts '" +
                          limits::EscapeForMessage(row[0], 40) + "'");
    }
    if (int(row.size()) != p.tile_width) {
      Fail(row_where, "pattern row has " + std::to_string(row.size()) + " ids; expected " +
                          std::to_string(p.tile_width));
    }
    for (const auto& t : row) {
      const int id = ParseInt(t, row_where, "a yarn id");
      if (id < 1) Fail(row_where, "yarn ids are 1-based; got " + std::to_string(id));
      p.pattern.push_back(id);
    }
    ++rows;
  }
}

// The "<field> <values...>" pairs of a yarn line from token 3 on; a "center" goes to
// *given_centres (checked against the pattern once it is known).
void ParseYarnFields(const std::vector<std::string_view>& tok, const std::string& where, int id,
                     Yarn* y, std::map<int, std::pair<double, double>>* given_centres) {
  std::map<std::string, bool> got;
  size_t i = 3;
  auto need = [&](size_t n_values, const std::string& k) {
    if (i + n_values >= tok.size()) {
      Fail(where, "'" + k + "' needs " + std::to_string(n_values) + " value(s)");
    }
  };
  while (i < tok.size()) {
    const std::string k(tok[i]);
    if (got.count(k)) Fail(where, "duplicate yarn field '" + k + "'");
    got[k] = true;
    if (k == "psi" || k == "umax" || k == "kappa" || k == "width" || k == "length") {
      need(1, k);
      const double v = ParseDouble(tok[i + 1], where, k);
      if (k == "psi") y->psi = v;
      if (k == "umax") y->umax = v;
      if (k == "kappa") y->kappa = v;
      if (k == "width") y->width = v;
      if (k == "length") y->length = v;
      i += 2;
    } else if (k == "kd" || k == "ks") {
      need(3, k);
      Rgb<double> c(ParseDouble(tok[i + 1], where, k), ParseDouble(tok[i + 2], where, k),
                    ParseDouble(tok[i + 3], where, k));
      (k == "kd" ? y->kd : y->ks) = c;
      i += 4;
    } else if (k == "center") {
      need(2, k);
      (*given_centres)[id] = {ParseDouble(tok[i + 1], where, k), ParseDouble(tok[i + 2], where, k)};
      i += 3;
    } else {
      Fail(where,
           "unknown yarn field '" + k + "' (valid: psi umax kappa width length kd ks center)");
    }
  }
  for (const char* k : {"psi", "umax", "kappa", "width", "length", "kd", "ks"}) {
    if (!got.count(k)) Fail(where, std::string("yarn is missing '") + k + "'");
  }
}

// "yarn <id> warp|weft <fields...>".
void ParseYarnLine(const std::vector<std::string_view>& tok, const std::string& where, int line_no,
                   WeaveDraft* d) {
  if (tok.size() < 3) Fail(where, "expected 'yarn <id> warp|weft ...'");
  const int id = ParseInt(tok[1], where, "the yarn id");
  if (id < 1) Fail(where, "yarn ids are 1-based; got " + std::to_string(id));
  if (d->yarns.count(id)) {
    Fail(where, "duplicate yarn " + std::to_string(id) + " (first on line " +
                    std::to_string(d->yarns[id].second) + ")");
  }
  Yarn y;
  if (tok[2] == "warp") {
    y.type = YarnType::kWarp;
  } else if (tok[2] == "weft") {
    y.type = YarnType::kWeft;
  } else {
    Fail(where, "yarn type must be 'warp' or 'weft', got '" + std::string(tok[2]) + "'");
  }
  ParseYarnFields(tok, where, id, &y, &d->given_centres);
  ValidateYarn(y, where);
  d->yarns[id] = {y, line_no};
}

// "<constant> <value>" for one of ScalarFields(); any other keyword is an error.
void ParseScalarLine(const std::vector<std::pair<const char*, double WeavePattern::*>>& fields,
                     const std::string& key, const std::vector<std::string_view>& tok,
                     const std::string& where, WeavePattern* p) {
  bool found = false;
  for (const auto& [name, member] : fields) {
    if (key == name) {
      if (tok.size() != 2) Fail(where, "expected '" + key + " <value>'");
      p->*member = ParseDouble(tok[1], where, key);
      found = true;
    }
  }
  if (!found) {
    Fail(where, "unknown keyword '" + key +
                    "' (valid: name, tile, pattern, yarn and the weave constants)");
  }
}

// After the last line: every required keyword given, yarn ids 1..n without gaps; moves the
// yarns into d->p in id order.
void CheckAllKeysGiven(const std::vector<std::pair<const char*, double WeavePattern::*>>& fields,
                       const std::string& end_where, WeaveDraft* d) {
  for (const auto& [name, member] : fields) {
    if (Required(name) && !d->seen.count(name)) {
      Fail(end_where, std::string("missing '") + name + "'");
    }
  }
  if (!d->seen.count("tile")) Fail(end_where, "missing 'tile'");
  if (!d->seen.count("pattern")) Fail(end_where, "missing 'pattern'");
  if (d->yarns.empty()) Fail(end_where, "no 'yarn' lines");
  for (int id = 1; id <= int(d->yarns.size()); ++id) {
    if (!d->yarns.count(id)) {
      Fail(end_where, "yarn ids must be 1.." + std::to_string(d->yarns.size()) + "; " +
                          std::to_string(id) + " is missing");
    }
    d->p.yarns.push_back(d->yarns[id].first);
  }
}

// A yarn's optional "center" must agree with the centre derived from the pattern.
void CheckGivenCentres(const WeaveDraft& d, const std::string& source) {
  for (const auto& [id, c] : d.given_centres) {
    const Yarn& y = d.p.yarns[size_t(id - 1)];
    if (std::abs(c.first - y.center_u) > 1e-9 || std::abs(c.second - y.center_v) > 1e-9) {
      Fail(Located(source, d.yarns.at(id).second),
           "center (" + Num(c.first) + ", " + Num(c.second) + ") disagrees with the centre " +
               "derived from the pattern (" + Num(y.center_u) + ", " + Num(y.center_v) + ")");
    }
  }
}

// Ranges of the weave constants, each reported on its keyword's line (or the last line).
void CheckWeaveConstants(const WeaveDraft& d, const std::string& source, int n_lines) {
  const WeavePattern& p = d.p;
  auto line_of = [&](const std::string& k) {
    return Located(source, d.seen.count(k) ? d.seen.at(k) : n_lines);
  };
  if (!(p.alpha >= 0.0)) Fail(line_of("alpha"), "alpha must be >= 0");
  if (std::abs(p.beta) > 100.0) Fail(line_of("beta"), "beta must be in [-100, 100]");
  if (!(p.ss >= 0.0 && p.ss < 1.0)) Fail(line_of("ss"), "ss must satisfy 0 <= ss < 1");
  if (!(p.h_width > 0.0 && p.h_width <= 1.0)) Fail(line_of("hWidth"), "hWidth must be in (0, 1]");
  if (!(p.fineness >= 0.0)) Fail(line_of("fineness"), "fineness must be >= 0");
  if (!(p.period >= 0.0)) Fail(line_of("period"), "period must be >= 0");
  if (!(p.warp_area > 0.0)) Fail(line_of("warpArea"), "warpArea must be > 0");
  if (!(p.weft_area > 0.0)) Fail(line_of("weftArea"), "weftArea must be > 0");
}

}  // namespace

WeavePattern ParseWeave(std::string_view text, const std::string& source) {
  const std::vector<std::string_view> lines = SplitLines(text);
  WeaveDraft d;
  const auto fields = ScalarFields();
  for (size_t li = 0; li < lines.size(); ++li) {
    const int line_no = int(li) + 1;
    const std::string where = Located(source, line_no);
    const auto tok = Tokens(lines[li]);
    if (tok.empty()) continue;
    const std::string key(tok[0]);
    if (!d.header) {
      if (key != "clothfit-weave" || tok.size() != 2 || tok[1] != "1") {
        Fail(where, "expected the header 'clothfit-weave 1'");
      }
      d.header = true;
      continue;
    }
    if (key != "yarn") {
      if (d.seen.count(key)) {
        Fail(where, "duplicate '" + key + "' (first on line " + std::to_string(d.seen[key]) + ")");
      }
      d.seen[key] = line_no;
    }
    if (key == "name") {
      ParseNameLine(lines[li], where, &d.p);
    } else if (key == "tile") {
      ParseTileLine(tok, where, &d.p);
    } else if (key == "pattern") {
      ParsePatternBlock(lines, source, tok, where, &li, &d);
    } else if (key == "yarn") {
      ParseYarnLine(tok, where, line_no, &d);
    } else if (d.seen.count("pattern") &&
               key.find_first_not_of("0123456789") == std::string::npos) {
      // Rows after the pattern: it is longer than the tile says (session 28: before, "unknown
      // keyword '1'").
      Fail(where, "a pattern row after the " + std::to_string(d.p.tile_height) +
                      " rows that 'tile " + std::to_string(d.p.tile_width) + " " +
                      std::to_string(d.p.tile_height) + "' (line " +
                      std::to_string(d.seen["tile"]) + ") declares");
    } else {
      ParseScalarLine(fields, key, tok, where, &d.p);
    }
  }
  if (!d.header) Fail(Located(source, 1), "empty file; expected the header 'clothfit-weave 1'");
  CheckAllKeysGiven(fields, Located(source, int(lines.size())), &d);
  // Whole-weave checks report the pattern's line (ids, rectangles) or the keyword's line.
  DeriveSegmentCentres(&d.p, Located(source, d.pattern_line));
  CheckGivenCentres(d, source);
  CheckWeaveConstants(d, source, int(lines.size()));
  ValidateWeave(d.p, Located(source, 1));
  return d.p;
}

WeavePattern LoadWeave(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw WeavePatternError(path + ": cannot open weave pattern file");
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  if (text.size() > (size_t(1) << 20)) throw WeavePatternError(path + ": file larger than 1 MiB");
  return ParseWeave(text, path);
}

std::string WriteWeave(const WeavePattern& p) {
  std::ostringstream o;
  o << "clothfit-weave 1\n";
  o << "name " << p.name << "\n";
  for (const auto& [name, member] : ScalarFields()) o << name << " " << Num(p.*member) << "\n";
  o << "tile " << p.tile_width << " " << p.tile_height << "\n";
  o << "pattern\n";
  for (int r = 0; r < p.tile_height; ++r) {
    for (int c = 0; c < p.tile_width; ++c) o << (c ? " " : "") << p.IdAt(c, r);
    o << "\n";
  }
  WeavePattern derived = p;
  DeriveSegmentCentres(&derived, "WriteWeave");
  for (size_t i = 0; i < p.yarns.size(); ++i) {
    const Yarn& y = derived.yarns[i];
    o << "yarn " << (i + 1) << (y.type == YarnType::kWarp ? " warp" : " weft") << " psi "
      << Num(y.psi) << " umax " << Num(y.umax) << " kappa " << Num(y.kappa) << " width "
      << Num(y.width) << " length " << Num(y.length) << " kd " << Num(y.kd.r) << " " << Num(y.kd.g)
      << " " << Num(y.kd.b) << " ks " << Num(y.ks.r) << " " << Num(y.ks.g) << " " << Num(y.ks.b)
      << " center " << Num(y.center_u) << " " << Num(y.center_v) << "\n";
  }
  return o.str();
}

bool operator==(const Yarn& a, const Yarn& b) {
  return a.type == b.type && a.psi == b.psi && a.umax == b.umax && a.kappa == b.kappa &&
         a.width == b.width && a.length == b.length && a.center_u == b.center_u &&
         a.center_v == b.center_v && a.kd.r == b.kd.r && a.kd.g == b.kd.g && a.kd.b == b.kd.b &&
         a.ks.r == b.ks.r && a.ks.g == b.ks.g && a.ks.b == b.ks.b;
}

bool operator==(const WeavePattern& a, const WeavePattern& b) {
  for (const auto& [name, member] : ScalarFields()) {
    if (a.*member != b.*member) return false;
  }
  return a.name == b.name && a.tile_width == b.tile_width && a.tile_height == b.tile_height &&
         a.pattern == b.pattern && a.yarns == b.yarns;
}

}  // namespace clothfit::render
