// model_matching: clusters (cellsight/ClusterArray) → detections (cellsight/DetectionArray, one
// message per scan), tf frames object/<model>_<k> (names kept across scans for a part found again
// where it was; re-published at ~frame_rate so tf never runs out of them), mesh markers for rviz, and the
// ~locate_objects service (cellsight/LocateObjects) on the latest clusters. The viewpoint of the
// visible-surface check is the scanner camera, looked up in tf at the clusters' stamp; without
// that transform the clusters are dropped with the reason (never an identity). The scan's light
// sheet (scan/light_sweep, from triangulation, the clusters' stamp) adds the illumination test;
// without it the fitness counts every camera-visible point, with a warning. A cell cycle may scan
// several passes (scan/pass, the clusters' stamp: cellsight/ScanPass): the node holds the cycle's
// passes and locates each on top of the earlier ones (locateScan's addPass), publishing the
// cycle's parts after every pass; a pass of another cycle is dropped with the reason.
#include <dynamic_reconfigure/server.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <map>
#include <optional>
#include <exception>
#include <mutex>
#include <cstdlib>
#include <thread>

#include "cellsight/ClusterArray.h"
#include "cellsight/CyclePass.h"
#include "cellsight/DetectionArray.h"
#include "cellsight/LaserSweep.h"
#include "cellsight/LocateObjects.h"
#include "cellsight/MatchingAcceptanceConfig.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight/localization/instance_names.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/localization/scan_localization.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"
#include "cellsight_ros/scan_messages.hpp"

namespace {

constexpr size_t kKept = 8;       // scans' sweeps and pass messages kept for pairing by stamp
constexpr size_t kMaxPasses = 8;  // passes of one cycle

/// A cell cycle's passes so far and what they located.
struct Cycle {
  std::string id;
  std_msgs::Header header;  // the latest pass's
  std::vector<cellsight::ScanPass> passes;
  std::vector<uint8_t> roles;  // cellsight/CyclePass roles, per pass
  cellsight::LocatedScan located;
  bool final = false;
};

class ModelMatching {
 public:
  ModelMatching(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "model_matching", "scans"), listener_(buffer_) {
    const std::string settings = cellsight_ros::requireParam<std::string>(
        pnh, "settings_file", "matching settings YAML, e.g. $(find cellsight)/config/matching.yaml");
    const std::string models = cellsight_ros::requireParam<std::string>(
        pnh, "models_dir", "model library folder, e.g. $(find cellsight)/config/models");
    cellsight_ros::param(pnh, "camera_frame", camera_frame_);
    cellsight_ros::param(pnh, "output_file", output_file_);
    cellsight_ros::param(pnh, "tf_timeout", tf_timeout_);
    double frame_rate = 10.0;
    cellsight_ros::param(pnh, "frame_rate", frame_rate);
    cellsight_ros::param(pnh, "instance_max_move", instance_max_move_);
    library_ = std::make_shared<const cellsight::ModelLibrary>(models);
    for (const auto& id : library_->ids()) {
      for (const auto& w : library_->model(id).warnings) ROS_WARN("model_matching: model '%s': %s", id.c_str(), w.c_str());
    }
    config_ = cellsight::loadMatchingConfig(settings);
    // prepared models are kept on disk (keyed by geometry and settings): a restart loads them
    std::string cache_dir;
    cellsight_ros::param(pnh, "model_cache_dir", cache_dir);
    if (cache_dir.empty()) cache_dir = cellsight_ros::rosHomePath("cellsight/model_cache");
    if (cache_dir != "none") config_.model_cache_dir = cache_dir;
    // the viewpoint comes per scan from tf; build the per-model data now, not on the first scan
    matcher_ = std::make_unique<cellsight::ModelMatcher>(library_, config_);
    const ros::WallTime t0 = ros::WallTime::now();
    // Preparation is seconds of CPU at start-up, when the scanner nodes start too: run it at a
    // lower priority (its worker threads inherit it) so a 2-core cell PC keeps serving images.
    std::exception_ptr failure;
    std::thread([&] {
      if (setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 10) != 0)
        ROS_DEBUG("model_matching: could not lower the preparation's priority");
      try {
        matcher_->prepare({});
      } catch (...) {
        failure = std::current_exception();
      }
    }).join();
    if (failure) std::rethrow_exception(failure);
    ROS_INFO("model_matching: %zu models ready in %.2f s (coarse stage: %s; prepared models cached in %s)",
             library_->ids().size(), (ros::WallTime::now() - t0).toSec(), config_.coarse.c_str(),
             config_.model_cache_dir.empty() ? "no folder" : config_.model_cache_dir.c_str());
    detections_pub_ = nh.advertise<cellsight::DetectionArray>("detections", 1, true);
    markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("detections/markers", 1, true);
    sweep_sub_ = nh.subscribe("scan/light_sweep", kKept, &ModelMatching::onSweep, this);
    pass_sub_ = nh.subscribe("scan/pass", kKept, &ModelMatching::onPass, this);
    // a cycle's next pass may come while this one is located: keep it
    clusters_sub_ = nh.subscribe("clusters", kKept, &ModelMatching::onClusters, this);
    service_ = pnh.advertiseService("locate_objects", &ModelMatching::onLocate, this);
    // the settings file's acceptance thresholds are the starting values of ~ (rqt_reconfigure)
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<cellsight::MatchingAcceptanceConfig>>(reconfigure_mutex_, pnh);
    cellsight::MatchingAcceptanceConfig start;
    cellsight::copyAcceptance(cellsight::acceptanceOf(matcher_->config()), &start);
    reconfigure_->updateConfig(start);
    reconfigure_->setCallback([this](cellsight::MatchingAcceptanceConfig& c, uint32_t) { onReconfigure(c); });
    if (frame_rate > 0) frame_timer_ = nh.createTimer(ros::Duration(1.0 / frame_rate), &ModelMatching::onFrameTimer, this);
  }

