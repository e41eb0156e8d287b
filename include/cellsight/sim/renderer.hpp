// The simulated cell's cameras: a scanner camera that sees the robot-carried laser line (with
// laser shadows, a Gaussian sheet profile, speckle, drop-outs, stray reflections on shiny parts),
// and a fixture camera that sees the printed QR codes.
#pragma once
#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

#include "cellsight/common/plane.hpp"
#include "cellsight/sim/qr_code.hpp"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

/// Every surface of a scene in one ray-casting structure, with per-geometry material data.
class CellGeometry {
 public:
  enum class Kind { kTable, kObject, kFixture };
  struct Surface {
    Kind kind;
    int index;  ///< into Scene::objects / Scene::fixtures
    double reflectivity;
    double shininess;
  };

  explicit CellGeometry(const Scene& scene);
  const RayCaster& caster() const { return caster_; }
  const Surface& surface(int geometry) const { return surfaces_[static_cast<size_t>(geometry)]; }
  /// Albedo at a world point on a fixture plate (QR module lookup, quiet zone white).
  double fixtureAlbedo(int fixture, const Eigen::Vector3d& p_world) const;
  const Scene& scene() const { return scene_; }

 private:
  Scene scene_;
  RayCaster caster_;
  std::vector<Surface> surfaces_;
  std::vector<QrMatrix> codes_;
  std::vector<Eigen::Isometry3d> T_fixture_base_;
};

struct ScannerRenderOptions {
  int supersample = 4;      ///< sub-samples per pixel side inside the laser band
  double band_sigmas = 4;   ///< the sheet profile is evaluated out to this many σ
  bool noise = true;        ///< false: noise-free (ambient still applied if `ambient`)
  bool ambient = true;
};

/// Renders scanner-camera frames. The camera and the scene are static during a scan, so the
/// first surface on every pixel's ray is cast once at construction; each frame then only
/// evaluates the light sheet and casts shadow rays for pixels near it.
class ScannerRenderer {
 public:
  ScannerRenderer(std::shared_ptr<const CellGeometry> geometry, ScannerRenderOptions options = {});

  /// Renders one frame (CV_8UC1, or CV_8UC3 RGB for rgb8 cameras) with the flange at
  /// T_base_flange. `frame_seed` makes the noise reproducible.
  cv::Mat render(const Eigen::Isometry3d& T_base_flange, uint64_t frame_seed) const;
  /// Noise-free laser intensity only (float, grey levels), for tests and ground truth.
  cv::Mat renderLaserOnly(const Eigen::Isometry3d& T_base_flange) const;

  /// The true light plane in the camera optical frame for a flange pose.
  Plane planeInCamera(const Eigen::Isometry3d& T_base_flange) const;
  const CameraConfig& camera() const { return geometry_->scene().scanner_camera; }
  const CellGeometry& geometry() const { return *geometry_; }
  /// Number of pixels whose ray hits a surface.
  size_t pixelsWithSurface() const { return hit_count_; }

 private:
  void laserPass(const Eigen::Isometry3d& T_base_flange, cv::Mat& laser, uint64_t seed,
                 bool noisy) const;
  static const std::vector<float>& noiseField();

  std::shared_ptr<const CellGeometry> geometry_;
  ScannerRenderOptions options_;
  int width_, height_;
  Eigen::Vector3f camera_center_;
  std::vector<Eigen::Vector3f> dirs_;    // per pixel, world frame, unit
  std::vector<Eigen::Vector3f> points_;  // first hit
  std::vector<Eigen::Vector3f> normals_;
  std::vector<float> albedo_;     // < 0: no surface
  std::vector<float> shininess_;
  std::vector<float> footprint_;  // metric size of the pixel on the surface (max over u, v)
  std::vector<float> ambient_;    // ambient grey level per pixel (albedo × ambient light)
  // 16×16-pixel tiles: bounds of their surface points and largest footprint, so a frame only
  // visits the tiles the light sheet can reach.
  struct Tile {
    Eigen::Vector3f center, half;
    float footprint;
    int u0, v0, u1, v1;
  };
  std::vector<Tile> tiles_;
  size_t hit_count_ = 0;
};

/// Renders the stationary fixture camera: overhead diffuse light, printed QR codes, blur, noise.
class FixtureRenderer {
 public:
  explicit FixtureRenderer(std::shared_ptr<const CellGeometry> geometry, double light = 200.0,
                           int supersample = 2);
  /// Noise-free image (rendered once at construction).
  const cv::Mat& clean() const { return clean_; }
  /// The clean image plus sensor noise; CV_8UC1 or CV_8UC3 per the camera's encoding.
  cv::Mat render(uint64_t frame_seed) const;
  const CellGeometry& geometry() const { return *geometry_; }

 private:
  std::shared_ptr<const CellGeometry> geometry_;
  cv::Mat clean_;  // CV_32F
};

/// Fast reproducible pseudo-random numbers for image noise (splitmix64 + Gaussian table).
class NoiseSource {
 public:
  explicit NoiseSource(uint64_t seed);
  uint64_t next();
  double uniform();   ///< [0, 1)
  float gaussian();   ///< N(0, 1), from a 64 Ki-entry table
 private:
  uint64_t state_;
};

}  // namespace cellsight
