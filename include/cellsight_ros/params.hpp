// Parameter loading with one place for each default and clear errors for required ones.
#pragma once
#include <ros/node_handle.h>

#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace cellsight_ros {

/// Reads a required private parameter; throws std::runtime_error naming it (and what it is for).
template <typename T>
T requireParam(const ros::NodeHandle& nh, const std::string& name, const std::string& what) {
  T value;
  if (!nh.getParam(name, value)) {
    throw std::runtime_error("required parameter " + nh.resolveName(name) + " is not set (" +
                             what + ")");
  }
  return value;
}

/// Reads an optional parameter, keeping `value` (the default) when it is absent.
template <typename T>
void param(const ros::NodeHandle& nh, const std::string& name, T& value) {
  nh.param(name, value, value);
}

/// `relative` under the user's ROS folder: $ROS_HOME, else $HOME/.ros ("" when neither is set).
/// Where a node keeps what it writes by default (never the package's own files, never /tmp).
inline std::string rosHomePath(const std::string& relative) {
  const char* ros_home = std::getenv("ROS_HOME");
  const char* home = std::getenv("HOME");
  if (ros_home && *ros_home) return std::string(ros_home) + "/" + relative;
  if (home && *home) return std::string(home) + "/.ros/" + relative;
  return "";
}

/// Why `name` cannot be a file a request asks a node to write ("" when it can, and for ""): a
/// plain name (letters, digits, '.', '_', '-'; not starting with '.'; at most 128 characters)
/// ending in one of `extensions`. Requests name files; the node's folder parameter says where.
std::string outputNameProblem(const std::string& name, const std::vector<std::string>& extensions);

}  // namespace cellsight_ros
