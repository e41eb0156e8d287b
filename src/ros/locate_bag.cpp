// cellsight_locate_bag: a recorded scan (a raw bag: scanner images, camera_info, /tf, /tf_static)
// located in one process by the functions the nodes run, in the nodes' order: per frame the
// light sheet from tf (laser_plane_tracker), the profile (triangulation), the scan's finish, the
// clusters as the clustering node publishes them, the cycle's passes located one by one as
// model_matching does (the passes and their roles from the Scan goals the bag recorded on
// /scan/goal; none recorded: one detect pass), named and written as model_matching writes its
// detections file. The ctests replay_equivalence and cycle_passes hold it to the nodes' result on
// the same bag. Exit 0 with detections, 3 with none, 1 on an error.
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2/buffer_core.h>
#include <tf2_msgs/TFMessage.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <memory>

#include "../tools/cli_args.hpp"
#include "cellsight/ScanActionGoal.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight/localization/instance_names.hpp"
#include "cellsight/scanner/scan_pipeline.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/scan_messages.hpp"

namespace {

struct Options {
  std::string bag, root = ".", scanner, clustering, matching, models, json, cloud;
  std::string base_frame = "base_link", laser_frame = "laser", camera_frame = "scanner_camera_optical";
  std::string image_topic = "/scanner_camera/image_raw", info_topic = "/scanner_camera/camera_info";
  std::string goal_topic = "/scan/goal";
  std::string orRoot(const std::string& v, const std::string& rel) const { return v.empty() ? root + "/" + rel : v; }
};

/// What the scanner's nodes make of the bag's frames: the finished scan, its light sweep (as
/// triangulation publishes it) and stamp.
struct RecordedScan {
  cellsight::ScanCloud cloud;
  cellsight::LightSweep light;
  ros::Time stamp;
  size_t frames = 0, dropped = 0;
};

/// Every transform of the bag, for lookups at any stamp of it.
void loadTf(const rosbag::Bag& bag, tf2::BufferCore* tf) {
  rosbag::View view(bag, rosbag::TopicQuery(std::vector<std::string>{"/tf", "/tf_static"}));
  for (const rosbag::MessageInstance& m : view) {
    const auto msg = m.instantiate<tf2_msgs::TFMessage>();
    if (!msg) continue;
    for (const auto& t : msg->transforms) tf->setTransform(t, "bag", m.getTopic() == "/tf_static");
  }
}

/// A pass of the recorded cycle: the Scan goal that started it and the frames taken after it.
struct RecordedPass {
  cellsight::ScanGoal goal;  // no goal recorded: a detect pass on its own
  std::vector<sensor_msgs::ImageConstPtr> images;
};

/// The bag's scanner frames split into the passes its Scan goals started (a frame belongs to the
/// latest goal sent before it), and the camera's undistortion from its first camera_info.
std::vector<RecordedPass> passesFromBag(const rosbag::Bag& bag, const Options& o, std::shared_ptr<cellsight::UndistortionMap>* map) {
  std::vector<sensor_msgs::ImageConstPtr> images;
  std::vector<std::pair<ros::Time, cellsight::ScanGoal>> goals;
  for (const rosbag::MessageInstance& m :
       rosbag::View(bag, rosbag::TopicQuery(std::vector<std::string>{o.info_topic, o.image_topic, o.goal_topic}))) {
    if (const auto info = m.instantiate<sensor_msgs::CameraInfo>()) {
      if (!*map) *map = std::make_shared<cellsight::UndistortionMap>(cellsight_ros::fromCameraInfo(*info));
    } else if (const auto image = m.instantiate<sensor_msgs::Image>()) {
      images.push_back(image);
    } else if (const auto goal = m.instantiate<cellsight::ScanActionGoal>()) {
      goals.emplace_back(goal->header.stamp, goal->goal);
    }
  }
  if (images.empty()) throw std::runtime_error(o.bag + ": no images on " + o.image_topic);
  if (!*map) throw std::runtime_error(o.bag + ": no camera_info on " + o.info_topic);
  std::stable_sort(images.begin(), images.end(), [](const auto& a, const auto& b) { return a->header.stamp < b->header.stamp; });
  std::stable_sort(goals.begin(), goals.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<RecordedPass> passes(std::max<size_t>(goals.size(), 1));
  std::vector<ros::Time> sent;
  for (size_t k = 0; k < goals.size(); ++k) {
    passes[k].goal = goals[k].second;
    sent.push_back(goals[k].first);
  }
  for (const auto& image : images) passes[cellsight_ros::passOfFrame(sent, image->header.stamp)].images.push_back(image);
  return passes;
}

RecordedScan scanFromBag(const std::vector<sensor_msgs::ImageConstPtr>& images, const cellsight::UndistortionMap& undistort,
                         const tf2::BufferCore& tf, const Options& o, const cellsight::ScannerSettings& settings) {
  RecordedScan out;
  out.cloud.frame_id = o.base_frame;
  Eigen::Vector3f viewpoint = Eigen::Vector3f::Zero();
  std::vector<Eigen::Isometry3d> lasers;
  for (const auto& image : images) {
    const ros::Time& t = image->header.stamp;
    try {
      // laser_plane_tracker: the sheet in the camera frame at the image's stamp, as its message carries it
      const cellsight::Plane plane = cellsight_ros::fromPlaneMsg(cellsight_ros::toPlaneMsg(
          cellsight::laserPlane(cellsight_ros::fromTransformMsg(tf.lookupTransform(image->header.frame_id, o.laser_frame, t).transform)),
          image->header.frame_id, t));
      // triangulation: the profile in the base frame, the sheet's origin for the light sweep
      const Eigen::Isometry3d T_base_camera =
          cellsight_ros::fromTransformMsg(tf.lookupTransform(o.base_frame, image->header.frame_id, t).transform);
      const Eigen::Isometry3d T_base_laser =
          cellsight_ros::fromTransformMsg(tf.lookupTransform(o.base_frame, o.laser_frame, t).transform);
      cellsight::addFrameProfile(cellsight_ros::fromImageMsg(*image), plane, T_base_camera, undistort,
                                 cellsight_ros::lineConfigFor(image->encoding, settings.line), settings.triangulation,
                                 out.cloud);
      viewpoint = T_base_camera.translation().cast<float>();
      lasers.push_back(T_base_laser);
      out.stamp = t;
      ++out.frames;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "cellsight_locate_bag: frame at %.6f dropped: %s\n", t.toSec(), e.what());
      ++out.dropped;
    }
  }
  out.cloud = cellsight::finishScan(out.cloud, settings, viewpoint);
  cellsight::LightSweep light;
  light.setFanHalfAngle(settings.laser_fan_angle / 2);
  for (const auto& T : lasers) light.addLaserFrame(T);
  // as the messages carry them to clustering and model_matching
  out.light = cellsight_ros::fromLaserSweepMsg(cellsight_ros::toLaserSweepMsg(light, o.base_frame, out.stamp));
  out.cloud = cellsight_ros::fromCloudMsg(cellsight_ros::toCloudMsg(out.cloud, out.stamp));
  return out;
}

int run(const Options& o) {
  const cellsight::ScannerSettings settings = cellsight::loadScannerSettings(o.orRoot(o.scanner, "config/scanner.yaml"));
  const cellsight::ClusteringConfig clustering = cellsight::loadClusteringConfig(o.orRoot(o.clustering, "config/clustering.yaml"));
  auto library = std::make_shared<const cellsight::ModelLibrary>(o.orRoot(o.models, "config/models"));
  const cellsight::ModelMatcher matcher(library, cellsight::loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml")));
  rosbag::Bag bag;
  bag.open(o.bag, rosbag::bagmode::Read);
  tf2::BufferCore tf(ros::Duration(std::max(10.0, (rosbag::View(bag).getEndTime() - rosbag::View(bag).getBeginTime()).toSec() + 10)));
  loadTf(bag, &tf);
  std::shared_ptr<cellsight::UndistortionMap> map;
  const std::vector<RecordedPass> recorded = passesFromBag(bag, o, &map);
  std::vector<cellsight::ScanPass> passes;
  cellsight::LocatedScan located;
  cellsight::DetectionArray out;
  std::vector<cellsight::NamedInstance> named;  // the latest detections, as model_matching names against them
  size_t frames = 0, dropped = 0, points = 0;
  for (const RecordedPass& p : recorded) {
    const RecordedScan scan = scanFromBag(p.images, *map, tf, o, settings);
    frames += scan.frames;
    dropped += scan.dropped;
    points += scan.cloud.size();
    if (scan.cloud.size() == 0) throw std::runtime_error(o.bag + ": a pass's scan is empty: no laser line in any frame");
    if (!o.cloud.empty() && passes.empty()) cellsight::saveCloud(o.cloud, scan.cloud);
    std_msgs::Header header;
    header.frame_id = o.base_frame;
    header.stamp = scan.stamp;
    const cellsight::ClusterArray clusters = cellsight_ros::toClusterArrayMsg(cellsight::clusterScene(scan.cloud, clustering), header);
    // model_matching: the camera at the clusters' stamp, the sweep when the illumination test is on
    const Eigen::Vector3f eye = cellsight_ros::fromTransformMsg(tf.lookupTransform(o.base_frame, o.camera_frame, scan.stamp).transform)
                                    .translation()
                                    .cast<float>();
    out = cellsight::DetectionArray();
    cellsight::ScanPass pass = cellsight_ros::toScanPass(clusters, eye, &out.warnings);
    pass.role = static_cast<cellsight::PassRole>(p.goal.role);
    if (matcher.config().check_illumination) pass.evidence.light = scan.light;
    passes.push_back(std::move(pass));
    cellsight::addPass(matcher, passes, &located);
    out.header = header;
    out.clusters = static_cast<uint32_t>(passes.back().clusters.size());
    out.locate_seconds = located.passes.back().stats.seconds;
    out.warnings.insert(out.warnings.end(), located.stats.warnings.begin(), located.stats.warnings.end());
    out.cycle_id = p.goal.cycle_id;
    for (const RecordedPass& q : recorded) {
      out.passes.push_back(q.goal.role);
      if (&q == &p) break;
    }
    out.final = p.goal.last_pass || p.goal.cycle_id.empty();
    std::vector<cellsight::NamedInstance> current;
    for (const auto& d : located.parts) current.push_back({d.model, "", d.pose.translation()});
    const std::vector<std::string> names = cellsight::assignInstanceNames(named, current);
    named.clear();
    for (size_t i = 0; i < located.parts.size(); ++i) {
      out.detections.push_back(cellsight_ros::toDetectionMsg(located.parts[i], names[i]));
      named.push_back({located.parts[i].model, names[i], located.parts[i].pose.translation()});
    }
  }
  if (!o.json.empty()) cellsight::writeFileAtomic(o.json, cellsight_ros::detectionsToJson(out).dump(2) + "\n");
  std::printf("cellsight_locate_bag: %zu pass(es), %zu frames (%zu dropped), %zu points, %zu parts located in %.3f s\n",
              passes.size(), frames, dropped, points, out.detections.size(), located.stats.seconds);
  for (const auto& d : out.detections)
    std::printf("  %s = %s at (%.4f, %.4f, %.4f), fitness %.2f\n", d.name.c_str(), d.model.c_str(), d.pose.position.x,
                d.pose.position.y, d.pose.position.z, d.fitness);
  return out.detections.empty() ? 3 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app("Locates a recorded scan (raw bag) in one process with the functions the cell's nodes run; writes "
               "the detections as model_matching does.",
               "cellsight_locate_bag");
  app.add_option("--bag", o.bag, "raw bag (scanner images, camera_info, /tf, /tf_static), e.g. out/demo/raw.bag")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--root", o.root, "the package folder the default settings are read from")->capture_default_str();
  app.add_option("--scanner-config", o.scanner, "scanner settings [default: <root>/config/scanner.yaml]")->check(CLI::ExistingFile);
  app.add_option("--clustering-config", o.clustering, "clustering settings [default: <root>/config/clustering.yaml]")
      ->check(CLI::ExistingFile);
  app.add_option("--matching-config", o.matching, "matching settings [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  app.add_option("--models", o.models, "model library [default: <root>/config/models]")->check(CLI::ExistingDirectory);
  app.add_option("--base-frame", o.base_frame, "the scan's frame")->capture_default_str();
  app.add_option("--laser-frame", o.laser_frame, "the light sheet's frame")->capture_default_str();
  app.add_option("--camera-frame", o.camera_frame, "the scanner camera's optical frame (the viewpoint)")->capture_default_str();
  app.add_option("--image-topic", o.image_topic, "scanner images")->capture_default_str();
  app.add_option("--info-topic", o.info_topic, "scanner camera_info")->capture_default_str();
  app.add_option("--goal-topic", o.goal_topic, "the Scan action's goals (the cycle's passes and their roles)")->capture_default_str();
  app.add_option("--json", o.json, "write the detections here (model_matching's detections file format)");
  app.add_option("--cloud", o.cloud, "write the finished scan here (.ply, .pcd)");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] { return run(o); });
}
