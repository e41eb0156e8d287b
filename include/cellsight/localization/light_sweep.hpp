// Where the light came from over one laser-line scan: the sheet and its emitter at every frame, in
// the scan's frame. A point of a part was scanned only if the camera saw it *and* the sheet
// reached it unshadowed; the matcher's fitness counts the model points that pass both
// (docs/localization.md, "Illumination").
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace cellsight {

class LightSweep {
 public:
  /// One frame, in time order: the sheet n·p + d = 0 (n unit) and its emitter (a point of it);
  /// `axis`, the fan's centre line (unit, in the sheet), bounds the lit sheet to the fan
  /// (setFanHalfAngle); zero: this frame's sheet is unbounded. Throws std::invalid_argument for a
  /// non-finite value, a normal that is not unit length or an axis neither zero nor unit.
  void add(const Eigen::Vector3f& emitter, const Eigen::Vector3f& normal, float d,
           const Eigen::Vector3f& axis = Eigen::Vector3f::Zero());
  /// One frame from the laser frame's pose (origin at the emitter, the sheet its y = 0 plane,
  /// z the fan's centre line).
  void addLaserFrame(const Eigen::Isometry3d& T_frame_laser);
  /// The frames of a scan from the flange poses the robot reported and the calibrated
  /// flange → laser transform (laser frame: origin at the emitter, y the sheet's normal, z the
  /// fan's centre line), the fan bounded to `fan_half_angle` (0: unbounded).
  static LightSweep fromFlangePoses(const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& T_base_flange,
                                    const Eigen::Isometry3d& T_flange_laser, double fan_half_angle = 0);

  /// The sheet lights only rays within this angle of the frame's axis (the projector's fan
  /// opening / 2, its datasheet); 0: unbounded. Throws std::invalid_argument outside [0, π/2).
  void setFanHalfAngle(double radians);
  double fanHalfAngle() const { return fan_half_angle_; }

  size_t size() const { return emitters_.size(); }
  bool empty() const { return emitters_.empty(); }
  const Eigen::Vector3f& emitter(size_t k) const { return emitters_.at(k); }
  const Eigen::Vector3f& normal(size_t k) const { return normals_.at(k); }
  float offset(size_t k) const { return d_.at(k); }
  const Eigen::Vector3f& axis(size_t k) const { return axes_.at(k); }

  /// The emitter of the sheet that passed through p: between the two successive frames whose
  /// sheets lie on either side of p, interpolated. False when no two frames of the sweep bracket
  /// p (the sheet never reached it), when p lies outside the fan of those frames (with a fan
  /// half-angle set and their axes given), or the sweep has fewer than two frames.
  /// `fan_margin` (optional): how far inside the fan p lies, rad (infinity when unbounded).
  bool emitterFor(const Eigen::Vector3f& p, Eigen::Vector3f* emitter, float* fan_margin = nullptr) const;

 private:
  float side(size_t k, const Eigen::Vector3f& p) const { return normals_[k].dot(p) + d_[k]; }
  /// p within the fan of frame k's sheet as seen from `emitter` (true when unbounded); *margin:
  /// the angle left to the fan's edge
  bool inFan(size_t k, const Eigen::Vector3f& emitter, const Eigen::Vector3f& p, float* margin) const;
  std::vector<Eigen::Vector3f> emitters_, normals_, axes_;
  std::vector<float> d_;
  double fan_half_angle_ = 0;
  float cos_fan_ = -1.f;
};

/// A sweep as text (`cellsight_evaluate_localization cells --dump-clusters`: `<scene>_sweep.txt`):
/// a line `# fan_half_angle <rad>`, then one frame per line — emitter (3), sheet normal (3),
/// offset, fan axis (3), metres; lines starting with `#` are comments. Written atomically.
void saveSweep(const std::string& path, const LightSweep& sweep);
/// Reads saveSweep's text; throws ConfigError naming the file and line for a missing file, a
/// line without ten numbers or a frame add() refuses.
LightSweep loadSweep(const std::string& path);

}  // namespace cellsight
