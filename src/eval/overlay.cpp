#include "cellsight/eval/overlay.hpp"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace cellsight {

cv::Mat drawDetectionOverlay(const ScanCloud& scene, const std::vector<Eigen::Vector3f>& model_points,
                             const Eigen::Isometry3f* pose, int width) {
  float zs = 0;
  for (const auto& p : scene.points) zs += p.z();
  const float dir = zs < 0 ? -1.f : 1.f;
  Eigen::AlignedBox2f box;
  auto proj = [&](const Eigen::Vector3f& p) { return Eigen::Vector2f(p.x() / (dir * p.z()), p.y() / (dir * p.z())); };
  for (const auto& p : scene.points)
    if (dir * p.z() > 0) box.extend(proj(p));
  if (box.isEmpty()) box.extend(Eigen::Vector2f::Zero());
  const float sx = (width - 20) / std::max(1e-6f, box.sizes().x());
  const int height = std::clamp(static_cast<int>(box.sizes().y() * sx) + 20, 20, 4 * width);
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  auto pix = [&](const Eigen::Vector3f& p) {
    const Eigen::Vector2f u = proj(p);
    return cv::Point(10 + static_cast<int>((u.x() - box.min().x()) * sx),
                     height - 10 - static_cast<int>((u.y() - box.min().y()) * sx));
  };
  for (const auto& p : scene.points)
    if (dir * p.z() > 0) cv::circle(img, pix(p), 1, cv::Scalar(150, 150, 150), -1);
  if (pose) {
    for (const auto& m : model_points) {
      const Eigen::Vector3f p = *pose * m;
      if (dir * p.z() > 0) cv::circle(img, pix(p), 1, cv::Scalar(30, 30, 220), -1);
    }
  }
  return img;
}

}  // namespace cellsight
