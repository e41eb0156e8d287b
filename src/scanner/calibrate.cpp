#include "cellsight/scanner/calibrate.hpp"

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/aruco/charuco.hpp>
#include <cstdio>
#include <map>
#include <numeric>
#include <stdexcept>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/scanner/triangulation.hpp"
#include "cellsight/common/yaml_reader.hpp"

#include <filesystem>

#include <algorithm>

namespace cellsight {

std::vector<LaserObservation> loadLaserObservations(const std::string& path) {
  YamlMap root(loadYamlFile(path), path);
  std::vector<LaserObservation> obs;
  for (const YamlMap& m : root.getMapList("observations")) {
    LaserObservation o;
    const std::string img = resolveRelative(path, m.getString("image"));
    try {
      o.image = readImage(img, cv::IMREAD_GRAYSCALE);
    } catch (const std::exception& e) {
      m.fail("image", e.what());
    }
    o.T_base_flange = m.getPose("flange_pose");
    o.plane_z = m.getDouble("plane_z", 0.0);
    o.block_z = m.getDouble("block_z", 0.0);
    m.finish();
    obs.push_back(o);
  }
  root.finish();
  if (obs.empty()) throw ConfigError(path + ": observations: the list is empty");
  return obs;
}

std::vector<std::string> listImages(const std::vector<std::string>& args) {
  namespace fs = std::filesystem;
  std::vector<std::string> out;
  for (const auto& p : args) {
    std::error_code ec;
    if (fs::is_directory(p, ec)) {
      std::vector<std::string> files;
      for (const auto& e : fs::directory_iterator(p, ec)) {
        std::string lower = e.path().filename().string();
        std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
        const auto ends = [&](const std::string& x) {
          return lower.size() > x.size() && lower.compare(lower.size() - x.size(), x.size(), x) == 0;
        };
        if (ends(".png") || ends(".jpg") || ends(".jpeg")) files.push_back(p + "/" + e.path().filename().string());
      }
      std::sort(files.begin(), files.end());
      out.insert(out.end(), files.begin(), files.end());
    } else {
      out.push_back(p);
    }
  }
  return out;
}

DistortionModel parseDistortionModel(const std::string& name) {
  if (name == "k1") return DistortionModel::kK1;
  if (name == "full") return DistortionModel::kFull;
  throw std::invalid_argument("unknown distortion model '" + name + "' (use k1 or full)");
}

ChessboardSpec::Kind ChessboardSpec::parseKind(const std::string& name) {
  if (name == "chessboard") return Kind::kChessboard;
  if (name == "circles") return Kind::kCircles;
  if (name == "acircles" || name == "asymmetric_circles") return Kind::kAsymmetricCircles;
  if (name == "charuco") return Kind::kCharuco;
  throw std::invalid_argument("unknown pattern '" + name + "' (use chessboard, circles, acircles or charuco)");
}

ChessboardSpec::Refinement ChessboardSpec::parseRefinement(const std::string& name) {
  if (name == "adaptive") return Refinement::kAdaptive;
  if (name == "fixed") return Refinement::kFixed;
  if (name == "sb") return Refinement::kSectorBased;
  throw std::invalid_argument("unknown corner refinement '" + name + "' (use adaptive, fixed or sb)");
}

namespace {

/// Smallest distance between neighbouring corners of a detected grid, px.
double smallestSquarePx(const std::vector<cv::Point2f>& c, const cv::Size& n) {
  double best = 1e9;
  for (int r = 0; r < n.height; ++r) {
    for (int k = 0; k < n.width; ++k) {
      const size_t i = static_cast<size_t>(r * n.width + k);
      if (k + 1 < n.width) best = std::min(best, static_cast<double>(cv::norm(c[i + 1] - c[i])));
      if (r + 1 < n.height) best = std::min(best, static_cast<double>(cv::norm(c[i + static_cast<size_t>(n.width)] - c[i])));
    }
  }
  return best;
}

cv::Ptr<cv::aruco::Dictionary> arucoDictionary(const std::string& name) {
  static const std::map<std::string, cv::aruco::PREDEFINED_DICTIONARY_NAME> kNames = {
      {"4x4_50", cv::aruco::DICT_4X4_50},     {"4x4_100", cv::aruco::DICT_4X4_100},
      {"4x4_250", cv::aruco::DICT_4X4_250},   {"4x4_1000", cv::aruco::DICT_4X4_1000},
      {"5x5_50", cv::aruco::DICT_5X5_50},     {"5x5_100", cv::aruco::DICT_5X5_100},
      {"5x5_250", cv::aruco::DICT_5X5_250},   {"5x5_1000", cv::aruco::DICT_5X5_1000},
      {"6x6_50", cv::aruco::DICT_6X6_50},     {"6x6_100", cv::aruco::DICT_6X6_100},
      {"6x6_250", cv::aruco::DICT_6X6_250},   {"6x6_1000", cv::aruco::DICT_6X6_1000},
      {"7x7_50", cv::aruco::DICT_7X7_50},     {"7x7_1000", cv::aruco::DICT_7X7_1000},
      {"original", cv::aruco::DICT_ARUCO_ORIGINAL}};
  const auto it = kNames.find(name);
  if (it == kNames.end()) {
    throw std::invalid_argument("unknown ArUco dictionary '" + name + "' (use e.g. 4x4_50, 5x5_100, 6x6_250, original)");
  }
  return cv::aruco::getPredefinedDictionary(it->second);
}

}  // namespace

void checkArucoDictionary(const std::string& name) { arucoDictionary(name); }

namespace {

std::vector<cv::Point3f> boardPoints(const ChessboardSpec& b) {
  std::vector<cv::Point3f> pts;
  const float s = static_cast<float>(b.square_size);
  for (int r = 0; r < b.inner_corners.height; ++r) {
    for (int c = 0; c < b.inner_corners.width; ++c) {
      const float x = b.kind == ChessboardSpec::Kind::kAsymmetricCircles ? static_cast<float>(2 * c + r % 2) * s
                                                                          : static_cast<float>(c) * s;
      pts.emplace_back(x, static_cast<float>(r) * s, 0.f);
    }
  }
  return pts;
}

}  // namespace

bool findChessboard(const cv::Mat& grey, const ChessboardSpec& board, std::vector<cv::Point2f>& corners) {
  corners.clear();
  if (board.refinement == ChessboardSpec::Refinement::kSectorBased) {
    return cv::findChessboardCornersSB(grey, board.inner_corners, corners,
                                       cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_ACCURACY);
  }
  // OpenCV's classic detector, on a copy of at most 0.4 MP: on a large image that shows only a
  // part of a board it searches for minutes (158 s on a 2 MP frame), on the copy for about 2 s.
  // Its corners are refined at full resolution.
  // Squares of a few pixels defeat the classic detector's morphology: then it runs on a 2× copy
  // (for images up to 1 MP), corners refined at full resolution all the same.
  const double down = std::min(1.0, std::sqrt(0.4e6 / static_cast<double>(grey.total())));
  std::vector<double> scales = {down};
  if (grey.total() <= 1000000) scales.push_back(2.0);
  for (const double scale : scales) {
    cv::Mat copy = grey;
    if (scale != 1.0) cv::resize(grey, copy, cv::Size(), scale, scale, scale < 1.0 ? cv::INTER_AREA : cv::INTER_CUBIC);
    if (!cv::findChessboardCorners(copy, board.inner_corners, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK)) {
      corners.clear();
      continue;
    }
    if (scale != 1.0)
      for (auto& c : corners) c = (c + cv::Point2f(0.5f, 0.5f)) * static_cast<float>(1.0 / scale) - cv::Point2f(0.5f, 0.5f);
    // The refinement window must not reach the neighbouring corners: on small squares a fixed
    // window pulls corners towards the square centres. Half-width 0.4 × the smallest square side
    // (2 … 10 px); kFixed keeps OpenCV's sample setting, winSize (11, 11): a 23 × 23 window.
    int half = 11;
    if (board.refinement == ChessboardSpec::Refinement::kAdaptive) {
      half = std::clamp(static_cast<int>(std::floor(0.4 * smallestSquarePx(corners, board.inner_corners))), 2, 10);
    }
    cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
    return true;
  }
  // A board too small in the image for the copy, or squares too small for the classic detector:
  // the sector-based detector at full resolution (bounded run time, sub-pixel corners of its own).
  corners.clear();
  if (cv::findChessboardCornersSB(grey, board.inner_corners, corners, cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_ACCURACY))
    return true;
  corners.clear();
  return false;
}

bool detectPattern(const cv::Mat& grey, const ChessboardSpec& board, PatternView& view) {
  view = PatternView{};
  switch (board.kind) {
    case ChessboardSpec::Kind::kChessboard:
    case ChessboardSpec::Kind::kCircles:
    case ChessboardSpec::Kind::kAsymmetricCircles: {
      bool found;
      if (board.kind == ChessboardSpec::Kind::kChessboard) {
        found = findChessboard(grey, board, view.image);
      } else {
        found = cv::findCirclesGrid(grey, board.inner_corners, view.image,
                                    board.kind == ChessboardSpec::Kind::kCircles ? cv::CALIB_CB_SYMMETRIC_GRID
                                                                                 : cv::CALIB_CB_ASYMMETRIC_GRID);
      }
      if (!found) return false;
      view.object = boardPoints(board);
      view.ids.resize(view.object.size());
      std::iota(view.ids.begin(), view.ids.end(), 0);
      return true;
    }
    case ChessboardSpec::Kind::kCharuco: {
      if (!(board.marker_size > 0 && board.marker_size < board.square_size)) {
        throw std::invalid_argument("ChArUco board: the marker size must be > 0 and smaller than the square size");
      }
      const auto dict = arucoDictionary(board.dictionary);
      const auto cb = cv::aruco::CharucoBoard::create(board.inner_corners.width, board.inner_corners.height,
                                                      static_cast<float>(board.square_size),
                                                      static_cast<float>(board.marker_size), dict);
      std::vector<std::vector<cv::Point2f>> marker_corners;
      std::vector<int> marker_ids;
      cv::aruco::detectMarkers(grey, dict, marker_corners, marker_ids);
      if (marker_ids.empty()) return false;
      std::vector<cv::Point2f> corners;
      std::vector<int> ids;
      cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, grey, cb, corners, ids);
      if (ids.size() < 6) return false;
      // Corners as ArUco refines them (cornerSubPix 11 × 11 inside interpolateCornersCharuco).
      view.image = corners;
      view.ids = ids;
      for (int id : ids) view.object.push_back(cb->chessboardCorners[static_cast<size_t>(id)]);
      return true;
    }
  }
  return false;
}

