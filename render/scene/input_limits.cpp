#include "render/scene/input_limits.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <vector>

namespace clothfit::limits {
namespace fs = std::filesystem;
namespace {

// Length of the valid UTF-8 sequence starting at s[i] (1..4), or 0 if the bytes there do not
// form one (RFC 3629: no overlongs, no surrogates, nothing above U+10FFFF).
size_t Utf8SequenceLength(std::string_view s, size_t i) {
  const auto b = [&](size_t k) { return static_cast<unsigned char>(s[i + k]); };
  const unsigned char c = b(0);
  if (c < 0x80) return 1;
  size_t n;
  unsigned lo = 0x80, hi = 0xBF;  // the allowed range of the second byte
  if (c >= 0xC2 && c <= 0xDF) {
    n = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    n = 3;
    if (c == 0xE0) lo = 0xA0;   // overlong
    if (c == 0xED) hi = 0x9F;   // surrogates
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4;
    if (c == 0xF0) lo = 0x90;   // overlong
    if (c == 0xF4) hi = 0x8F;   // above U+10FFFF
  } else {
    return 0;
  }
  if (i + n > s.size()) return 0;
  if (b(1) < lo || b(1) > hi) return 0;
  for (size_t k = 2; k < n; ++k)
    if (b(k) < 0x80 || b(k) > 0xBF) return 0;
  return n;
}

void AppendHex(std::string& out, unsigned char c) {
  static const char* kHex = "0123456789ABCDEF";
  out += "\\x";
  out += kHex[c >> 4];
  out += kHex[c & 15];
}

std::string Errno() { return std::strerror(errno); }

// Opens `path` read-only and checks the descriptor; returns the fd and its size.
int OpenChecked(const std::string& path, size_t max_bytes, std::string_view what, size_t* size) {
  const std::string shown = EscapeForMessage(path, 400);
  // O_NONBLOCK: opening a FIFO must not wait for a writer (it is refused below anyway).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) throw InputError(shown + ": cannot open " + std::string(what) + ": " + Errno());
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const std::string e = Errno();
    ::close(fd);
    throw InputError(shown + ": cannot stat " + std::string(what) + ": " + e);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    throw InputError(shown + ": " + std::string(what) +
                     " is not a regular file (devices, FIFOs and directories are refused)");
  }
  if (st.st_size <= 0) {
    ::close(fd);
    throw InputError(shown + ": " + std::string(what) +
                     " is empty (or a special file that reports no size, e.g. under /proc)");
  }
  if (size_t(st.st_size) > max_bytes) {
    ::close(fd);
    throw InputError(shown + ": " + std::string(what) + " is " + std::to_string(st.st_size) +
                     " bytes, over the limit of " + std::to_string(max_bytes) + " bytes " +
                     LimitRef(max_bytes == kMaxJsonFileBytes      ? "kMaxJsonFileBytes"
                              : max_bytes == kMaxGltfFileBytes    ? "kMaxGltfFileBytes"
                              : max_bytes == kMaxSmallTextBytes   ? "kMaxSmallTextBytes"
                              : max_bytes == kMaxImageFileBytes   ? "kMaxImageFileBytes"
                              : max_bytes == kMaxMerlBytes        ? "kMaxMerlBytes"
                                                                  : "limit"));
  }
  *size = size_t(st.st_size);
  return fd;
}

}  // namespace

std::string LimitRef(std::string_view constant) {
  return "(" + std::string(constant) + "; docs/reliability.md)";
}

std::optional<size_t> CheckedProduct(std::initializer_list<size_t> factors) {
  size_t r = 1;
  for (size_t f : factors) {
    auto p = CheckedMul(r, f);
    if (!p) return std::nullopt;
    r = *p;
  }
  return r;
}

size_t CheckedFileSize(const std::string& path, size_t max_bytes, std::string_view what) {
  size_t size = 0;
  const int fd = OpenChecked(path, max_bytes, what, &size);
  ::close(fd);
  return size;
}

std::string ReadFileBounded(const std::string& path, size_t max_bytes, std::string_view what) {
  size_t size = 0;
  const int fd = OpenChecked(path, max_bytes, what, &size);
  std::string data(size, '\0');
  size_t got = 0;
  while (got < size) {
    const ssize_t n = ::read(fd, data.data() + got, size - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const std::string e = Errno();
      ::close(fd);
      throw InputError(EscapeForMessage(path, 400) + ": read error: " + e);
    }
    if (n == 0) break;  // the file shrank while we read it: keep what is there
    got += size_t(n);
  }
  ::close(fd);
  data.resize(got);
  return data;
}

std::optional<size_t> FindJsonDepthExcess(std::string_view t, size_t max_depth) {
  size_t depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < t.size(); ++i) {
    const char c = t[i];
    if (in_string) {
      if (c == '\\')
        ++i;  // the escaped character cannot end the string
      else if (c == '"')
        in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return i;
    } else if ((c == ']' || c == '}') && depth > 0) {
      --depth;
    }
  }
  return std::nullopt;
}

