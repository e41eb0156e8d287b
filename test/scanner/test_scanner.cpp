#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "cellsight/scanner/accuracy.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/scanner/scan_pipeline.hpp"
#include "cellsight/scanner/triangulation.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {
// A synthetic line: Gaussian across rows with centre v(u) = v0 + slope·u, sigma in px.
cv::Mat syntheticLine(int w, int h, double v0, double slope, double sigma, double peak, double bg,
                      double noise = 0, unsigned seed = 1) {
  cv::Mat img(h, w, CV_8UC1);
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, noise > 0 ? noise : 1);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const double c = v0 + slope * u;
      // Pixel-integrated Gaussian (erf differences) so the true centre is exactly c.
      const double a = (v - 0.5 - c) / (std::sqrt(2.0) * sigma), b = (v + 0.5 - c) / (std::sqrt(2.0) * sigma);
      const double x = bg + peak * std::sqrt(M_PI / 2) * sigma * (std::erf(b) - std::erf(a)) +
                       (noise > 0 ? noise * n(rng) : 0);
      img.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(x);
    }
  }
  return img;
}
/// A line through (cx, cy) at `deg` to the image rows, or (radius > 0) a circle of that radius
/// around (cx, cy); Gaussian profile across it (sigma px), 4×4 supersampled.
cv::Mat syntheticTrace(int w, int h, double cx, double cy, double deg, double radius, double sigma, double peak,
                       double bg, double noise = 0, unsigned seed = 1) {
  cv::Mat img(h, w, CV_8UC1);
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, 1);
  const double a = deg * M_PI / 180, nx = -std::sin(a), ny = std::cos(a);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      double acc = 0;
      for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
          const double x = u - 0.375 + 0.25 * i - cx, y = v - 0.375 + 0.25 * j - cy;
          const double d = radius > 0 ? std::hypot(x, y) - radius : x * nx + y * ny;
          acc += std::exp(-d * d / (2 * sigma * sigma));
        }
      }
      img.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(bg + peak * acc / 16 + (noise > 0 ? noise * n(rng) : 0));
    }
  }
  return img;
}

}  // namespace

TEST(LineExtraction, RidgeFindsLinesAtAnyAngleWithTheirNormal) {
  for (double deg : {0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0, 135.0}) {
    const cv::Mat img = syntheticTrace(240, 240, 120.3, 119.6, deg, 0, 1.2, 180, 10);
    LineExtractionConfig c;  // default: ridge
    c.smoothing_degree = 0;
    LineExtractionStats st;
    const auto pts = extractLine(img, c, &st);
    const double a = deg * M_PI / 180, nx = -std::sin(a), ny = std::cos(a);
    // The line crosses the 240-px square (clipped by the ridge's border of 3σ and the erosion).
    EXPECT_GT(pts.size(), 200u) << deg << " deg";
    EXPECT_EQ(st.segments, 1) << deg << " deg";
    double max_err = 0, min_dot = 1;
    for (const auto& p : pts) {
      max_err = std::max(max_err, std::abs((p.u - 120.3) * nx + (p.v - 119.6) * ny));
      min_dot = std::min(min_dot, std::abs(p.nx * nx + p.ny * ny));
      EXPECT_NEAR(p.width, 2.3548 * 1.2, 0.6);
    }
    EXPECT_LT(max_err, 0.03) << deg << " deg";
    EXPECT_GT(min_dot, 0.999) << deg << " deg";
  }
}

TEST(LineExtraction, RidgeFollowsACurvedTraceAndTheColumnMethodDoesNot) {
  // A circle of radius 90 px: every direction, slopes up to vertical.
  const cv::Mat img = syntheticTrace(240, 240, 120, 120, 0, 90, 1.2, 180, 10, 2.0, 5);
  LineExtractionConfig ridge;
  LineExtractionStats st;
  const auto pts = extractLine(img, ridge, &st);
  double s2 = 0;
  for (const auto& p : pts) s2 += std::pow(std::hypot(p.u - 120, p.v - 120) - 90, 2);
  const double rms = std::sqrt(s2 / static_cast<double>(pts.size()));
  EXPECT_LT(rms, 0.05);
  EXPECT_GT(pts.size(), 0.95 * 2 * M_PI * 90 * 0.9);  // centres at ≥ 0.9 per px of arc length
  EXPECT_LE(st.segments, 2);
  LineExtractionConfig cols;
  cols.estimator = LineExtractionConfig::Estimator::kCentroid;
  // One centre per column at most, and the steep parts lost to the jump limit.
  EXPECT_LT(extractLine(img, cols).size(), 0.5 * pts.size());
}

