#include "cellsight/common/trajectory.hpp"

#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

Trajectory linearTrajectory(const Eigen::Isometry3d& start, const Eigen::Isometry3d& end,
                            int steps) {
  Trajectory t;
  t.type = "linear";
  const Eigen::Quaterniond q0(start.linear()), q1(end.linear());
  for (int i = 0; i < steps; ++i) {
    const double a = steps > 1 ? static_cast<double>(i) / (steps - 1) : 0.0;
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = q0.slerp(a, q1).toRotationMatrix();
    p.translation() = (1 - a) * start.translation() + a * end.translation();
    t.poses.push_back(p);
  }
  return t;
}

std::map<std::string, Trajectory> loadTrajectories(const std::string& path) {
  YamlMap root(loadYamlFile(path), path);
  std::map<std::string, Trajectory> out;
  for (const auto& kv : root.raw("trajectories")) {
    const std::string name = kv.first.as<std::string>();
    YamlMap m(kv.second, path, "trajectories." + name);
    const std::string type = m.getString("type");
    Trajectory t;
    if (type == "linear") {
      const int steps = m.getInt("steps");
      if (steps < 2 || steps > kMaxTrajectorySteps)
        m.fail("steps", "a linear trajectory needs 2 to " + std::to_string(kMaxTrajectorySteps) + " steps (got " +
                            std::to_string(steps) + ")");
      t = linearTrajectory(m.getPose("start"), m.getPose("end"), steps);
    } else if (type == "rotation") {
      const Eigen::Isometry3d start = m.getPose("start");
      const Eigen::Vector3d pivot = m.getVector3("pivot");
      Eigen::Vector3d axis = m.getVector3("axis");
      if (axis.norm() < 1e-9) m.fail("axis", "must be non-zero");
      axis.normalize();
      const double a0 = m.getDouble("angle_from"), a1 = m.getDouble("angle_to");
      const int steps = m.getInt("steps");
      if (steps < 2 || steps > kMaxTrajectorySteps)
        m.fail("steps", "a rotation trajectory needs 2 to " + std::to_string(kMaxTrajectorySteps) + " steps (got " +
                            std::to_string(steps) + ")");
      for (int i = 0; i < steps; ++i) {
        const double a = a0 + (a1 - a0) * i / (steps - 1);
        const Eigen::Isometry3d R = Eigen::Translation3d(pivot) * Eigen::AngleAxisd(a, axis) *
                                    Eigen::Translation3d(-pivot);
        t.poses.push_back(R * start);
      }
    } else if (type == "poses") {
      for (const YamlMap& p : m.getMapList("poses")) {
        t.poses.push_back(parsePose(p));
        p.finish();
      }
      if (t.poses.empty()) m.fail("poses", "must list at least one pose");
    } else {
      m.fail("type", "must be linear, rotation or poses (got '" + type + "')");
    }
    m.finish();
    t.name = name;
    t.type = type;
    out[name] = t;
  }
  root.finish();
  return out;
}

Trajectory loadTrajectory(const std::string& path, const std::string& name) {
  const auto all = loadTrajectories(path);
  const auto it = all.find(name);
  if (it != all.end()) return it->second;
  std::string names;
  for (const auto& kv : all) names += (names.empty() ? "" : ", ") + kv.first;
  throw ConfigError(path + ": no trajectory '" + name + "' (the file has: " + names + ")");
}

}  // namespace cellsight
