#include "cellsight/scanner/scanner_config.hpp"

#include <cmath>

#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

LineThresholds lineThresholdsOf(const LineExtractionConfig& c) {
  return {c.min_contrast, c.threshold_fraction, c.max_run, c.secondary_peak_ratio, c.min_segment, c.segment_max_jump};
}

std::pair<std::string, std::string> checkLineThresholds(const LineThresholds& t) {
  if (!(t.min_contrast >= 0 && t.min_contrast <= 255)) return {"min_contrast", "must be in [0, 255] (grey levels)"};
  if (!(t.threshold_fraction > 0 && t.threshold_fraction < 1)) return {"threshold_fraction", "must lie in (0, 1)"};
  if (t.max_run < 1) return {"max_run", "must be >= 1 (pixels)"};
  if (!(t.secondary_peak_ratio > 0 && t.secondary_peak_ratio <= 1)) return {"secondary_peak_ratio", "must lie in (0, 1]"};
  if (t.min_segment < 1) return {"min_segment", "must be >= 1 (pixels)"};
  if (!(t.segment_max_jump > 0)) return {"segment_max_jump", "must be > 0 (pixels)"};
  return {"", ""};
}

ScannerSettings loadScannerSettings(const std::string& path) {
  YamlMap m(loadYamlFile(path), path);
  ScannerSettings s;
  if (m.has("line")) {
    YamlMap l = m.getMap("line");
    LineExtractionConfig& c = s.line;
    try {
      c.estimator = LineExtractionConfig::parseEstimator(l.getString("estimator", LineExtractionConfig::estimatorName(c.estimator)));
    } catch (const std::invalid_argument& e) {
      l.fail("estimator", e.what());
    }
    c.channel = l.getInt("channel", c.channel);
    if (c.channel < -1 || c.channel > 2) l.fail("channel", "must be -1 (mono), 0, 1 or 2");
    c.background_percentile = l.getDouble("background_percentile", c.background_percentile);
    if (c.background_percentile <= 0 || c.background_percentile >= 1) l.fail("background_percentile", "must lie in (0, 1)");
    c.min_contrast = l.getDouble("min_contrast", c.min_contrast);
    c.threshold_fraction = l.getDouble("threshold_fraction", c.threshold_fraction);
    if (c.threshold_fraction <= 0 || c.threshold_fraction >= 1) l.fail("threshold_fraction", "must lie in (0, 1)");
    c.centroid_margin = l.getInt("centroid_margin", c.centroid_margin);
    c.centroid_floor = l.getDouble("centroid_floor", c.centroid_floor);
    if (c.centroid_floor < 0 || c.centroid_floor >= 1) l.fail("centroid_floor", "must lie in [0, 1)");
    c.max_run = l.getInt("max_run", c.max_run);
    c.secondary_peak_ratio = l.getDouble("secondary_peak_ratio", c.secondary_peak_ratio);
    c.secondary_peak_gap = l.getInt("secondary_peak_gap", c.secondary_peak_gap);
    c.segment_max_jump = l.getDouble("segment_max_jump", c.segment_max_jump);
    c.segment_erode = l.getInt("segment_erode", c.segment_erode);
    c.min_segment = l.getInt("min_segment", c.min_segment);
    c.smoothing_degree = l.getInt("smoothing_degree", c.smoothing_degree);
    if (c.smoothing_degree < 0 || c.smoothing_degree > 3) l.fail("smoothing_degree", "must be 0..3");
    c.smoothing_half_window = l.getInt("smoothing_half_window", c.smoothing_half_window);
    if (c.smoothing_half_window < 1) l.fail("smoothing_half_window", "must be >= 1");
    c.ridge_sigma = l.getDouble("ridge_sigma", c.ridge_sigma);
    if (!(c.ridge_sigma >= 0.5 && c.ridge_sigma <= 10)) l.fail("ridge_sigma", "must lie in [0.5, 10] (pixels)");
    c.ridge_gaussian_profile = l.getBool("ridge_gaussian_profile", c.ridge_gaussian_profile);
    c.ridge_max_isotropy = l.getDouble("ridge_max_isotropy", c.ridge_max_isotropy);
    if (!(c.ridge_max_isotropy > 0 && c.ridge_max_isotropy <= 1)) l.fail("ridge_max_isotropy", "must lie in (0, 1]");
    c.link_max_gap = l.getDouble("link_max_gap", c.link_max_gap);
    if (!(c.link_max_gap >= 1 && c.link_max_gap <= 10)) l.fail("link_max_gap", "must lie in [1, 10] (pixels)");
    c.link_max_angle = l.getDouble("link_max_angle", c.link_max_angle);
    if (!(c.link_max_angle > 0 && c.link_max_angle <= M_PI / 2)) l.fail("link_max_angle", "must lie in (0, pi/2] (radians)");
    if (const auto bad = checkLineThresholds(lineThresholdsOf(c)); !bad.first.empty()) l.fail(bad.first, bad.second);
    l.finish();
  }
  if (m.has("triangulation")) {
    YamlMap t = m.getMap("triangulation");
    s.triangulation.min_ray_plane_angle = t.getDouble("min_ray_plane_angle", s.triangulation.min_ray_plane_angle);
    s.triangulation.min_range = t.getDouble("min_range", s.triangulation.min_range);
    s.triangulation.max_range = t.getDouble("max_range", s.triangulation.max_range);
    if (s.triangulation.max_range <= s.triangulation.min_range) t.fail("max_range", "must exceed min_range");
    t.finish();
  }
  s.outlier_k = m.getInt("outlier_k", s.outlier_k);
  if (s.outlier_k < 0) m.fail("outlier_k", "must be >= 0 (0: no outlier removal)");
  s.outlier_std = m.getDouble("outlier_std", s.outlier_std);
  if (!(s.outlier_std > 0)) m.fail("outlier_std", "must be > 0 (standard deviations)");
  s.normal_k = m.getInt("normal_k", s.normal_k);
  if (s.normal_k != 0 && s.normal_k < 3) m.fail("normal_k", "must be 0 (no normals) or >= 3 (neighbours of a plane fit)");
  if (m.has("workspace_min") || m.has("workspace_max")) {
    const Eigen::Vector3f lo = m.getVector3("workspace_min").cast<float>(), hi = m.getVector3("workspace_max").cast<float>();
    if ((hi.array() <= lo.array()).any()) m.fail("workspace_max", "must exceed workspace_min on every axis");
    s.workspace = Eigen::AlignedBox3f(lo, hi);
    s.has_workspace = true;
  }
  s.laser_fan_angle = m.getDouble("laser_fan_angle", s.laser_fan_angle);
  if (!(s.laser_fan_angle >= 0 && s.laser_fan_angle < M_PI))
    m.fail("laser_fan_angle", "must be in [0, pi) (radians, the projector's full fan; 0: unbounded)");
  m.finish();
  return s;
}

}  // namespace cellsight