TEST(LineExtraction, RidgeRejectsSpeckleAndShortStreaks) {
  cv::Mat img(200, 200, CV_8UC1, cv::Scalar(10));
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> jitter(-2, 2);
  for (int v = 8; v < 192; v += 12) {  // 256 separate speckle blobs
    for (int u = 8; u < 192; u += 12) cv::circle(img, {u + jitter(rng), v + jitter(rng)}, 1, cv::Scalar(200), cv::FILLED);
  }
  cv::line(img, {20, 20}, {23, 21}, cv::Scalar(200));  // a 4-px streak
  LineExtractionConfig c;
  LineExtractionStats st;
  const auto pts = extractLine(img, c, &st);
  EXPECT_EQ(pts.size(), 0u) << "speckle should not become a line";
  EXPECT_GT(st.not_ridge, 200);
}

TEST(LineExtraction, RidgeSurvivesDegenerateSettingsAndImages) {
  // A flat frame at the background level with no contrast asked and Steger's step: derivatives
  // of exactly zero (0/0 where the profile width is estimated) give no centre, no crash.
  LineExtractionConfig c;
  c.min_contrast = 0;
  c.ridge_gaussian_profile = false;
  EXPECT_TRUE(extractLine(cv::Mat(120, 160, CV_8UC1, cv::Scalar(50)), c).empty());
  c.min_contrast = 1e10;  // no pixel can reach it
  EXPECT_TRUE(extractLine(syntheticTrace(80, 80, 40, 40, 0, 0, 1.2, 180, 10), c).empty());
  LineExtractionConfig wide;
  wide.ridge_sigma = 10;  // a kernel wider than the image
  EXPECT_TRUE(extractLine(syntheticTrace(40, 40, 20, 20, 30, 0, 1.2, 180, 10), wide).empty());
  LineExtractionConfig loose;  // every setting at its permissive end
  loose.min_segment = 1;
  loose.segment_erode = 0;
  loose.link_max_gap = 10;
  loose.smoothing_degree = 3;
  EXPECT_GT(extractLine(syntheticTrace(200, 200, 100, 100, 20, 0, 1.2, 180, 10), loose).size(), 150u);
}

TEST(LineExtraction, EveryEstimatorFindsTheKnownCentreNoiseFree) {
  const cv::Mat img = syntheticLine(400, 200, 80.3, 0.05, 1.2, 200, 10);
  for (auto est : {LineExtractionConfig::Estimator::kRidge, LineExtractionConfig::Estimator::kRunCentre,
                   LineExtractionConfig::Estimator::kCentroid, LineExtractionConfig::Estimator::kGaussian3}) {
    LineExtractionConfig c;
    c.estimator = est;
    c.smoothing_degree = 0;
    LineExtractionStats st;
    const auto pts = extractLine(img, c, &st);
    ASSERT_GT(pts.size(), 370u);
    double max_err = 0;
    for (const auto& p : pts) max_err = std::max(max_err, std::abs(p.v - (80.3 + 0.05 * p.u)));
    EXPECT_LT(max_err, 0.06) << "estimator " << static_cast<int>(est);
    EXPECT_NEAR(st.background, 10, 1);
  }
}

TEST(LineExtraction, SmoothingReducesNoiseOnAStraightLine) {
  const cv::Mat img = syntheticLine(600, 200, 100.0, 0.02, 1.2, 120, 10, 4.0, 3);
  auto rms = [&](LineExtractionConfig::Estimator e, int degree) {
    LineExtractionConfig c;
    c.estimator = e;
    c.smoothing_degree = degree;
    double s2 = 0;
    const auto pts = extractLine(img, c);
    for (const auto& p : pts) s2 += std::pow(p.v - (100.0 + 0.02 * p.u), 2);
    return std::sqrt(s2 / pts.size());
  };
  using E = LineExtractionConfig::Estimator;
  EXPECT_LT(rms(E::kCentroid, 2), 0.6 * rms(E::kCentroid, 0));
  // The ridge's centres are already smoothed along the line by its Gaussian (σ 1.5 px), so the
  // polyline fit gains less — but it ends below the smoothed column centroid.
  EXPECT_LT(rms(E::kRidge, 2), 0.85 * rms(E::kRidge, 0));
  EXPECT_LT(rms(E::kRidge, 2), rms(E::kCentroid, 2));
}

