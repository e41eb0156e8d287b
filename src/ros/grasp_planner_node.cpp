// grasp_planner: from located parts to checked robot motions. Keeps the collision world of the
// latest scan (scan/cloud) and detections (cellsight/DetectionArray: each located part as its
// model mesh, the rest of the scan as an OctoMap, the table), the robot's joint state
// (joint_states), and answers ~plan (cellsight/PlanGrasp): a GraspPlan for one part or the next
// of config/assembly.yaml, with a time-parameterised joint trajectory that was checked for
// collisions edge by edge. ~plan with placed = true moves the part to its target in the world.
// rviz: ~markers (path, named poses, OctoMap voxels, the part at its target), tf grasp/<object>.
// Detections in another frame than ~base_frame are transformed at their stamp; without the
// transform they are dropped with the reason (never an identity).
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <sensor_msgs/PointCloud2.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <map>
#include <mutex>
#include <nlohmann/json.hpp>

#include "cellsight/DetectionArray.h"
#include "cellsight/GraspPlan.h"
#include "cellsight/PlanGrasp.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/planning/grasp_planner.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/params.hpp"

namespace {

std::string instanceName(const std::string& frame) {
  const std::string prefix = "object/";
  return frame.compare(0, prefix.size(), prefix) == 0 ? frame.substr(prefix.size()) : frame;
}

class GraspPlannerNode {
 public:
  GraspPlannerNode(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "grasp_planner", "plans"), listener_(buffer_) {
    std::string urdf;
    if (!nh.getParam("robot_description", urdf) || urdf.empty()) {
      throw std::runtime_error("parameter " + nh.resolveName("robot_description") +
                               " is not set: load the arm's URDF there (launch/cell.launch does: urdf/cellsight_arm.urdf)");
    }
    arm_ = std::make_unique<cellsight::ArmModel>(cellsight::ArmModel::fromUrdfString(urdf, nh.resolveName("robot_description")));
    const std::string assembly_file = cellsight_ros::requireParam<std::string>(
        pnh, "assembly_file", "the assembly: base part, order, motion distances, e.g. $(find cellsight)/config/assembly.yaml");
    const std::string models = cellsight_ros::requireParam<std::string>(
        pnh, "models_dir", "model library folder, e.g. $(find cellsight)/config/models");
    cellsight_ros::param(pnh, "base_frame", base_frame_);
    cellsight_ros::param(pnh, "output_file", output_file_);
    cellsight_ros::param(pnh, "joint_state_timeout", joint_state_timeout_);
    cellsight_ros::param(pnh, "tf_timeout", tf_timeout_);
    std::vector<double> center{0.52, 0.0}, size{0.8, 0.7};
    cellsight_ros::param(pnh, "table_z", table_z_);
    cellsight_ros::param(pnh, "table_center", center);
    cellsight_ros::param(pnh, "table_size", size);
    if (center.size() != 2 || size.size() != 2 || !(size[0] > 0 && size[1] > 0)) {
      throw std::runtime_error("~table_center and ~table_size must be [x, y] with a positive size");
    }
    table_center_ = Eigen::Vector2d(center[0], center[1]);
    table_size_ = Eigen::Vector2d(size[0], size[1]);
    cellsight::MotionPlannerConfig motion;
    cellsight_ros::param(pnh, "planning_time", motion.planning_time);
    cellsight_ros::param(pnh, "edge_resolution", motion.edge_resolution);
    cellsight_ros::param(pnh, "velocity_scale", motion.velocity_scale);
    const cellsight::AssemblyConfig assembly = cellsight::loadAssemblyConfig(assembly_file);
    const cellsight::ModelLibrary lib(models);
    for (const std::string& id : lib.ids()) {
      const auto& e = lib.model(id);
      if (e.mesh.faces.empty()) {
        ROS_WARN("grasp_planner: model '%s' has no mesh (a cloud model): it cannot be grasped", id.c_str());
        continue;
      }
      models_[id] = {e.info, std::make_shared<cellsight::TriangleMesh>(e.mesh)};
    }
    planner_ = std::make_unique<cellsight::GraspPlanner>(*arm_, assembly, cellsight::GripperConfig{}, motion, models_);
    const ros::WallTime t0 = ros::WallTime::now();
    size_t n = 0;
    for (const auto& [id, m] : models_) n += planner_->candidates(id).size();  // once, now rather than on the first plan
    ROS_INFO("grasp_planner: arm with %zu collision shapes, %zu models, %zu grasp candidates ready in %.2f s", arm_->shapes().size(),
             models_.size(), n, (ros::WallTime::now() - t0).toSec());
    markers_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("markers", 1, true);
    plan_pub_ = pnh.advertise<cellsight::GraspPlan>("plan", 1, true);
    detections_sub_ = nh.subscribe("detections", 1, &GraspPlannerNode::onDetections, this);
    cloud_sub_ = nh.subscribe("scan/cloud", 1, &GraspPlannerNode::onCloud, this);
    joints_sub_ = nh.subscribe("joint_states", 10, &GraspPlannerNode::onJoints, this);
    service_ = pnh.advertiseService("plan", &GraspPlannerNode::onPlan, this);
    tf_timer_ = nh.createTimer(ros::Duration(0.1), &GraspPlannerNode::onTfTimer, this);
  }

