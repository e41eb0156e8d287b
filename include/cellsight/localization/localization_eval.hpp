// Test material for localisation (thesis §3 tests): single-view clouds of a model, the thesis's
// random-walk occlusion, uniform outliers with random normals, and TP/FP/FN → P/R/F1.
#pragma once
#include <Eigen/Geometry>
#include <random>

#include "cellsight/common/mesh.hpp"
#include "cellsight/common/scan_cloud.hpp"

namespace cellsight {

/// Points of `mesh` placed at T (model → scene) that `viewpoint` sees (facing it within
/// `max_view_angle`, not hidden by the mesh itself), about `spacing` apart, with Gaussian noise
/// of `noise` m along the view ray; normals from the mesh. One point per `spacing` cell is the
/// cell's centroid, as the clustering's voxel grid gives the matcher.
ScanCloud singleViewCloud(const TriangleMesh& mesh, const Eigen::Isometry3d& T, const Eigen::Vector3f& viewpoint,
                          double spacing, double noise, uint64_t seed, double max_view_angle = 1.40);

/// The thesis's occlusion: from a random start point take its k_s nearest neighbours, delete
/// them all but the farthest, which becomes the next start; until `share` of the points are gone.
ScanCloud randomWalkOcclusion(const ScanCloud& cloud, double share, int k_s, std::mt19937_64& rng);

/// Adds round(ratio · size) points uniform in `box` with random unit normals.
ScanCloud addUniformOutliers(const ScanCloud& cloud, const Eigen::AlignedBox3f& box, double ratio, std::mt19937_64& rng);

struct DetectionCounts {
  int tp = 0, fp = 0, fn = 0;
  /// of tp and fp: detections the matcher reported ambiguous (PartDetection::ambiguous_poses); of
  /// those false, the ones whose alternative pose is a part's
  int ambiguous_tp = 0, ambiguous_fp = 0, ambiguous_fp_alternative_right = 0;
  double precision() const { return tp + fp ? static_cast<double>(tp) / (tp + fp) : 0.0; }
  double recall() const { return tp + fn ? static_cast<double>(tp) / (tp + fn) : 0.0; }
  double f1() const {
    const double p = precision(), r = recall();
    return p + r > 0 ? 2 * p * r / (p + r) : 0.0;
  }
};

}  // namespace cellsight