 private:
  /// New acceptance thresholds, checked like config/matching.yaml; refused ones are logged and
  /// the running values sent back. Callbacks are serial (one spinner thread): no locate() runs.
  void onReconfigure(cellsight::MatchingAcceptanceConfig& c) {
    try {
      matcher_->setAcceptance({c.min_fitness, c.min_coverage, c.max_rmse, c.max_instances});
      ROS_INFO("model_matching: acceptance now min_fitness %.2f, min_coverage %.2f, max_rmse %.2f mm, max_instances %d",
               c.min_fitness, c.min_coverage, c.max_rmse * 1e3, c.max_instances);
    } catch (const std::exception& e) {
      ROS_ERROR("model_matching: reconfigure refused: %s; the running thresholds stay", e.what());
      cellsight::copyAcceptance(cellsight::acceptanceOf(matcher_->config()), &c);
    }
  }

  /// The light sheets of the latest scans, for the clusters that carry the same stamp.
  void onSweep(const cellsight::LaserSweepConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    sweeps_.push_back(msg);
    if (sweeps_.size() > kKept) sweeps_.erase(sweeps_.begin());
  }

  /// What the latest scans are for in their cycles, for the clusters that carry the same stamp.
  void onPass(const cellsight::CyclePassConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    pass_infos_.push_back(msg);
    if (pass_infos_.size() > kKept) pass_infos_.erase(pass_infos_.begin());
  }

