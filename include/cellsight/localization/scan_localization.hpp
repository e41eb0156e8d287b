// The localization pipeline, the one entry point the model_matching node, the in-process
// evaluation and the planning cycles call: one or more passes of a cell's scan (each its
// clusters and the evidence the scan gives besides them) located, their detections merged, and
// the parts refined on later passes.
#pragma once
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "cellsight/localization/clustering.hpp"
#include "cellsight/localization/light_sweep.hpp"
#include "cellsight/localization/model_matching.hpp"

namespace cellsight {

/// What a scan tells the matcher besides its clusters, in the clusters' frame.
struct ScanEvidence {
  /// the scanner camera's centre (the visible-surface test); none: MatchingConfig::viewpoint
  std::optional<Eigen::Vector3f> viewpoint;
  /// the support a·x + b·y + c·z + d = 0 (unit normal up): the support tests and the turned poses
  std::optional<Eigen::Vector4f> support_plane;
  std::vector<Eigen::Vector3f> support_points;  ///< where the scan saw the support (free-space tests)
  std::optional<LightSweep> light;              ///< the scan's light sheet (illumination, unseen tests)
  std::vector<Eigen::Vector3f> fragments;       ///< points above the support in no cluster
};

/// What a pass is for: the first finds the parts; a later one adds the parts the earlier left
/// unfound (ModelMatcher::mergePasses) or refines the parts found (ModelMatcher::refine).
enum class PassRole { kDetect, kAddDetections, kRefine };
const char* passRoleName(PassRole role);
/// "detect", "add_detections", "refine"; throws std::invalid_argument naming the word otherwise.
PassRole passRoleFromName(const std::string& name);

struct ScanPass {
  PassRole role = PassRole::kDetect;
  std::vector<ScanCloud> clusters;
  ScanEvidence evidence;
};

/// A pass from a clustered scan: its clusters, support plane (when found), support points and
/// fragments, with the scan's viewpoint and light sheet.
ScanPass scanPass(PassRole role, const ClusteringResult& clustered, const std::optional<Eigen::Vector3f>& viewpoint,
                  std::optional<LightSweep> light);

struct PassResult {
  std::vector<PartDetection> found;  ///< this pass's own detections (refine: the parts after it)
  MatchStats stats;
};

struct LocatedScan {
  std::vector<PartDetection> parts;  ///< the cell's parts after every pass
  /// the detect pass's figures with every add pass's refused poses (pass 1), merge counts and
  /// time added; refine passes' warnings added
  MatchStats stats;
  std::vector<PassResult> passes;  ///< per pass, in order
};

/// Runs `passes` in order over `models` (empty: all). The first must be kDetect and no other may
/// be; an add pass's free-space tests read the support points of every pass so far (the cell
/// stands still between passes); a refine pass refines on its clusters and every earlier pass's
/// clusters, with the detect pass's viewpoint and support plane. Throws std::invalid_argument for
/// a malformed list, std::out_of_range for an unknown model.
LocatedScan locateScan(const ModelMatcher& matcher, const std::vector<ScanPass>& passes,
                       const std::vector<std::string>& models = {});

/// The next pass of a cycle whose passes arrive one by one (the model_matching node): locates
/// passes[k], k = so_far->passes.size(), on top of *so_far, which holds passes 0..k-1 located.
/// locateScan is this for k = 0, 1, ..., so both give the same result. Throws as locateScan for a
/// malformed list, and std::invalid_argument when every pass is located already.
void addPass(const ModelMatcher& matcher, const std::vector<ScanPass>& passes, LocatedScan* so_far,
             const std::vector<std::string>& models = {});

}  // namespace cellsight
