// replay_finisher: used by replay.launch. Counts the scanner frames in the bag being played,
// waits until the triangulation node has processed them all, finishes the scan into
// ~output_file and exits (0 on success).
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include "cellsight/FinishScan.h"
#include "cellsight_ros/params.hpp"

int main(int argc, char** argv) {
  ros::init(argc, argv, "replay_finisher");
  ros::NodeHandle nh, pnh("~");
  try {
    const std::string bag_file = cellsight_ros::requireParam<std::string>(pnh, "bag", "the bag being replayed");
    const std::string output = cellsight_ros::requireParam<std::string>(pnh, "output_file", ".ply or .pcd to write");
    double rate = 1.0;
    cellsight_ros::param(pnh, "rate", rate);
    rosbag::Bag bag(bag_file, rosbag::bagmode::Read);
    rosbag::View view(bag, rosbag::TopicQuery(std::vector<std::string>{"/scanner_camera/image_raw"}));
    const uint32_t frames = view.size();
    const double duration = (view.getEndTime() - view.getBeginTime()).toSec() / std::max(0.01, rate);
    bag.close();
    if (frames == 0) throw std::runtime_error(bag_file + " holds no /scanner_camera/image_raw messages");
    ros::ServiceClient finish = nh.serviceClient<cellsight::FinishScan>("scan/finish");
    if (!finish.waitForExistence(ros::Duration(60.0))) {
      throw std::runtime_error("scan/finish did not appear: is the triangulation node running?");
    }
    cellsight::FinishScan srv;
    srv.request.output_file = output;
    srv.request.expected_frames = frames;
    srv.request.wait_frames_timeout = duration + 60.0;
    ROS_INFO("replay_finisher: waiting for %u frames (%.1f s of bag)", frames, duration);
    if (!finish.call(srv)) throw std::runtime_error("call to scan/finish failed");
    if (srv.response.status != cellsight::FinishScan::Response::OK) throw std::runtime_error(srv.response.message);
    ROS_INFO("replay_finisher: %s, written to %s", srv.response.message.c_str(), output.c_str());
  } catch (const std::exception& e) {
    ROS_ERROR("replay_finisher: %s", e.what());
    return 1;
  }
  return 0;
}
