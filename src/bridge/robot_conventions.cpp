#include "cellsight/bridge/robot_conventions.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace cellsight {
namespace {

// Z-Y-X angles (a about z, b about y, c about x) of R = Rz(a)·Ry(b)·Rx(c)
Eigen::Vector3d zyx(const Eigen::Matrix3d& R) {
  const double cb = std::hypot(R(2, 1), R(2, 2));
  const double b = std::atan2(-R(2, 0), cb);
  if (cb < 1e-9) {
    // gimbal lock (b = ±90°): only a ∓ c is defined; c = 0, and the middle column is
    // (−sin a, cos a, 0) for either sign
    return {std::atan2(-R(0, 1), R(1, 1)), b, 0.0};
  }
  return {std::atan2(R(1, 0), R(0, 0)), b, std::atan2(R(2, 1), R(2, 2))};
}

Eigen::Matrix3d fromZyx(double a, double b, double c) {
  return (Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(b, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(c, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

std::string join(const std::vector<std::pair<double, int>>& v) {
  std::string out;
  char buf[64];
  for (const auto& [x, decimals] : v) {
    std::snprintf(buf, sizeof(buf), "%.*f", decimals, std::abs(x) < 0.5 * std::pow(10.0, -decimals) ? 0.0 : x);
    if (!out.empty()) out += ' ';
    out += buf;
  }
  return out;
}

}  // namespace

PoseConvention parsePoseConvention(const std::string& name) {
  if (name == "kuka") return PoseConvention::kKuka;
  if (name == "abb") return PoseConvention::kAbb;
  if (name == "fanuc") return PoseConvention::kFanuc;
  if (name == "rep103") return PoseConvention::kRep103;
  throw std::invalid_argument("unknown pose convention '" + name + "' (kuka | abb | fanuc | rep103)");
}

std::string poseConventionName(PoseConvention c) {
  switch (c) {
    case PoseConvention::kKuka: return "kuka";
    case PoseConvention::kAbb: return "abb";
    case PoseConvention::kFanuc: return "fanuc";
    case PoseConvention::kRep103: return "rep103";
  }
  return "?";
}

std::string formatRobotPose(const Eigen::Isometry3d& T, PoseConvention c) {
  const Eigen::Vector3d t = T.translation();
  const Eigen::Vector3d mm = t * 1000.0;
  const double deg = 180.0 / M_PI;
  switch (c) {
    case PoseConvention::kKuka: {
      const Eigen::Vector3d abc = zyx(T.linear()) * deg;
      return join({{mm.x(), 3}, {mm.y(), 3}, {mm.z(), 3}, {abc.x(), 4}, {abc.y(), 4}, {abc.z(), 4}});
    }
    case PoseConvention::kFanuc: {
      const Eigen::Vector3d rpw = zyx(T.linear()) * deg;  // R (z), P (y), W (x)
      return join({{mm.x(), 3}, {mm.y(), 3}, {mm.z(), 3}, {rpw.z(), 4}, {rpw.y(), 4}, {rpw.x(), 4}});
    }
    case PoseConvention::kAbb: {
      Eigen::Quaterniond q(T.linear());
      q.normalize();
      if (q.w() < 0) q.coeffs() *= -1;
      return join({{mm.x(), 3}, {mm.y(), 3}, {mm.z(), 3}, {q.w(), 7}, {q.x(), 7}, {q.y(), 7}, {q.z(), 7}});
    }
    case PoseConvention::kRep103: {
      const Eigen::Vector3d ypr = zyx(T.linear());
      return join({{t.x(), 6}, {t.y(), 6}, {t.z(), 6}, {ypr.z(), 7}, {ypr.y(), 7}, {ypr.x(), 7}});
    }
  }
  return "";
}

Eigen::Isometry3d parseRobotPose(const std::string& fields, PoseConvention c) {
  std::istringstream in(fields);
  std::vector<double> v;
  std::string token;
  while (in >> token) {
    size_t used = 0;
    double x = 0;
    try {
      x = std::stod(token, &used);
    } catch (const std::exception&) {
      throw std::invalid_argument("'" + token + "' is not a number");
    }
    if (used != token.size() || !std::isfinite(x)) throw std::invalid_argument("'" + token + "' is not a finite number");
    v.push_back(x);
  }
  const size_t expected = c == PoseConvention::kAbb ? 7 : 6;
  if (v.size() != expected) {
    throw std::invalid_argument(poseConventionName(c) + " pose needs " + std::to_string(expected) + " numbers, got " +
                                std::to_string(v.size()));
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const double rad = M_PI / 180.0;
  switch (c) {
    case PoseConvention::kKuka:
      T.translation() = Eigen::Vector3d(v[0], v[1], v[2]) / 1000.0;
      T.linear() = fromZyx(v[3] * rad, v[4] * rad, v[5] * rad);
      break;
    case PoseConvention::kFanuc:
      T.translation() = Eigen::Vector3d(v[0], v[1], v[2]) / 1000.0;
      T.linear() = fromZyx(v[5] * rad, v[4] * rad, v[3] * rad);
      break;
    case PoseConvention::kAbb: {
      const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
      if (q.norm() < 1e-9) throw std::invalid_argument("the quaternion is zero");
      T.translation() = Eigen::Vector3d(v[0], v[1], v[2]) / 1000.0;
      T.linear() = q.normalized().toRotationMatrix();
      break;
    }
    case PoseConvention::kRep103:
      T.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
      T.linear() = fromZyx(v[5], v[4], v[3]);
      break;
  }
  return T;
}

}  // namespace cellsight
