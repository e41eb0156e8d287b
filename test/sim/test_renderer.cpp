#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include <random>

#include "cellsight/common/closest_point_grid.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/sim/renderer.hpp"
#include "sim/sim_test_scenes.hpp"

using namespace cellsight;

TEST(RayCaster, HitsTheRightTriangle) {
  RayCaster rc;
  rc.addMesh(makeBox({0.1, 0.1, 0.1}), Eigen::Isometry3d(Eigen::Translation3d(0, 0, 0)));
  rc.addMesh(makeBox({0.1, 0.1, 0.1}), Eigen::Isometry3d(Eigen::Translation3d(1, 0, 0)));
  rc.commit();
  // Down onto the second box's top face (z = 0.05), from z = 1.
  RayHit h = rc.intersect({1.02, 0.01, 1.0}, {0, 0, -1});
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.geometry, 1);
  EXPECT_NEAR(h.t, 0.95, 1e-6);
  EXPECT_NEAR((h.normal - Eigen::Vector3f::UnitZ()).norm(), 0, 1e-6);
  // The top face is triangles 2 and 3 of makeBox ({4,5,7,6}); the hit point decides which.
  EXPECT_TRUE(h.triangle == 2 || h.triangle == 3);
  // Sideways into the first box's -x face.
  h = rc.intersect({-1, 0.0, 0.0}, {1, 0, 0});
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.geometry, 0);
  EXPECT_NEAR(h.t, 0.95, 1e-6);
  EXPECT_NEAR((h.normal + Eigen::Vector3f::UnitX()).norm(), 0, 1e-6);
  EXPECT_FALSE(rc.intersect({0.5, 0, 1}, {0, 0, -1}).hit);
  EXPECT_TRUE(rc.occluded({-1, 0, 0}, {1, 0, 0}, 0, 2));
  EXPECT_FALSE(rc.occluded({-1, 0, 0}, {1, 0, 0}, 0, 0.9));
}

// The point query against every triangle by brute force, on a shipped part (a U-profile with
// inner corners) and two placed boxes; beyond max_distance nothing is found.
TEST(RayCaster, ClosestPointMatchesBruteForce) {
  const TriangleMesh u = loadMesh(std::string(CELLSIGHT_SOURCE_DIR) + "/config/models/holder/mesh.ply");
  RayCaster rc;
  rc.addMesh(u, Eigen::Isometry3d::Identity());
  rc.addMesh(makeBox({0.01, 0.01, 0.01}), Eigen::Isometry3d(Eigen::Translation3d(0.05, 0, 0)));
  rc.commit();
  std::vector<Eigen::Vector3d> a, b, c;
  for (const auto& f : u.faces) {
    a.push_back(u.vertices[f[0]].cast<double>());
    b.push_back(u.vertices[f[1]].cast<double>());
    c.push_back(u.vertices[f[2]].cast<double>());
  }
  const TriangleMesh box = makeBox({0.01, 0.01, 0.01});
  for (const auto& f : box.faces) {
    const Eigen::Vector3d o(0.05, 0, 0);
    a.push_back(o + box.vertices[f[0]].cast<double>());
    b.push_back(o + box.vertices[f[1]].cast<double>());
    c.push_back(o + box.vertices[f[2]].cast<double>());
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(-0.035f, 0.06f);
  int found = 0;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3f p(U(rng), U(rng) * 0.6f, U(rng) * 0.7f);
    double best = 1e9;
    for (size_t k = 0; k < a.size(); ++k) best = std::min(best, pointTriangleDistance(p.cast<double>(), a[k], b[k], c[k]));
    const ClosestPoint cp = rc.closestPoint(p, 0.004f);
    ASSERT_EQ(cp.found, best < 0.004) << i;
    if (!cp.found) continue;
    ++found;
    EXPECT_NEAR(cp.distance, best, 1e-6);
    EXPECT_NEAR((cp.point - p).norm(), best, 1e-6);
    EXPECT_NEAR(cp.normal.norm(), 1.0, 1e-5);
  }
  EXPECT_GT(found, 300);
  // and independently of the triangle routine both share: a box's distance in closed form
  RayCaster box_only;
  box_only.addMesh(makeBox({0.02, 0.01, 0.03}), Eigen::Isometry3d(Eigen::Translation3d(0.1, 0.2, 0.3)));
  box_only.commit();
  const Eigen::Vector3f centre(0.1f, 0.2f, 0.3f), half(0.01f, 0.005f, 0.015f);
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3f p = centre + Eigen::Vector3f(U(rng), U(rng), U(rng)) * 0.4f;
    const Eigen::Vector3f a = (p - centre).cwiseAbs() - half;
    const float exact = a.maxCoeff() > 0 ? a.cwiseMax(0.f).norm() : -a.maxCoeff();  // outside / inside
    const ClosestPoint cp = box_only.closestPoint(p, 1.f);
    ASSERT_TRUE(cp.found);
    EXPECT_NEAR(cp.distance, exact, 1e-6f) << p.transpose();
  }
}

