// libFuzzer target: the messages the nodes receive, through the conversions they use
// (src/ros/conversions.cpp): PointCloud2 → fromCloudMsg (clustering, model_matching),
// Image → fromImageMsg (triangulation, camera_trigger, scanner_calibration), CameraInfo →
// fromCameraInfo (triangulation, laser_plane_tracker), LaserSweep → fromLaserSweepMsg
// (model_matching) and the sweep's emitterFor as the fitness asks it. The input is decoded field by field, so
// every size, offset, step and count a publisher controls is the fuzzer's; the byte payload is
// the input's tail. A clean rejection is std::invalid_argument.
#include <fuzzer/FuzzedDataProvider.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>

#include "cellsight/localization/light_sweep.hpp"
#include "cellsight_ros/conversions.hpp"

namespace {

std::string pick(FuzzedDataProvider& in, std::initializer_list<const char*> names) {
  const size_t i = in.ConsumeIntegralInRange<size_t>(0, names.size());
  if (i == names.size()) return in.ConsumeRandomLengthString(16);
  return *(names.begin() + i);
}

void cloud(FuzzedDataProvider& in) {
  sensor_msgs::PointCloud2 m;
  m.height = in.ConsumeIntegral<uint32_t>();
  m.width = in.ConsumeIntegral<uint32_t>();
  m.point_step = in.ConsumeIntegral<uint32_t>();
  m.row_step = in.ConsumeIntegral<uint32_t>();
  m.is_bigendian = in.ConsumeIntegral<uint8_t>();
  m.is_dense = in.ConsumeIntegral<uint8_t>();
  const int n = in.ConsumeIntegralInRange<int>(0, 8);
  for (int i = 0; i < n; ++i) {
    sensor_msgs::PointField f;
    f.name = pick(in, {"x", "y", "z", "intensity", "normal_x", "normal_y", "normal_z", "rgb"});
    f.offset = in.ConsumeIntegral<uint32_t>();
    f.datatype = in.ConsumeIntegral<uint8_t>();
    f.count = in.ConsumeIntegral<uint32_t>();
    m.fields.push_back(f);
  }
  m.data = in.ConsumeRemainingBytes<uint8_t>();
  size_t dropped = 0;
  const cellsight::ScanCloud c = cellsight_ros::fromCloudMsg(m, &dropped);
  if (c.points.size() + dropped > static_cast<size_t>(m.width) * m.height) abort();  // more points than the message holds
}

void image(FuzzedDataProvider& in) {
  sensor_msgs::Image m;
  m.height = in.ConsumeIntegral<uint32_t>();
  m.width = in.ConsumeIntegral<uint32_t>();
  m.step = in.ConsumeIntegral<uint32_t>();
  m.is_bigendian = in.ConsumeIntegral<uint8_t>();
  m.encoding = pick(in, {"mono8", "rgb8", "bgr8", "mono16", "rgba8", "bayer_rggb8", "32FC1"});
  m.data = in.ConsumeRemainingBytes<uint8_t>();
  const cv::Mat img = cellsight_ros::fromImageMsg(m);
  // every byte of the view is read, as the line extractor would
  volatile double s = cv::sum(img)[0];
  (void)s;
}

void cameraInfo(FuzzedDataProvider& in) {
  sensor_msgs::CameraInfo m;
  m.height = in.ConsumeIntegral<uint32_t>();
  m.width = in.ConsumeIntegral<uint32_t>();
  m.distortion_model = pick(in, {"plumb_bob", "rational_polynomial", "equidistant"});
  const int nd = in.ConsumeIntegralInRange<int>(0, 16);
  for (int i = 0; i < nd; ++i) m.D.push_back(in.ConsumeFloatingPoint<double>());
  for (auto& v : m.K) v = in.ConsumeFloatingPoint<double>();
  for (auto& v : m.R) v = in.ConsumeFloatingPoint<double>();
  for (auto& v : m.P) v = in.ConsumeFloatingPoint<double>();
  m.binning_x = in.ConsumeIntegral<uint32_t>();
  m.binning_y = in.ConsumeIntegral<uint32_t>();
  cellsight_ros::fromCameraInfo(m);
}

void laserSweep(FuzzedDataProvider& in) {
  cellsight::LaserSweep m;
  const int n = in.ConsumeIntegralInRange<int>(0, 64);
  const bool same_length = in.ConsumeBool();
  for (int i = 0; i < n; ++i) {
    geometry_msgs::Point e;
    e.x = in.ConsumeFloatingPoint<double>();
    e.y = in.ConsumeFloatingPoint<double>();
    e.z = in.ConsumeFloatingPoint<double>();
    geometry_msgs::Vector3 v;
    v.x = in.ConsumeFloatingPoint<double>();
    v.y = in.ConsumeFloatingPoint<double>();
    v.z = in.ConsumeFloatingPoint<double>();
    if (in.ConsumeBool()) v.z = std::sqrt(std::max(0.0, 1.0 - v.x * v.x - v.y * v.y));  // often unit
    m.emitters.push_back(e);
    m.normals.push_back(v);
    if (same_length || in.ConsumeBool()) m.offsets.push_back(in.ConsumeFloatingPoint<double>());
  }
  const cellsight::LightSweep s = cellsight_ros::fromLaserSweepMsg(m);
  if (s.size() != m.emitters.size()) abort();  // a frame dropped without a refusal
  while (in.remaining_bytes() >= 3 * sizeof(float)) {
    const Eigen::Vector3f p(in.ConsumeFloatingPoint<float>(), in.ConsumeFloatingPoint<float>(),
                            in.ConsumeFloatingPoint<float>());
    Eigen::Vector3f e;
    s.emitterFor(p, &e);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  try {
    switch (in.ConsumeIntegralInRange<int>(0, 3)) {
      case 0: cloud(in); break;
      case 1: image(in); break;
      case 2: cameraInfo(in); break;
      default: laserSweep(in);
    }
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
