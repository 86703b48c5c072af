// fit/parameter_layout.h: Ceres parameter blocks and bounds built from a model's parameter
// table (brdf/params.h), with any subset of parameters locked to fixed values.
#pragma once

#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "brdf/params.h"

namespace clothfit::fit {

struct Block {
  std::string name;
  int offset = 0;  // into the flat parameter vector (model table order)
  int size = 0;
  double lower = 0.0, upper = 0.0;
  bool locked = false;
};

struct ParameterLayout {
  std::vector<Block> blocks;
  int flat_size = 0;

  // Flat vector of the table's defaults.
  std::vector<double> Defaults(std::span<const ParamInfo> table) const;
  const Block& Find(const std::string& name) const;  // throws std::invalid_argument
};

// `locked`: names of parameters to hold fixed. Unknown names throw std::invalid_argument
// naming the parameter and listing the valid ones.
ParameterLayout MakeLayout(std::span<const ParamInfo> table,
                           const std::vector<std::string>& locked = {});

}  // namespace clothfit::fit