TEST(LightSheet, PlaneIsTheLaserFramesXZPlane) {
  const Eigen::Isometry3d T = cellsight_test::laserAiming({0.1, -0.3, 0.2}, {0.1, 0.05, 0});
  const Plane p = laserPlane(T);
  EXPECT_NEAR(p.n.norm(), 1.0, 1e-12);
  EXPECT_NEAR(p.distance(T.translation()), 0, 1e-12);
  EXPECT_NEAR(p.distance(T * Eigen::Vector3d(0.3, 0, 0.5)), 0, 1e-12);  // fan and beam
  EXPECT_NEAR(p.distance(T * Eigen::Vector3d(0, 0.01, 0)), 0.01, 1e-12);
  EXPECT_NEAR(p.distance({0.3, 0.05, 0}), 0, 1e-12);  // the aimed line on the table
}

namespace {
// Where the analytic light-sheet ∩ table line projects: v at column u.
double analyticRow(const CameraIntrinsics& K, const Eigen::Isometry3d& T_cam_base,
                   const Eigen::Vector3d& p0, const Eigen::Vector3d& dir, double u) {
  double lo = -0.5, hi = 0.5;
  auto ucol = [&](double s) { return K.project(T_cam_base * (p0 + s * dir)).x(); };
  const bool increasing = ucol(hi) > ucol(lo);
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    if ((ucol(mid) < u) == increasing) lo = mid; else hi = mid;
  }
  return K.project(T_cam_base * (p0 + 0.5 * (lo + hi) * dir)).y();
}
}  // namespace

TEST(ScannerRenderer, LineOnPlaneMatchesAnalyticProjection) {
  Scene scene = cellsight_test::planeScene();
  // Sheet through the line y = 0.02 on the table, tilted 30° about x.
  const Eigen::Isometry3d T_base_laser = cellsight_test::laserAiming({0, -0.12, 0.2}, {0, 0.02, 0});
  scene.laser.T_flange_laser = Eigen::Isometry3d::Identity();
  ScannerRenderer r(std::make_shared<CellGeometry>(scene));
  const cv::Mat laser = r.renderLaserOnly(T_base_laser);
  const Eigen::Isometry3d T_cam_base = scene.scanner_camera.T_base_camera.inverse();
  double max_err = 0, sum2 = 0, max_sum = 0;
  int columns = 0;
  cv::Mat column_sums;
  cv::reduce(laser, column_sums, 0, cv::REDUCE_SUM, CV_64F);
  cv::minMaxLoc(column_sums, nullptr, &max_sum);
  for (int u = 0; u < laser.cols; ++u) {
    double s = 0, sv = 0;
    for (int v = 0; v < laser.rows; ++v) {
      const double w = laser.at<float>(v, u);
      s += w;
      sv += w * v;
    }
    // Columns cut by the end of the fan hold part of the line's footprint only.
    if (s < 0.8 * max_sum) continue;
    const double err = sv / s - analyticRow(scene.scanner_camera.intrinsics, T_cam_base,
                                            {0, 0.02, 0}, Eigen::Vector3d::UnitX(), u);
    max_err = std::max(max_err, std::abs(err));
    sum2 += err * err;
    ++columns;
  }
  EXPECT_GT(columns, 500);
  EXPECT_LT(max_err, 0.05) << "rms " << std::sqrt(sum2 / columns);
}

TEST(ScannerRenderer, LaserShadowBehindABox) {
  const std::string dir = cellsight_test::tempDir();
  Scene scene = cellsight_test::planeScene();
  // A 40 mm cube between the emitter and the lit line on the table.
  cellsight_test::addObject(scene, dir, "cube", makeBox({0.04, 0.04, 0.04}),
                            Eigen::Isometry3d(Eigen::Translation3d(0, 0, 0.02)));
  scene.laser.T_flange_laser = Eigen::Isometry3d::Identity();
  const Eigen::Isometry3d T_base_laser = cellsight_test::laserAiming({0, -0.3, 0.15}, {0, 0.05, 0});
  ScannerRenderer r(std::make_shared<CellGeometry>(scene));
  const cv::Mat laser = r.renderLaserOnly(T_base_laser);
  const Eigen::Isometry3d T_cam_base = scene.scanner_camera.T_base_camera.inverse();
  auto peakNear = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector2d uv = scene.scanner_camera.intrinsics.project(T_cam_base * p);
    float best = 0;
    for (int dv = -4; dv <= 4; ++dv) {
      best = std::max(best, laser.at<float>(static_cast<int>(std::lround(uv.y())) + dv,
                                            static_cast<int>(std::lround(uv.x()))));
    }
    return best;
  };
  EXPECT_GT(peakNear({0.08, 0.05, 0}), 50.f);   // beside the box: lit
  EXPECT_LT(peakNear({0.0, 0.05, 0}), 1e-3f);   // behind the box: in its laser shadow
  EXPECT_LT(peakNear({0.012, 0.05, 0}), 1e-3f);
}

