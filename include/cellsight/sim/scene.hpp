// The simulated cell's scene description (config/scenes/*.yaml). Units: metres, radians; poses in the robot base frame.
#pragma once
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/model_info.hpp"
#include "cellsight/sim/robot_model.hpp"

namespace cellsight {

struct SceneObject {
  std::string name;   ///< instance name, unique in the scene
  std::string model;  ///< model id (config/models/<id>)
  ModelInfo info;
  Eigen::Isometry3d T_base_object = Eigen::Isometry3d::Identity();
  double reflectivity = 0.6;  ///< diffuse albedo 0..1
  double shininess = 0.0;     ///< 0..1: share of laser light mirrored (stray reflections)
};

struct QrFixture {
  std::string id;
  std::string payload;  ///< text encoded in the code
  double code_size = 0.04;   ///< printed code side without quiet zone, metres
  double plate_size = 0.06;  ///< white plate side (≥ code + quiet zone), metres
  Eigen::Isometry3d T_base_fixture = Eigen::Isometry3d::Identity();  ///< code centre, z up
};

struct CameraConfig {
  CameraIntrinsics intrinsics;
  std::string frame_id;
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();  ///< optical frame
  std::string encoding = "mono8";  ///< mono8 | rgb8
  double frame_rate = 0.0;         ///< free-running rate; 0 = hardware-triggered
  double blur_sigma_px = 0.0;      ///< optical blur
};

struct LaserConfig {
  /// Laser frame L in the flange frame: origin at the emitter, z along the central beam,
  /// the light sheet is the plane y = 0 of L (its normal is L's y axis), fan spreads along x.
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();
  double fan_angle = 1.0;           ///< full opening angle, radians
  double line_width = 0.5e-3;       ///< full width at half maximum across the sheet, metres
  double brightness = 220.0;        ///< grey level of the line centre on a white, facing surface
  std::string colour = "red";       ///< red | green | blue (channel in rgb8 images)
};

struct NoiseConfig {
  bool enabled = true;
  double sensor_sigma = 2.0;        ///< grey levels, additive Gaussian
  double ambient = 12.0;            ///< grey level of a white surface under ambient light
  double speckle = 0.15;            ///< relative std of the laser intensity per pixel
  double dropout_probability = 0.002;  ///< share of lit pixels that read dark
  double stray_gain = 0.35;         ///< brightness of mirrored laser light on shiny parts
  uint64_t seed = 1;
};

struct RobotConfig {
  Eigen::Isometry3d home = Eigen::Isometry3d::Identity();  ///< flange pose at start
  double linear_speed = 0.25;   ///< m/s
  double angular_speed = 1.0;   ///< rad/s
  double settle_time = 0.02;    ///< s after arrival before "in position"
  Eigen::AlignedBox3d reach{Eigen::Vector3d(-1, -1, 0), Eigen::Vector3d(1, 1, 1.5)};
};

struct TableConfig {
  double z = 0.0;
  Eigen::Vector2d center{0.0, 0.0};
  Eigen::Vector2d size{0.8, 0.6};
  double reflectivity = 0.35;
};

/// How the built cell differs from its drawing (scene section `as_built`). The scene's camera
/// and laser poses are the drawing; loadScene moves them by seeded draws of these sizes (σ per
/// axis) unless `perfect`. Only the simulator and the evaluation see the result.
struct AsBuiltConfig {
  bool perfect = true;                  ///< true (or no section): the cell is its drawing, the robot exact
  uint64_t seed = 1;
  double camera_translation_mm = 0.0;   ///< scanner and fixture camera mounting
  double camera_rotation_deg = 0.0;
  double laser_translation_mm = 0.0;    ///< light-sheet projector on the flange
  double laser_rotation_deg = 0.0;
  RobotErrorConfig robot;               ///< enabled = !perfect
  // the drawing, kept for makePerfect() and the reports
  Eigen::Isometry3d drawn_scanner_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d drawn_fixture_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d drawn_laser = Eigen::Isometry3d::Identity();
};

struct Scene {
  std::string file;
  std::string name;
  std::string base_frame = "base_link";
  std::string flange_frame = "flange";
  std::string laser_frame = "laser";
  Eigen::AlignedBox3d workspace;  ///< scanner working volume in base_link
  TableConfig table;
  std::vector<SceneObject> objects;
  std::vector<QrFixture> fixtures;
  CameraConfig scanner_camera;
  CameraConfig fixture_camera;
  LaserConfig laser;
  NoiseConfig noise;
  RobotConfig robot;
  AsBuiltConfig as_built;
};

struct SceneLoadOptions {
  /// Folders searched for `<model id>/model.yaml`; empty means `<scene dir>/../models`.
  std::vector<std::string> model_paths;
};

/// Loads and validates a scene file: unknown keys, missing meshes, invalid meshes, cameras
/// that see none of the workspace → ConfigError naming the file and field.
Scene loadScene(const std::string& path, const SceneLoadOptions& options = {});

/// The ideal cell: camera and laser as drawn, the robot exact (the `perfect` switch).
void makePerfect(Scene& scene);

}  // namespace cellsight
