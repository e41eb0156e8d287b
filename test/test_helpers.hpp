// Shared helpers for the core tests: error messages, temporary folders, files, poses.
#pragma once
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>

#include <Eigen/Geometry>
#include <cmath>

namespace cellsight_test {

/// The message of the exception `f` throws ("" when it throws nothing).
inline std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

inline std::string tempDir() {
  char tmpl[] = "/tmp/cellsight_test_XXXXXX";
  const char* d = mkdtemp(tmpl);
  if (!d) throw std::runtime_error("mkdtemp failed");
  return d;
}

inline void writeText(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
}

inline Eigen::Isometry3d lookDown(const Eigen::Vector3d& position) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T.translation() = position;
  return T;
}

}  // namespace cellsight_test
