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
  /// The distance to the nearest surface, and in *object the index of the scene object whose
  /// surface it is (-1: the table, or nothing within reach).
  double nearest(const Eigen::Vector3d& p, int* object) const;
  /// Distance statistics of `points`; with `on_object`, also the scene objects each point lies
  /// on: the index of the nearest surface's object where it is within `radius` (-1: the table,
  /// or farther from every surface), one per point.
  SurfaceErrorStats stats(const std::vector<Eigen::Vector3d>& points, std::vector<int>* on_object = nullptr,
                          double radius = 0.001) const;

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


/// Line-centre accuracy on a rendered frame whose truth is known: for every extracted centre
/// (u, v) the ray through it meets the true surface at X; f(u, v) = signed distance of X to the
/// true light sheet, and the centre's error is f / |∇f| (px, across the line, first order, from
/// rays at ±0.5 px) — valid for lines in any direction and curved traces. Centres whose five
/// rays do not all meet the same surface, or that lie where the noise-free laser does not reach
/// (shadows, depth edges), are not compared. Coverage: lineCoverage() of the centres against the
/// noise-free laser render (LineCoverageRule{20 grey levels}).
struct LineCentreErrors {
  size_t points = 0;    ///< centres compared
  size_t centres = 0;   ///< centres extracted
  double coverage = 0;  ///< share of the noise-free trace's row/column crossings with a centre
  double false_share = 0;  ///< share of centres away from the noise-free trace
  double rms_px = 0, max_px = 0, mean_px = 0, p95_px = 0;
  /// The same over centres whose surface continues 3 px around them (no depth edge or surface
  /// change near: the centre estimator on smooth, possibly curved traces).
  size_t interior_points = 0;
  double interior_rms_px = 0;
};
LineCentreErrors lineCentreErrors(const ScannerRenderer& renderer,
                                  const Eigen::Isometry3d& T_base_flange,
                                  const LineExtractionConfig& config, uint64_t seed);

/// A reference for "where is a line visible", independent of the extractor: after Gaussian
/// smoothing and a white top-hat (element 2·max_width + 1: the local background under a glow or
/// a lit area is removed; skipped when `background` ≥ 0 is given), every image column and every
/// image row is split into runs of pixels at least `min_contrast` above the background; a run no
/// wider than `max_width`, and not longer than the run the other way through its middle, is one
/// crossing of a visible line (a wider run is a lit area; a longer one runs along the line). A centre is false when no
/// pixel within the tolerance reaches half the contrast (nothing there; between half and full
/// contrast, or in a lit area, the rule does not judge).
struct LineCoverageRule {
  double min_contrast = 40;
  int max_width = 16;
  double smooth_sigma = 1.0;   ///< px; 0: none
  double background = -1;     ///< ≥ 0: a fixed background level instead of the top-hat
  double tolerance_px = 2.0;   ///< a centre covers a crossing within the run ± this
  /// Count no crossing in or near lit areas wider than a line (a glow, a specular spot: what the
  /// opening by the 2·max_width + 1 element keeps at half the contrast, widened by as much),
  /// where the rule's runs follow the glow's texture rather than a line.
  bool skip_lit_areas = false;
};
struct LineCoverage {
  long crossings = 0;      ///< column and row crossings of a visible line
  long covered = 0;        ///< crossings with a centre in them
  long centres = 0;
  long false_centres = 0;  ///< centres with nothing at half the contrast within the tolerance
  cv::Mat mask;            ///< CV_8UC1, 255 on the crossings' pixels (for an overlay)
  cv::Mat missed;          ///< CV_8UC1, 255 on the pixels of crossings without a centre
  double coverage() const { return crossings ? double(covered) / double(crossings) : 0.0; }
  double falseShare() const { return centres ? double(false_centres) / double(centres) : 0.0; }
};
LineCoverage lineCoverage(const cv::Mat& mono, const std::vector<LinePoint>& centres, const LineCoverageRule& rule);

}  // namespace cellsight
