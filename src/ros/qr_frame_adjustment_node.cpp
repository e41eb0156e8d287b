// qr_frame_adjustment: the stationary fixture camera reads which QR fixtures lie on the table and
// where; the robot program's user frame (UCS) follows each fixture (thesis ch. 4).
//   in:  fixture_camera/image_raw + camera_info (intrinsics from ~camera_file when set, as a
//        driver's camera_info_url), tf base ← camera optical frame at the image's stamp
//   out: ~fixtures (cellsight/FixtureArray), tf fixture/<id> and ucs/<program>, ~markers,
//        ~adjust (AdjustFixtures: detect now), ~teach (TeachFixture: store a program's UCS in
//        ~teach_file, by default $ROS_HOME/cellsight/fixtures_taught.yaml, checked and written
//        atomically; a taught file that loads replaces ~registry at start)
// A fixture not seen in the latest image keeps its last good pose, marked stale. An image
// without its camera pose in tf is dropped with a log (never read with an identity).
#include <geometry_msgs/TransformStamped.h>
#include <image_transport/image_transport.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <opencv2/imgproc.hpp>

#include <chrono>
#include <condition_variable>
#include <map>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>

#include "cellsight/AdjustFixtures.h"
#include "cellsight/FixtureArray.h"
#include "cellsight/TeachFixture.h"
#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/fixtures/fixture_adjustment.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/params.hpp"

namespace {

nlohmann::json poseJson(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return {{"xyz", {T.translation().x(), T.translation().y(), T.translation().z()}}, {"quat", {q.x(), q.y(), q.z(), q.w()}}};
}

class QrFrameAdjustment {
 public:
  QrFrameAdjustment(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "qr_frame_adjustment", "images"), listener_(buffer_) {
    registry_file_ = cellsight_ros::requireParam<std::string>(pnh, "registry", "the fixture registry, config/fixtures.yaml");
    registry_ = cellsight::loadFixtureRegistry(registry_file_);
    // taught user frames go to the user's folder, never into the package's registry; a taught
    // copy that loads replaces the registry at start, one that does not is named and left out
    teach_file_ = cellsight_ros::rosHomePath("cellsight/fixtures_taught.yaml");
    cellsight_ros::param(pnh, "teach_file", teach_file_);
    if (teach_file_.empty()) throw std::runtime_error("~teach_file is not set and neither $ROS_HOME nor $HOME is");
    if (teach_file_ != registry_file_ && std::ifstream(teach_file_).good()) {
      try {
        registry_ = cellsight::loadFixtureRegistry(teach_file_);
        ROS_INFO("qr_frame_adjustment: the taught registry %s is in use (delete it to start again from %s)",
                 teach_file_.c_str(), registry_file_.c_str());
      } catch (const std::exception& e) {
        ROS_ERROR("qr_frame_adjustment: the taught registry cannot be used, %s is: %s", registry_file_.c_str(), e.what());
      }
    }
    std::string camera_file, pose = "table", method = "visp";
    cellsight_ros::param(pnh, "camera_file", camera_file);
    cellsight_ros::param(pnh, "pose", pose);
    cellsight_ros::param(pnh, "free_method", method);
    cellsight_ros::param(pnh, "corner_sigma_px", config_.corner_sigma_px);
    cellsight_ros::param(pnh, "max_reprojection_px", config_.max_reprojection_px);
    cellsight_ros::param(pnh, "tf_timeout", tf_timeout_);
    cellsight_ros::param(pnh, "output_file", output_file_);
    if (pose != "table" && pose != "free") throw std::runtime_error("~pose must be 'table' or 'free', not '" + pose + "'");
    config_.table_constrained = pose == "table";
    config_.free_method = cellsight::parseCodePoseMethod(method);
    if (!camera_file.empty()) {
      camera_ = cellsight::loadCameraInfoYaml(camera_file);
      camera_from_file_ = true;
    }
    cellsight::QrDetectorConfig dc;
    dc.expected_codes = 0;
    for (const auto& f : registry_.fixtures) dc.expected_codes += static_cast<int>(f.codes.size());
    registry_codes_ = dc.expected_codes;
    cellsight_ros::param(pnh, "full_search_every", full_search_every_);
    detector_ = std::make_unique<cellsight::QrDetector>(dc);
    fixtures_pub_ = pnh.advertise<cellsight::FixtureArray>("fixtures", 1, true);
    markers_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("markers", 1, true);
    // images on a queue and thread of their own: requests waiting for an image never hold the
    // thread that would process it
    image_nh_ = nh;
    image_nh_.setCallbackQueue(&image_queue_);
    image_it_ = std::make_unique<image_transport::ImageTransport>(image_nh_);
    image_sub_ = image_it_->subscribeCamera("fixture_camera/image_raw", 1, &QrFrameAdjustment::onImage, this);
    image_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &image_queue_);
    image_spinner_->start();
    adjust_srv_ = pnh.advertiseService("adjust", &QrFrameAdjustment::onAdjust, this);
    teach_srv_ = pnh.advertiseService("teach", &QrFrameAdjustment::onTeach, this);
    frame_timer_ = nh.createTimer(ros::Duration(0.5), [this](const ros::TimerEvent&) { republish(); });
    ROS_INFO("qr_frame_adjustment: %zu fixture types from %s, %s pose, intrinsics from %s", registry_.fixtures.size(),
             registry_file_.c_str(), pose.c_str(), camera_from_file_ ? camera_file.c_str() : "camera_info");
  }