  /// The pass the clusters came from (same stamp); none: a scan on its own, one detect pass.
  cellsight::CyclePass passInfoFor(const cellsight::ClusterArray& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& p : pass_infos_)
      if (p->header.stamp == msg.header.stamp) return *p;
    cellsight::CyclePass own;
    own.header = msg.header;
    own.role = cellsight::CyclePass::DETECT;
    own.last = true;
    return own;
  }

  /// The sweep of the scan the clusters came from (same stamp and frame), or a warning why none.
  std::unique_ptr<cellsight::LightSweep> sweepFor(const cellsight::ClusterArray& msg, std::vector<std::string>* warnings) {
    cellsight::LaserSweepConstPtr found;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& s : sweeps_)
        if (s->header.stamp == msg.header.stamp) found = s;
    }
    std::string why;
    if (!found) {
      why = "no " + sweep_sub_.getTopic() + " with the clusters' stamp (is triangulation publishing it?)";
    } else if (found->header.frame_id != msg.header.frame_id) {
      why = sweep_sub_.getTopic() + " in '" + found->header.frame_id + "', the clusters in '" + msg.header.frame_id + "'";
    } else {
      try {
        return std::make_unique<cellsight::LightSweep>(cellsight_ros::fromLaserSweepMsg(*found));
      } catch (const std::exception& e) {
        why = sweep_sub_.getTopic() + " unusable: " + e.what();
      }
    }
    warnings->push_back(why + ": fitness counts every camera-visible point, lit or not");
    ROS_WARN_THROTTLE(10.0, "model_matching: %s: fitness counts every camera-visible point, lit or not", why.c_str());
    return nullptr;
  }

  void onClusters(const cellsight::ClusterArrayConstPtr& msg) {
    const cellsight::CyclePass info = passInfoFor(*msg);
    const std::string refused = refusal(info);
    if (!refused.empty()) {
      ROS_ERROR("model_matching: clusters at %.3f dropped: %s", msg->header.stamp.toSec(), refused.c_str());
      diag_.dropped("a pass outside its cycle");
      return;
    }
    cellsight::DetectionArray out;
    std::string why;
    try {
      std::optional<cellsight::ScanPass> pass = scanPassOf(*msg, &out.warnings, &why);
      if (!pass) {
        ROS_ERROR("model_matching: clusters at %.3f dropped: %s", msg->header.stamp.toSec(), why.c_str());
        diag_.dropped("no scanner camera transform at the scan's stamp");
        return;
      }
      pass->role = static_cast<cellsight::PassRole>(info.role);
      addToCycle(info, std::move(*pass), msg->header);
      fillDetections(*cycle_, cycle_->located, &out);
      publish(out);
    } catch (const std::exception& e) {  // e.g. a cluster far outside any workspace
      ROS_ERROR("model_matching: clusters at %.3f dropped: they cannot be located: %s (is the scan cropped to the "
                "workspace?)", msg->header.stamp.toSec(), e.what());
      diag_.dropped("clusters that cannot be located");
    }
  }

  /// Why this pass cannot join a cycle ("" when it can): a detect pass starts one; a later pass
  /// needs the open cycle of its id, not yet ended and not full.
  std::string refusal(const cellsight::CyclePass& info) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (info.role == cellsight::CyclePass::DETECT) return "";
    const std::string name = "pass " + std::string(cellsight::passRoleName(static_cast<cellsight::PassRole>(info.role))) +
                             " of cycle '" + info.cycle_id + "'";
    if (info.role > cellsight::CyclePass::REFINE) return "unknown pass role " + std::to_string(info.role) + " of cycle '" + info.cycle_id + "'";
    if (!cycle_ || cycle_->id != info.cycle_id || cycle_->id.empty())
      return name + ": the open cycle is " + (cycle_ ? "'" + cycle_->id + "'" : "none") +
             " (a cycle starts with its detect pass; was it dropped, or scanned by another client?)";
    if (cycle_->final) return name + ": that cycle has ended (its last pass came); start a new cycle with a detect pass";
    if (cycle_->passes.size() >= kMaxPasses) return name + ": a cycle holds at most " + std::to_string(kMaxPasses) + " passes";
    return "";
  }

  /// A detect pass starts a cycle; a later pass (refusal() is empty) is located on top of the
  /// earlier ones. Throws what locating throws, the cycle left as it was.
  void addToCycle(const cellsight::CyclePass& info, cellsight::ScanPass&& pass, const std_msgs::Header& header) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (info.role == cellsight::CyclePass::DETECT) {
      cycle_ = std::make_shared<Cycle>();
      cycle_->id = info.cycle_id;
    }
    cycle_->passes.push_back(std::move(pass));
    cycle_->roles.push_back(info.role);
    try {
      cellsight::addPass(*matcher_, cycle_->passes, &cycle_->located);
    } catch (...) {  // the cycle stays as it was before this pass (none when it was its first)
      cycle_->passes.pop_back();
      cycle_->roles.pop_back();
      if (cycle_->passes.empty()) cycle_.reset();
      throw;
    }
    cycle_->final = info.last || info.cycle_id.empty();
    cycle_->header = header;
  }

  bool onLocate(cellsight::LocateObjects::Request& req, cellsight::LocateObjects::Response& res) {
    std::shared_ptr<const Cycle> cycle;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      cycle = cycle_;
    }
    using Res = cellsight::LocateObjects::Response;
    if (!cycle) {
      res.status = Res::NO_CLUSTERS;
      res.message = "no clusters received yet on " + clusters_sub_.getTopic() + ": scan first";
      return true;
    }
    for (const auto& id : req.models) {
      if (!library_->has(id)) {
        res.status = Res::UNKNOWN_MODEL;
        std::string known;
        for (const auto& k : library_->ids()) known += " " + k;
        res.message = "unknown model '" + id + "' (known:" + known + ")";
        return true;
      }
    }
    try {
      // the latest cycle's passes again, for the models asked
      fillDetections(*cycle, cellsight::locateScan(*matcher_, cycle->passes, req.models), &res.detections);
      res.status = Res::OK;
      res.message = std::to_string(res.detections.detections.size()) + " detections";
      publish(res.detections, req.models);
    } catch (const std::exception& e) {
      res.status = Res::FAILED;
      res.message = std::string("the latest clusters cannot be located: ") + e.what();
      res.detections = cellsight::DetectionArray();
    }
    return true;
  }

  /// The clusters as a pass of their scan: the camera from tf at their stamp, the light sheet
  /// when the illumination test is on; none (with the reason) without the camera's transform.
  std::optional<cellsight::ScanPass> scanPassOf(const cellsight::ClusterArray& msg, std::vector<std::string>* warnings,
                                                std::string* why) {
    Eigen::Isometry3d T_frame_camera;
    try {
      T_frame_camera = tf2::transformToEigen(
          buffer_.lookupTransform(msg.header.frame_id, camera_frame_, msg.header.stamp, ros::Duration(tf_timeout_)));
    } catch (const tf2::TransformException& e) {
      *why = "no transform " + msg.header.frame_id + " <- " + camera_frame_ + " at the scan's stamp (" + e.what() +
             "); is the calibration published?";
      return std::nullopt;
    }
    cellsight::ScanPass pass = cellsight_ros::toScanPass(msg, T_frame_camera.translation().cast<float>(), warnings);
    if (matcher_->config().check_illumination) {
      std::unique_ptr<cellsight::LightSweep> light = sweepFor(msg, warnings);
      if (light) pass.evidence.light = std::move(*light);
    }
    return pass;
  }

  /// `located` (the cycle's passes) as the message, named against the latest detections
  /// (a part found again where it was keeps its name).
  void fillDetections(const Cycle& cycle, const cellsight::LocatedScan& located, cellsight::DetectionArray* out) {
    const cellsight::MatchStats& stats = located.stats;
    const std::vector<cellsight::PartDetection>& dets = located.parts;
    out->header = cycle.header;
    out->clusters = static_cast<uint32_t>(cycle.passes.back().clusters.size());
    out->locate_seconds = located.passes.back().stats.seconds;
    out->cycle_id = cycle.id;
    out->passes = cycle.roles;
    out->final = cycle.final;
    diag_.processed(out->locate_seconds);
    diag_.set("parts found in the last scan", std::to_string(dets.size()));
    for (const auto& w : stats.warnings) out->warnings.push_back(w);
    // which test refused what each unexplained cluster looked most like (rosconsole debug level)
    for (const auto& line : cellsight::refusedClusters(dets, stats)) ROS_DEBUG("model_matching: %s", line.c_str());
    std::vector<cellsight::NamedInstance> current;
    for (const cellsight::PartDetection& d : dets) current.push_back({d.model, "", d.pose.translation()});
    std::vector<std::string> names;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      names = cellsight::assignInstanceNames(instances_, current, instance_max_move_);
    }
    size_t n = 0;
    for (const cellsight::PartDetection& d : dets) {
      const cellsight::Detection m = cellsight_ros::toDetectionMsg(d, names[n++]);
      if (!d.ambiguous_poses.empty())
        ROS_WARN("model_matching: %s (%s): %zu pose(s) turned about the table's normal (the first by %.0f deg, scoring %.2f of "
                 "this pose's) fit the scan about as well, so the scan cannot tell them apart; the detection carries them "
                 "(Detection.ambiguous_poses): check the part's orientation before placing it, or turn it and scan again",
                 m.name.c_str(), d.model.c_str(), d.ambiguous_poses.size(),
                 // the turn between them as the model's symmetry leaves it (the rotation does not depend on the centroid)
                 cellsight::poseError(library_->model(d.model).info, Eigen::Vector3d::Zero(), d.ambiguous_poses.front(), d.pose)
                         .rotation * 180 / M_PI,
                 d.alternative_score_share);
      out->detections.push_back(m);
    }
  }

  /// Sends a frame unless tf already has it at that stamp or later (a repeated or older stamp
  /// makes every listener warn). Called with mutex_ held.
  void sendFrame(const geometry_msgs::TransformStamped& t) {
    ros::Time& last = last_sent_[t.child_frame_id];
    if (t.header.stamp <= last) return;
    last = t.header.stamp;
    broadcaster_.sendTransform(t);
  }

  /// The latest detections' frames again, stamped now: tf keeps them while nothing new is scanned.
  void onFrameTimer(const ros::TimerEvent&) {
    std::lock_guard<std::mutex> lock(mutex_);
    const ros::Time now = ros::Time::now();
    for (geometry_msgs::TransformStamped t : frames_) {
      t.header.stamp = std::max(now, t.header.stamp);
      sendFrame(t);
    }
  }

  /// `models`: the models this result was searched for (empty: all); the instances and frames of
  /// the others stay as they were.
  void publish(const cellsight::DetectionArray& out, const std::vector<std::string>& models = {}) {
    detections_pub_.publish(out);
    std::vector<cellsight::NamedInstance> instances;
    std::vector<geometry_msgs::TransformStamped> frames;
    if (!models.empty()) {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto searched = [&](const std::string& m) { return std::find(models.begin(), models.end(), m) != models.end(); };
      for (const auto& i : instances_) {
        if (searched(i.model)) continue;
        instances.push_back(i);
        for (const auto& f : frames_)
          if (f.child_frame_id == i.name) frames.push_back(f);
      }
    }
    visualization_msgs::MarkerArray markers;
    visualization_msgs::Marker clear;
    clear.action = visualization_msgs::Marker::DELETEALL;
    markers.markers.push_back(clear);
    int id = 0;
    for (const auto& d : out.detections) {
      geometry_msgs::TransformStamped t;
      t.header = out.header;
      t.child_frame_id = d.name;
      t.transform.translation.x = d.pose.position.x;
      t.transform.translation.y = d.pose.position.y;
      t.transform.translation.z = d.pose.position.z;
      t.transform.rotation = d.pose.orientation;
      frames.push_back(t);
      instances.push_back({d.model, d.name, Eigen::Vector3d(d.pose.position.x, d.pose.position.y, d.pose.position.z)});
      visualization_msgs::Marker m;
      m.header = out.header;
      m.ns = "detections";
      m.id = id++;
      // the mesh's triangles (a MESH_RESOURCE goes through rviz's assimp loader); a cloud model: a 1 cm ball
      const cellsight::TriangleMesh& mesh = library_->model(d.model).mesh;
      m.type = mesh.faces.empty() ? visualization_msgs::Marker::SPHERE : visualization_msgs::Marker::TRIANGLE_LIST;
      m.points = cellsight_ros::meshTriangles(mesh);
      m.pose = d.pose;
      m.scale.x = m.scale.y = m.scale.z = mesh.faces.empty() ? 0.01 : 1.0;
      m.color.r = 0.9f;  // magenta: no other marker of the cell's rviz view is (scripts/rviz-shot.sh counts it)
      m.color.g = 0.1f;
      m.color.b = 0.8f;
      m.color.a = 0.9f;
      markers.markers.push_back(m);
      ROS_INFO("model_matching: %s = %s at (%.4f, %.4f, %.4f), fitness %.2f, coverage %.2f, rmse %.3f mm", d.name.c_str(),
               d.model.c_str(), d.pose.position.x, d.pose.position.y, d.pose.position.z, d.fitness, d.coverage,
               d.rmse * 1e3);
    }
    markers_pub_.publish(markers);
    {
      // at the scan's stamp (exact-time lookups), then at once at `now` too, so a lookup of the
      // latest pose does not return the previous result until the next timer tick
      std::lock_guard<std::mutex> lock(mutex_);
      const ros::Time now = ros::Time::now();
      for (geometry_msgs::TransformStamped t : frames) {
        sendFrame(t);
        t.header.stamp = std::max(now, t.header.stamp);
        sendFrame(t);
      }
      instances_ = std::move(instances);
      frames_ = std::move(frames);
    }
    for (const auto& w : out.warnings) ROS_WARN("model_matching: %s", w.c_str());
    ROS_INFO("model_matching: %zu parts located in %u clusters in %.3f s", out.detections.size(), out.clusters,
             out.locate_seconds);
    if (!output_file_.empty()) {
      try {
        cellsight::writeFileAtomic(output_file_, cellsight_ros::detectionsToJson(out).dump(2) + "\n");
      } catch (const std::exception& e) {
        ROS_ERROR("model_matching: cannot write %s: %s", output_file_.c_str(), e.what());
      }
    }
  }

  cellsight_ros::NodeDiagnostics diag_;
  std::shared_ptr<const cellsight::ModelLibrary> library_;
  cellsight::MatchingConfig config_;
  std::unique_ptr<cellsight::ModelMatcher> matcher_;
  std::string camera_frame_ = "scanner_camera_optical";
  std::string output_file_;
  double tf_timeout_ = 0.5;
  double instance_max_move_ = 0.05;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<cellsight::MatchingAcceptanceConfig>> reconfigure_;  // m: a part found again within this keeps its name
  std::vector<cellsight::NamedInstance> instances_;     // the latest detections, for naming
  std::vector<geometry_msgs::TransformStamped> frames_;  // and their tf frames, re-published
  ros::Timer frame_timer_;
  std::map<std::string, ros::Time> last_sent_;  // per frame: the newest stamp sent to tf
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  tf2_ros::TransformBroadcaster broadcaster_;
  ros::Publisher detections_pub_, markers_pub_;
  ros::Subscriber clusters_sub_, sweep_sub_, pass_sub_;
  std::vector<cellsight::LaserSweepConstPtr> sweeps_;  // the latest few, oldest first
  std::vector<cellsight::CyclePassConstPtr> pass_infos_;  // the same for scan/pass
  ros::ServiceServer service_;
  std::mutex mutex_;
  std::shared_ptr<Cycle> cycle_;  // the latest cycle's passes (guarded by mutex_; callbacks are serial)
};

}  // namespace

CELLSIGHT_NODE(ModelMatching, "model_matching", 1)
