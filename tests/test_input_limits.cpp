// The shared input-hardening helpers (render/scene/input_limits.h): bounded reads, the JSON
// nesting pre-scan, checked arithmetic, message escaping, UTF-8-safe JSON writing, path
// confinement.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>

#include "render/scene/input_limits.h"
#include "tests/hostile_fixtures.h"

namespace clothfit {
namespace {
namespace fs = std::filesystem;
using namespace limits;

std::string Nest(size_t depth, char open = '[', char close = ']') {
  return std::string(depth, open) + std::string(depth, close);
}

TEST(JsonDepth, CountsBracketsOutsideStringsOnly) {
  EXPECT_FALSE(FindJsonDepthExcess(R"(["[[\"[[", {"a": "{{{{"}])", 2));
  EXPECT_TRUE(FindJsonDepthExcess(R"([[[1]]])", 2));
  // An escaped backslash before the closing quote ends the string.
  EXPECT_FALSE(FindJsonDepthExcess(R"(["\\", [1]])", 2));
  EXPECT_TRUE(FindJsonDepthExcess(R"(["\\", [[1]]])", 2));
}

TEST(JsonDepth, LimitIsExactAndOffsetPointsAtTheBracket) {
  EXPECT_FALSE(FindJsonDepthExcess(Nest(kMaxJsonDepth)));
  const std::string deep = "  " + Nest(kMaxJsonDepth + 1, '{', '}');
  const auto at = FindJsonDepthExcess(deep);
  ASSERT_TRUE(at);
  EXPECT_EQ(*at, 2 + kMaxJsonDepth);
  try {
    CheckJsonDepth("\n" + Nest(100000), "deep.json");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("deep.json:2:65"), std::string::npos) << m;
    EXPECT_NE(m.find("kMaxJsonDepth"), std::string::npos) << m;
  }
}

TEST(Escape, ControlsAndInvalidUtf8BecomeHex) {
  EXPECT_EQ(EscapeForMessage("a\xFF\x1B[31m\xC3\xBC\\"), "a\\xFF\\x1B[31m\xC3\xBC\\\\");
  EXPECT_EQ(EscapeForMessage("\xC0\xAF"), "\\xC0\\xAF");           // overlong '/'
  EXPECT_EQ(EscapeForMessage("\xED\xA0\x80"), "\\xED\\xA0\\x80");  // surrogate
  EXPECT_EQ(EscapeForMessage("\xC2\x9B"), "\\xC2\\x9B");           // C1 CSI
  EXPECT_EQ(EscapeForMessage("\xE2\x82\xAC"), "\xE2\x82\xAC");     // euro sign passes
  const std::string cut = EscapeForMessage(std::string(500, 'x'), 10);
  EXPECT_EQ(cut, "xxxxxxxxxx...");
  EXPECT_TRUE(IsValidUtf8(EscapeForMessage("\xF0\x9F\x98\x80\xF0\x9F", 5)));
  EXPECT_FALSE(IsValidUtf8("\xFF"));
  EXPECT_TRUE(IsValidUtf8("plain \xC3\xA9"));
}

TEST(DumpJsonTest, InvalidUtf8IsReplacedNotThrown) {
  const nlohmann::json j = {{"reason", "bad \xFF byte"}};
  EXPECT_THROW((void)j.dump(), nlohmann::json::type_error);
  const std::string s = DumpJson(j);
  EXPECT_TRUE(IsValidUtf8(s));
  EXPECT_NE(s.find("\xEF\xBF\xBD"), std::string::npos);  // U+FFFD
}

TEST(CheckedArithmetic, DetectsWrap) {
  const size_t big = size_t(-1) / 3 + 1;  // (2^64+2)/3, the reproducer's count: x3 wraps to 2
  EXPECT_FALSE(CheckedMul(big, 3));
  EXPECT_EQ(*CheckedMul(7, 6), 42u);
  EXPECT_FALSE(CheckedAdd(size_t(-8), 300));
  EXPECT_FALSE(CheckedProduct({size_t(1) << 32, size_t(1) << 32}));
  EXPECT_EQ(*CheckedProduct({2, 3, 4}), 24u);
}

TEST(BoundedRead, RefusesSpecialFilesAndOversizeBeforeReading) {
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_THROW(ReadFileBounded("/dev/zero", 1 << 20, "test file"), InputError);
  EXPECT_THROW(ReadFileBounded("/proc/self/pagemap", 1 << 20, "test file"), InputError);
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
  const fs::path d = testing::Scratch("bounded");
  const std::string f = (d / "big.json").string();
  {
    std::ofstream o(f);
    o << std::string(2000, ' ');
  }
  try {
    ReadFileBounded(f, 1000, "JSON file");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("big.json"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("over the limit of 1000"), std::string::npos);
  }
  EXPECT_EQ(ReadFileBounded(f, 2000, "JSON file").size(), 2000u);
  fs::remove_all(d);
}

TEST(GlbChunk, OnlyAWellFormedHeaderYieldsTheJson) {
  std::string glb = "glTF";
  auto put32 = [&](uint32_t v) {
    for (int k = 0; k < 4; ++k) glb += char((v >> (8 * k)) & 0xFF);
  };
  put32(2);
  put32(20 + 4);
  put32(4);
  put32(0x4E4F534A);
  glb += "[[]]";
  auto span = std::span<const unsigned char>(reinterpret_cast<const unsigned char*>(glb.data()),
                                             glb.size());
  EXPECT_EQ(GlbJsonChunk(span), "[[]]");
  glb[12] = char(200);  // chunk length past the end
  span = std::span<const unsigned char>(reinterpret_cast<const unsigned char*>(glb.data()),
                                        glb.size());
  EXPECT_TRUE(GlbJsonChunk(span).empty());
}

TEST(PathConfinement, OutsideAbsoluteAndSchemesAreRefusedUnlessAllowed) {
  const fs::path d = testing::Scratch("confine");
  fs::create_directories(d / "cat" / "maps");
  fs::create_directories(d / "elsewhere");
  for (const fs::path& p : {d / "cat/maps/n.png", d / "elsewhere/n.png"}) {
    std::ofstream o(p);
    o << "x";
  }
  const std::string file = (d / "cat/s.json").string();
  const PathPolicy strict{d / "cat", false};
  EXPECT_EQ(ResolveConfined(file, "maps.normal.uri", "maps/n.png", strict),
            fs::weakly_canonical(d / "cat/maps/n.png"));
  auto expect_refused = [&](const std::string& uri, const char* why) {
    try {
      ResolveConfined(file, "maps.normal.uri", uri, strict);
      ADD_FAILURE() << uri << " accepted";
    } catch (const InputError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("s.json"), std::string::npos) << m;
      EXPECT_NE(m.find("maps.normal.uri"), std::string::npos) << m;
      EXPECT_NE(m.find(why), std::string::npos) << m;
      EXPECT_TRUE(IsValidUtf8(m));
    }
  };
  expect_refused("../elsewhere/n.png", "outside");
  expect_refused("../../../../../etc/shadow", "outside");
  expect_refused((d / "elsewhere/n.png").string(), "absolute");
  expect_refused("/proc/self/pagemap", "absolute");
  expect_refused("file:///etc/passwd", "scheme");
  expect_refused("maps/\x01n.png", "control");
  // A symlink inside the tree that points out of it is outside.
  fs::create_symlink(d / "elsewhere", d / "cat/link");
  expect_refused("link/n.png", "outside");
  // The user may allow it, but special files stay refused.
  const PathPolicy open{d / "cat", true};
  EXPECT_NO_THROW(ResolveConfined(file, "maps.normal.uri", "../elsewhere/n.png", open));
  EXPECT_THROW(ResolveConfined(file, "maps.normal.uri", "/proc/self/pagemap", open), InputError);
  fs::remove_all(d);
}

}  // namespace
}  // namespace clothfit