TEST(LineExtraction, ReflectionMakesAColumnAmbiguous) {
  cv::Mat img = syntheticLine(200, 200, 50.0, 0.0, 1.2, 200, 10);
  for (int u = 100; u < 120; ++u) {
    for (int v = 150; v < 153; ++v) img.at<uint8_t>(v, u) = 230;  // a strong second spot
  }
  LineExtractionConfig c;
  c.estimator = LineExtractionConfig::Estimator::kCentroid;
  c.segment_erode = 0;
  LineExtractionStats st;
  const auto pts = extractLine(img, c, &st);
  EXPECT_EQ(st.ambiguous, 20);
  for (const auto& p : pts) EXPECT_TRUE(p.u < 100 || p.u >= 120);
}

TEST(LineExtraction, EdgeFilterDropsSegmentEndsAndJumps) {
  cv::Mat img = syntheticLine(200, 200, 50.0, 0.0, 1.2, 200, 10);
  cv::Mat step = syntheticLine(200, 200, 80.0, 0.0, 1.2, 200, 10);
  step.colRange(100, 200).copyTo(img.colRange(100, 200));  // depth edge at u = 100
  LineExtractionConfig c;
  c.estimator = LineExtractionConfig::Estimator::kCentroid;
  c.smoothing_degree = 0;
  LineExtractionStats st;
  const auto pts = extractLine(img, c, &st);
  EXPECT_EQ(st.edge, 8);  // 2 at each end of two segments
  EXPECT_EQ(st.segments, 2);
  for (const auto& p : pts) EXPECT_FALSE(p.u >= 98 && p.u <= 101);
  // The ridge: the same two segments, cut where linking finds no continuation, ends eroded.
  LineExtractionConfig ridge;
  ridge.smoothing_degree = 0;
  LineExtractionStats rs;
  const auto rp = extractLine(img, ridge, &rs);
  EXPECT_EQ(rs.segments, 2);
  for (const auto& p : rp) EXPECT_FALSE(p.u >= 98 && p.u <= 101) << p.u << " " << p.v;
  for (const auto& p : rp) EXPECT_NEAR(p.v, p.u < 100 ? 50.0 : 80.0, 0.05);
}

TEST(LineExtraction, BadFramesGiveNoPointsOrAClearError) {
  LineExtractionConfig c;
  c.estimator = LineExtractionConfig::Estimator::kCentroid;
  LineExtractionStats st;
  cv::Mat dark(100, 100, CV_8UC1, cv::Scalar(12));
  EXPECT_TRUE(extractLine(dark, c, &st).empty());
  EXPECT_EQ(st.no_line, 100);
  cv::Mat saturated(100, 100, CV_8UC1, cv::Scalar(255));
  EXPECT_TRUE(extractLine(saturated, c).empty());
  LineExtractionConfig ridge;
  EXPECT_TRUE(extractLine(dark, ridge).empty());
  EXPECT_TRUE(extractLine(saturated, ridge).empty());
  EXPECT_TRUE(extractLine(cv::Mat(3, 3, CV_8UC1, cv::Scalar(200)), ridge).empty());  // smaller than the kernel
  EXPECT_THROW(extractLine(cv::Mat(10, 10, CV_16UC1), c), std::invalid_argument);
  EXPECT_THROW(extractLine(cv::Mat(), c), std::invalid_argument);
  cv::Mat rgb(100, 100, CV_8UC3, cv::Scalar(0, 0, 0));
  EXPECT_THROW(extractLine(rgb, c), std::invalid_argument);  // channel not chosen
}

TEST(LineExtraction, ColourChannelAndColumnOrientation) {
  const cv::Mat mono = syntheticLine(300, 120, 60.25, 0.0, 1.2, 200, 10);
  cv::Mat zero(mono.size(), CV_8UC1, cv::Scalar(10));
  cv::Mat rgb;
  cv::merge(std::vector<cv::Mat>{mono, zero, zero}, rgb);
  LineExtractionConfig c;
  c.channel = 0;
  EXPECT_GT(extractLine(rgb, c).size(), 270u);  // 300 columns less the kernel border and the eroded ends
  c.channel = 1;
  EXPECT_TRUE(extractLine(rgb, c).empty());
  LineExtractionConfig cols;
  cols.estimator = LineExtractionConfig::Estimator::kCentroid;
  cols.line_along_rows = false;
  const auto pts = extractLine(mono.t(), cols);
  ASSERT_GT(pts.size(), 280u);
  EXPECT_NEAR(pts[50].u, 60.25, 0.05);  // transposed: the centre is a column position
}