IntrinsicsResult calibrateIntrinsics(const std::vector<std::string>& files, const ChessboardSpec& board,
                                     DistortionModel model, bool fix_aspect_ratio) {
  IntrinsicsOptions o;
  o.model = model;
  o.fix_aspect_ratio = fix_aspect_ratio;
  return calibrateIntrinsics(files, board, o);
}

IntrinsicsResult calibrateIntrinsics(const std::vector<std::string>& files, const ChessboardSpec& board,
                                     const IntrinsicsOptions& options) {
  std::vector<std::pair<std::string, cv::Mat>> views;
  views.reserve(files.size());
  for (const auto& f : files) {
    cv::Mat img;
    try {
      img = readImage(f, cv::IMREAD_GRAYSCALE);
    } catch (const std::exception&) {
      // reported as unreadable with the rejected views (an empty image)
    }
    views.emplace_back(f, img);
  }
  return calibrateIntrinsics(views, board, options);
}

IntrinsicsResult calibrateIntrinsics(const std::vector<std::pair<std::string, cv::Mat>>& views,
                                     const ChessboardSpec& board, DistortionModel model, bool fix_aspect_ratio) {
  IntrinsicsOptions o;
  o.model = model;
  o.fix_aspect_ratio = fix_aspect_ratio;
  return calibrateIntrinsics(views, board, o);
}

