// locateScan(): the localization pipeline's entry point runs its passes exactly as the matcher's
// own calls would (locate, mergePasses, refine), and refuses malformed pass lists.
#include <gtest/gtest.h>

#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/localization/scan_localization.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {

const std::string kModels = std::string(CELLSIGHT_SOURCE_DIR) + "/config/models";
const Eigen::Vector3f kEye(0.52f, 0.f, 0.62f);  // the demo's scanner camera
const Eigen::Vector4f kTable(0, 0, 1, 0);

std::shared_ptr<const ModelLibrary> library() {
  static auto lib = std::make_shared<const ModelLibrary>(kModels);
  return lib;
}

Eigen::Isometry3d onTable(double x, double y, double yaw) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, 0);
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

ScanPass pass(PassRole role, std::vector<ScanCloud> clusters, std::vector<Eigen::Vector3f> table_points = {}) {
  ScanPass p;
  p.role = role;
  p.clusters = std::move(clusters);
  p.evidence.viewpoint = kEye;
  p.evidence.support_plane = kTable;
  p.evidence.support_points = std::move(table_points);
  return p;
}

void expectSame(const std::vector<PartDetection>& a, const std::vector<PartDetection>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].model, b[i].model) << i;
    EXPECT_TRUE(a[i].pose.isApprox(b[i].pose, 0.0)) << i;
    EXPECT_EQ(a[i].pass, b[i].pass) << i;
    EXPECT_EQ(a[i].refined, b[i].refined) << i;
  }
}

}  // namespace

// A housing seen in the first pass, a bracket only in the second, the housing scanned again for
// refinement: the detections are those of locate + mergePasses + refine called by hand.
TEST(ScanLocalization, PassesGiveWhatTheMatcherGivesCalledByHand) {
  const ModelEntry& housing = library()->model("housing");
  const ModelEntry& bracket = library()->model("bracket");
  const Eigen::Isometry3d T_housing = onTable(0.48, 0.03, 0.6), T_bracket = onTable(0.56, -0.05, 2.1);
  const ScanCloud a = singleViewCloud(housing.mesh, T_housing, kEye, 0.001, 2e-5, 1);
  const ScanCloud b = singleViewCloud(bracket.mesh, T_bracket, kEye, 0.001, 2e-5, 2);
  const ScanCloud c = singleViewCloud(housing.mesh, T_housing, kEye, 0.0007, 2e-5, 3);
  const std::vector<Eigen::Vector3f> table_a{{0.40f, 0.10f, 0.f}}, table_b{{0.62f, 0.08f, 0.f}};
  MatchingConfig cfg;
  cfg.viewpoint = kEye;
  const ModelMatcher m(library(), cfg);
  const std::vector<std::string> models{"housing", "bracket"};

  const std::vector<ScanPass> passes{pass(PassRole::kDetect, {a}, table_a), pass(PassRole::kAddDetections, {b}, table_b),
                                     pass(PassRole::kRefine, {c})};
  const LocatedScan located = locateScan(m, passes, models);
  // the passes one by one, as the node receives them, give the same after each
  LocatedScan one_by_one;
  for (size_t k = 0; k < passes.size(); ++k) {
    addPass(m, passes, &one_by_one, models);
    ASSERT_EQ(one_by_one.passes.size(), k + 1);
    expectSame(one_by_one.passes[k].found, located.passes[k].found);
  }
  expectSame(one_by_one.parts, located.parts);
  EXPECT_EQ(one_by_one.stats.second_pass_added, located.stats.second_pass_added);
  EXPECT_THROW(addPass(m, passes, &one_by_one, models), std::invalid_argument);  // none left

  MatchStats st;
  const auto first = m.locate({a}, models, &st, &kEye, &kTable, &table_a, nullptr, nullptr);
  std::vector<Eigen::Vector3f> both = table_b;
  both.insert(both.end(), table_a.begin(), table_a.end());
  const auto second = m.locate({b}, models, nullptr, &kEye, &kTable, &both, nullptr, nullptr);
  const auto merged = m.mergePasses(first, second, &st);
  ScanCloud above = c;
  above.points.insert(above.points.end(), b.points.begin(), b.points.end());
  above.points.insert(above.points.end(), a.points.begin(), a.points.end());
  const auto refined = m.refine(above, merged, nullptr, &kEye, &kTable);

  ASSERT_EQ(located.passes.size(), 3u);
  expectSame(located.passes[0].found, first);
  expectSame(located.passes[1].found, second);
  expectSame(located.parts, refined);
  ASSERT_EQ(located.parts.size(), 2u);
  EXPECT_EQ(located.stats.second_pass_added, 1u);
  EXPECT_EQ(located.parts[1].model, "bracket");
  EXPECT_EQ(located.parts[1].pass, 1);
  for (const auto& d : located.parts) {
    const Eigen::Isometry3d& truth = d.model == "housing" ? T_housing : T_bracket;
    const PoseError e = poseError(library()->model(d.model).info, m.centroid(d.model), d.pose, truth);
    EXPECT_LT(e.translation, 1e-3) << d.model;
  }
}

TEST(ScanLocalization, MalformedPassListsAreRefusedByName) {
  const ModelMatcher m(library(), MatchingConfig{});
  EXPECT_THROW(locateScan(m, {}), std::invalid_argument);
  const std::string add_first = cellsight_test::errorOf([&] { locateScan(m, {pass(PassRole::kAddDetections, {})}); });
  EXPECT_NE(add_first.find("the first pass must detect, not add_detections"), std::string::npos) << add_first;
  const std::string twice =
      cellsight_test::errorOf([&] { locateScan(m, {pass(PassRole::kDetect, {}), pass(PassRole::kDetect, {})}); });
  EXPECT_NE(twice.find("pass 1 detects again"), std::string::npos) << twice;
  LocatedScan so_far;
  const std::string add_alone = cellsight_test::errorOf([&] { addPass(m, {pass(PassRole::kRefine, {})}, &so_far); });
  EXPECT_NE(add_alone.find("the first pass must detect, not refine"), std::string::npos) << add_alone;
  // an empty first pass is no error: nothing found
  EXPECT_TRUE(locateScan(m, {pass(PassRole::kDetect, {})}).parts.empty());
  EXPECT_THROW(locateScan(m, {pass(PassRole::kDetect, {})}, {"no_such_part"}), std::out_of_range);
  for (PassRole r : {PassRole::kDetect, PassRole::kAddDetections, PassRole::kRefine})
    EXPECT_EQ(passRoleFromName(passRoleName(r)), r);
  EXPECT_THROW(passRoleFromName("scan"), std::invalid_argument);
}
