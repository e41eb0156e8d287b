// Measuring the QR fixture chain against the simulator's truth (the pipeline itself never sees
// it): N noisy renders of the fixture camera, each decoded and adjusted with the calibration the
// run was given, the user frames compared with the truth; and decoding rates on photo folders.
#pragma once
#include <Eigen/Geometry>
#include <map>
#include <string>
#include <vector>

#include "cellsight/fixtures/fixture_adjustment.hpp"
#include "cellsight/fixtures/hand_eye.hpp"
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

/// Mean, σ and maximum of one error over the renders in which the fixture was reported.
struct ErrorSummary {
  double mean = 0, sigma = 0, max = 0;
};

struct FixtureErrorStats {
  std::string type, program;
  int markers = 0;               ///< codes of this fixture in the scene
  int found = 0;                 ///< renders in which the fixture was reported
  ErrorSummary t_err, r_err;     ///< the reported (table-constrained or configured) UCS vs truth: m, rad
  ErrorSummary free_t_err, free_r_err;      ///< free 6-DoF (ViSP) averaged over the fixture's codes
  ErrorSummary single_t_err, single_r_err;  ///< free 6-DoF of the fixture's first code alone
  ErrorSummary reported_sigma;   ///< the node's own 1σ of the UCS origin, m
};

struct FixtureSimConfig {
  int renders = 100;
  std::string dump_misses;   ///< folder: renders where a fixture of the scene was not reported (PNG)
  uint64_t seed = 1;
  QrDetectorConfig detector;
  FixtureAdjustmentConfig adjustment;
};

struct FixtureSimResult {
  std::vector<FixtureErrorStats> fixtures;
  int renders = 0;
  int false_fixtures = 0;        ///< fixture reports of a type absent from the scene
  std::map<std::string, int> messages;  ///< what the adjustment refused or ignored, and how often
  std::map<std::string, int> decoders;  ///< codes per decoder path (zbar_region, zbar, zbar_2x, wechat, …)
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

/// Camera–robot calibration of the fixture camera on synthetic data: a 9×6 board (30 mm squares)
/// on top of the robot's tool, `views` flange poses in the camera's view (the first seven: a
/// reference and ±50 mm moves along the base axes, for the axes method), the board corners
/// projected with the scene's true camera and disturbed by `corner_sigma_px`, their PnP pose;
/// the flange poses reported with repeatability noise (σ per axis) and an orientation noise.
struct HandEyeSweepConfig {
  int views = 20;
  int trials = 10;
  uint64_t seed = 1;
  double corner_sigma_px = 0.1;
  double repeatability_mm = 0.02;
  double flange_rotation_deg = 0.002;
  double pointer_sigma_mm = 0.05;      ///< the axes method's touch of the target origin
};

/// One synthetic data set; the truth returned beside it (for the evaluation only).
HandEyeInput simulateHandEyeViews(const Scene& scene, const HandEyeSweepConfig& config, uint64_t seed,
                                  Eigen::Isometry3d* true_base_camera, Eigen::Isometry3d* true_flange_target);

struct HandEyeSweepRow {
  std::string factor;    ///< corner_sigma_px | repeatability_mm | flange_rotation_deg
  double value = 0;
  /// per method: mean error over the trials of a table point under the camera (mm) and of the
  /// rotation (deg); failures counted apart (a failed trial is never averaged in)
  std::vector<std::string> methods;
  std::vector<double> t_err_mm, r_err_deg;
  std::vector<int> failures;
};

/// Each factor swept with the others at the config's (realistic) values.
std::vector<HandEyeSweepRow> handEyeSweep(const Scene& scene, const HandEyeSweepConfig& config);

}  // namespace cellsight
