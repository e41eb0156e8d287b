#include <gtest/gtest.h>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/localization/model_library.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

TEST(ModelLibrary, SampledCloudsHaveTheResolutionAndOutwardNormals) {
  const ScanCloud c = sampleMesh(makeBox({0.04, 0.03, 0.02}), 0.001, 3);
  // Surface 2·(12 + 8 + 6) cm² at 1 mm spacing: about 5 200 points.
  EXPECT_GT(c.size(), 4000u);
  EXPECT_LT(c.size(), 6500u);
  ASSERT_EQ(c.normals.size(), c.size());
  size_t outward = 0;
  for (size_t i = 0; i < c.size(); ++i) outward += c.normals[i].dot(c.points[i]) > 0;
  EXPECT_EQ(outward, c.size());  // box centred at the origin: every face normal points away
  EXPECT_THROW(sampleMesh(makeBox({1, 1, 1}), 0.0), std::invalid_argument);
}

// Samples are points of the surface with their face's normal (cell centroids would sit inside
// the solid at every edge, with blended normals).
TEST(ModelLibrary, SamplesLieOnTheSurface) {
  const TriangleMesh box = makeBox({0.04, 0.03, 0.02});
  const ScanCloud c = sampleMesh(box, 0.001, 3);
  size_t on_edge_band = 0;
  for (size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3f p = c.points[i], a = p.cwiseAbs();
    const Eigen::Vector3f half(0.02f, 0.015f, 0.01f);
    const float off = (a - half).maxCoeff();  // 0 on the box's surface, < 0 inside
    EXPECT_NEAR(off, 0.f, 1e-6f) << i;
    // the normal is the axis of a face the point lies on
    int axis;
    c.normals[i].cwiseAbs().maxCoeff(&axis);
    EXPECT_NEAR(std::abs(c.normals[i][axis]), 1.f, 1e-5f) << i;
    EXPECT_NEAR(a[axis], half[axis], 1e-6f) << i;
    on_edge_band += ((half - a).array() < 0.0005f).count() >= 2;
  }
  EXPECT_GT(on_edge_band, 50u);  // edges are sampled too
}

TEST(ModelLibrary, ShippedModelsLoadCacheAndDescribe) {
  const ModelLibrary lib(std::string(CELLSIGHT_SOURCE_DIR) + "/config/models");
  EXPECT_GE(lib.ids().size(), 6u);
  const auto a = lib.cloud("housing", 0.002), b = lib.cloud("housing", 0.002);
  EXPECT_EQ(a.get(), b.get());  // cached
  EXPECT_GT(a->size(), 1000u);
  const auto d = lib.descriptors("housing", 0.002, 0.01);
  ASSERT_EQ(d->size(), a->size());
  float sum = 0;
  for (float x : (*d)[0]) sum += x;
  EXPECT_NEAR(sum, 300.f, 1.f);  // FPFH: three 11-bin histograms of 100 each
  EXPECT_EQ(lib.descriptors("housing", 0.002, 0.01).get(), d.get());
  try {
    lib.model("nope");
    FAIL();
  } catch (const std::out_of_range& e) {
    EXPECT_NE(std::string(e.what()).find("unknown model 'nope'"), std::string::npos);
  }
}

TEST(ModelLibrary, FlatModelWarnsAndCorruptModelIsRefused) {
  const std::string dir = cellsight_test::tempDir();
  makeDirs(dir + "/plate");
  saveMeshPly(dir + "/plate/mesh.ply", makeBox({0.1, 0.1, 0.0005}));
  cellsight_test::writeText(dir + "/plate/model.yaml", "id: plate\nmesh: mesh.ply\n");
  const ModelLibrary lib(dir);
  ASSERT_EQ(lib.model("plate").warnings.size(), 1u);
  EXPECT_NE(lib.model("plate").warnings[0].find("flat"), std::string::npos);
  makeDirs(dir + "/broken");
  cellsight_test::writeText(dir + "/broken/mesh.ply", "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n");
  cellsight_test::writeText(dir + "/broken/model.yaml", "id: broken\nmesh: mesh.ply\n");
  EXPECT_THROW(ModelLibrary{dir}, ConfigError);
}
