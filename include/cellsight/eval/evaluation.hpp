// Scanner evaluation against the simulator's truth: distance of scan points to the true surfaces,
// line-centre errors against the analytic line.
#pragma once
#include <Eigen/Geometry>
#include <vector>

#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

struct SurfaceErrorStats {
  size_t points = 0;
  double rms = 0, max = 0, mean_abs = 0, p99 = 0;  ///< metres
};

/// Exact distance from a point to the nearest true surface of a scene: the table top (a plane
/// over its extent) and every object mesh (closest point on its triangles; objects whose
/// bounding box is farther than the current best are skipped).
class SurfaceDistance {
 public:
  explicit SurfaceDistance(const Scene& scene);
  double operator()(const Eigen::Vector3d& p) const;
  SurfaceErrorStats stats(const std::vector<Eigen::Vector3d>& points) const;

 private:
  struct Object {
    std::vector<Eigen::Vector3d> a, b, c;  // triangle corners, base frame
    Eigen::AlignedBox3d box;
  };
  std::vector<Object> objects_;
  TableConfig table_;
};

/// Closest distance between point p and triangle (a, b, c).
double pointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                             const Eigen::Vector3d& b, const Eigen::Vector3d& c);


/// Line-centre accuracy on a rendered line with a known centre: the scene's objects are removed,
/// the flange is placed so the sheet crosses the bare table, and each extracted centre is
/// compared with the analytic projection of the sheet ∩ table line (px, along the search
/// direction). Columns within 10 % of the line's ends are skipped (fan cut-off).
struct LineCentreErrors {
  size_t columns = 0;  ///< columns with a centre, compared
  size_t expected = 0; ///< columns the line crosses (10 % margins excluded)
  double rms_px = 0, max_px = 0, mean_px = 0;
};
LineCentreErrors lineCentreErrors(const ScannerRenderer& bare_renderer,
                                  const Eigen::Isometry3d& T_base_flange,
                                  const LineExtractionConfig& config, uint64_t seed);

}  // namespace cellsight