namespace {

/// calibrateCamera over the detections; fills camera, rms and per-view RMS.
void solveIntrinsics(IntrinsicsResult& res, const cv::Size& size, const IntrinsicsOptions& o) {
  std::vector<std::vector<cv::Point2f>> image_points;
  std::vector<std::vector<cv::Point3f>> object_points;
  for (const auto& d : res.detections) {
    image_points.push_back(d.image);
    object_points.push_back(d.object);
  }
  int flags = 0;
  if (o.model == DistortionModel::kK1) flags |= cv::CALIB_FIX_K2 | cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
  if (o.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  cv::Mat K = cv::Mat::eye(3, 3, CV_64F), D = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  cv::Mat std_in, std_ex, per_view;
  res.rms_px = cv::calibrateCamera(object_points, image_points, size, K, D, rvecs, tvecs, std_in, std_ex,
                                   per_view, flags);
  res.per_view_rms_px.clear();
  for (int i = 0; i < per_view.rows; ++i) res.per_view_rms_px.push_back(per_view.at<double>(i));
  res.camera.width = size.width;
  res.camera.height = size.height;
  res.camera.fx = K.at<double>(0, 0);
  res.camera.fy = K.at<double>(1, 1);
  res.camera.cx = K.at<double>(0, 2);
  res.camera.cy = K.at<double>(1, 2);
  for (int i = 0; i < 5; ++i) res.camera.dist[static_cast<size_t>(i)] = D.at<double>(i);
}

std::string fixed(double x, int digits) {
  char b[32];
  std::snprintf(b, sizeof b, "%.*f", digits, x);
  return b;
}

}  // namespace

IntrinsicsResult calibrateIntrinsics(const std::vector<std::pair<std::string, cv::Mat>>& views,
                                     const ChessboardSpec& board, const IntrinsicsOptions& options) {
  IntrinsicsResult res;
  cv::Size size;
  std::string first;
  for (const auto& [f, grey] : views) {
    if (grey.empty()) {
      res.rejected.push_back(f + " (unreadable)");
      continue;
    }
    if (size.area() == 0) {
      size = grey.size();
      first = f;
    }
    if (grey.size() != size) {
      throw std::invalid_argument(f + " is " + std::to_string(grey.cols) + "x" + std::to_string(grey.rows) + " but " +
                                  first + " is " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                                  ": calibrate one camera's images at one resolution");
    }
    PatternView v;
    if (!detectPattern(grey, board, v)) {
      res.rejected.push_back(f + " (no board)");
      continue;
    }
    res.detections.push_back(std::move(v));
    res.used.push_back(f);
  }
  if (res.detections.size() < 3) {
    throw std::runtime_error("intrinsic calibration needs at least 3 views of the board, found " +
                             std::to_string(res.detections.size()) + " of " + std::to_string(views.size()) +
                             (res.detections.empty() ? " (check --board: inner corners, not squares, for a chessboard)" : ""));
  }
  solveIntrinsics(res, size, options);
  auto flag = [&]() {
    std::vector<double> sorted = res.per_view_rms_px;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2), sorted.end());
    const double limit = std::max(options.view_rms_threshold_px, 3.0 * sorted[sorted.size() / 2]);
    std::vector<size_t> high;
    for (size_t i = 0; i < res.per_view_rms_px.size(); ++i) {
      if (res.per_view_rms_px[i] > limit) high.push_back(i);
    }
    return high;
  };
  std::vector<size_t> high = flag();
  for (size_t i : high) res.high_rms_views.push_back(res.used[i] + " (" + fixed(res.per_view_rms_px[i], 2) + " px)");
  if (options.drop_high_rms_views && !high.empty() && res.detections.size() - high.size() >= 3) {
    for (auto it = high.rbegin(); it != high.rend(); ++it) {
      res.dropped.push_back(res.used[*it]);
      res.detections.erase(res.detections.begin() + static_cast<long>(*it));
      res.used.erase(res.used.begin() + static_cast<long>(*it));
    }
    solveIntrinsics(res, size, options);
  }
  res.warnings = intrinsicsWarnings(res, options.model);
  return res;
}