 private:
  /// The scan read once, here: one that cannot be read is dropped, the last good one kept (one
  /// malformed message must not fail every later plan).
  void onCloud(const sensor_msgs::PointCloud2ConstPtr& msg) {
    auto scan = std::make_shared<Scan>();
    try {
      scan->cloud = cellsight_ros::fromCloudMsg(*msg, &scan->dropped);
    } catch (const std::exception& e) {
      ROS_ERROR("grasp_planner: %s dropped, the previous scan kept: %s", cloud_sub_.getTopic().c_str(), e.what());
      diag_.dropped("unreadable scan");
      return;
    }
    scan->frame_id = msg->header.frame_id;
    std::lock_guard<std::mutex> lock(mutex_);
    cloud_ = std::move(scan);
    scene_dirty_ = true;
  }

  void onDetections(const cellsight::DetectionArrayConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    detections_ = msg;
    scene_dirty_ = true;
  }

  void onJoints(const sensor_msgs::JointStateConstPtr& msg) {
    cellsight::JointVector q;
    const auto& names = arm_->jointNames();
    for (int j = 0; j < 6; ++j) {
      const auto it = std::find(msg->name.begin(), msg->name.end(), names[static_cast<size_t>(j)]);
      if (it == msg->name.end() || static_cast<size_t>(it - msg->name.begin()) >= msg->position.size()) return;  // another group
      q[j] = msg->position[static_cast<size_t>(it - msg->name.begin())];
    }
    if (!q.allFinite()) {
      ROS_WARN_THROTTLE(5, "grasp_planner: joint_states with non-finite positions ignored");
      return;
    }
    std::lock_guard<std::mutex> lock(joints_mutex_);  // not mutex_: a plan in progress must not hold the joints up
    joints_ = q;
    joints_stamp_ = ros::Time::now();
  }

  /// Rebuilds the planner's world from the latest detections and cloud (mutex_ held). False with
  /// the reason when something is missing.
  bool updateScene(std::string* why) {
    if (!detections_) return *why = "no detections received on " + detections_sub_.getTopic() + " yet: scan and locate first", false;
    if (!cloud_) return *why = "no scan received on " + cloud_sub_.getTopic() + " yet", false;
    if (!scene_dirty_) return true;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    const std::string& frame = detections_->header.frame_id;
    if (!frame.empty() && frame != base_frame_) {
      try {
        const auto ts = buffer_.lookupTransform(base_frame_, frame, detections_->header.stamp, ros::Duration(tf_timeout_));
        T = cellsight_ros::fromTransformMsg(ts.transform);
      } catch (const std::exception& e) {
        return *why = "detections in '" + frame + "' dropped: no transform to '" + base_frame_ + "' at their stamp (" + e.what() + ")",
               false;
      }
    }
    if (cloud_->frame_id != base_frame_) {
      return *why = "the scan is in '" + cloud_->frame_id + "', the planner needs it in '" + base_frame_ + "'", false;
    }
    parts_.clear();
    for (const auto& d : detections_->detections) {
      try {
        // whole or not at all: a part whose other poses could not be read must not be planned as if it had none
        cellsight::LocatedPart part{instanceName(d.name), d.model, T * cellsight_ros::fromPoseMsg(d.pose), {}};
        for (const auto& a : d.ambiguous_poses) part.ambiguous_poses.push_back(T * cellsight_ros::fromPoseMsg(a));
        parts_.push_back(std::move(part));
      } catch (const std::exception& e) {
        ROS_WARN("grasp_planner: detection '%s' skipped: %s", d.name.c_str(), e.what());
      }
    }
    const cellsight::ScanCloud& cloud = cloud_->cloud;
    const size_t dropped = cloud_->dropped;
    cellsight::CollisionWorld world(cellsight::CollisionWorldConfig{}, table_z_, table_center_, table_size_);
    const ros::WallTime t0 = ros::WallTime::now();
    planner_->setScene(world, parts_, cloud.points);
    ROS_INFO("grasp_planner: world of %zu located parts and %zu occupied voxels (%zu scan points, %zu dropped as invalid) in %.2f s",
             parts_.size(), planner_->world().occupiedVoxels(), cloud.size(), dropped, (ros::WallTime::now() - t0).toSec());
    scene_dirty_ = false;
    publishVoxels();
    return true;
  }

