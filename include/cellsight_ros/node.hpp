// The one main() of every long-running node: ROS init, the node object built from
// (node handle, private node handle), spinning, and a non-zero exit with a FATAL log naming the
// cause when the node cannot start (bad parameter, bad file).
#pragma once
#include <ros/ros.h>

#include <exception>
#include <string>

namespace cellsight_ros {

/// `threads` > 1 runs callbacks on an AsyncSpinner (needed where a callback waits on another).
template <typename Node>
int runNode(int argc, char** argv, const std::string& name, int threads = 1) {
  ros::init(argc, argv, name);
  ros::NodeHandle nh, pnh("~");
  try {
    Node node(nh, pnh);
    if (threads > 1) {
      ros::AsyncSpinner spinner(threads);
      spinner.start();
      ros::waitForShutdown();
    } else {
      ros::spin();
    }
  } catch (const std::exception& e) {
    ROS_FATAL("%s cannot start: %s", name.c_str(), e.what());
    return 1;
  }
  return 0;
}

}  // namespace cellsight_ros
