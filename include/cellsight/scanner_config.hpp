// The scanner's processing settings file (config/scanner.yaml), validated strictly: the same
// keys the triangulation node reads from its private namespace.
#pragma once
#include <Eigen/Geometry>
#include <string>

#include "cellsight/line_extraction.hpp"
#include "cellsight/triangulation.hpp"

namespace cellsight {

struct ScannerSettings {
  LineExtractionConfig line;
  TriangulationConfig triangulation;
  int outlier_k = 20;
  double outlier_std = 3.0;
  int normal_k = 15;
  bool has_workspace = false;
  Eigen::AlignedBox3f workspace;
};

/// Throws ConfigError naming the file and key for unknown keys and out-of-range values.
ScannerSettings loadScannerSettings(const std::string& path);

}  // namespace cellsight
