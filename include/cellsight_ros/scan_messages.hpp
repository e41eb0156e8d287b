// The scan's messages between the nodes, built and read by one function each, so that the
// nodes and cellsight_locate_bag (the same frames located in-process) run the same code:
// the line settings for an image's encoding, the clustering result as a ClusterArray, a
// ClusterArray as a localization pass, and the detections file.
#pragma once
#include <std_msgs/Header.h>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cellsight/ClusterArray.h"
#include "cellsight/DetectionArray.h"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/localization/scan_localization.hpp"
#include "cellsight/scanner/line_extraction.hpp"

namespace cellsight_ros {

/// `line` for an image of `encoding`: mono8 reads its one channel; an RGB image the configured
/// channel (red when unset), mirrored for bgr8.
cellsight::LineExtractionConfig lineConfigFor(const std::string& encoding, cellsight::LineExtractionConfig line);

/// A clustered scan as the clustering node publishes it (clouds in `header`'s frame and stamp).
cellsight::ClusterArray toClusterArrayMsg(const cellsight::ClusteringResult& r, const std_msgs::Header& header);

/// A ClusterArray as a detect pass seen from `viewpoint` (no light sweep: the caller adds it).
/// Unreadable clouds become empty clusters or missing evidence, each with a line in `warnings`;
/// a support plane that is not finite and unit is left out.
cellsight::ScanPass toScanPass(const cellsight::ClusterArray& msg, const Eigen::Vector3f& viewpoint,
                               std::vector<std::string>* warnings);

/// The detections file model_matching writes (~output_file) for one DetectionArray.
nlohmann::json detectionsToJson(const cellsight::DetectionArray& out);

/// The pass of a recorded cycle a frame stamped `stamp` belongs to: the latest of the Scan goals
/// sent at `goals_sent` (sorted) at or before it; 0 when none is (a scan on its own).
size_t passOfFrame(const std::vector<ros::Time>& goals_sent, const ros::Time& stamp);

/// Where pass k of a cycle writes its cloud: `file` for the first, "_pass<k>" before the
/// extension for a later one (empty stays empty).
std::string passOutputFile(const std::string& file, size_t k);

}  // namespace cellsight_ros
