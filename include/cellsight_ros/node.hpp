// The one entry point of every long-running node, built two ways from the same node class:
//  - a standalone executable (main): ROS init, the node object built from (node handle,
//    private node handle), spinning, and a non-zero exit with a FATAL log naming the cause when
//    the node cannot start (bad parameter, bad file);
//  - with CELLSIGHT_NODELET defined, a nodelet (cellsight/<Class>) for a nodelet manager, so the
//    image path (camera → camera_trigger, triangulation) passes 2 MP frames as shared pointers
//    instead of serialising them between processes.
// A node source ends with CELLSIGHT_NODE(Class, "name", threads).
#pragma once
#include <ros/ros.h>

#include <exception>
#include <memory>
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

#ifdef CELLSIGHT_NODELET
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

// The node object lives as long as the nodelet; callbacks run on the manager's worker threads
// (multi-threaded handles: give the manager enough workers for the nodes' blocking callbacks).
// A node that cannot start logs FATAL and the load fails (the loader catches the exception and
// drops the nodelet, `nodelet load` exits non-zero, so a required launch node stops the launch);
// the manager and its other nodelets run on.
#define CELLSIGHT_NODE(Class, name, threads)                                          \
  namespace cellsight_nodelets {                                                      \
  class Class : public nodelet::Nodelet {                                             \
    void onInit() override {                                                          \
      nh_ = getMTNodeHandle();                                                        \
      pnh_ = getMTPrivateNodeHandle();                                                \
      try {                                                                           \
        node_ = std::make_unique<::Class>(nh_, pnh_);                                 \
      } catch (const std::exception& e) {                                             \
        NODELET_FATAL("%s cannot start: %s", getName().c_str(), e.what());            \
        throw;                                                                        \
      }                                                                               \
    }                                                                                 \
    ros::NodeHandle nh_, pnh_;                                                        \
    std::unique_ptr<::Class> node_;                                                   \
  };                                                                                  \
  }                                                                                   \
  PLUGINLIB_EXPORT_CLASS(cellsight_nodelets::Class, nodelet::Nodelet)
#else
#define CELLSIGHT_NODE(Class, name, threads) \
  int main(int argc, char** argv) { return cellsight_ros::runNode<Class>(argc, argv, name, threads); }
#endif
