#include "cellsight/localization/light_sweep.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/file_io.hpp"
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

void saveSweep(const std::string& path, const LightSweep& sweep) {
  std::ostringstream out;
  out.precision(9);
  out << "# fan_half_angle " << sweep.fanHalfAngle() << "\n# emitter (3) normal (3) offset axis (3), metres\n";
  for (size_t k = 0; k < sweep.size(); ++k) {
    const auto &e = sweep.emitter(k), &n = sweep.normal(k), &a = sweep.axis(k);
    out << e.x() << ' ' << e.y() << ' ' << e.z() << ' ' << n.x() << ' ' << n.y() << ' ' << n.z() << ' ' << sweep.offset(k)
        << ' ' << a.x() << ' ' << a.y() << ' ' << a.z() << '\n';
  }
  writeFileAtomic(path, out.str());
}

LightSweep loadSweep(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open the sweep file (missing or unreadable)");
  LightSweep sweep;
  std::string line;
  double half = 0;
  for (int no = 1; std::getline(in, line); ++no) {
    std::istringstream l(line);
    if (line.rfind("# fan_half_angle ", 0) == 0) {
      l.ignore(17);
      if (!(l >> half)) throw ConfigError(path + ":" + std::to_string(no) + ": fan_half_angle is not a number");
      continue;
    }
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    float v[10];
    for (float& x : v) l >> x;
    std::string rest;
    if (!l || (l >> rest))
      throw ConfigError(path + ":" + std::to_string(no) + ": a frame is ten numbers (emitter, normal, offset, axis)");
    try {
      sweep.add({v[0], v[1], v[2]}, {v[3], v[4], v[5]}, v[6], {v[7], v[8], v[9]});
    } catch (const std::invalid_argument& e) {
      throw ConfigError(path + ":" + std::to_string(no) + ": " + e.what());
    }
  }
  try {
    sweep.setFanHalfAngle(half);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(path + ": fan_half_angle: " + e.what());
  }
  return sweep;
}

}  // namespace cellsight