TEST(Triangulation, RayPlaneIntersectionRecoversPointsOnTheSheet) {
  CameraIntrinsics K{"c", 1920, 1080, 2400, 2400, 962.5, 537, {-0.08, 0.05, 3e-4, -2e-4, 0}};
  Plane sheet;
  sheet.n = Eigen::Vector3d(0, 0.866, 0.5).normalized();
  sheet.d = -0.25;
  std::vector<LinePoint> line;
  std::vector<Eigen::Vector3d> truth;
  for (double x = -0.1; x <= 0.1; x += 0.01) {
    // A point on the sheet at depth ~0.5 m.
    Eigen::Vector3d p(x, 0, 0);
    p.z() = (-sheet.d - sheet.n.y() * p.y() - sheet.n.x() * x) / sheet.n.z();
    p.y() = 0.02;
    p.z() = (-sheet.d - sheet.n.y() * p.y() - sheet.n.x() * x) / sheet.n.z();
    truth.push_back(p);
    const Eigen::Vector2d uv = K.project(p);
    line.push_back({static_cast<float>(uv.x()), static_cast<float>(uv.y()), 100, 3});
  }
  const UndistortionMap map(K);
  for (const auto& prof : {triangulate(line, K, sheet), triangulate(line, map, sheet)}) {
    ASSERT_EQ(prof.size(), truth.size());
    for (size_t i = 0; i < truth.size(); ++i) {
      // float pixel coordinates limit this to ~1e-7 m
      EXPECT_LT((prof[i].p - truth[i]).norm(), 2e-6) << i;
    }
  }
  Plane parallel;  // the sheet contains the camera's rays: nothing can be triangulated
  parallel.n = Eigen::Vector3d(1, 0, 0);
  parallel.d = 0.0;
  EXPECT_TRUE(triangulate(line, K, parallel).empty());
}

TEST(Accuracy, SphereFitMpeAlAndFlatness) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0, 1e-5);
  std::vector<Eigen::Vector3d> pts;
  const Eigen::Vector3d c(0.6, -0.07, 0.0125);
  for (int i = 0; i < 2000; ++i) {
    Eigen::Vector3d d(n(rng), n(rng), std::abs(n(rng)) + 1e-6);  // upper hemisphere
    d = Eigen::Vector3d::Random();
    d.z() = std::abs(d.z());
    d.normalize();
    pts.push_back(c + (0.0125 + n(rng)) * d);
  }
  const SphereFit f = fitSphere(pts);
  ASSERT_TRUE(f.ok);
  EXPECT_LT((f.center - c).norm(), 2e-6);
  EXPECT_NEAR(f.radius, 0.0125, 2e-6);
  EXPECT_NEAR(f.rms, 1e-5, 2e-6);
  EXPECT_GT(f.max_abs_dev, 2e-5);
  EXPECT_LT(f.max_abs_dev, 6e-5);
  EXPECT_NEAR(fitSphere(pts, 0.0125).radius, 0.0125, 1e-12);
  // Smallest enclosing sphere: a regular tetrahedron of edge a has circumradius a·√(3/8).
  const double a = 1e-4;
  std::vector<Eigen::Vector3d> tet = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  for (auto& p : tet) p *= a / std::sqrt(8.0);
  tet.push_back(Eigen::Vector3d::Zero());  // inside
  EXPECT_NEAR(minimumEnclosingDiameter(tet), 2 * a * std::sqrt(3.0 / 8.0), 1e-12);
  EXPECT_NEAR(minimumEnclosingDiameter({{0, 0, 0}, {3e-5, 0, 0}, {1e-5, 1e-6, 0}}), 3e-5, 1e-12);
  std::vector<Eigen::Vector3d> plane;
  for (int i = 0; i < 100; ++i) plane.push_back({i * 1e-3, (i % 7) * 1e-3, (i % 2 ? 1 : -1) * 1e-5});
  EXPECT_NEAR(fitPlane(plane).flatness, 2e-5, 1e-6);
}