  bool onPlan(cellsight::PlanGrasp::Request& req, cellsight::PlanGrasp::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const ros::WallTime t0 = ros::WallTime::now();
    cellsight::GraspPlan& plan = res.plan;
    plan.header.frame_id = base_frame_;
    plan.header.stamp = ros::Time::now();
    plan.object = instanceName(req.object);
    auto refuse = [&](const std::string& why) {
      plan.status = cellsight::GraspPlan::BAD_INPUT;
      plan.reason = why;
      res.message = why;
      ROS_WARN("grasp_planner: %s", why.c_str());
      diag_.dropped(why);
      return true;
    };
    std::string why;
    if (!updateScene(&why)) return refuse(why);
    size_t index = parts_.size();
    if (!plan.object.empty()) {
      for (size_t i = 0; i < parts_.size(); ++i) {
        if (parts_[i].name == plan.object) index = i;
      }
      if (index == parts_.size()) return refuse("no located part named '" + plan.object + "' in the latest detections");
    }
    if (req.placed) {
      const auto it = last_ok_.find(plan.object);
      if (it == last_ok_.end()) return refuse("'" + plan.object + "' has no OK plan to mark as carried out");
      planner_->commit(index, it->second);
      last_ok_.erase(it);
      plan.status = cellsight::GraspPlan::OK;
      res.message = "'" + plan.object + "' now lies at its target in the planner's world";
      ROS_INFO("grasp_planner: %s", res.message.c_str());
      return true;
    }
    cellsight::JointVector start;
    ros::Time joints_stamp;
    {
      std::lock_guard<std::mutex> jl(joints_mutex_);
      start = joints_;
      joints_stamp = joints_stamp_;
    }
    if (joints_stamp.isZero() || (ros::Time::now() - joints_stamp).toSec() > joint_state_timeout_) {
      return refuse("no joint state of the arm on " + joints_sub_.getTopic() + " for " + std::to_string(joint_state_timeout_) +
                    " s: the plan must start where the robot is");
    }
    cellsight::PartPlan p = plan.object.empty() ? planner_->planNext(start, &index) : planner_->plan(index, start);
    plan = cellsight_ros::toGraspPlanMsg(p, arm_->jointNames(), base_frame_, ros::Time::now());
    if (p.status == cellsight::PlanStatus::kOk) {
      last_ok_[p.part.name] = p;
      {
        std::lock_guard<std::mutex> tl(tf_mutex_);
        grasp_frames_[p.part.name] = p.poses[1].T_base_tcp;
      }
      res.message = "planned '" + p.part.name + "' (" + p.part.model + ") in " + std::to_string(p.seconds * 1e3) + " ms: " +
                    std::to_string(p.trajectory.duration()) + " s of motion";
      diag_.processed((ros::WallTime::now() - t0).toSec());
      publishPlanMarkers(p);
    } else {
      res.message = std::string(cellsight::planStatusName(p.status)) + ": " + p.reason;
      diag_.dropped(cellsight::planStatusName(p.status));
    }
    ROS_INFO("grasp_planner: %s", res.message.c_str());
    plan_pub_.publish(plan);
    record(p);
    return true;
  }

