#include "cellsight_ros/params.hpp"

#include <ros/package.h>

namespace cellsight_ros {

std::string packagePath() {
  const std::string p = ros::package::getPath("cellsight");
  if (p.empty()) {
    throw std::runtime_error("package 'cellsight' not found: source <build>/devel/setup.bash first");
  }
  return p;
}

}  // namespace cellsight_ros
