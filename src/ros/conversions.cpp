#include "cellsight_ros/conversions.hpp"

#include "cellsight/localization/model_matching.hpp"

#include <algorithm>

#include <sensor_msgs/image_encodings.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <cmath>
#include <cstring>
#include <stdexcept>

namespace cellsight_ros {

geometry_msgs::Pose toPoseMsg(const Eigen::Isometry3d& T) {
  geometry_msgs::Pose p;
  p.position.x = T.translation().x();
  p.position.y = T.translation().y();
  p.position.z = T.translation().z();
  const Eigen::Quaterniond q(T.linear());
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  p.orientation.w = q.w();
  return p;
}

geometry_msgs::Point toPointMsg(const Eigen::Vector3f& p) {
  geometry_msgs::Point q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  return q;
}

std::vector<geometry_msgs::Point> meshTriangles(const cellsight::TriangleMesh& mesh) {
  std::vector<geometry_msgs::Point> points;
  points.reserve(mesh.faces.size() * 3);
  for (const auto& f : mesh.faces) {
    for (int k = 0; k < 3; ++k) {
      geometry_msgs::Point p;
      p.x = mesh.vertices[f[k]].x();
      p.y = mesh.vertices[f[k]].y();
      p.z = mesh.vertices[f[k]].z();
      points.push_back(p);
    }
  }
  return points;
}

Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& p) {
  Eigen::Quaterniond q(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
  if (!std::isfinite(q.norm()) || q.norm() < 1e-6) {
    throw std::invalid_argument("pose orientation is not a valid quaternion");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() << p.position.x, p.position.y, p.position.z;
  if (!T.translation().allFinite()) throw std::invalid_argument("pose position is not finite");
  return T;
}

geometry_msgs::Transform toTransformMsg(const Eigen::Isometry3d& T) {
  const geometry_msgs::Pose p = toPoseMsg(T);
  geometry_msgs::Transform t;
  t.translation.x = p.position.x;
  t.translation.y = p.position.y;
  t.translation.z = p.position.z;
  t.rotation = p.orientation;
  return t;
}

Eigen::Isometry3d fromTransformMsg(const geometry_msgs::Transform& t) {
  geometry_msgs::Pose p;
  p.position.x = t.translation.x;
  p.position.y = t.translation.y;
  p.position.z = t.translation.z;
  p.orientation = t.rotation;
  return fromPoseMsg(p);
}

geometry_msgs::TransformStamped toTransformStamped(const cellsight::TransformCalibration& cal,
                                                   const ros::Time& stamp) {
  geometry_msgs::TransformStamped ts;
  ts.header.stamp = stamp;
  ts.header.frame_id = cal.parent_frame;
  ts.child_frame_id = cal.child_frame;
  ts.transform = toTransformMsg(cal.T_parent_child);
  return ts;
}

cellsight::LaserPlaneStamped toPlaneMsg(const cellsight::Plane& plane, const std::string& frame,
                                        const ros::Time& stamp) {
  cellsight::LaserPlaneStamped m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.normal.x = plane.n.x();
  m.normal.y = plane.n.y();
  m.normal.z = plane.n.z();
  m.d = plane.d;
  return m;
}

cellsight::Plane fromPlaneMsg(const cellsight::LaserPlaneStamped& m) {
  cellsight::Plane p;
  p.n << m.normal.x, m.normal.y, m.normal.z;
  const double norm = p.n.norm();
  if (!std::isfinite(norm) || norm < 1e-9 || !std::isfinite(m.d)) {
    throw std::invalid_argument("laser plane has a zero or non-finite normal or offset");
  }
  p.n /= norm;
  p.d = m.d / norm;
  return p;
}

cellsight::LaserSweep toLaserSweepMsg(const cellsight::LightSweep& sweep, const std::string& frame, const ros::Time& stamp) {
  cellsight::LaserSweep m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  for (size_t k = 0; k < sweep.size(); ++k) {
    geometry_msgs::Point e;
    e.x = sweep.emitter(k).x();
    e.y = sweep.emitter(k).y();
    e.z = sweep.emitter(k).z();
    geometry_msgs::Vector3 n;
    n.x = sweep.normal(k).x();
    n.y = sweep.normal(k).y();
    n.z = sweep.normal(k).z();
    geometry_msgs::Vector3 a;
    a.x = sweep.axis(k).x();
    a.y = sweep.axis(k).y();
    a.z = sweep.axis(k).z();
    m.emitters.push_back(e);
    m.normals.push_back(n);
    m.offsets.push_back(sweep.offset(k));
    m.axes.push_back(a);
  }
  m.fan_half_angle = sweep.fanHalfAngle();
  return m;
}

cellsight::LightSweep fromLaserSweepMsg(const cellsight::LaserSweep& m) {
  if (m.emitters.size() != m.normals.size() || m.emitters.size() != m.offsets.size()) {
    throw std::invalid_argument("laser sweep: " + std::to_string(m.emitters.size()) + " emitters, " +
                                std::to_string(m.normals.size()) + " normals and " + std::to_string(m.offsets.size()) +
                                " offsets: the arrays must have one entry per frame");
  }
  if (!m.axes.empty() && m.axes.size() != m.emitters.size()) {
    throw std::invalid_argument("laser sweep: " + std::to_string(m.axes.size()) + " fan axes for " +
                                std::to_string(m.emitters.size()) + " frames: give one per frame or none");
  }
  cellsight::LightSweep s;
  s.setFanHalfAngle(m.fan_half_angle);  // throws naming the range
  for (size_t k = 0; k < m.emitters.size(); ++k) {
    const auto& e = m.emitters[k];
    const auto& n = m.normals[k];
    Eigen::Vector3f axis = Eigen::Vector3f::Zero();
    if (!m.axes.empty()) axis = Eigen::Vector3d(m.axes[k].x, m.axes[k].y, m.axes[k].z).cast<float>();
    s.add(Eigen::Vector3d(e.x, e.y, e.z).cast<float>(), Eigen::Vector3d(n.x, n.y, n.z).cast<float>(),
          static_cast<float>(m.offsets[k]), axis);  // throws naming the frame
  }
  return s;
}

sensor_msgs::CameraInfo toCameraInfo(const cellsight::CameraIntrinsics& c,
                                     const std::string& frame, const ros::Time& stamp) {
  sensor_msgs::CameraInfo ci;
  ci.header.frame_id = frame;
  ci.header.stamp = stamp;
  ci.width = static_cast<uint32_t>(c.width);
  ci.height = static_cast<uint32_t>(c.height);
  ci.distortion_model = "plumb_bob";
  ci.D.assign(c.dist.begin(), c.dist.end());
  ci.K = {c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1};
  ci.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ci.P = {c.fx, 0, c.cx, 0, 0, c.fy, c.cy, 0, 0, 0, 1, 0};
  return ci;
}

cellsight::CameraIntrinsics fromCameraInfo(const sensor_msgs::CameraInfo& ci) {
  if (ci.distortion_model != "plumb_bob" && !ci.distortion_model.empty() &&
      ci.distortion_model != "rational_polynomial") {
    throw std::invalid_argument("camera_info distortion model '" + ci.distortion_model +
                                "' is not supported (use plumb_bob)");
  }
  cellsight::CameraIntrinsics c;
  c.width = static_cast<int>(ci.width);
  c.height = static_cast<int>(ci.height);
  c.fx = ci.K[0];
  c.fy = ci.K[4];
  c.cx = ci.K[2];
  c.cy = ci.K[5];
  for (size_t i = 0; i < 5 && i < ci.D.size(); ++i) c.dist[i] = ci.D[i];
  try {
    c.validate("camera_info (" + ci.header.frame_id + ")");
  } catch (const std::exception& e) {
    throw std::invalid_argument(e.what());
  }
  return c;
}

sensor_msgs::Image toImageMsg(const cv::Mat& image, const std::string& frame,
                              const ros::Time& stamp) {
  sensor_msgs::Image m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.height = static_cast<uint32_t>(image.rows);
  m.width = static_cast<uint32_t>(image.cols);
  if (image.type() == CV_8UC1) {
    m.encoding = sensor_msgs::image_encodings::MONO8;
  } else if (image.type() == CV_8UC3) {
    m.encoding = sensor_msgs::image_encodings::RGB8;
  } else {
    throw std::invalid_argument("toImageMsg: only CV_8UC1 and CV_8UC3 images are supported");
  }
  m.is_bigendian = 0;
  m.step = static_cast<uint32_t>(image.cols * image.elemSize());
  m.data.resize(static_cast<size_t>(m.step) * m.height);
  for (int r = 0; r < image.rows; ++r) {
    std::memcpy(&m.data[static_cast<size_t>(r) * m.step], image.ptr(r), m.step);
  }
  return m;
}

cv::Mat fromImageMsg(const sensor_msgs::Image& m) {
  namespace enc = sensor_msgs::image_encodings;
  int channels = 0;
  if (m.encoding == enc::MONO8) {
    channels = 1;
  } else if (m.encoding == enc::RGB8 || m.encoding == enc::BGR8) {
    channels = 3;
  } else {
    throw std::invalid_argument("image encoding '" + m.encoding.substr(0, 64) +
                                "' is not supported (mono8, rgb8, bgr8)");
  }
  const auto size = [&] { return std::to_string(m.width) + "x" + std::to_string(m.height); };
  if (m.width == 0 || m.height == 0) throw std::invalid_argument("image is empty (" + size() + ")");
  if (m.width > static_cast<uint32_t>(cellsight::kMaxImageSide) ||
      m.height > static_cast<uint32_t>(cellsight::kMaxImageSide) ||
      static_cast<int64_t>(m.width) * m.height > cellsight::kMaxImagePixels) {
    throw std::invalid_argument("image " + size() + " exceeds the limit of " +
                                std::to_string(cellsight::kMaxImageSide) + " px per side and " +
                                std::to_string(cellsight::kMaxImagePixels) + " px");
  }
  const uint64_t row = static_cast<uint64_t>(m.width) * static_cast<uint64_t>(channels);
  if (m.step < row) {
    throw std::invalid_argument("image step " + std::to_string(m.step) + " is less than width x channels (" +
                                std::to_string(row) + ")");
  }
  const uint64_t need = static_cast<uint64_t>(m.step) * m.height;
  if (m.data.size() != need) {
    throw std::invalid_argument("image data holds " + std::to_string(m.data.size()) + " bytes, step x height is " +
                                std::to_string(need));
  }
  // a read-only header over the message's bytes; callers only read it
  return cv::Mat(static_cast<int>(m.height), static_cast<int>(m.width), CV_8UC(channels),
                 const_cast<uint8_t*>(m.data.data()), static_cast<size_t>(m.step));
}

sensor_msgs::PointCloud2 toCloudMsg(const cellsight::ScanCloud& c, const ros::Time& stamp) {
  sensor_msgs::PointCloud2 m;
  m.header.frame_id = c.frame_id;
  m.header.stamp = stamp;
  sensor_msgs::PointCloud2Modifier mod(m);
  const bool normals = c.normals.size() == c.points.size() && !c.points.empty();
  if (normals) {
    mod.setPointCloud2Fields(7, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                             sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32,
                             "intensity", 1, sensor_msgs::PointField::FLOAT32, "normal_x", 1,
                             sensor_msgs::PointField::FLOAT32, "normal_y", 1,
                             sensor_msgs::PointField::FLOAT32, "normal_z", 1, sensor_msgs::PointField::FLOAT32);
  } else {
    mod.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                             sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32,
                             "intensity", 1, sensor_msgs::PointField::FLOAT32);
  }
  mod.resize(c.points.size());
  m.height = 1;
  m.width = static_cast<uint32_t>(c.points.size());
  m.is_dense = true;
  if (c.points.empty()) return m;
  sensor_msgs::PointCloud2Iterator<float> x(m, "x"), i(m, "intensity");
  for (size_t k = 0; k < c.points.size(); ++k, ++x, ++i) {
    x[0] = c.points[k].x();
    x[1] = c.points[k].y();
    x[2] = c.points[k].z();
    *i = k < c.intensity.size() ? c.intensity[k] : 0.f;
  }
  if (normals) {
    sensor_msgs::PointCloud2Iterator<float> n(m, "normal_x");
    for (size_t k = 0; k < c.points.size(); ++k, ++n) {
      n[0] = c.normals[k].x();
      n[1] = c.normals[k].y();
      n[2] = c.normals[k].z();
    }
  }
  return m;
}

cellsight::ScanCloud fromCloudMsg(const sensor_msgs::PointCloud2& m, size_t* dropped) {
  // Every size and offset is checked in 64 bits against the bytes the message holds before a
  // point is read: a malformed message costs an error, never a crash or a huge allocation.
  auto offsetOf = [&](const std::string& name, bool required) -> int64_t {
    for (const auto& f : m.fields) {
      if (f.name != name) continue;
      if (f.datatype != sensor_msgs::PointField::FLOAT32 || f.count > 1) {
        if (required) throw std::invalid_argument("PointCloud2 field '" + name + "' must be one float32");
        return -1;
      }
      if (static_cast<uint64_t>(f.offset) + 4 > m.point_step) {
        throw std::invalid_argument("PointCloud2 field '" + name + "' at offset " + std::to_string(f.offset) +
                                    " lies past point_step " + std::to_string(m.point_step));
      }
      return f.offset;
    }
    if (required) throw std::invalid_argument(std::string("PointCloud2 has no float32 field '") + name + "'");
    return -1;
  };
  const int64_t ox = offsetOf("x", true), oy = offsetOf("y", true), oz = offsetOf("z", true);
  const int64_t oi = offsetOf("intensity", false);
  const int64_t onx = offsetOf("normal_x", false), ony = offsetOf("normal_y", false), onz = offsetOf("normal_z", false);
  const bool normals = onx >= 0 && ony >= 0 && onz >= 0;
  if (m.point_step < 12) throw std::invalid_argument("PointCloud2 point_step " + std::to_string(m.point_step) + " < 12");
  if (static_cast<uint64_t>(m.point_step) * m.width > m.row_step ||
      static_cast<uint64_t>(m.row_step) * m.height > m.data.size()) {
    throw std::invalid_argument("PointCloud2 data (" + std::to_string(m.data.size()) + " bytes) is shorter than width " +
                                std::to_string(m.width) + " x height " + std::to_string(m.height) + " x point_step " +
                                std::to_string(m.point_step) + " (row_step " + std::to_string(m.row_step) + ")");
  }
  const uint16_t probe = 1;
  const bool little = *reinterpret_cast<const uint8_t*>(&probe) == 1;
  if (m.is_bigendian == little) throw std::invalid_argument("PointCloud2 byte order differs from this machine's");
  cellsight::ScanCloud c;
  c.frame_id = m.header.frame_id;
  const size_t n = static_cast<size_t>(m.width) * m.height;  // ≤ data.size() / 12 after the checks
  // no points: done (a width of 0 under a height of 2^32 would otherwise walk 2^32 empty rows)
  if (n == 0) {
    if (dropped) *dropped = 0;
    return c;
  }
  c.points.reserve(n);
  c.intensity.reserve(n);
  if (normals) c.normals.reserve(n);
  auto at = [&](const uint8_t* base, int64_t off) {
    float v;
    std::memcpy(&v, base + off, sizeof(float));
    return v;
  };
  size_t bad = 0;
  for (uint32_t r = 0; r < m.height; ++r) {
    const uint8_t* row = m.data.data() + static_cast<size_t>(r) * m.row_step;
    for (uint32_t k = 0; k < m.width; ++k) {
      const uint8_t* p = row + static_cast<size_t>(k) * m.point_step;
      const Eigen::Vector3f xyz(at(p, ox), at(p, oy), at(p, oz));
      if (!xyz.allFinite()) {
        ++bad;
        continue;
      }
      c.append(xyz, oi >= 0 ? at(p, oi) : 0.f);
      if (normals) c.normals.emplace_back(at(p, onx), at(p, ony), at(p, onz));
    }
  }
  if (dropped) *dropped = bad;
  return c;
}

int64_t toNanoseconds(const ros::Time& t) { return static_cast<int64_t>(t.toNSec()); }
ros::Time fromNanoseconds(int64_t ns) {
  ros::Time t;
  t.fromNSec(static_cast<uint64_t>(ns));
  return t;
}

uint8_t toPlanStatus(cellsight::PlanStatus s) {
  using M = cellsight::GraspPlan;
  switch (s) {
    case cellsight::PlanStatus::kOk: return M::OK;
    case cellsight::PlanStatus::kUnknownModel: return M::UNKNOWN_MODEL;
    case cellsight::PlanStatus::kNotInAssembly:
    case cellsight::PlanStatus::kBasePart: return M::NOT_IN_ASSEMBLY;
    case cellsight::PlanStatus::kNoBase: return M::NO_BASE_PART;
    case cellsight::PlanStatus::kNoGrasp: return M::NO_GRASP;
    case cellsight::PlanStatus::kUnreachable: return M::UNREACHABLE;
    case cellsight::PlanStatus::kNoPath: return M::NO_PATH;
    case cellsight::PlanStatus::kBadInput: return M::BAD_INPUT;
    case cellsight::PlanStatus::kNothingLeft: return M::NOTHING_LEFT;
    case cellsight::PlanStatus::kAmbiguousPose: return M::AMBIGUOUS_POSE;
  }
  return M::BAD_INPUT;
}

cellsight::Detection toDetectionMsg(const cellsight::PartDetection& d, const std::string& name) {
  cellsight::Detection m;
  m.model = d.model;
  m.name = name;
  m.pose = toPoseMsg(d.pose);
  m.fitness = d.fitness;
  m.coverage = d.coverage;
  m.rmse = d.rmse;
  m.matcher = d.matcher;
  m.cluster = d.cluster;
  for (const auto& a : d.ambiguous_poses) m.ambiguous_poses.push_back(toPoseMsg(a));
  m.alternative_score_share = d.alternative_score_share;
  return m;
}

cellsight::GraspPlan toGraspPlanMsg(const cellsight::PartPlan& plan, const std::array<std::string, 6>& joint_names,
                                    const std::string& frame, const ros::Time& stamp) {
  cellsight::GraspPlan m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.object = plan.part.name;
  m.model = plan.part.model;
  m.status = toPlanStatus(plan.status);
  m.reason = plan.reason;
  for (const auto& p : plan.poses) {
    m.pose_names.push_back(p.name);
    m.poses.push_back(toPoseMsg(p.T_base_tcp));
  }
  m.target = toPoseMsg(plan.T_base_target);
  m.grip_width = plan.grip_opening;
  m.jaw_opening = plan.segments.empty() ? 0.0 : plan.segments.front().opening;
  m.grasp_source = plan.grasp.source;
  m.candidates = plan.candidates;
  m.candidates_tried = plan.candidates_tried;
  m.plan_seconds = plan.seconds;
  m.sampled = plan.sampled;
  m.passed_over = plan.passed_over;
  if (plan.status == cellsight::PlanStatus::kOk) {
    m.trajectory.header.frame_id = frame;
    m.trajectory.header.stamp = stamp;
    m.trajectory.joint_names.assign(joint_names.begin(), joint_names.end());
    for (size_t i = 0; i < plan.trajectory.positions.size(); ++i) {
      trajectory_msgs::JointTrajectoryPoint pt;
      for (int j = 0; j < 6; ++j) {
        pt.positions.push_back(plan.trajectory.positions[i][j]);
        pt.velocities.push_back(plan.trajectory.velocities[i][j]);
      }
      pt.time_from_start = ros::Duration(plan.trajectory.times[i]);
      m.trajectory.points.push_back(pt);
    }
    m.grasp_index = static_cast<uint32_t>(plan.grasp_index);
    m.release_index = static_cast<uint32_t>(plan.release_index);
  }
  return m;
}

cellsight::TimedTrajectory fromTrajectoryMsg(const trajectory_msgs::JointTrajectory& msg,
                                             const std::array<std::string, 6>& joint_names) {
  if (msg.points.empty()) throw std::invalid_argument("the trajectory has no points");
  if (msg.joint_names.size() != 6) {
    throw std::invalid_argument("the trajectory names " + std::to_string(msg.joint_names.size()) + " joints, the arm has 6");
  }
  std::array<int, 6> column{};
  for (int j = 0; j < 6; ++j) {
    const auto it = std::find(msg.joint_names.begin(), msg.joint_names.end(), joint_names[static_cast<size_t>(j)]);
    if (it == msg.joint_names.end()) {
      throw std::invalid_argument("the trajectory has no joint '" + joint_names[static_cast<size_t>(j)] + "'");
    }
    column[static_cast<size_t>(j)] = static_cast<int>(it - msg.joint_names.begin());
  }
  cellsight::TimedTrajectory t;
  double last = -1;
  for (size_t i = 0; i < msg.points.size(); ++i) {
    const auto& p = msg.points[i];
    if (p.positions.size() != 6) {
      throw std::invalid_argument("trajectory point " + std::to_string(i) + " has " + std::to_string(p.positions.size()) +
                                  " positions, 6 expected");
    }
    cellsight::JointVector q, v = cellsight::JointVector::Zero();
    for (int j = 0; j < 6; ++j) {
      q[j] = p.positions[static_cast<size_t>(column[static_cast<size_t>(j)])];
      if (p.velocities.size() == 6) v[j] = p.velocities[static_cast<size_t>(column[static_cast<size_t>(j)])];
    }
    const double time = p.time_from_start.toSec();
    if (!q.allFinite() || !v.allFinite() || !std::isfinite(time)) {
      throw std::invalid_argument("trajectory point " + std::to_string(i) + " is not finite");
    }
    if (time <= last) throw std::invalid_argument("trajectory times must increase (point " + std::to_string(i) + ")");
    last = time;
    t.positions.push_back(q);
    t.velocities.push_back(v);
    t.times.push_back(time);
  }
  return t;
}

}  // namespace cellsight_ros
