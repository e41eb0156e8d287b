// replay_finisher: used by replay.launch. Counts the scanner frames in the bag being played,
// starts the player (paused until then, ~player) once the processing nodes are subscribed,
// waits until the triangulation node has processed every frame, finishes the scan into
// ~output_file and exits (0 on success). A bag of a cycle's passes (its recorded /scan/goal) is
// finished pass by pass with their cycle id and roles, as camera_trigger did: the player is
// paused after each pass's last frame, the pass finished (later ones into <output>_pass<k>), the
// scan reset and the player resumed.
#include <ros/master.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <xmlrpcpp/XmlRpcClient.h>
#include <xmlrpcpp/XmlRpcException.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/Image.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <algorithm>
#include <map>
#include <set>
#include <string>

#include "cellsight/FinishScan.h"
#include "cellsight/ScanActionGoal.h"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/scan_messages.hpp"
#include "cellsight_ros/params.hpp"

namespace {

/// The subscribers of `publisher`'s topics that it has no connection to yet, as "topic: node"
/// (empty: every node the master lists as a subscriber of each topic it publishes is connected);
/// *links: how many (topic, subscriber) pairs there are.
/// A subscriber registers with the master first and connects to the publisher afterwards, on a
/// busy machine a second or more later: a message played in between is lost to it. Throws
/// std::runtime_error when the master or the publisher cannot be asked.
std::vector<std::string> unconnectedSubscribers(const std::string& publisher, size_t* links) {
  XmlRpc::XmlRpcValue args, result, state, uri;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, state, false))
    throw std::runtime_error("the master's getSystemState failed");
  // [publishers, subscribers, services], each a list of [name, [nodes]]
  std::set<std::string> published;
  std::map<std::string, std::set<std::string>> subscribers;
  for (int i = 0; i < state[0].size(); ++i)
    for (int j = 0; j < state[0][i][1].size(); ++j)
      if (static_cast<std::string>(state[0][i][1][j]) == publisher) published.insert(state[0][i][0]);
  for (int i = 0; i < state[1].size(); ++i)
    for (int j = 0; j < state[1][i][1].size(); ++j) subscribers[state[1][i][0]].insert(state[1][i][1][j]);
  args[1] = publisher;
  if (!ros::master::execute("lookupNode", args, result, uri, false))
    throw std::runtime_error("the master does not know " + publisher);
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(uri, host, port)) throw std::runtime_error(publisher + " has a bad URI: " + std::string(uri));
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue request, bus;
  request[0] = ros::this_node::getName();
  if (!client.execute("getBusInfo", request, bus) || bus.getType() != XmlRpc::XmlRpcValue::TypeArray || bus.size() < 3)
    throw std::runtime_error(publisher + " did not answer getBusInfo");
  // each connection: [id, the other node, direction ("o": out), transport, topic, connected, ...]
  std::map<std::string, std::set<std::string>> connected;
  for (int i = 0; i < bus[2].size(); ++i) {
    XmlRpc::XmlRpcValue& c = bus[2][i];
    if (c.size() < 5 || static_cast<std::string>(c[2]) != "o") continue;
    if (c.size() > 5 && c[5].getType() == XmlRpc::XmlRpcValue::TypeBoolean && !static_cast<bool>(c[5])) continue;
    connected[c[4]].insert(c[1]);
  }
  std::vector<std::string> missing;
  *links = 0;
  for (const auto& topic : published)
    for (const auto& node : subscribers[topic]) {
      if (node == publisher) continue;
      ++*links;
      if (!connected[topic].count(node)) missing.push_back(topic + ": " + node);
    }
  return missing;
}

/// A pass of the bag's cycle: its goal (none recorded: one pass on its own) and its frames.
struct BagPass {
  cellsight::ScanGoal goal;
  uint32_t frames = 0;
  ros::Time first, last;  // its frames' stamps
};

