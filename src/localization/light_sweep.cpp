#include "cellsight/localization/light_sweep.hpp"

#include <cmath>
#include <stdexcept>

#include "cellsight/common/plane.hpp"

namespace cellsight {

void LightSweep::add(const Eigen::Vector3f& emitter, const Eigen::Vector3f& normal, float d) {
  if (!emitter.allFinite() || !normal.allFinite() || !std::isfinite(d))
    throw std::invalid_argument("LightSweep: frame " + std::to_string(size()) + " has a non-finite emitter, normal or offset");
  if (std::abs(normal.norm() - 1.f) > 1e-3f)
    throw std::invalid_argument("LightSweep: frame " + std::to_string(size()) + ": the sheet's normal must be unit length (got " +
                                std::to_string(normal.norm()) + ")");
  emitters_.push_back(emitter);
  normals_.push_back(normal);
  d_.push_back(d);
}

void LightSweep::addLaserFrame(const Eigen::Isometry3d& T_frame_laser) {
  const Plane sheet = laserPlane(T_frame_laser);
  add(T_frame_laser.translation().cast<float>(), sheet.n.cast<float>(), static_cast<float>(sheet.d));
}

LightSweep LightSweep::fromFlangePoses(
    const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& T_base_flange,
    const Eigen::Isometry3d& T_flange_laser) {
  LightSweep s;
  for (const auto& F : T_base_flange) s.addLaserFrame(F * T_flange_laser);
  return s;
}

bool LightSweep::emitterFor(const Eigen::Vector3f& p, Eigen::Vector3f* emitter) const {
  if (size() < 2) return false;
  size_t lo = 0, hi = size() - 1;
  float s_lo = side(lo, p), s_hi = side(hi, p);
  constexpr float kOnSheet = 1e-6f;  // m: on the first or the last sheet (rounding)
  if (std::abs(s_lo) <= kOnSheet || std::abs(s_hi) <= kOnSheet) {
    *emitter = emitters_[std::abs(s_lo) <= kOnSheet ? lo : hi];
    return true;
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
  return true;
}

}  // namespace cellsight
