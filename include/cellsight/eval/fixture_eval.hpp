// Measuring the QR fixture chain against the simulator's truth (the pipeline itself never sees
// it): N noisy renders of the fixture camera, each decoded and adjusted with the calibration the
// run was given, the user frames compared with the truth; and decoding rates on photo folders.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "cellsight/fixtures/fixture_adjustment.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

/// The truth of one registry fixture in a scene: its scene fixtures (one per code) must carry the
/// registry's payloads; the fixture frame is placed from the first code found.
struct FixtureTruth {
  std::string type, program;
  std::vector<std::string> payloads;   ///< the codes present in the scene
  Eigen::Isometry3d T_base_fixture = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_base_ucs = Eigen::Isometry3d::Identity();
};
std::vector<FixtureTruth> fixtureTruth(const Scene& scene, const FixtureRegistry& registry);

struct FixtureErrorStats {
  std::string type, program;
  int markers = 0;               ///< codes of this fixture in the scene
  int found = 0;                 ///< renders in which the fixture was reported
  // table-constrained (or the configured) pose vs truth: mean, σ and max over the renders
  double t_err_mean = 0, t_err_sigma = 0, t_err_max = 0;   ///< metres
  double r_err_mean = 0, r_err_sigma = 0, r_err_max = 0;   ///< radians
  // free 6-DoF (ViSP) averaged over the fixture's codes
  double free_t_err_mean = 0, free_t_err_sigma = 0, free_r_err_mean = 0, free_r_err_sigma = 0;
  // free 6-DoF of the first code alone
  double single_t_err_mean = 0, single_r_err_mean = 0;
  double sigma_translation_reported = 0;  ///< the node's own 1σ estimate (mean over renders)
};

struct FixtureSimConfig {
  int renders = 100;
  uint64_t seed = 1;
  QrDetectorConfig detector;
  FixtureAdjustmentConfig adjustment;
};

struct FixtureSimResult {
  std::vector<FixtureErrorStats> fixtures;
  int renders = 0;
  int false_fixtures = 0;        ///< fixture reports of a type absent from the scene
  double detect_ms_median = 0;   ///< decoding + refinement per frame
  double adjust_ms_median = 0;   ///< poses + averaging per frame
};

/// Renders the scene's fixture camera `renders` times (sensor noise redrawn each time) and runs
/// the chain with `camera` and `T_base_camera` (a calibration, not the truth).
FixtureSimResult evaluateFixturesSim(const Scene& scene, const FixtureRegistry& registry,
                                     const CameraIntrinsics& camera, const Eigen::Isometry3d& T_base_camera,
                                     const FixtureSimConfig& config = {});

struct DecodeRate {
  int images = 0;
  int decoded = 0;               ///< images where one decoded payload equals the expected text byte-exactly
  int decoded_zbar_only = 0;
  int decoded_wechat_only = 0;
  std::vector<std::string> missed; ///< image paths, relative to the folder
};

/// Every image under `folder` (png, jpg) with a `<name>.txt` beside it holding the expected text.
DecodeRate evaluateDecodeRate(const std::string& folder, const QrDetectorConfig& config = {});

}  // namespace cellsight