  /// The latest kKeptPlans plans to ~output_file (JSON array, atomic): memory and the file's
  /// rewrite stay bounded however many plans a client asks for.
  void record(const cellsight::PartPlan& p) {
    if (output_file_.empty()) return;
    const auto cut = [](const std::string& t) { return t.size() <= 200 ? t : t.substr(0, 200) + "..."; };
    nlohmann::json j = {{"object", cut(p.part.name)}, {"model", cut(p.part.model)}, {"status", cellsight::planStatusName(p.status)},
                        {"reason", cut(p.reason)}, {"plan_seconds", p.seconds}, {"candidates", p.candidates},
                        {"candidates_tried", p.candidates_tried}, {"sampled", p.sampled}};
    if (p.status == cellsight::PlanStatus::kOk) {
      const Eigen::Vector3d t = p.T_base_target.translation();
      const Eigen::Quaterniond q(p.T_base_target.linear());
      j["target"] = {{"xyz", {t.x(), t.y(), t.z()}}, {"quat", {q.x(), q.y(), q.z(), q.w()}}};
      j["grasp_source"] = p.grasp.source;
      j["grip_width_mm"] = p.grip_opening * 1e3;
      j["motion_seconds"] = p.trajectory.duration();
      j["trajectory_points"] = p.trajectory.positions.size();
    }
    plans_json_.push_back(j);
    if (plans_json_.size() > kKeptPlans) plans_json_.erase(plans_json_.begin());
    try {
      cellsight::writeFileAtomic(output_file_, plans_json_.dump(2) + "\n");
    } catch (const std::exception& e) {
      ROS_ERROR("grasp_planner: %s", e.what());
    }
  }

  visualization_msgs::Marker marker(const std::string& ns, int id, int type) const {
    visualization_msgs::Marker m;
    m.header.frame_id = base_frame_;
    m.header.stamp = ros::Time::now();
    m.ns = ns;
    m.id = id;
    m.type = type;
    m.action = visualization_msgs::Marker::ADD;
    m.pose.orientation.w = 1;
    m.scale.x = m.scale.y = m.scale.z = 1;
    m.color.a = 1;
    return m;
  }

  void publishVoxels() {
    visualization_msgs::MarkerArray arr;
    visualization_msgs::Marker m = marker("octomap", 0, visualization_msgs::Marker::CUBE_LIST);
    const double s = planner_->world().voxelSize();
    m.scale.x = m.scale.y = m.scale.z = s;
    m.color.r = 0.9f;
    m.color.g = 0.6f;
    m.color.b = 0.1f;
    m.color.a = 0.8f;
    for (const auto& c : planner_->world().voxelCentres()) {
      geometry_msgs::Point p;
      p.x = c.x();
      p.y = c.y();
      p.z = c.z();
      m.points.push_back(p);
    }
    if (m.points.empty()) m.action = visualization_msgs::Marker::DELETE;
    arr.markers.push_back(m);
    markers_pub_.publish(arr);
  }

