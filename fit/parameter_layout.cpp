#include "fit/parameter_layout.h"

#include <algorithm>

namespace clothfit::fit {

std::vector<double> ParameterLayout::Defaults(std::span<const ParamInfo> table) const {
  std::vector<double> x(size_t(flat_size), 0.0);
  for (size_t i = 0; i < table.size() && i < blocks.size(); ++i)
    for (int c = 0; c < blocks[i].size; ++c)
      x[size_t(blocks[i].offset + c)] = table[i].def[size_t(c)];
  return x;
}

const Block& ParameterLayout::Find(const std::string& name) const {
  for (const Block& b : blocks)
    if (b.name == name) return b;
  throw std::invalid_argument("unknown parameter '" + name + "'");
}

ParameterLayout MakeLayout(std::span<const ParamInfo> table,
                           const std::vector<std::string>& locked) {
  ParameterLayout layout;
  std::string valid;
  for (const ParamInfo& p : table) {
    Block b;
    b.name = std::string(p.name);
    b.offset = layout.flat_size;
    b.size = p.size;
    b.lower = p.lower;
    b.upper = p.upper;
    b.locked = !p.differentiable;
    layout.flat_size += p.size;
    layout.blocks.push_back(b);
    valid += (valid.empty() ? "" : ", ") + b.name;
  }
  for (const std::string& name : locked) {
    auto it = std::find_if(layout.blocks.begin(), layout.blocks.end(),
                           [&](const Block& b) { return b.name == name; });
    if (it == layout.blocks.end()) {
      throw std::invalid_argument("--lock: unknown parameter '" + name + "' (valid: " + valid +
                                  ")");
    }
    it->locked = true;
  }
  return layout;
}

}  // namespace clothfit::fit
