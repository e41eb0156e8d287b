// The random-cell generator: scenes load, parts rest on the table inside the workspace without
// interpenetrating, the seeds give lying, touching and distractor cases, and one seed is one scene.
#include <gtest/gtest.h>

#include <filesystem>

#include "cellsight/eval/scene_generator.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {
const std::string kConfig = std::string(CELLSIGHT_SOURCE_DIR) + "/config";

struct Footprint {
  Eigen::Vector2d centre;
  double radius, min_z;
};

Footprint footprintOf(const SceneObject& o) {
  const TriangleMesh mesh = loadMesh(o.info.mesh_file);
  Eigen::AlignedBox3d box;
  for (const auto& v : mesh.vertices) box.extend(o.T_base_object * v.cast<double>());
  Footprint f{box.center().head<2>(), 0, box.min().z()};
  for (const auto& v : mesh.vertices)
    f.radius = std::max(f.radius, ((o.T_base_object * v.cast<double>()).head<2>() - f.centre).norm());
  return f;
}
}  // namespace

TEST(SceneGenerator, StableRestsOfABoxAndACylinder) {
  EXPECT_EQ(stableRestRotations(makeBox({0.02, 0.03, 0.04})).size(), 6u);
  EXPECT_EQ(stableRestRotations(makeCylinder(0.01, 0.02)).size(), 2u);  // faceted side: no flat side big enough
  // the first rest of a part is its own standing side
  EXPECT_TRUE(stableRestRotations(makeCylinder(0.01, 0.02)).front().isIdentity(1e-9));
}

TEST(SceneGenerator, TwentySeedsGiveValidVariedScenes) {
  const std::string dir = cellsight_test::tempDir();
  int lying = 0, touching = 0, distractors = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const GeneratedScene g = generateScene(kConfig + "/scenes/demo.yaml", kConfig + "/models", seed, {}, dir);
    const Scene& s = g.scene;
    ASSERT_GE(s.objects.size(), 4u) << "seed " << seed;
    distractors += static_cast<int>(g.distractors.size());
    std::vector<Footprint> fp;
    for (const auto& o : s.objects) {
      fp.push_back(footprintOf(o));
      EXPECT_NEAR(fp.back().min_z, s.table.z, 1e-6) << o.name << " does not rest on the table (seed " << seed << ")";
      EXPECT_GE(fp.back().centre.x() - fp.back().radius, s.workspace.min().x()) << o.name;
      EXPECT_LE(fp.back().centre.x() + fp.back().radius, s.workspace.max().x()) << o.name;
      EXPECT_GE(fp.back().centre.y() - fp.back().radius, s.workspace.min().y()) << o.name;
      EXPECT_LE(fp.back().centre.y() + fp.back().radius, s.workspace.max().y()) << o.name;
      const Eigen::Vector3d up = o.T_base_object.linear().col(2);
      if (o.model.rfind("distractor", 0) != 0 && o.model != "sphere25" && std::abs(up.z()) < 0.99) ++lying;
    }
    for (size_t i = 0; i < fp.size(); ++i) {
      for (size_t j = i + 1; j < fp.size(); ++j) {
        const double gap = (fp[i].centre - fp[j].centre).norm() - fp[i].radius - fp[j].radius;
        EXPECT_GE(gap, -1e-6) << s.objects[i].name << " and " << s.objects[j].name << " overlap (seed " << seed << ")";
        touching += gap < 1e-3;
      }
    }
  }
  std::printf("20 seeds: %d parts lying on a side, %d touching pairs, %d distractors\n", lying, touching, distractors);
  EXPECT_GT(lying, 0);
  EXPECT_GT(touching, 0);
  EXPECT_GT(distractors, 0);
}

TEST(SceneGenerator, OneSeedOneScene) {
  const std::string a = cellsight_test::tempDir(), b = cellsight_test::tempDir();
  const auto ga = generateScene(kConfig + "/scenes/demo.yaml", kConfig + "/models", 5, {}, a);
  const auto gb = generateScene(kConfig + "/scenes/demo.yaml", kConfig + "/models", 5, {}, b);
  EXPECT_EQ(ga.scene.objects.size(), gb.scene.objects.size());
  for (size_t i = 0; i < ga.scene.objects.size(); ++i)
    EXPECT_TRUE(ga.scene.objects[i].T_base_object.isApprox(gb.scene.objects[i].T_base_object, 1e-12));
  const auto gc = generateScene(kConfig + "/scenes/demo.yaml", kConfig + "/models", 6, {}, a);
  EXPECT_NE(ga.yaml, gc.yaml);
}
