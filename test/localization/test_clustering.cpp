#include <gtest/gtest.h>

#include <random>

#include "cellsight/localization/clustering.hpp"
#include "cellsight/common/errors.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {
// A table (z = 0) sampled at 1 mm with three boxes standing on it (top faces and sides).
ScanCloud syntheticScene(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, 0.0002f);
  ScanCloud c;
  auto inBox = [](float x, float y, float cx, float cy, float h) { return std::abs(x - cx) <= h && std::abs(y - cy) <= h; };
  const float boxes[3][4] = {{0.40f, 0.0f, 0.02f, 0.03f}, {0.50f, 0.05f, 0.015f, 0.02f}, {0.55f, -0.06f, 0.025f, 0.05f}};
  for (float x = 0.35f; x < 0.65f; x += 0.001f) {
    for (float y = -0.1f; y < 0.1f; y += 0.001f) {
      bool covered = false;
      for (const auto& b : boxes) {
        if (inBox(x, y, b[0], b[1], b[2])) {
          c.append({x, y, b[3] + noise(rng)}, 100.f);  // top face
          covered = true;
        }
      }
      if (!covered) c.append({x, y, noise(rng)}, 80.f);
    }
  }
  for (const auto& b : boxes) {  // one side face each
    for (float z = 0.002f; z < b[3]; z += 0.001f)
      for (float y = b[1] - b[2]; y <= b[1] + b[2]; y += 0.001f) c.append({b[0] - b[2] - 0.0005f, y, z}, 90.f);
  }
  return c;
}
}  // namespace

TEST(Clustering, ThreeBoxesOnATable) {
  ClusteringConfig cfg;
  const ClusteringResult r = clusterScene(syntheticScene(1), cfg);
  ASSERT_TRUE(r.plane_found);
  EXPECT_NEAR(r.support.n.z(), 1.0, 1e-3);
  EXPECT_NEAR(r.support.d, 0.0, 5e-4);
  ASSERT_EQ(r.clusters.size(), 3u);
  // Largest first: the 50 mm box, then 40 mm, then 30 mm; each cluster's box holds its box top.
  const float centres[3][3] = {{0.55f, -0.06f, 0.05f}, {0.40f, 0.0f, 0.03f}, {0.50f, 0.05f, 0.02f}};
  for (int k = 0; k < 3; ++k) {
    Eigen::AlignedBox3f b = r.clusters[static_cast<size_t>(k)].box;
    b.extend(b.max() + Eigen::Vector3f::Constant(1e-3f));
    b.extend(b.min() - Eigen::Vector3f::Constant(1e-3f));
    EXPECT_TRUE(b.contains(Eigen::Vector3f(centres[k][0], centres[k][1], centres[k][2]))) << k;
  }
  for (const auto& c : r.clusters) EXPECT_GT(c.box.min().z(), 0.0f);
  // where the table was seen: on the plane, one per 2 mm cell, none under the boxes' tops
  ASSERT_GT(r.support_points.size(), 1000u);
  for (const auto& p : r.support_points) {
    EXPECT_LE(std::abs(r.support.distance(p.cast<double>())), cfg.plane_distance + 1e-9);
    EXPECT_FALSE(std::abs(p.x() - 0.55f) < 0.02f && std::abs(p.y() + 0.06f) < 0.02f) << p.transpose();
  }
}

// A group of points smaller than min_cluster_points is not a cluster but stays as fragments:
// the matcher counts them as measured surface.
TEST(Clustering, SmallGroupsAreKeptAsFragments) {
  ClusteringConfig cfg;
  ScanCloud scene = syntheticScene(3);
  EXPECT_TRUE(clusterScene(scene, cfg).fragments.empty());
  for (float x = 0.46f; x < 0.4645f; x += 0.001f)  // a 5 x 5 mm patch at 5 mm, 25 points
    for (float y = -0.08f; y < -0.0755f; y += 0.001f) scene.append({x, y, 0.005f}, 90.f);
  const ClusteringResult r = clusterScene(scene, cfg);
  EXPECT_EQ(r.clusters.size(), 3u);
  ASSERT_GE(r.fragments.size(), 16u);  // the voxel grid may merge a few
  EXPECT_LE(r.fragments.size(), 25u);
  for (const auto& p : r.fragments) EXPECT_NEAR(p.z(), 0.005f, 1e-4f);
  cfg.min_cluster_points = 20;  // ... which is a cluster when it is large enough
  EXPECT_EQ(clusterScene(scene, cfg).clusters.size(), 4u);
}

TEST(Clustering, BadCloudsGiveAClearEmptyResult) {
  ClusteringConfig cfg;
  ClusteringResult r = clusterScene(ScanCloud(), cfg);
  EXPECT_TRUE(r.clusters.empty());
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("empty cloud"), std::string::npos);
  ScanCloud nan;
  for (int i = 0; i < 100; ++i) nan.append(Eigen::Vector3f::Constant(std::nanf("")), 0);
  r = clusterScene(nan, cfg);
  EXPECT_TRUE(r.clusters.empty());
  EXPECT_EQ(r.non_finite, 100u);
  // A huge input is voxelised coarser, with a warning, and still segmented.
  cfg.max_input_points = 20000;
  r = clusterScene(syntheticScene(2), cfg);
  EXPECT_EQ(r.clusters.size(), 3u);
  bool warned = false;
  for (const auto& w : r.warnings) warned = warned || w.find("max_input_points") != std::string::npos;
  EXPECT_TRUE(warned);
  EXPECT_LT(r.after_voxel, 30000u);
}

TEST(Clustering, ShippedConfigLoadsAndTyposAreNamed) {
  const ClusteringConfig c = loadClusteringConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/clustering.yaml");
  EXPECT_TRUE(c.crop);
  const std::string dir = cellsight_test::tempDir();
  cellsight_test::writeText(dir + "/c.yaml", "cluster_tolerence: 0.003\n");
  const std::string msg = cellsight_test::errorOf([&] { loadClusteringConfig(dir + "/c.yaml"); });
  EXPECT_NE(msg.find("cluster_tolerence: unknown key"), std::string::npos) << msg;
  for (const auto& [text, key] : std::vector<std::pair<std::string, std::string>>{
           {"max_input_points: -1\n", "max_input_points"}, {"min_cluster_points: 0\n", "min_cluster_points"}}) {
    cellsight_test::writeText(dir + "/c.yaml", text);
    const std::string e = cellsight_test::errorOf([&] { loadClusteringConfig(dir + "/c.yaml"); });
    EXPECT_NE(e.find(key + ": must be"), std::string::npos) << text << " -> " << e;
  }
}
