// Where the light came from over one laser-line scan: the sheet and its emitter at every frame, in
// the scan's frame. A point of a part was scanned only if the camera saw it *and* the sheet
// reached it unshadowed; the matcher's fitness counts the model points that pass both
// (docs/localization.md, "Illumination").
#pragma once
#include <Eigen/Geometry>
#include <vector>

namespace cellsight {

class LightSweep {
 public:
  /// One frame, in time order: the sheet n·p + d = 0 (n unit) and its emitter (a point of it).
  /// Throws std::invalid_argument for a non-finite value or a normal that is not unit length.
  void add(const Eigen::Vector3f& emitter, const Eigen::Vector3f& normal, float d);
  /// One frame from the laser frame's pose (origin at the emitter, the sheet its y = 0 plane).
  void addLaserFrame(const Eigen::Isometry3d& T_frame_laser);
  /// The frames of a scan from the flange poses the robot reported and the calibrated
  /// flange → laser transform (laser frame: origin at the emitter, y the sheet's normal).
  static LightSweep fromFlangePoses(const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& T_base_flange,
                                    const Eigen::Isometry3d& T_flange_laser);

  size_t size() const { return emitters_.size(); }
  bool empty() const { return emitters_.empty(); }
  const Eigen::Vector3f& emitter(size_t k) const { return emitters_.at(k); }
  const Eigen::Vector3f& normal(size_t k) const { return normals_.at(k); }
  float offset(size_t k) const { return d_.at(k); }

  /// The emitter of the sheet that passed through p: between the two successive frames whose
  /// sheets lie on either side of p, interpolated. False when no two frames of the sweep bracket
  /// p (the sheet never reached it) or the sweep has fewer than two frames.
  bool emitterFor(const Eigen::Vector3f& p, Eigen::Vector3f* emitter) const;

 private:
  float side(size_t k, const Eigen::Vector3f& p) const { return normals_[k].dot(p) + d_[k]; }
  std::vector<Eigen::Vector3f> emitters_, normals_;
  std::vector<float> d_;
};

}  // namespace cellsight