TEST(ScannerRenderer, NoiseIsReproducibleAndEncodingsHold) {
  Scene scene = cellsight_test::planeScene();
  scene.noise.enabled = true;
  scene.laser.T_flange_laser = Eigen::Isometry3d::Identity();
  const Eigen::Isometry3d T = cellsight_test::laserAiming({0, -0.12, 0.2}, {0, 0.0, 0});
  auto geometry = std::make_shared<CellGeometry>(scene);
  ScannerRenderer r(geometry);
  const cv::Mat a = r.render(T, 5), b = r.render(T, 5), c = r.render(T, 6);
  EXPECT_EQ(a.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_L1), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 0.0);
  scene.scanner_camera.encoding = "rgb8";
  ScannerRenderer rgb(std::make_shared<CellGeometry>(scene));
  const cv::Mat im = rgb.render(T, 1);
  ASSERT_EQ(im.type(), CV_8UC3);
  cv::Scalar mean = cv::mean(im);
  EXPECT_GT(mean[0], mean[1] + 0.1);  // red laser in channel 0
}

TEST(FixtureRenderer, QrCodeIsPrintedWithDarkAndLightModules) {
  Scene scene = cellsight_test::planeScene();
  QrFixture f;
  f.id = "a";
  f.payload = "cellsight test";
  f.code_size = 0.06;
  f.plate_size = 0.08;
  f.T_base_fixture = Eigen::Isometry3d(Eigen::Translation3d(0, 0, 0.001));
  scene.fixtures.push_back(f);
  FixtureRenderer r(std::make_shared<CellGeometry>(scene));
  const cv::Mat& img = r.clean();
  // The code spans ~96 px around the image centre: both dark and light modules are there.
  const cv::Mat roi = img(cv::Rect(320 - 40, 240 - 40, 80, 80));
  double lo, hi;
  cv::minMaxLoc(roi, &lo, &hi);
  EXPECT_LT(lo, 30);
  EXPECT_GT(hi, 150);
}

// The candidate-triangle grid gives Embree's answers (distance, point, face normal) on shipped
// part meshes, for points near the surface (covered), and says "not covered" only for points
// farther than its margin.
TEST(ClosestPointGrid, MatchesTheRayCaster) {
  for (const std::string part : {"holder", "flanged_shaft", "housing"}) {
    const TriangleMesh mesh = loadMesh(std::string(CELLSIGHT_SOURCE_DIR) + "/config/models/" + part + "/mesh.ply");
    RayCaster rc;
    rc.addMesh(mesh, Eigen::Isometry3d::Identity());
    rc.commit();
    const float margin = 0.0025f;
    const ClosestPointGrid grid(mesh, 0.001f, margin);
    ASSERT_FALSE(grid.empty());
    const Eigen::AlignedBox3f box = mesh.bounds();
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> U(0.f, 1.f);
    int covered_n = 0;
    for (int i = 0; i < 20000; ++i) {
      const Eigen::Vector3f p = box.min() - Eigen::Vector3f::Constant(0.004f) +
                                (box.sizes() + Eigen::Vector3f::Constant(0.008f)).cwiseProduct(Eigen::Vector3f(U(rng), U(rng), U(rng)));
      const ClosestPoint want = rc.closestPoint(p, 0.006f);
      bool covered = false;
      const ClosestPoint got = grid.closestPoint(p, 0.006f, &covered);
      if (!covered) {
        // nothing within the margin of an uncovered point
        EXPECT_FALSE(want.found && want.distance < margin - 1e-6f) << part << " " << p.transpose();
        continue;
      }
      ++covered_n;
      ASSERT_EQ(got.found, want.found) << part << " " << p.transpose();
      if (!got.found) continue;
      EXPECT_NEAR(got.distance, want.distance, 1e-7f) << part;
      EXPECT_NEAR((got.point - want.point).norm(), 0.f, 1e-6f) << part;
      // on a shared edge either face may be reported: both give the same closest point
      if (got.triangle != want.triangle) continue;
      EXPECT_NEAR((got.normal - want.normal).norm(), 0.f, 1e-6f) << part;
    }
    EXPECT_GT(covered_n, 2000) << part;
  }
  EXPECT_TRUE(ClosestPointGrid(TriangleMesh(), 0.001f, 0.002f).empty());
}