  ~QrFrameAdjustment() {  // the image thread and subscription go before the queue they use
    if (image_spinner_) image_spinner_->stop();
    image_sub_.shutdown();
  }

 private:
  void onImage(const sensor_msgs::ImageConstPtr& image, const sensor_msgs::CameraInfoConstPtr& info) {
    const auto t0 = std::chrono::steady_clock::now();
    cellsight::CameraIntrinsics cam;
    cv::Mat img;
    try {
      cam = camera_from_file_ ? camera_ : cellsight_ros::fromCameraInfo(*info);
      img = cellsight_ros::fromImageMsg(*image);
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(5, "qr_frame_adjustment: image dropped: %s", e.what());
      diag_.dropped("bad image or camera_info");
      return;
    }
    if (img.cols != cam.width || img.rows != cam.height) {
      ROS_ERROR_THROTTLE(5, "qr_frame_adjustment: image is %dx%d but the intrinsics are for %dx%d; image dropped (check ~camera_file)",
                         img.cols, img.rows, cam.width, cam.height);
      diag_.dropped("image size differs from the intrinsics");
      return;
    }
    if (img.type() == CV_8UC3) cv::cvtColor(img, img, cv::COLOR_RGB2GRAY);
    cellsight::FixtureRegistry registry;  // ~teach may replace registry_ meanwhile
    {
      std::lock_guard<std::mutex> lock(mutex_);
      registry = registry_;
    }
    Eigen::Isometry3d T_base_camera;
    try {
      T_base_camera = tf2::transformToEigen(buffer_.lookupTransform(registry.base_frame, image->header.frame_id,
                                                                    image->header.stamp, ros::Duration(tf_timeout_)));
    } catch (const tf2::TransformException& e) {
      ROS_ERROR_THROTTLE(5, "qr_frame_adjustment: image dropped: no transform %s <- %s at its stamp (%s); is the fixture camera calibrated (calibration_dir/fixture_camera_pose.yaml)?",
                         registry.base_frame.c_str(), image->header.frame_id.c_str(), e.what());
      diag_.dropped("no tf at the image stamp");
      std::lock_guard<std::mutex> lock(mutex_);
      last_status_ = cellsight::AdjustFixtures::Response::NO_TRANSFORM;
      last_message_ = std::string("no transform for the fixture camera: ") + e.what();
      last_stamp_ = image->header.stamp;
      ++frames_;
      cv_.notify_all();
      return;
    }
    cellsight::AdjustmentResult result;
    try {
      // The wider passes (whole frame, enlarged, wechat_qrcode) run while fewer codes are found
      // than were seen in the last image, on every ~full_search_every-th image and for an
      // ~adjust request; otherwise absent fixtures would cost them on every image.
      int expected = std::max(1, last_codes_);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (full_search_pending_ || full_search_every_ <= 1 || images_ % static_cast<uint64_t>(full_search_every_) == 0) {
          expected = registry_codes_;
        }
        full_search_pending_ = false;
        ++images_;
      }
      const auto detections = detector_->detect(img, &cam, expected);
      last_codes_ = static_cast<int>(detections.size());
      result = cellsight::adjustFixtures(detections, registry, cam, T_base_camera, config_);
      for (const auto& inst : result.fixtures)
        if (!inst.T_base_fixture.matrix().allFinite() || !inst.T_base_ucs.matrix().allFinite() ||
            !inst.T_base_ucs_free.matrix().allFinite())
          throw std::runtime_error("fixture " + inst.id + ": a pose is not finite (check its ucs in the registry)");
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(5, "qr_frame_adjustment: image dropped: %s", e.what());
      diag_.dropped("detection failed");
      return;
    }
    for (const auto& m : result.messages) ROS_WARN_THROTTLE(10, "qr_frame_adjustment: %s", m.c_str());
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (auto& [id, f] : state_) f.stale = true;
      for (const auto& inst : result.fixtures) {
        cellsight::Fixture f;
        f.id = inst.id;
        f.type = inst.type;
        f.program = inst.program;
        f.fixture = cellsight_ros::toPoseMsg(inst.T_base_fixture);
        f.ucs = cellsight_ros::toPoseMsg(inst.T_base_ucs);
        f.ucs_free = cellsight_ros::toPoseMsg(inst.T_base_ucs_free);
        f.markers = inst.inliers;
        f.rms_px = inst.rms_px;
        f.sigma_translation = inst.sigma_translation;
        f.sigma_yaw = inst.sigma_yaw;
        f.stale = false;
        f.last_seen = image->header.stamp;
        state_[inst.id] = f;
      }
      latest_.header.stamp = image->header.stamp;
      latest_.header.frame_id = registry_.base_frame;
      latest_.fixtures.clear();
      for (const auto& [id, f] : state_) latest_.fixtures.push_back(f);
      latest_.messages = result.messages;
      last_status_ = result.fixtures.empty() ? cellsight::AdjustFixtures::Response::NO_FIXTURE
                                             : cellsight::AdjustFixtures::Response::OK;
      last_message_ = std::to_string(result.fixtures.size()) + " fixture(s) in the image" +
                      (result.messages.empty() ? "" : "; " + result.messages.front());
      last_stamp_ = image->header.stamp;
      ++frames_;
    }
    cv_.notify_all();
    fixtures_pub_.publish(latest_);
    republish();
    writeOutput();
    diag_.processed(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }

  std::string ucsFrame(const cellsight::Fixture& f) const {
    return "ucs/" + f.program + (f.id == f.type ? "" : f.id.substr(f.type.size()));
  }

  void republish() {
    std::vector<geometry_msgs::TransformStamped> frames;
    visualization_msgs::MarkerArray markers;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      int k = 0;
      for (const auto& [id, f] : state_) {
        for (const auto& [child, pose] : {std::pair<std::string, geometry_msgs::Pose>{"fixture/" + id, f.fixture},
                                          {ucsFrame(f), f.ucs}}) {
          geometry_msgs::TransformStamped t;
          t.header.stamp = ros::Time::now();
          t.header.frame_id = registry_.base_frame;
          t.child_frame_id = child;
          t.transform.translation.x = pose.position.x;
          t.transform.translation.y = pose.position.y;
          t.transform.translation.z = pose.position.z;
          t.transform.rotation = pose.orientation;
          frames.push_back(t);
        }
        visualization_msgs::Marker m;
        m.header.frame_id = registry_.base_frame;
        m.header.stamp = ros::Time::now();
        m.ns = "ucs";
        m.id = k++;
        m.type = visualization_msgs::Marker::ARROW;
        m.pose = f.ucs;
        m.scale.x = 0.05;
        m.scale.y = m.scale.z = 0.005;
        m.color.r = f.stale ? 0.5f : 1.0f;
        m.color.g = f.stale ? 0.5f : 0.6f;
        m.color.a = 1.0f;
        markers.markers.push_back(m);
        m.ns = "label";
        m.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
        m.text = id + ": " + f.program + (f.stale ? " (stale)" : "");  // ASCII: rviz's text markers crash on UTF-8
        m.scale.z = 0.015;
        m.pose.position.z += 0.02;
        markers.markers.push_back(m);
      }
    }
    if (!frames.empty()) broadcaster_.sendTransform(frames);
    if (!markers.markers.empty()) markers_pub_.publish(markers);
  }

  void writeOutput() {
    if (output_file_.empty()) return;
    nlohmann::json list = nlohmann::json::array();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& f : latest_.fixtures) {
        list.push_back({{"id", f.id}, {"type", f.type}, {"program", f.program}, {"markers", f.markers},
                        {"stale", static_cast<bool>(f.stale)},
                        {"ucs", poseJson(cellsight_ros::fromPoseMsg(f.ucs))},
                        {"ucs_free", poseJson(cellsight_ros::fromPoseMsg(f.ucs_free))},
                        {"fixture", poseJson(cellsight_ros::fromPoseMsg(f.fixture))},
                        {"rms_px", f.rms_px}, {"sigma_translation", f.sigma_translation}, {"sigma_yaw", f.sigma_yaw}});
      }
    }
    try {
      cellsight::writeFileAtomic(output_file_, nlohmann::json({{"pose", config_.table_constrained ? "table" : "free"},
                                                                {"fixtures", list}}).dump(2) + "\n");
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(10, "qr_frame_adjustment: cannot write %s: %s", output_file_.c_str(), e.what());
    }
  }

  bool onAdjust(cellsight::AdjustFixtures::Request& req, cellsight::AdjustFixtures::Response& res) {
    // an image taken after the request: one already being processed when it came may show the
    // table before the fixture was put down
    const ros::Time asked = ros::Time::now();
    std::unique_lock<std::mutex> lock(mutex_);
    if (adjust_waiting_ >= kMaxAdjustWaiting) {
      res.status = res.BUSY;
      res.message = std::to_string(adjust_waiting_) + " adjust requests wait for an image already: ask again after them";
      return true;
    }
    full_search_pending_ = true;  // the next image gets every pass
    const double timeout = req.timeout > 0 ? std::min(req.timeout, 10.0) : 5.0;
    ++adjust_waiting_;
    struct Done {
      int& n;
      ~Done() { --n; }
    } done{adjust_waiting_};  // under mutex_: the wait below re-locks it before returning
    if (!cv_.wait_for(lock, std::chrono::duration<double>(timeout), [&] { return frames_ > 0 && last_stamp_ >= asked; })) {
      res.status = res.NO_IMAGE;
      res.message = "no fixture camera image within " + std::to_string(timeout) + " s (is fixture_camera/image_raw published?)";
      return true;
    }
    res.status = last_status_;
    res.message = last_message_;
    for (const auto& f : latest_.fixtures) {
      if (f.stale) continue;
      res.fixtures.push_back(f);
      if (res.program.empty()) res.program = f.program;
    }
    return true;
  }

  bool onTeach(cellsight::TeachFixture::Request& req, cellsight::TeachFixture::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = state_.find(req.type);
    cellsight::FixtureType* type = registry_.findType(req.type);
    if (!type) {
      res.message = "fixture type '" + req.type + "' is not in " + registry_file_;
      return true;
    }
    if (it == state_.end() || it->second.stale) {
      res.message = "fixture '" + req.type + "' is not in the latest image: put it in the fixture camera's view first";
      return true;
    }
    const Eigen::Isometry3d T_base_ucs = cellsight_ros::fromPoseMsg(req.ucs);
    if (!T_base_ucs.matrix().allFinite()) {
      res.message = "the UCS pose is not finite";
      return true;
    }
    cellsight::FixtureRegistry next = registry_;
    cellsight::FixtureType* t = next.findType(req.type);
    t->T_fixture_ucs = cellsight_ros::fromPoseMsg(it->second.fixture).inverse() * T_base_ucs;
    t->taught = cellsight::isoDateNow();
    try {
      cellsight::makeDirs(cellsight::parentDir(teach_file_));
      cellsight::saveFixtureRegistry(teach_file_, next);
    } catch (const std::exception& e) {
      res.message = std::string("cannot write the registry (kept unchanged): ") + e.what();
      return true;
    }
    registry_ = next;
    res.success = true;
    res.message = "program " + t->program + "'s user frame taught on fixture " + req.type + " and saved to " + teach_file_;
    ROS_INFO("qr_frame_adjustment: %s", res.message.c_str());
    return true;
  }

  cellsight_ros::NodeDiagnostics diag_;
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  tf2_ros::TransformBroadcaster broadcaster_;
  image_transport::CameraSubscriber image_sub_;
  ros::Publisher fixtures_pub_, markers_pub_;
  ros::ServiceServer adjust_srv_, teach_srv_;
  ros::Timer frame_timer_;
  std::string registry_file_, teach_file_, output_file_;
  cellsight::FixtureRegistry registry_;
  cellsight::FixtureAdjustmentConfig config_;
  cellsight::CameraIntrinsics camera_;
  bool camera_from_file_ = false;
  double tf_timeout_ = 0.5;
  std::unique_ptr<cellsight::QrDetector> detector_;
  std::mutex mutex_;
  std::condition_variable cv_;
  uint64_t frames_ = 0, images_ = 0;
  ros::Time last_stamp_;
  int registry_codes_ = 1, last_codes_ = 0, full_search_every_ = 10;
  bool full_search_pending_ = false;
  int adjust_waiting_ = 0;  // ~adjust requests waiting for an image (guarded by mutex_)
  static constexpr int kMaxAdjustWaiting = 2;
  ros::NodeHandle image_nh_;
  ros::CallbackQueue image_queue_;
  std::unique_ptr<image_transport::ImageTransport> image_it_;
  std::unique_ptr<ros::AsyncSpinner> image_spinner_;
  uint8_t last_status_ = cellsight::AdjustFixtures::Response::NO_IMAGE;
  std::string last_message_;
  std::map<std::string, cellsight::Fixture> state_;
  cellsight::FixtureArray latest_;
};

}  // namespace

// four threads: up to two ~adjust calls waiting for images, ~teach, the timer (images have their own)
CELLSIGHT_NODE(QrFrameAdjustment, "qr_frame_adjustment", 4)
