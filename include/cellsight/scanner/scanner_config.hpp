// The scanner's processing settings file (config/scanner.yaml), validated strictly: the same
// keys the triangulation node reads from its private namespace.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <utility>

#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/scanner/triangulation.hpp"

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

/// The line-extraction thresholds a user tunes on a running cell (triangulation's
/// dynamic_reconfigure); the YAML loader applies the same checks to them.
struct LineThresholds {
  double min_contrast = 25;
  double threshold_fraction = 0.5;
  int max_run = 40;
  double secondary_peak_ratio = 0.6;
  int min_segment = 5;
  double segment_max_jump = 1.0;
};
LineThresholds lineThresholdsOf(const LineExtractionConfig& c);
void applyLineThresholds(const LineThresholds& t, LineExtractionConfig* c);
/// {"", ""} when valid, else {key, why} (the YAML loader's rules for these keys).
std::pair<std::string, std::string> checkLineThresholds(const LineThresholds& t);

/// Throws ConfigError naming the file and key for unknown keys and out-of-range values.
ScannerSettings loadScannerSettings(const std::string& path);

}  // namespace cellsight
