#include "cellsight_ros/params.hpp"

#include <ros/package.h>

namespace cellsight_ros {

cellsight::LineExtractionConfig loadLineConfig(const ros::NodeHandle& nh) {
  cellsight::LineExtractionConfig c;
  std::string estimator = "centroid";
  param(nh, "line/estimator", estimator);
  c.estimator = cellsight::LineExtractionConfig::parseEstimator(estimator);
  param(nh, "line/channel", c.channel);
  param(nh, "line/background_percentile", c.background_percentile);
  param(nh, "line/min_contrast", c.min_contrast);
  param(nh, "line/threshold_fraction", c.threshold_fraction);
  param(nh, "line/centroid_margin", c.centroid_margin);
  param(nh, "line/centroid_floor", c.centroid_floor);
  param(nh, "line/max_run", c.max_run);
  param(nh, "line/secondary_peak_ratio", c.secondary_peak_ratio);
  param(nh, "line/secondary_peak_gap", c.secondary_peak_gap);
  param(nh, "line/segment_max_jump", c.segment_max_jump);
  param(nh, "line/segment_erode", c.segment_erode);
  param(nh, "line/min_segment", c.min_segment);
  param(nh, "line/smoothing_degree", c.smoothing_degree);
  param(nh, "line/smoothing_half_window", c.smoothing_half_window);
  if (c.background_percentile <= 0 || c.background_percentile >= 1) {
    throw std::runtime_error(nh.resolveName("line/background_percentile") + " must lie in (0, 1)");
  }
  if (c.threshold_fraction <= 0 || c.threshold_fraction >= 1) {
    throw std::runtime_error(nh.resolveName("line/threshold_fraction") + " must lie in (0, 1)");
  }
  if (c.smoothing_degree < 0 || c.smoothing_degree > 3) {
    throw std::runtime_error(nh.resolveName("line/smoothing_degree") + " must be 0..3");
  }
  return c;
}

cellsight::TriangulationConfig loadTriangulationConfig(const ros::NodeHandle& nh) {
  cellsight::TriangulationConfig c;
  param(nh, "triangulation/min_ray_plane_angle", c.min_ray_plane_angle);
  param(nh, "triangulation/min_range", c.min_range);
  param(nh, "triangulation/max_range", c.max_range);
  return c;
}

std::string packagePath() {
  const std::string p = ros::package::getPath("cellsight");
  if (p.empty()) {
    throw std::runtime_error("package 'cellsight' not found: source <build>/devel/setup.bash first");
  }
  return p;
}

}  // namespace cellsight_ros
