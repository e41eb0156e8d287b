#include "cellsight/localization/light_sweep.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "cellsight/common/plane.hpp"

namespace cellsight {

void LightSweep::add(const Eigen::Vector3f& emitter, const Eigen::Vector3f& normal, float d, const Eigen::Vector3f& axis) {
  if (!emitter.allFinite() || !normal.allFinite() || !std::isfinite(d) || !axis.allFinite())
    throw std::invalid_argument("LightSweep: frame " + std::to_string(size()) +
                                " has a non-finite emitter, normal, offset or fan axis");
  if (!axis.isZero() && std::abs(axis.norm() - 1.f) > 1e-3f)
    throw std::invalid_argument("LightSweep: frame " + std::to_string(size()) +
                                ": the fan's axis must be unit length or zero (got " + std::to_string(axis.norm()) + ")");
  if (std::abs(normal.norm() - 1.f) > 1e-3f)
    throw std::invalid_argument("LightSweep: frame " + std::to_string(size()) + ": the sheet's normal must be unit length (got " +
                                std::to_string(normal.norm()) + ")");
  emitters_.push_back(emitter);
  normals_.push_back(normal);
  axes_.push_back(axis);
  d_.push_back(d);
}

void LightSweep::setFanHalfAngle(double radians) {
  if (!(radians >= 0 && radians < M_PI / 2))
    throw std::invalid_argument("LightSweep: the fan's half-angle must lie in [0, pi/2) rad (0: unbounded), got " +
                                std::to_string(radians));
  fan_half_angle_ = radians;
  cos_fan_ = radians > 0 ? static_cast<float>(std::cos(radians)) : -1.f;
}

bool LightSweep::inFan(size_t k, const Eigen::Vector3f& emitter, const Eigen::Vector3f& p, float* margin) const {
  if (margin) *margin = std::numeric_limits<float>::infinity();
  if (fan_half_angle_ <= 0 || axes_[k].isZero()) return true;
  Eigen::Vector3f v = p - emitter;
  v -= v.dot(normals_[k]) * normals_[k];  // within the sheet
  const float len = v.norm();
  if (!(len > 0)) return false;
  const float c = axes_[k].dot(v) / len;
  if (margin) *margin = static_cast<float>(fan_half_angle_) - std::acos(std::clamp(c, -1.f, 1.f));
  return c >= cos_fan_;
}

void LightSweep::addLaserFrame(const Eigen::Isometry3d& T_frame_laser) {
  const Plane sheet = laserPlane(T_frame_laser);
  add(T_frame_laser.translation().cast<float>(), sheet.n.cast<float>(), static_cast<float>(sheet.d),
      T_frame_laser.linear().col(2).normalized().cast<float>());
}

LightSweep LightSweep::fromFlangePoses(
    const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& T_base_flange,
    const Eigen::Isometry3d& T_flange_laser, double fan_half_angle) {
  LightSweep s;
  s.setFanHalfAngle(fan_half_angle);
  for (const auto& F : T_base_flange) s.addLaserFrame(F * T_flange_laser);
  return s;
}

bool LightSweep::emitterFor(const Eigen::Vector3f& p, Eigen::Vector3f* emitter, float* fan_margin) const {
  if (size() < 2) return false;
  size_t lo = 0, hi = size() - 1;
  float s_lo = side(lo, p), s_hi = side(hi, p);
  constexpr float kOnSheet = 1e-6f;  // m: on the first or the last sheet (rounding)
  if (std::abs(s_lo) <= kOnSheet || std::abs(s_hi) <= kOnSheet) {
    const size_t k = std::abs(s_lo) <= kOnSheet ? lo : hi;
    *emitter = emitters_[k];
    return inFan(k, *emitter, p, fan_margin);
  }
  if ((s_lo > 0) == (s_hi > 0)) return false;  // every sheet on one side of p
  // bisection on the side of p: one pair of successive frames whose sheets bracket it
  while (hi - lo > 1) {
    const size_t mid = lo + (hi - lo) / 2;
    const float s = side(mid, p);
    if ((s > 0) == (s_lo > 0)) {
      lo = mid;
      s_lo = s;
    } else {
      hi = mid;
      s_hi = s;
    }
  }
  const float t = s_lo / (s_lo - s_hi);
  *emitter = emitters_[lo] + t * (emitters_[hi] - emitters_[lo]);
  return inFan(t < 0.5f ? lo : hi, *emitter, p, fan_margin);
}

}  // namespace cellsight
