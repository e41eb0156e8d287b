// cellsight_evaluate_localization's shared parts: the options of a subcommand and the
// occlusion / outlier sweeps (evaluate_sweeps.cpp), the scoring against the truth
// (evaluate_scoring.cpp).
#pragma once
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight_tools {

using cellsight::DetectionCounts;
using cellsight::ModelLibrary;
using cellsight::ModelMatcher;
using cellsight::ScanCloud;
using cellsight::Scene;

/// The options of one subcommand (each has its own instance and defaults).
struct EvalOptions {
  std::string root = ".", scene, models, matching, json, png;
  std::string search = "all";
  double max_t_mm = 2, max_r_deg = 2;
  int trials = 100, ks = 20;
  double from = 0.25, to = 0.75, step = 0.05;
  double min_fitness = 0;
  bool min_fitness_given = false;
  std::vector<std::string> parts;
  std::vector<double> ratios;
  std::string detections, cloud, calibration;
  std::string trajectory = "demo_sweep";  ///< cells: the scan's trajectory (config/trajectories.yaml)
  /// cells: a second scan's trajectory (empty: none), located on its own and merged
  /// (ModelMatcher::mergePasses)
  std::string second_pass;
  double limit_rms_mm = 0, limit_t_mm = 0, limit_r_deg = 0, limit_recall = 0;  ///< cells: 0 = no limit
  std::string dump_clusters;  ///< cells, cloud: write each scene's clusters as PLY here
  /// `value`, or `<root>/<relative>` when not given
  std::string orRoot(const std::string& value, const std::string& relative) const {
    return value.empty() ? root + "/" + relative : value;
  }
};

/// Drops empty names ("a,,b" -> a, b), as the comma-separated lists always did.
inline std::vector<std::string> nonEmpty(const std::vector<std::string>& v) {
  std::vector<std::string> out;
  for (const auto& s : v)
    if (!s.empty()) out.push_back(s);
  return out;
}

/// The thesis's random-walk occlusion test on single-view clouds of the parts (subcommand occlusion).
int runOcclusion(const EvalOptions& o);
/// Uniform outliers in the workspace box, 0…200 % of a part's points (subcommand outliers).
int runOutliers(const EvalOptions& o);

struct ScoredDetection {
  std::string model;
  Eigen::Isometry3d pose;
  double fitness = 0, coverage = 0, rmse = 0, see_through = 0, unseen = 0, continuation = 0, overhang = 0;
  double alternative_score_share = 0;             ///< PartDetection's (0: none fits as closely, or turns not scored)
  std::vector<Eigen::Isometry3d> ambiguous_poses{};  ///< PartDetection's (empty: not ambiguous)
  int pass = 0;                                   ///< PartDetection's: the scan it was found on
};

/// Detections against a scene's truth: each object takes the nearest unused detection of its
/// model, found when within max_t / max_r; detections left over are false. Per part and totals.
nlohmann::json scoreDetections(const Scene& scene, const ModelLibrary& lib, const ModelMatcher& centroids,
                               const std::vector<ScoredDetection>& dets, double max_t, double max_r,
                               DetectionCounts* counts, std::vector<double>* terr, std::vector<double>* rerr);

/// What the scan measured of each part (evaluation only: from the truth). Each part gets
/// `scan_points`, the scan points on its true surface (`on_object`: per point, the scene object
/// it lies on within kOnSurface, SurfaceDistance::stats). A false detection of a part's model
/// whose nearest object is that part, missed, gets `part_points_on_it`: the share of the part's
/// scan points that lie within kOnSurface of the detected pose's surface too (1: the points
/// cannot tell the two poses apart; only where nothing was measured can).
constexpr double kOnSurface = 0.001;  // m
constexpr double kFitsBoth = 0.99;    // part_points_on_it from which the scan cannot tell the poses apart
void describeScanPoints(const Scene& scene, const ModelLibrary& lib, const ScanCloud& cloud, const std::vector<int>& on_object,
                        const std::vector<ScoredDetection>& dets, nlohmann::json* sj);

}  // namespace cellsight_tools