std::vector<std::string> intrinsicsWarnings(const IntrinsicsResult& r, DistortionModel model) {
  std::vector<std::string> w;
  const CameraIntrinsics& c = r.camera;
  if (r.rms_px > 1.0) {
    w.push_back("reprojection RMS " + fixed(r.rms_px, 2) +
                " px is high (a sharp, flat board gives < 0.5 px): check the square size, the board's flatness and "
                "blurred views; see the per-view RMS");
  }
  if (!r.high_rms_views.empty() && r.dropped.empty()) {
    w.push_back(std::to_string(r.high_rms_views.size()) +
                " view(s) reproject far worse than the others (see high_rms_views): drop them (--drop-high-rms) "
                "or retake them");
  }
  const double diag = std::hypot(c.width, c.height);
  for (double f : {c.fx, c.fy}) {
    if (!(f > 0.3 * c.width && f < 5.0 * diag)) {
      w.push_back("focal length " + fixed(f, 1) + " px is outside the usual range for a " + std::to_string(c.width) +
                  "x" + std::to_string(c.height) + " image (" + fixed(0.3 * c.width, 0) + " … " + fixed(5 * diag, 0) +
                  " px): the views may not constrain it (tilt the board more)");
      break;
    }
  }
  if (std::abs(c.fx - c.fy) > 0.05 * std::max(c.fx, c.fy)) {
    w.push_back("fx and fy differ by " + fixed(100 * std::abs(c.fx - c.fy) / std::max(c.fx, c.fy), 1) +
                " %: square pixels are usual (try --fix-aspect) unless the sensor says otherwise");
  }
  if (std::abs(c.cx - 0.5 * c.width) > 0.2 * c.width || std::abs(c.cy - 0.5 * c.height) > 0.2 * c.height) {
    w.push_back("principal point (" + fixed(c.cx, 1) + ", " + fixed(c.cy, 1) +
                ") lies far from the image centre: views that reach the image corners fix it");
  }
  if (model == DistortionModel::kFull && r.used.size() < 10 &&
      (std::abs(c.dist[0]) > 1.0 || std::abs(c.dist[1]) > 5.0 || std::abs(c.dist[4]) > 20.0)) {
    w.push_back("strong distortion terms (k1 " + fixed(c.dist[0], 2) + ", k2 " + fixed(c.dist[1], 2) + ", k3 " +
                fixed(c.dist[4], 2) + ") from only " + std::to_string(r.used.size()) +
                " views: take more views reaching the image corners, or use --model k1");
  }
  return w;
}

