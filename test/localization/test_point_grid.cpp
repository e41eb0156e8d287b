#include <gtest/gtest.h>

#include <pcl/features/normal_3d.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include <random>

#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/common/point_grid.hpp"

using namespace cellsight;

namespace {

std::vector<Eigen::Vector3f> randomCloud(size_t n, float extent, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(-extent, extent);
  std::vector<Eigen::Vector3f> p(n);
  for (auto& x : p) x = Eigen::Vector3f(U(rng), U(rng), 0.3f * U(rng));
  return p;
}

}  // namespace

// Radius and any-within queries against brute force, with the dense cell array (a
// compact cloud) and the hash map (two far-apart clumps), and with NaN points left out.
TEST(PointGrid, QueriesMatchBruteForce) {
  std::vector<Eigen::Vector3f> dense = randomCloud(3000, 0.05f, 1);
  std::vector<Eigen::Vector3f> sparse = randomCloud(1500, 0.02f, 2);
  for (auto p : randomCloud(1500, 0.02f, 3)) sparse.push_back(p + Eigen::Vector3f(40.f, -30.f, 5.f));
  dense[7] = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
  for (const auto* cloud : {&dense, &sparse}) {
    const PointGrid grid(*cloud, 0.005f);
    std::mt19937 rng(9);
    std::uniform_int_distribution<size_t> pick(0, cloud->size() - 1);
    std::normal_distribution<float> jitter(0.f, 0.004f);
    for (int i = 0; i < 500; ++i) {
      Eigen::Vector3f q = (*cloud)[pick(rng)];
      if (!q.allFinite()) continue;
      q += Eigen::Vector3f(jitter(rng), jitter(rng), jitter(rng));
      const float r = (i % 3 == 0) ? 0.002f : (i % 3 == 1 ? 0.005f : 0.012f);  // below, at and above the cell
      std::vector<uint32_t> want, got;
      for (size_t k = 0; k < cloud->size(); ++k) {
        if (!(*cloud)[k].allFinite()) continue;
        if (((*cloud)[k] - q).squaredNorm() <= r * r) want.push_back(static_cast<uint32_t>(k));
      }
      grid.forEachWithin(q, r, [&](uint32_t k, float d2) {
        got.push_back(k);
        EXPECT_NEAR(d2, ((*cloud)[k] - q).squaredNorm(), 1e-12f);
      });
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, want) << "query " << i << " r " << r;
      EXPECT_EQ(grid.anyWithin(q, r), !want.empty());
    }
  }
  // outside the points' box and empty grids answer nothing
  const PointGrid grid(dense, 0.005f);
  EXPECT_FALSE(grid.anyWithin(Eigen::Vector3f(1, 1, 1), 0.01f));
  EXPECT_FALSE(PointGrid({}, 0.01f).anyWithin(Eigen::Vector3f::Zero(), 1.f));
  EXPECT_THROW(PointGrid(dense, 0.f), std::invalid_argument);
}

// The grid's PCA normals are PCL's NormalEstimation (radius search over the full-resolution
// points, turned toward the viewpoint) on a single-view scan of a part with edges and corners.
TEST(PointGrid, NormalsMatchPcl) {
  ModelLibrary lib(std::string(CELLSIGHT_SOURCE_DIR) + "/config/models");
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(0.5, 0.02, 0);
  const Eigen::Vector3f eye(0.52f, 0.f, 0.62f);
  const ScanCloud view = singleViewCloud(lib.model("bracket").mesh, T, eye, 0.001, 2e-5, 4);
  ASSERT_GT(view.size(), 1000u);
  std::vector<Eigen::Vector3f> queries;
  for (size_t i = 0; i < view.size(); i += 3) queries.push_back(view.points[i]);
  const float radius = 0.005f;
  const PointGrid grid(view.points, radius);
  const std::vector<Eigen::Vector3f> ours = gridNormals(grid, queries, radius, eye);

  pcl::PointCloud<pcl::PointXYZ>::Ptr all(new pcl::PointCloud<pcl::PointXYZ>), q(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& p : view.points) all->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  for (const auto& p : queries) q->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
  ne.setInputCloud(q);
  ne.setSearchSurface(all);
  ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  ne.setRadiusSearch(radius);
  ne.setViewPoint(eye.x(), eye.y(), eye.z());
  pcl::PointCloud<pcl::Normal> theirs;
  ne.compute(theirs);
  ASSERT_EQ(theirs.size(), ours.size());
  double worst = 0;
  for (size_t i = 0; i < ours.size(); ++i) {
    const Eigen::Vector3f n = theirs[i].getNormalVector3fMap();
    ASSERT_EQ(n.allFinite(), ours[i].allFinite()) << i;
    if (!n.allFinite()) continue;
    worst = std::max(worst, static_cast<double>(std::acos(std::clamp(n.normalized().dot(ours[i]), -1.f, 1.f))));
  }
  std::printf("largest angle between PCL's and the grid's normals: %.2e rad over %zu points\n", worst, ours.size());
  EXPECT_LT(worst, 1e-3);
  // fewer than 3 neighbours: NaN, as PCL
  const PointGrid two({Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(0.001f, 0, 0)}, 0.005f);
  EXPECT_FALSE(gridNormals(two, {Eigen::Vector3f(0, 0, 0)}, 0.005f, eye)[0].allFinite());
}
