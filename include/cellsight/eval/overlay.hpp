// A picture of a localisation result on a whole scan: the scene's points seen from the sensor
// (a pinhole at the origin looking along whichever of ±z holds the points), in grey, and the
// located model's points on top, in red. Used by cellsight_locate and the evaluation tools.
#pragma once
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <vector>

#include "cellsight/common/scan_cloud.hpp"

namespace cellsight {

/// `model_points` in the model frame, drawn at `pose` (scene frame) when one is given.
cv::Mat drawDetectionOverlay(const ScanCloud& scene, const std::vector<Eigen::Vector3f>& model_points,
                             const Eigen::Isometry3f* pose, int width = 900);

}  // namespace cellsight