Eigen::Isometry3d frameFromThreePoints(const Eigen::Vector3d& o, const Eigen::Vector3d& on_x,
                                       const Eigen::Vector3d& in_xy) {
  const Eigen::Vector3d x = on_x - o;
  const Eigen::Vector3d z = x.cross(in_xy - o);
  if (x.norm() < 1e-6 || z.norm() < 1e-9) {
    throw std::invalid_argument("taught points are too close or collinear to define a frame");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x.normalized();
  T.linear().col(2) = z.normalized();
  T.linear().col(1) = T.linear().col(2).cross(T.linear().col(0));
  T.translation() = o;
  return T;
}

ExtrinsicsResult calibrateExtrinsics(const cv::Mat& grey, const ChessboardSpec& board, const CameraIntrinsics& cam,
                                     const Eigen::Isometry3d& T_base_pattern) {
  const int w = board.inner_corners.width, h = board.inner_corners.height;
  if ((w + h) % 2 == 0) {
    throw std::runtime_error("a " + std::to_string(w) + "x" + std::to_string(h) +
                             " board looks the same after a half turn, so its frame is ambiguous: use inner corner "
                             "counts of different parity (e.g. 9x6)");
  }
  std::vector<cv::Point2f> corners;
  if (!findChessboard(grey, board, corners)) {
    throw std::runtime_error("the calibration pattern (" + std::to_string(w) + "x" + std::to_string(h) +
                             " inner corners) was not found in the image: is the whole board in view and in focus?");
  }
  // The detector may list the corners from either end. By convention the square between the
  // first four corners is black (and then the one between the last four is white): reverse the
  // list when the image says otherwise.
  auto squareGrey = [&](size_t a, size_t b, size_t c, size_t d) {
    const cv::Point2f m = (corners[a] + corners[b] + corners[c] + corners[d]) * 0.25f;
    const float r = 0.15f * static_cast<float>(cv::norm(corners[a] - corners[d]));
    const cv::Rect roi(cv::Point(cvRound(m.x - r), cvRound(m.y - r)), cv::Point(cvRound(m.x + r) + 1, cvRound(m.y + r) + 1));
    return cv::mean(grey(roi & cv::Rect(0, 0, grey.cols, grey.rows)))[0];
  };
  const size_t n = corners.size(), W = static_cast<size_t>(w);
  if (squareGrey(0, 1, W, W + 1) > squareGrey(n - 1, n - 2, n - 1 - W, n - 2 - W)) std::reverse(corners.begin(), corners.end());
  const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  const std::vector<double> D(cam.dist.begin(), cam.dist.end());
  const auto obj = boardPoints(board);
  cv::Mat rvec, tvec;
  cv::solvePnP(obj, corners, K, D, rvec, tvec, false, cv::SOLVEPNP_ITERATIVE);
  cv::solvePnPRefineLM(obj, corners, K, D, rvec, tvec);
  std::vector<cv::Point2f> reproj;
  cv::projectPoints(obj, rvec, tvec, K, D, reproj);
  double s2 = 0;
  for (size_t i = 0; i < reproj.size(); ++i) s2 += std::pow(cv::norm(reproj[i] - corners[i]), 2);
  cv::Mat R;
  cv::Rodrigues(rvec, R);
  ExtrinsicsResult r;
  Eigen::Matrix3d Re;
  cv::cv2eigen(R, Re);
  r.T_camera_pattern.linear() = Re;
  r.T_camera_pattern.translation() << tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2);
  r.T_base_camera = T_base_pattern * r.T_camera_pattern.inverse();
  r.rms_px = std::sqrt(s2 / static_cast<double>(reproj.size()));
  return r;
}

