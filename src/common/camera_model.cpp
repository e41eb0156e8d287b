#include "cellsight/common/camera_model.hpp"

#include <cmath>
#include <iomanip>
#include <sstream>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

Eigen::Vector2d CameraIntrinsics::distortNormalized(const Eigen::Vector2d& xn) const {
  const double x = xn.x(), y = xn.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + dist[0] * r2 + dist[1] * r2 * r2 + dist[4] * r2 * r2 * r2;
  const double xd = x * radial + 2 * dist[2] * x * y + dist[3] * (r2 + 2 * x * x);
  const double yd = y * radial + dist[2] * (r2 + 2 * y * y) + 2 * dist[3] * x * y;
  return {fx * xd + cx, fy * yd + cy};
}

Eigen::Vector2d CameraIntrinsics::project(const Eigen::Vector3d& p) const {
  return distortNormalized({p.x() / p.z(), p.y() / p.z()});
}

Eigen::Vector2d CameraIntrinsics::undistortPixel(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d xd((pixel.x() - cx) / fx, (pixel.y() - cy) / fy);
  Eigen::Vector2d x = xd;
  // Gauss-Newton on distort(x) = pixel with the analytic Jacobian; a few steps suffice.
  for (int it = 0; it < 20; ++it) {
    const double r2 = x.squaredNorm();
    const double radial = 1 + dist[0] * r2 + dist[1] * r2 * r2 + dist[4] * r2 * r2 * r2;
    const double dradial = dist[0] + 2 * dist[1] * r2 + 3 * dist[4] * r2 * r2;  // d/d(r2)
    const double px = x.x(), py = x.y();
    Eigen::Vector2d f(px * radial + 2 * dist[2] * px * py + dist[3] * (r2 + 2 * px * px),
                      py * radial + dist[2] * (r2 + 2 * py * py) + 2 * dist[3] * px * py);
    Eigen::Matrix2d J;
    J(0, 0) = radial + px * dradial * 2 * px + 2 * dist[2] * py + dist[3] * 6 * px;
    J(0, 1) = px * dradial * 2 * py + 2 * dist[2] * px + dist[3] * 2 * py;
    J(1, 0) = py * dradial * 2 * px + dist[2] * 2 * px + 2 * dist[3] * py;
    J(1, 1) = radial + py * dradial * 2 * py + dist[2] * 6 * py + 2 * dist[3] * px;
    const Eigen::Vector2d step = J.partialPivLu().solve(f - xd);
    x -= step;
    if (step.squaredNorm() < 1e-30) break;
  }
  return x;
}

Eigen::Vector3d CameraIntrinsics::pixelRay(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d x = undistortPixel(pixel);
  return Eigen::Vector3d(x.x(), x.y(), 1.0).normalized();
}

void CameraIntrinsics::validate(const std::string& where) const {
  if (width <= 0 || height <= 0) throw ConfigError(where + ": image size must be positive");
  // a bound on what one image may cost (undistortion maps, frames): sides and pixels
  if (width > kMaxImageSide || height > kMaxImageSide ||
      static_cast<int64_t>(width) * height > kMaxImagePixels) {
    throw ConfigError(where + ": image size " + std::to_string(width) + "x" + std::to_string(height) +
                      " is over the limit of " + std::to_string(kMaxImageSide) + " px a side and " +
                      std::to_string(kMaxImagePixels / 1000000) + " MP");
  }
  if (!(fx > 0) || !(fy > 0)) throw ConfigError(where + ": focal lengths must be positive");
  if (!std::isfinite(cx) || !std::isfinite(cy)) {
    throw ConfigError(where + ": principal point must be finite");
  }
  for (double d : dist) {
    if (!std::isfinite(d)) throw ConfigError(where + ": distortion coefficients must be finite");
  }
}

namespace {
std::vector<double> matrixData(const YamlMap& m, const std::string& key, int rows, int cols) {
  YamlMap mat = m.getMap(key);
  if (mat.getInt("rows") != rows || mat.getInt("cols") != cols) {
    m.fail(key, "must be a " + std::to_string(rows) + "x" + std::to_string(cols) + " matrix");
  }
  auto data = mat.getDoubles("data", static_cast<size_t>(rows * cols));
  mat.finish();
  return data;
}
}  // namespace

namespace {

CameraIntrinsics parseCameraInfoYaml(const YAML::Node& root, const std::string& path) {
  YamlMap m(root, path);
  CameraIntrinsics cam;
  cam.camera_name = m.getString("camera_name", "camera");
  cam.width = m.getInt("image_width");
  cam.height = m.getInt("image_height");
  auto K = matrixData(m, "camera_matrix", 3, 3);
  cam.fx = K[0];
  cam.fy = K[4];
  cam.cx = K[2];
  cam.cy = K[5];
  const std::string model = m.getString("distortion_model", "plumb_bob");
  if (model != "plumb_bob" && model != "rational_polynomial") {
    m.fail("distortion_model", "'" + model + "' is not supported (use plumb_bob)");
  }
  YamlMap d = m.getMap("distortion_coefficients");
  const int cols = d.getInt("cols");
  d.getInt("rows");
  auto dd = d.getDoubles("data", static_cast<size_t>(cols));
  d.finish();
  if (cols < 4) m.fail("distortion_coefficients", "needs at least 4 coefficients (k1 k2 p1 p2)");
  for (int i = 0; i < 5 && i < cols; ++i) cam.dist[i] = dd[i];
  if (m.has("rectification_matrix")) matrixData(m, "rectification_matrix", 3, 3);
  if (m.has("projection_matrix")) matrixData(m, "projection_matrix", 3, 4);
  m.finish();
  cam.validate(path);
  return cam;
}

}  // namespace

CameraIntrinsics loadCameraInfoYaml(const std::string& path) { return parseCameraInfoYaml(loadYamlFile(path), path); }

std::string cameraInfoYaml(const CameraIntrinsics& c) {
  YAML::Emitter name;  // quoted where YAML needs it: a name never becomes structure
  name << c.camera_name;
  std::ostringstream s;
  s << std::setprecision(17);
  s << "image_width: " << c.width << "\nimage_height: " << c.height
    << "\ncamera_name: " << name.c_str() << "\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: ["
    << c.fx << ", 0, " << c.cx << ", 0, " << c.fy << ", " << c.cy << ", 0, 0, 1]\n"
    << "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n  data: ["
    << c.dist[0] << ", " << c.dist[1] << ", " << c.dist[2] << ", " << c.dist[3] << ", "
    << c.dist[4] << "]\n"
    << "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n"
    << "projection_matrix:\n  rows: 3\n  cols: 4\n  data: [" << c.fx << ", 0, " << c.cx
    << ", 0, 0, " << c.fy << ", " << c.cy << ", 0, 0, 0, 1, 0]\n";
  return s.str();
}

void saveCameraInfoYaml(const std::string& path, const CameraIntrinsics& cam) {
  const std::string text = cameraInfoYaml(cam);
  parseCameraInfoYaml(YAML::Load(text), path);  // what its loader would refuse is never written
  writeFileAtomic(path, text);
}

}  // namespace cellsight
