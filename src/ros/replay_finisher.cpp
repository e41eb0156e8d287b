// replay_finisher: used by replay.launch. Counts the scanner frames in the bag being played,
// starts the player (paused until then, ~player) once the processing nodes are subscribed,
// waits until the triangulation node has processed every frame, finishes the scan into
// ~output_file and exits (0 on success).
#include <ros/master.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <std_srvs/SetBool.h>

#include <algorithm>

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
    std::string player;
    cellsight_ros::param(pnh, "player", player);
    ros::ServiceClient finish = nh.serviceClient<cellsight::FinishScan>("scan/finish");
    if (!finish.waitForExistence(ros::Duration(60.0))) {
      throw std::runtime_error("scan/finish did not appear: is the triangulation node running?");
    }
    if (!player.empty()) {
      // A message played before its subscriber connected is lost, and with it a frame. The
      // triangulation node offers scan/finish after subscribing, the tracker advertises
      // scan/laser_plane after subscribing: when both stand, the player may start.
      const std::string plane_topic = ros::names::resolve("scan/laser_plane");
      const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(60.0);
      for (;;) {
        ros::master::V_TopicInfo topics;
        ros::master::getTopics(topics);
        if (std::any_of(topics.begin(), topics.end(), [&](const ros::master::TopicInfo& t) { return t.name == plane_topic; }))
          break;
        if (ros::WallTime::now() > give_up)
          throw std::runtime_error("nobody publishes " + plane_topic + " after 60 s: is laser_plane_tracker running?");
        ros::WallDuration(0.1).sleep();
      }
      ros::WallDuration(1.0).sleep();  // subscribers connect to the player after registering
      ros::ServiceClient pause = nh.serviceClient<std_srvs::SetBool>(player + "/pause_playback");
      if (!pause.waitForExistence(ros::Duration(60.0)))
        throw std::runtime_error(pause.getService() + " did not appear: is the bag player (rosbag play --pause) running?");
      std_srvs::SetBool go;
      go.request.data = false;
      if (!pause.call(go)) throw std::runtime_error("call to " + pause.getService() + " failed");
      ROS_INFO("replay_finisher: the processing nodes are subscribed; playback started");
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