Eigen::Isometry3d laserFrameFromPlane(const Plane& p, const Eigen::Vector3d& towards) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d origin = -p.d * p.n;  // flange origin projected on the sheet
  Eigen::Vector3d z = towards - origin;
  z -= z.dot(p.n) * p.n;
  if (z.norm() < 1e-9) throw std::runtime_error("laser frame: beam direction lies along the sheet normal");
  z.normalize();
  T.linear().col(1) = p.n;
  T.linear().col(2) = z;
  T.linear().col(0) = p.n.cross(z);
  T.translation() = origin;
  return T;
}

namespace {
// Line points of one observation cut with the horizontal plane z = h, in the base frame.
std::vector<Eigen::Vector3d> linePointsOnPlane(const std::vector<LinePoint>& pts, const CameraIntrinsics& cam,
                                               const Eigen::Isometry3d& T_base_camera, double h) {
  std::vector<Eigen::Vector3d> out;
  const Eigen::Vector3d C = T_base_camera.translation();
  for (const auto& lp : pts) {
    const Eigen::Vector3d r = T_base_camera.linear() * cam.pixelRay({lp.u, lp.v});
    if (std::abs(r.z()) < 1e-9) continue;
    const double t = (h - C.z()) / r.z();
    if (t <= 0) continue;
    out.push_back(C + t * r);
  }
  return out;
}

LaserCalibrationResult fitSheet(const std::vector<Eigen::Vector3d>& pts_flange) {
  if (pts_flange.size() < 3) throw std::runtime_error("laser calibration: fewer than 3 line points observed");
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts_flange) mean += p;
  mean /= static_cast<double>(pts_flange.size());
  Eigen::MatrixXd M(pts_flange.size(), 3);
  for (size_t i = 0; i < pts_flange.size(); ++i) M.row(static_cast<Eigen::Index>(i)) = (pts_flange[i] - mean).transpose();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(M, Eigen::ComputeThinV);
  const Eigen::Vector3d sv = svd.singularValues();
  LaserCalibrationResult r;
  r.spread_ratio = sv(0) > 0 ? sv(1) / sv(0) : 0;
  // Across the line, the points must spread by millimetres, not by noise: views that only move
  // the flange parallel to the surface (same height, same orientation) all see the same line of
  // the sheet and leave its tilt about that line unknown.
  const double across_mm = sv(1) / std::sqrt(static_cast<double>(pts_flange.size())) * 1e3;
  if (r.spread_ratio < 1e-3 || across_mm < 2.0) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%.3f mm", across_mm);
    throw std::runtime_error(std::string("laser calibration: the observed points lie on one line in the flange frame "
                                         "(spread across it ") + buf +
                             "): the views differ only by moves parallel to the surface; observe the sheet from "
                             "different flange heights or tilts, or on surfaces at different heights");
  }
  r.plane_flange.n = svd.matrixV().col(2).normalized();
  r.plane_flange.d = -r.plane_flange.n.dot(mean);
  double s2 = 0;
  for (const auto& p : pts_flange) s2 += std::pow(r.plane_flange.distance(p), 2);
  r.rms_m = std::sqrt(s2 / static_cast<double>(pts_flange.size()));
  r.points = pts_flange.size();
  r.T_flange_laser = laserFrameFromPlane(r.plane_flange, mean);
  return r;
}
}  // namespace

