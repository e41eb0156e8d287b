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
  /// The projector's full fan opening (its datasheet), rad, centred on the calibrated laser
  /// frame's z: the light sweep lights nothing outside it (LightSweep). 0: unbounded.
  double laser_fan_angle = 0;
};

/// The line-extraction thresholds a user tunes on a running cell (triangulation's
/// dynamic_reconfigure); the YAML loader applies the same checks to them.
/// (The defaults live in LineExtractionConfig: take them with lineThresholdsOf({}).)
struct LineThresholds {
  double min_contrast = 0, threshold_fraction = 0;
  int max_run = 0;
  double secondary_peak_ratio = 0;
  int min_segment = 0;
  double segment_max_jump = 0;
};
/// Copies the thresholds into anything with fields of the same names (LineExtractionConfig, the
/// node's dynamic_reconfigure config).
template <typename Config>
void copyLineThresholds(const LineThresholds& t, Config* c) {
  c->min_contrast = t.min_contrast;
  c->threshold_fraction = t.threshold_fraction;
  c->max_run = t.max_run;
  c->secondary_peak_ratio = t.secondary_peak_ratio;
  c->min_segment = t.min_segment;
  c->segment_max_jump = t.segment_max_jump;
}
LineThresholds lineThresholdsOf(const LineExtractionConfig& c);
/// {"", ""} when valid, else {key, why} (the YAML loader's rules for these keys).
std::pair<std::string, std::string> checkLineThresholds(const LineThresholds& t);

/// Throws ConfigError naming the file and key for unknown keys and out-of-range values.
ScannerSettings loadScannerSettings(const std::string& path);

}  // namespace cellsight
