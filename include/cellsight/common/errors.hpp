// Error types of the cellsight core. Every message names the file and the key it is about.
#pragma once
#include <stdexcept>
#include <string>

namespace cellsight {

/// A configuration, calibration or data file is malformed: the message names file and key.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace cellsight