LaserCalibrationResult calibrateLaserLeastSquares(const std::vector<LaserObservation>& obs,
                                                  const CameraIntrinsics& cam, const Eigen::Isometry3d& T_base_camera,
                                                  const LineExtractionConfig& line) {
  std::vector<Eigen::Vector3d> pts_flange;
  for (const auto& o : obs) {
    const auto pts = extractLine(o.image, line);
    const Eigen::Isometry3d T_flange_base = o.T_base_flange.inverse();
    for (const auto& p : linePointsOnPlane(pts, cam, T_base_camera, o.plane_z)) pts_flange.push_back(T_flange_base * p);
  }
  return fitSheet(pts_flange);
}

LaserCalibrationResult calibrateLaserThreePoint(const LaserObservation& o, const CameraIntrinsics& cam,
                                                const Eigen::Isometry3d& T_base_camera,
                                                const LineExtractionConfig& line) {
  const auto pts = extractLine(o.image, line);
  // Split the polyline into straight runs at jumps (the block's edges).
  std::vector<std::vector<LinePoint>> segs;
  for (const auto& p : pts) {
    if (segs.empty() || std::abs(p.v - segs.back().back().v) > 3.0 || p.u - segs.back().back().u > 3.0) segs.emplace_back();
    segs.back().push_back(p);
  }
  std::sort(segs.begin(), segs.end(), [](const auto& a, const auto& b) { return a.size() > b.size(); });
  if (segs.size() < 2 || segs[1].size() < 10) {
    throw std::runtime_error("three-point laser calibration: the line must cross both the plate and the gauge block");
  }
  // The plate carries the longest straight run. The block top is nearer the emitter, so with the
  // sheet leaning its line is displaced towards the flange in the image: the block segment is
  // the run (≥ 10 points) whose middle lies nearest the flange's image.
  auto mid = [](const std::vector<LinePoint>& s) { return s[s.size() / 2]; };
  const Eigen::Isometry3d T_cam_base = T_base_camera.inverse();
  const Eigen::Vector2d flange_px = cam.project(T_cam_base * o.T_base_flange.translation());
  auto dist_to_flange = [&](const std::vector<LinePoint>& s) {
    return (Eigen::Vector2d(mid(s).u, mid(s).v) - flange_px).norm();
  };
  const auto& plate = segs[0];
  const std::vector<LinePoint>* block_ptr = nullptr;
  for (size_t i = 1; i < segs.size(); ++i) {
    if (segs[i].size() < 10) continue;
    if (!block_ptr || dist_to_flange(segs[i]) < dist_to_flange(*block_ptr)) block_ptr = &segs[i];
  }
  if (!block_ptr || dist_to_flange(*block_ptr) >= dist_to_flange(plate)) {
    throw std::runtime_error("three-point laser calibration: no line segment on the gauge block was found");
  }
  const auto& block = *block_ptr;
  const std::vector<LinePoint> chosen_plate = {plate[plate.size() / 10], plate[plate.size() * 9 / 10]};
  const std::vector<LinePoint> chosen_block = {mid(block)};
  std::vector<Eigen::Vector3d> three = linePointsOnPlane(chosen_plate, cam, T_base_camera, o.plane_z);
  for (const auto& p : linePointsOnPlane(chosen_block, cam, T_base_camera, o.block_z)) three.push_back(p);
  if (three.size() != 3) throw std::runtime_error("three-point laser calibration: a chosen ray misses its plane");
  const Eigen::Isometry3d T_flange_base = o.T_base_flange.inverse();
  for (auto& p : three) p = T_flange_base * p;
  const Eigen::Vector3d n = (three[1] - three[0]).cross(three[2] - three[0]);
  if (n.norm() < 1e-12) throw std::runtime_error("three-point laser calibration: the three points are collinear");
  LaserCalibrationResult r;
  r.plane_flange.n = n.normalized();
  r.plane_flange.d = -r.plane_flange.n.dot(three[0]);
  r.points = 3;
  r.spread_ratio = 1.0;
  r.T_flange_laser = laserFrameFromPlane(r.plane_flange, (three[0] + three[1] + three[2]) / 3);
  return r;
}

}  // namespace cellsight