std::vector<BagPass> bagPasses(const std::string& bag_file) {
  rosbag::Bag bag(bag_file, rosbag::bagmode::Read);
  std::vector<std::pair<ros::Time, cellsight::ScanGoal>> goals;
  for (const rosbag::MessageInstance& m : rosbag::View(bag, rosbag::TopicQuery(std::vector<std::string>{"/scan/goal"})))
    if (const auto g = m.instantiate<cellsight::ScanActionGoal>()) goals.emplace_back(g->header.stamp, g->goal);
  std::stable_sort(goals.begin(), goals.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<ros::Time> sent;
  std::vector<BagPass> passes(std::max<size_t>(goals.size(), 1));
  for (size_t k = 0; k < goals.size(); ++k) {
    sent.push_back(goals[k].first);
    passes[k].goal = goals[k].second;
  }
  for (const rosbag::MessageInstance& m :
       rosbag::View(bag, rosbag::TopicQuery(std::vector<std::string>{"/scanner_camera/image_raw"}))) {
    const auto image = m.instantiate<sensor_msgs::Image>();
    if (!image) continue;
    BagPass& p = passes[cellsight_ros::passOfFrame(sent, image->header.stamp)];
    if (p.frames == 0 || image->header.stamp < p.first) p.first = image->header.stamp;
    p.last = std::max(p.last, image->header.stamp);
    ++p.frames;
  }
  // a goal with no frame after it (a pass that failed at once) is no pass of the scan
  passes.erase(std::remove_if(passes.begin(), passes.end(), [](const BagPass& p) { return p.frames == 0; }), passes.end());
  return passes;
}

}  // namespace

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
      // ... and once every subscriber of the player's topics has connected to it
      const ros::WallTime t_connect = ros::WallTime::now();
      size_t links = 0;
      for (;;) {
        std::vector<std::string> missing;
        try {
          missing = unconnectedSubscribers(ros::names::resolve(player), &links);
        } catch (const std::exception& e) {
          missing = {e.what()};
        } catch (const XmlRpc::XmlRpcException& e) {
          missing = {"a malformed answer (" + e.getMessage() + ")"};
        }
        if (missing.empty()) break;
        if (ros::WallTime::now() > give_up)
          throw std::runtime_error("after 60 s the player " + player + " is still not connected to " + missing.front() +
                                   " (" + std::to_string(missing.size()) + " in all): is that node stuck?");
        ros::WallDuration(0.1).sleep();
      }
      ros::ServiceClient pause = nh.serviceClient<std_srvs::SetBool>(player + "/pause_playback");
      if (!pause.waitForExistence(ros::Duration(60.0)))
        throw std::runtime_error(pause.getService() + " did not appear: is the bag player (rosbag play --pause) running?");
      std_srvs::SetBool go;
      go.request.data = false;
      if (!pause.call(go)) throw std::runtime_error("call to " + pause.getService() + " failed");
      ROS_INFO("replay_finisher: the processing nodes are subscribed and the player is connected to all %zu "
               "subscribers of its topics (waited %.2f s for them); playback started",
               links, (ros::WallTime::now() - t_connect).toSec());
    }
    ros::ServiceClient pause = nh.serviceClient<std_srvs::SetBool>(player + "/pause_playback");
    ros::ServiceClient reset = nh.serviceClient<std_srvs::Trigger>("scan/reset");
    const std::vector<BagPass> passes = bagPasses(bag_file);
    if (passes.size() > 1 && player.empty())
      throw std::runtime_error(bag_file + " holds " + std::to_string(passes.size()) +
                               " passes: replaying them needs the player (play:=true) to pause between them");
    for (size_t k = 0; k < passes.size(); ++k) {
      const BagPass& p = passes[k];
      if (k + 1 < passes.size()) {
        // pause once the bag's clock has passed this pass's last frame, before the next pass's first
        while (ros::ok() && ros::Time::now() <= p.last) ros::WallDuration(0.005).sleep();
        std_srvs::SetBool stop;
        stop.request.data = true;
        if (!pause.call(stop)) throw std::runtime_error("call to " + pause.getService() + " failed");
        if (ros::Time::now() >= passes[k + 1].first)
          throw std::runtime_error("the player ran into pass " + std::to_string(k + 2) +
                                   " before it could be paused: replay at a lower rate (rate:=0.5)");
      }
      cellsight::FinishScan srv;
      // the finisher writes the cloud itself: triangulation writes only into its own folder
      srv.request.expected_frames = p.frames;
      srv.request.wait_frames_timeout = duration + 60.0;
      srv.request.cycle_id = p.goal.cycle_id;
      srv.request.role = p.goal.role;
      srv.request.last_pass = p.goal.last_pass;
      ROS_INFO("replay_finisher: waiting for %u frames of pass %zu/%zu (%.1f s of bag in all)", p.frames, k + 1,
               passes.size(), duration);
      if (!finish.call(srv)) throw std::runtime_error("call to scan/finish failed");
      if (srv.response.status != cellsight::FinishScan::Response::OK) throw std::runtime_error(srv.response.message);
      const std::string file = cellsight_ros::passOutputFile(output, k);
      cellsight::saveCloud(file, cellsight_ros::fromCloudMsg(srv.response.cloud));
      ROS_INFO("replay_finisher: %s, written to %s", srv.response.message.c_str(), file.c_str());
      if (k + 1 < passes.size()) {
        std_srvs::Trigger cleared;
        if (!reset.call(cleared) || !cleared.response.success) throw std::runtime_error("call to scan/reset failed");
        std_srvs::SetBool go;
        go.request.data = false;
        if (!pause.call(go)) throw std::runtime_error("call to " + pause.getService() + " failed");
      }
    }
  } catch (const std::exception& e) {
    ROS_ERROR("replay_finisher: %s", e.what());
    return 1;
  }
  return 0;
}