void CheckJsonDepth(std::string_view text, const std::string& file) {
  const auto at = FindJsonDepthExcess(text, kMaxJsonDepth);
  if (!at) return;
  size_t line = 1, col = 1;
  for (size_t i = 0; i < *at; ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  throw InputError(EscapeForMessage(file, 400) + ":" + std::to_string(line) + ":" +
                   std::to_string(col) + ": JSON nested deeper than " +
                   std::to_string(kMaxJsonDepth) + " levels " + LimitRef("kMaxJsonDepth"));
}

std::string_view GlbJsonChunk(std::span<const unsigned char> b) {
  if (b.size() < 20 || std::memcmp(b.data(), "glTF", 4) != 0) return {};
  auto u32 = [&](size_t o) {
    return uint32_t(b[o]) | uint32_t(b[o + 1]) << 8 | uint32_t(b[o + 2]) << 16 |
           uint32_t(b[o + 3]) << 24;
  };
  const uint32_t len = u32(12), type = u32(16);
  if (type != 0x4E4F534Au || len > b.size() - 20) return {};
  return {reinterpret_cast<const char*>(b.data()) + 20, len};
}

std::string DumpJson(const nlohmann::json& j, int indent) {
  return j.dump(indent, ' ', false, nlohmann::json::error_handler_t::replace);
}

bool IsValidUtf8(std::string_view s) {
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

size_t NameDistance(std::string_view a, std::string_view b, bool fold_case) {
  if (a.size() > 64 || b.size() > 64) return 1000;
  const auto at = [fold_case](std::string_view s, size_t i) {
    const char c = s[i];
    return fold_case ? char(std::tolower(static_cast<unsigned char>(c))) : c;
  };
  // d[i][j]: distance between a's first i bytes and b's first j bytes
  std::vector<std::vector<size_t>> d(a.size() + 1, std::vector<size_t>(b.size() + 1));
  for (size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (size_t i = 1; i <= a.size(); ++i)
    for (size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1,
                          d[i - 1][j - 1] + (at(a, i - 1) == at(b, j - 1) ? 0 : 1)});
      if (i > 1 && j > 1 && at(a, i - 1) == at(b, j - 2) && at(a, i - 2) == at(b, j - 1))
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[a.size()][b.size()];
}

std::string EscapeForMessage(std::string_view s, size_t max_bytes) {
  std::string out;
  out.reserve(std::min(s.size(), max_bytes) + 8);
  for (size_t i = 0; i < s.size();) {
    if (out.size() >= max_bytes) {
      out += "...";
      break;
    }
    const unsigned char c = static_cast<unsigned char>(s[i]);
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) {
      AppendHex(out, c);
      ++i;
      continue;
    }
    if (n == 1) {
      if (c < 0x20 || c == 0x7F)
        AppendHex(out, c);
      else if (c == '\\')
        out += "\\\\";
      else
        out += char(c);
    } else if (n == 2 && c == 0xC2 && static_cast<unsigned char>(s[i + 1]) < 0xA0) {
      // C1 controls U+0080..U+009F (a terminal may act on them).
      AppendHex(out, c);
      AppendHex(out, static_cast<unsigned char>(s[i + 1]));
    } else {
      out.append(s.data() + i, n);
    }
    i += n;
  }
  return out;
}

bool IsInside(const fs::path& p, const fs::path& root) {
  const fs::path rel = p.lexically_relative(root);
  if (rel.empty()) return false;
  if (rel == ".") return true;
  return *rel.begin() != "..";
}

fs::path ResolveConfined(const std::string& file, const std::string& field,
                         const std::string& uri, const PathPolicy& policy, size_t max_bytes) {
  const std::string where = EscapeForMessage(file, 400) + ": " + field + ": ";
  const std::string shown = "'" + EscapeForMessage(uri, 200) + "'";
  if (uri.empty()) throw InputError(where + "empty path");
  for (unsigned char c : uri)
    if (c < 0x20 || c == 0x7F) throw InputError(where + shown + " contains a control byte");
  // A URI scheme ("http:", "file:", "data:") is not a file path.
  {
    size_t k = 0;
    if (std::isalpha(static_cast<unsigned char>(uri[0]))) {
      k = 1;
      while (k < uri.size() && (std::isalnum(static_cast<unsigned char>(uri[k])) ||
                                uri[k] == '+' || uri[k] == '-' || uri[k] == '.'))
        ++k;
      if (k < uri.size() && uri[k] == ':' && k > 1)
        throw InputError(where + shown + " is a URI with a scheme; only relative file paths are read");
    }
  }
  const fs::path u(uri);
  const bool confine = !policy.root.empty() && !policy.allow_outside;
  if (u.is_absolute() && confine)
    throw InputError(where + shown +
                     " is an absolute path; maps must lie inside the input directory " +
                     EscapeForMessage(policy.root.string(), 400) +
                     " (pass --allow-outside-paths to allow it)");
  const fs::path joined = u.is_absolute() ? u : fs::path(file).parent_path() / u;
  std::error_code ec;
  const fs::path canon = fs::weakly_canonical(joined, ec);
  if (ec) throw InputError(where + shown + ": " + ec.message());
  if (confine) {
    const fs::path root = fs::weakly_canonical(policy.root, ec);
    if (ec || !IsInside(canon, root))
      throw InputError(where + shown + " resolves outside the input directory " +
                       EscapeForMessage(policy.root.string(), 400) +
                       "; pass --allow-outside-paths to allow it");
  }
  try {
    CheckedFileSize(canon.string(), max_bytes, "the file it names");
  } catch (const InputError& e) {
    throw InputError(where + shown + ": " + e.what());
  }
  return canon;
}

}  // namespace clothfit::limits