  void publishPlanMarkers(const cellsight::PartPlan& p) {
    visualization_msgs::MarkerArray arr;
    visualization_msgs::Marker path = marker("path", 0, visualization_msgs::Marker::LINE_STRIP);
    path.scale.x = 0.002;
    path.color.r = 0.1f;
    path.color.g = 0.9f;
    path.color.b = 0.2f;
    for (const auto& q : p.trajectory.positions) {
      const Eigen::Vector3d t = (arm_->fk(q) * arm_->toolTcp()).translation();
      geometry_msgs::Point pt;
      pt.x = t.x();
      pt.y = t.y();
      pt.z = t.z();
      path.points.push_back(pt);
    }
    arr.markers.push_back(path);
    int id = 0;
    for (const auto& np : p.poses) {
      visualization_msgs::Marker a = marker("poses", id++, visualization_msgs::Marker::ARROW);
      a.pose = cellsight_ros::toPoseMsg(np.T_base_tcp * Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitY()) *
                                        Eigen::Translation3d(-0.03, 0, 0));  // along the tool axis, ending at the tcp
      a.scale.x = 0.03;
      a.scale.y = a.scale.z = 0.004;
      a.color.r = 0.2f;
      a.color.g = 0.4f;
      a.color.b = 1.0f;
      arr.markers.push_back(a);
    }
    // the part's grasp candidates that fit the jaws (every 20th, up to 60): short lines along
    // the approach ending at the tcp, the chosen one drawn by the poses above
    visualization_msgs::Marker cands = marker("candidates", 0, visualization_msgs::Marker::LINE_LIST);
    cands.scale.x = 0.0008;
    cands.color.r = 0.9f;
    cands.color.g = 0.9f;
    cands.color.b = 0.2f;
    cands.color.a = 0.7f;
    const auto& all = planner_->candidates(p.part.model);
    for (size_t i = 0, shown = 0; i < all.size() && shown < 60; i += 20) {
      if (!all[i].valid) continue;
      const Eigen::Isometry3d T = p.part.pose * all[i].T_model_tcp;
      for (const Eigen::Vector3d& v : {Eigen::Vector3d(T.translation() - 0.02 * T.linear().col(2)), Eigen::Vector3d(T.translation())}) {
        geometry_msgs::Point pt;
        pt.x = v.x();
        pt.y = v.y();
        pt.z = v.z();
        cands.points.push_back(pt);
      }
      ++shown;
    }
    if (cands.points.empty()) cands.action = visualization_msgs::Marker::DELETE;
    arr.markers.push_back(cands);
    visualization_msgs::Marker target = marker("target", 0, visualization_msgs::Marker::TRIANGLE_LIST);
    target.pose = cellsight_ros::toPoseMsg(p.T_base_target);
    target.points = cellsight_ros::meshTriangles(*models_.at(p.part.model).second);
    target.color.r = 0.2f;
    target.color.g = 0.9f;
    target.color.b = 0.3f;
    target.color.a = 0.4f;
    arr.markers.push_back(target);
    markers_pub_.publish(arr);
  }

  void onTfTimer(const ros::TimerEvent&) {
    std::lock_guard<std::mutex> lock(tf_mutex_);
    const ros::Time now = ros::Time::now();
    if (now == last_tf_) return;
    last_tf_ = now;
    for (const auto& [name, T] : grasp_frames_) {
      geometry_msgs::TransformStamped ts;
      ts.header.stamp = now;
      ts.header.frame_id = base_frame_;
      ts.child_frame_id = "grasp/" + name;
      ts.transform = cellsight_ros::toTransformMsg(T);
      broadcaster_.sendTransform(ts);
    }
  }

  cellsight_ros::NodeDiagnostics diag_;
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  tf2_ros::TransformBroadcaster broadcaster_;
  std::unique_ptr<cellsight::ArmModel> arm_;
  std::map<std::string, std::pair<cellsight::ModelInfo, std::shared_ptr<const cellsight::TriangleMesh>>> models_;
  std::unique_ptr<cellsight::GraspPlanner> planner_;
  std::string base_frame_ = "base_link", output_file_;
  double joint_state_timeout_ = 1.0, tf_timeout_ = 0.5, table_z_ = 0.0;
  Eigen::Vector2d table_center_, table_size_;
  cellsight::JointVector joints_ = cellsight::JointVector::Zero();
  ros::Time joints_stamp_, last_tf_;
  cellsight::DetectionArrayConstPtr detections_;
  struct Scan {
    cellsight::ScanCloud cloud;
    size_t dropped = 0;  // invalid points left out when it was read
    std::string frame_id;
  };
  std::shared_ptr<const Scan> cloud_;  // the latest readable scan
  bool scene_dirty_ = false;
  std::vector<cellsight::LocatedPart> parts_;
  std::map<std::string, cellsight::PartPlan> last_ok_;
  std::map<std::string, Eigen::Isometry3d, std::less<>, Eigen::aligned_allocator<std::pair<const std::string, Eigen::Isometry3d>>>
      grasp_frames_;
  nlohmann::json plans_json_ = nlohmann::json::array();
  static constexpr size_t kKeptPlans = 1000;
  ros::Publisher markers_pub_, plan_pub_;
  ros::Subscriber detections_sub_, cloud_sub_, joints_sub_;
  ros::ServiceServer service_;
  ros::Timer tf_timer_;
  std::mutex mutex_;         // the planner, its world and the latest inputs
  std::mutex joints_mutex_;  // joints_, joints_stamp_
  std::mutex tf_mutex_;      // grasp_frames_, last_tf_
};

}  // namespace

// the service waits on nothing but must not block joint_states
CELLSIGHT_NODE(GraspPlannerNode, "grasp_planner", 2)