// The pipeline's per-frame profile (scan_pipeline): the line searched across the sheet's trace,
// triangulated on the sheet, moved to the base frame; from the flange pose the same profile.
TEST(ScanPipeline, FrameProfileIsTheLineOnTheSheetInTheBaseFrame) {
  const CameraIntrinsics K{"c", 640, 480, 800, 800, 320, 240, {0, 0, 0, 0, 0}};
  const UndistortionMap map(K);
  Plane sheet;  // |n_y| > |n_x|: its trace runs along the rows
  sheet.n = Eigen::Vector3d(0, 0.8, 0.6);
  sheet.d = -0.3;
  EXPECT_TRUE(lineAlongRows(sheet));
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  T_base_camera.translation() = Eigen::Vector3d(0.5, 0, 0.6);
  T_base_camera.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const cv::Mat img = syntheticLine(640, 480, 200.3, 0.0, 1.5, 120, 10);
  LineExtractionConfig line;
  line.line_along_rows = false;  // overridden by the sheet's trace
  ScanCloud cloud;
  LineExtractionStats st;
  const size_t n = addFrameProfile(img, sheet, T_base_camera, map, line, TriangulationConfig{}, cloud, &st);
  ASSERT_GT(n, 600u);
  EXPECT_EQ(cloud.size(), n);
  EXPECT_GE(st.found, static_cast<int>(n));
  for (const auto& p : cloud.points) {
    const Eigen::Vector3d q = T_base_camera.inverse() * p.cast<double>();
    EXPECT_NEAR(sheet.n.dot(q) + sheet.d, 0, 1e-6);
    EXPECT_NEAR(K.project(q).y(), 200.3, 0.05);
  }
  // the flange pose and the calibration give the same sheet, so the same points
  ScannerCalibration cal;
  cal.intrinsics = K;
  cal.T_base_camera = T_base_camera;
  Eigen::Isometry3d T_camera_laser = Eigen::Isometry3d::Identity();  // laser y = the sheet's normal
  const Eigen::Vector3d ny = sheet.n, nz = ny.unitOrthogonal();
  T_camera_laser.linear() << ny.cross(nz), ny, nz;
  T_camera_laser.translation() = -sheet.d * sheet.n;
  const Eigen::Isometry3d T_base_flange = Eigen::Translation3d(0.1, 0.2, 0.3) * Eigen::Isometry3d::Identity();
  cal.T_flange_laser = T_base_flange.inverse() * T_base_camera * T_camera_laser;
  ScanCloud from_flange;
  EXPECT_THROW(addProfile(img, T_base_flange, cal, line, TriangulationConfig{}, from_flange), std::invalid_argument);
  cal.undistortion = std::make_shared<UndistortionMap>(K);
  ASSERT_EQ(addProfile(img, T_base_flange, cal, line, TriangulationConfig{}, from_flange), n);
  for (size_t i = 0; i < n; ++i) EXPECT_LT((from_flange.points[i] - cloud.points[i]).norm(), 1e-6f) << i;
}

// The scan's finish: the workspace crop, the outlier filter and normals towards the camera, each
// off where the settings turn it off.
TEST(ScanPipeline, FinishCropsFiltersAndOrientsNormals) {
  ScanCloud raw;
  raw.frame_id = "base_link";
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j) raw.append(Eigen::Vector3f(0.4f + 0.001f * i, 0.001f * j, 0.01f), 1.f);
  raw.append(Eigen::Vector3f(0.42f, 0.02f, 0.05f), 1.f);  // a stray point 40 mm above the surface
  raw.append(Eigen::Vector3f(0.9f, 0.02f, 0.01f), 1.f);   // outside the workspace
  ScannerSettings s;
  s.has_workspace = true;
  s.workspace = Eigen::AlignedBox3f(Eigen::Vector3f(0.3f, -0.1f, -0.01f), Eigen::Vector3f(0.7f, 0.1f, 0.1f));
  const Eigen::Vector3f eye(0.5f, 0.f, 0.6f);
  const ScanCloud done = finishScan(raw, s, eye);
  EXPECT_EQ(done.size(), 1600u);
  EXPECT_EQ(done.frame_id, "base_link");
  ASSERT_EQ(done.normals.size(), done.size());
  for (size_t i = 0; i < done.size(); ++i) EXPECT_GT(done.normals[i].z(), 0.99f) << i;
  s.outlier_k = 0;
  s.normal_k = 0;
  const ScanCloud cropped = finishScan(raw, s, eye);
  EXPECT_EQ(cropped.size(), 1601u);
  EXPECT_TRUE(cropped.normals.empty());
  s.has_workspace = false;
  EXPECT_EQ(finishScan(raw, s, eye).size(), raw.size());
  EXPECT_EQ(finishScan(ScanCloud{}, ScannerSettings{}, eye).size(), 0u);
}
