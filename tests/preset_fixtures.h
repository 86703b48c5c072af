// tests/preset_fixtures.h: the "every bad field is named" check of the preset reader, shared by
// the yarn-lobe tests (session 19: tests/test_s12_yarn_lobe.cpp, tests/test_s19_microcylinder.cpp).
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "render/scene/material.h"

namespace clothfit::testing {

// One edit of a good preset's "woven": {"yarn_lobe"} block and the field its error must name.
struct BadLobeField {
  const char* what;
  std::function<void(nlohmann::json&)> edit;
  const char* field;
};

// Each edit of good["woven"]["yarn_lobe"] must be refused by render::ParsePreset(j, "p.json")
// with a MaterialError naming the file and the field.
inline void ExpectBadLobeFieldsNamed(const nlohmann::json& good, const std::vector<BadLobeField>& cases) {
  for (const BadLobeField& c : cases) {
    nlohmann::json j = good;
    c.edit(j["woven"]["yarn_lobe"]);
    try {
      render::ParsePreset(j, "p.json");
      ADD_FAILURE() << c.what << ": accepted";
    } catch (const render::MaterialError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("p.json"), std::string::npos) << c.what << ": " << m;
      EXPECT_NE(m.find(c.field), std::string::npos) << c.what << ": " << m;
    }
  }
}

}  // namespace clothfit::testing
