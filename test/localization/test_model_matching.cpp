#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/localization/light_sweep.hpp"
#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/localization/rest_poses.hpp"
#include "test_helpers.hpp"

using namespace cellsight;
using cellsight_test::errorOf;

namespace {

const std::string kModels = std::string(CELLSIGHT_SOURCE_DIR) + "/config/models";
const Eigen::Vector3f kEye(0.52f, 0.f, 0.62f);  // the demo's scanner camera

std::shared_ptr<const ModelLibrary> library() {
  static auto lib = std::make_shared<const ModelLibrary>(kModels);
  return lib;
}

MatchingConfig config() {
  MatchingConfig c;
  c.viewpoint = kEye;
  return c;
}

Eigen::Isometry3d onTable(double x, double y, double yaw) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, 0);
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

/// What the camera sees of `mesh` at T (singleViewCloud) and the sheet of `sweep` reached
/// unshadowed by the part: the points a laser-line scan of it holds.
ScanCloud litView(const TriangleMesh& mesh, const Eigen::Isometry3d& T, const LightSweep& sweep, uint64_t seed) {
  const ScanCloud view = singleViewCloud(mesh, T, kEye, 0.001, 2e-5, seed);
  RayCaster part;
  part.addMesh(mesh, T);
  part.commit();
  ScanCloud lit;
  for (size_t i = 0; i < view.size(); ++i) {
    Eigen::Vector3f e;
    if (!sweep.emitterFor(view.points[i], &e)) continue;
    const Eigen::Vector3f beam = view.points[i] - e;
    const float along = beam.norm();
    if (!part.occluded(e, beam / along, 0.f, along - 0.0005f)) lit.append(view.points[i], 0.f);
  }
  return lit;
}

}  // namespace

TEST(ModelMatching, FindsEachPartInItsSingleViewCloud) {
  ModelMatcher m(library(), config());
  int k = 0;
  for (const std::string id : {"bracket", "housing", "blade", "holder"}) {
    const Eigen::Isometry3d truth = onTable(0.45 + 0.03 * k, -0.05 + 0.04 * k, 0.4 + 1.3 * k);
    ++k;
    const ScanCloud view = singleViewCloud(library()->model(id).mesh, truth, kEye, 0.001, 2e-5, 7 + k);
    MatchStats st;
    const auto d = m.locate({view}, {}, &st);
    ASSERT_EQ(d.size(), 1u) << id;
    EXPECT_EQ(d[0].model, id);
    const PoseError e = poseError(library()->model(id).info, m.centroid(id), d[0].pose, truth);
    std::printf("%-8s %zu points: %.3f mm %.3f deg, fitness %.2f coverage %.2f rmse %.3f mm, %.3f s\n", id.c_str(),
                view.size(), e.translation * 1e3, e.rotation * 180 / M_PI, d[0].fitness, d[0].coverage, d[0].rmse * 1e3,
                st.seconds);
    EXPECT_LT(e.translation, 0.5e-3) << id;
    EXPECT_LT(e.rotation, 0.5 * M_PI / 180) << id;
  }
}

TEST(ModelMatching, SymmetryAwareErrorsAndCanonicalPoses) {
  ModelInfo info;
  const Eigen::Vector3d c(0, 0, 0.01);
  const Eigen::Isometry3d T = onTable(0.5, 0.1, 0.3);
  const Eigen::Isometry3d half = T * onTable(0, 0, M_PI);
  info.symmetry.type = Symmetry::Type::kNone;
  EXPECT_NEAR(poseError(info, c, half, T).rotation, M_PI, 1e-9);
  info.symmetry.type = Symmetry::Type::kDiscrete;
  info.symmetry.order = 2;
  EXPECT_NEAR(poseError(info, c, half, T).rotation, 0, 1e-9);
  EXPECT_NEAR(poseError(info, c, T * onTable(0, 0, 0.5 * M_PI), T).rotation, 0.5 * M_PI, 1e-9);
  // canonical poses of equivalent poses coincide
  EXPECT_TRUE(canonicalPose(info, c, half).isApprox(canonicalPose(info, c, T), 1e-9));
  info.symmetry.type = Symmetry::Type::kAxial;
  EXPECT_NEAR(poseError(info, c, T * onTable(0, 0, 1.234), T).rotation, 0, 1e-9);
  EXPECT_TRUE(canonicalPose(info, c, T * onTable(0, 0, 1.234)).isApprox(canonicalPose(info, c, T), 1e-9));
  Eigen::Isometry3d tilted = T;
  tilted.linear() = T.linear() * Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()).toRotationMatrix();
  EXPECT_NEAR(poseError(info, c, tilted, T).rotation, 0.1, 1e-9);
  info.symmetry.type = Symmetry::Type::kSpherical;
  EXPECT_EQ(poseError(info, c, tilted, T).rotation, 0);
  const Eigen::Isometry3d s = canonicalPose(info, c, tilted);
  EXPECT_TRUE(s.linear().isIdentity(1e-12));
  EXPECT_TRUE((s * c).isApprox(tilted * c, 1e-12));  // the centre stays
}

TEST(ModelMatching, OcclusionAndOutliersKeepThePart) {
  ModelMatcher m(library(), config());
  const Eigen::Isometry3d truth = onTable(0.5, 0.02, 0.7);
  const ScanCloud view = singleViewCloud(library()->model("bracket").mesh, truth, kEye, 0.001, 2e-5, 3);
  std::mt19937_64 rng(5);
  const ScanCloud occluded = randomWalkOcclusion(view, 0.4, 20, rng);
  EXPECT_NEAR(static_cast<double>(occluded.size()) / view.size(), 0.6, 0.01);
  Eigen::AlignedBox3f box;
  for (const auto& p : view.points) box.extend(p);
  const ScanCloud noisy = addUniformOutliers(view, box, 1.0, rng);
  EXPECT_EQ(noisy.size(), 2 * view.size());
  MatchingConfig whole = config();
  whole.min_coverage = 0;  // outliers are not part of the cluster to explain
  ModelMatcher mw(library(), whole);
  for (const ScanCloud* c : {&occluded, &noisy}) {
    MatchStats st;
    const auto d = (c == &noisy ? mw : m).locate({*c}, {"bracket", "housing"}, &st);
    ASSERT_GE(d.size(), 1u) << (c == &noisy ? "outliers" : "occlusion");
    EXPECT_EQ(d[0].model, "bracket");
    const PoseError e = poseError(library()->model("bracket").info, m.centroid("bracket"), d[0].pose, truth);
    // strict success (2 mm / 2 deg): seen from above, the bracket's in-plane pose rests on its
    // outline, and uniform outliers near the surface move it within that slack (over 10 seeds at
    // 100 % outliers: 0.05-0.37 mm, 0.01-1.1 deg)
    EXPECT_LT(e.translation, 2e-3);
    EXPECT_LT(e.rotation, 2 * M_PI / 180);
  }
}

// A U-profile seen from above says little along its extrusion once the walk has eaten an end:
// the exact polish (mesh face normals) is then singular in that direction and used to step
// metres along it (occlusion test, holder at 25 %: 80 % success). Unconstrained directions get
// no step now (measured, 40 trials: 36 with the plain LDLT solve, 40 now).
TEST(ModelMatching, UnconstrainedDirectionGetsNoStep) {
  MatchingConfig c = config();
  c.min_fitness = 0.1;  // as the occlusion test
  ModelMatcher m(library(), c);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> U(0, 1);
  const Eigen::Vector4f table(0, 0, 1, 0);
  int ok = 0;
  const int trials = 40;
  for (int t = 0; t < trials; ++t) {
    const Eigen::Isometry3d truth = onTable(0.40 + 0.24 * U(rng), -0.09 + 0.18 * U(rng), 2 * M_PI * U(rng));
    const ScanCloud view = singleViewCloud(library()->model("holder").mesh, truth, kEye, 0.001, 2e-5, rng());
    const auto d = m.locate({randomWalkOcclusion(view, 0.25, 20, rng)}, {"holder"}, nullptr, nullptr, &table);
    if (d.empty()) continue;
    ASSERT_TRUE(d[0].pose.matrix().allFinite());
    const PoseError e = poseError(library()->model("holder").info, m.centroid("holder"), d[0].pose, truth);
    ok += e.translation < 2e-3 && e.rotation < 2 * M_PI / 180;
  }
  std::printf("holder, 25 %% occluded: %d of %d within 2 mm / 2 deg\n", ok, trials);
  EXPECT_GE(ok, trials - 1);
}

// A blade whose root block the walk removed is a thin tapered plate: seen from above it fits
// upside down too (measured: most blade failures at 30-45 % occlusion). With the table given,
// sunken poses are discarded; a plane above the part leaves no physical pose at all.
TEST(ModelMatching, SupportPlaneDiscardsSunkenPoses) {
  ModelMatcher m(library(), config());
  const Eigen::Isometry3d truth = onTable(0.47, 0.03, 2.1);
  const ScanCloud view = singleViewCloud(library()->model("blade").mesh, truth, kEye, 0.001, 2e-5, 11);
  const Eigen::Vector4f table(0, 0, 1, 0), above(0, 0, 1, -0.02);
  const auto on_table = m.locate({view}, {"blade"}, nullptr, nullptr, &table);
  ASSERT_EQ(on_table.size(), 1u);
  const PoseError e = poseError(library()->model("blade").info, m.centroid("blade"), on_table[0].pose, truth);
  EXPECT_LT(e.translation, 0.5e-3);
  EXPECT_LT(e.rotation, 0.5 * M_PI / 180);
  MatchStats st;
  EXPECT_TRUE(m.locate({view}, {"blade"}, &st, nullptr, &above).empty());
}

namespace {
/// The table (z = 0) around a part as the camera at kEye sees it: 1 mm grid points within
/// `half` of (x, y), those hidden by the part left out unless `through` (a camera that saw
/// through the part: what the free-space test must refuse).
std::vector<Eigen::Vector3f> seenTable(const TriangleMesh& mesh, const Eigen::Isometry3d& T, float half, bool through) {
  RayCaster rc;
  rc.addMesh(mesh, T);
  rc.commit();
  std::vector<Eigen::Vector3f> out;
  const Eigen::Vector3f c = T.translation().cast<float>();
  for (float x = c.x() - half; x <= c.x() + half; x += 0.001f) {
    for (float y = c.y() - half; y <= c.y() + half; y += 0.001f) {
      const Eigen::Vector3f p(x, y, 0.f);
      const Eigen::Vector3f ray = p - kEye;
      if (!through && rc.occluded(kEye, ray.normalized(), 0.f, ray.norm() - 1e-4f)) continue;
      out.push_back(p);
    }
  }
  return out;
}
}  // namespace

namespace {
const std::string kData = std::string(CELLSIGHT_SOURCE_DIR) + "/test/localization/data/";

/// A true pose as the scene files give it (t; q as w, x, y, z).
Eigen::Isometry3d truePose(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = t;
  T.linear() = q.normalized().toRotationMatrix();
  return T;
}

/// A cluster the simulated scanner recorded (test/localization/data/<file>) located among
/// `models` on the table z = 0, floating poses refused: the detections, and the first one's
/// error against the part's true pose (t; q as w, x, y, z).
struct Recorded {
  std::vector<PartDetection> found;
  PoseError error;
};
Recorded locateRecorded(const std::string& file, size_t points, const std::vector<std::string>& models,
                        const std::string& part, const Eigen::Vector3d& t, const Eigen::Quaterniond& q,
                        int rest_candidates = 0) {
  MatchingConfig c = config();
  c.max_support_gap = 0.005;
  c.rest_candidates = rest_candidates;
  ModelMatcher m(library(), c);
  const ScanCloud view = loadCloud(kData + file);
  EXPECT_EQ(view.size(), points);
  const Eigen::Isometry3d truth = truePose(t, q);
  const Eigen::Vector4f table(0, 0, 1, 0);
  Recorded r;
  r.found = m.locate({view}, models, nullptr, nullptr, &table);
  if (!r.found.empty()) r.error = poseError(library()->model(part).info, m.centroid(part), r.found[0].pose, truth);
  return r;
}
}  // namespace

// A shaft standing on its end, flange up, as the simulated scanner saw it in generated cell
// 3001: one flat disc (the rim is too steep or in the laser's shadow). Its point pairs share one
// feature, which the PPF table leaves out; the part's flat faces are laid onto the disc instead,
// and the flange-down reading of the disc, floating 55 mm above the table, is refused.
TEST(ModelMatching, FlatViewIsLaidOnTheFacesAndFloatingPosesAreRefused) {
  const Recorded r = locateRecorded(
      "shaft_on_its_end.ply", 904, {"flanged_shaft"}, "flanged_shaft", {0.4097116667616737, -0.04060711225567744, 0.0625},
      {6.082787948976912e-17, -0.11474777071769761, 0.9933946592947431, 7.026274505936138e-18});
  ASSERT_EQ(r.found.size(), 1u);
  EXPECT_LT(r.error.translation, 1e-3);
  EXPECT_LT(r.error.rotation, 1 * M_PI / 180);
}

// A bracket lying on its side (a real cluster of the simulator's scan, seed 3010): the camera
// sees its L face, 5 mm strips, and a little of the boss and the rib. Most points lie on that
// face, so their pairs share one feature that PPF leaves out; laid onto the patch, the face is
// a few millimetres off (only part of it is scanned) and must be brought in before it is
// ranked, or a wrong face that happens to be centred explains more. Every model is tried.
TEST(ModelMatching, ABracketOnItsSideIsFoundFromItsLFace) {
  const Recorded r = locateRecorded(
      "bracket_on_its_side.ply", 282, {}, "bracket", {0.59029575278284996, 0.093655090378981481, 0.019999999552965164},
      {0.68004937342103744, 0.68004937342103733, 0.19373396632922787, 0.1937339663292279});
  ASSERT_EQ(r.found.size(), 1u);
  EXPECT_EQ(r.found[0].model, "bracket");
  EXPECT_LT(r.error.translation, 1e-3);
  EXPECT_LT(r.error.rotation, 1 * M_PI / 180);
}

// A bracket lying on its side in generated cell 3082 (the simulator's scan, self-calibrated):
// PPF alone does not find it. Laid in each of its stable rests on the table, turned in 15°
// steps and brought in, it is found.
TEST(ModelMatching, APartLyingOnTheTableIsFoundFromItsRests) {
  const Eigen::Vector3d t(0.64128073083887493, 0.066760020858458335, 0.019999999552965164);
  const Eigen::Quaterniond q(0.67694612164135337, 0.67694612164135304, -0.20431335833647821, -0.20431335833647823);
  EXPECT_TRUE(locateRecorded("bracket_on_its_side_3082.ply", 437, {"bracket"}, "bracket", t, q, 0).found.empty())
      << "PPF alone finds this bracket now: the test no longer shows what the rest poses add";
  const Recorded r = locateRecorded("bracket_on_its_side_3082.ply", 437, {"bracket"}, "bracket", t, q, 3);
  ASSERT_EQ(r.found.size(), 1u);
  EXPECT_LT(r.error.translation, 1e-3);
  EXPECT_LT(r.error.rotation, 1 * M_PI / 180);
}

// A bracket standing on its side as the simulated scanner saw it in generated cell 3014 (capture
// seed 2's calibration), with the scan's sweep (cellsight_evaluate_localization cells
// --dump-clusters). Its refined pose stops 1.4 mm off across its narrow top face, whose far
// model edge then reaches 3 mm past the scanned one: the unseen test refuses it there. Centred in
// its slack first, the pose is right and the unseen share is measured where it settles.
TEST(ModelMatching, APoseIsCentredInItsSlackBeforeItsUnseenShareIsTaken) {
  const ScanCloud view = loadCloud(kData + "bracket_standing_3014.ply");
  ASSERT_EQ(view.size(), 244u);
  const LightSweep sweep = loadSweep(kData + "sweep_3014.txt");
  ASSERT_EQ(sweep.size(), 150u);
  const Eigen::Isometry3d truth =
      truePose({0.53838319225177966, -0.062067200442959179, 0.019999999552965164},
               {0.53692517908050297, -0.53692517908050263, 0.46012101893889812, -0.46012101893889823});
  const MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  MatchingConfig c = shipped;
  c.viewpoint = kEye;
  // rest poses centred on the cluster only: laid on its ends too, one of them polishes to a
  // pose the unseen test passes uncentred (the shipped settings, checked below)
  c.rest_end_ratio = 0;
  const Eigen::Vector4f table(0, 0, 1, 0);
  auto run = [&](bool centre, MatchStats* st) {
    c.icp_centre_slack = centre;
    return ModelMatcher(library(), c).locate({view}, {"bracket"}, st, nullptr, &table, nullptr, &sweep);
  };
  MatchStats st;
  EXPECT_TRUE(run(false, &st).empty()) << "found uncentred: the test no longer shows what the centring adds";
  ASSERT_FALSE(st.rejected.empty());
  EXPECT_GT(st.rejected[0].unseen, c.max_unseen);
  const auto found = run(true, nullptr);
  ASSERT_EQ(found.size(), 1u);
  const PoseError e = poseError(library()->model("bracket").info, ModelMatcher(library(), c).centroid("bracket"),
                                found[0].pose, truth);
  std::printf("uncentred: refused at unseen %.3f; centred: %.2f mm, %.2f deg off, unseen %.3f\n", st.rejected[0].unseen,
              e.translation * 1e3, e.rotation * 180 / M_PI, found[0].unseen);
  EXPECT_LT(e.translation, 0.5e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  EXPECT_LE(found[0].unseen, c.max_unseen);
  // as shipped
  c = shipped;
  c.viewpoint = kEye;
  const auto as_shipped = ModelMatcher(library(), c).locate({view}, {"bracket"}, nullptr, nullptr, &table, nullptr, &sweep);
  ASSERT_EQ(as_shipped.size(), 1u);
  const PoseError s = poseError(library()->model("bracket").info, ModelMatcher(library(), c).centroid("bracket"),
                                as_shipped[0].pose, truth);
  std::printf("as shipped: %.2f mm, %.2f deg off\n", s.translation * 1e3, s.rotation * 180 / M_PI);
  EXPECT_LT(s.translation, 0.5e-3);
  EXPECT_LT(s.rotation, 1 * M_PI / 180);
}

// A shaft standing on its end, flange up, near the workspace's end as the simulated scanner saw
// it in generated cell 3017 (capture seed 1's calibration, with the scan's sweep): 62 mm up, the
// sheet's fan reaches only a 17 mm strip of the 50 mm flange. Laid centred on the strip, the
// flange is 15 mm off, and a short ICP on a flat face does not slide it back; laid with its end
// on the strip's end, it is found. Turned about its own axis it is one pose, so the turns do not
// fill the rest quota with copies of the centred one.
TEST(ModelMatching, APartlyLitFlangeIsLaidByItsEnd) {
  const ScanCloud view = loadCloud(kData + "shaft_flange_up_at_the_fan_edge_3017.ply");
  ASSERT_EQ(view.size(), 355u);
  const LightSweep sweep = loadSweep(kData + "sweep_capture_seed_1.txt");
  ASSERT_EQ(sweep.size(), 150u);
  const Eigen::Isometry3d truth = truePose({0.38309092001588868, 0.086631768258378677, 0.0625},
                                           {1.3262429713065958e-17, 0.97626223053469918, 0.21659191404901035,
                                            -5.9778820787638735e-17});
  MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  c.viewpoint = kEye;
  const Eigen::Vector4f table(0, 0, 1, 0);
  auto run = [&](int rests) {
    c.rest_candidates = rests;
    ModelMatcher m(library(), c);
    const auto d = m.locate({view}, {"flanged_shaft"}, nullptr, nullptr, &table, nullptr, &sweep);
    return d.empty() ? PoseError{1e9, 1e9} : poseError(library()->model("flanged_shaft").info, m.centroid("flanged_shaft"), d[0].pose, truth);
  };
  const PoseError without = run(0), with = run(3);
  std::printf("without rests: %s; with: %.2f mm, %.2f deg off\n",
              without.translation > 1 ? "none found" : (std::to_string(without.translation * 1e3) + " mm off").c_str(),
              with.translation * 1e3, with.rotation * 180 / M_PI);
  EXPECT_GT(without.translation, 5e-3) << "PPF alone finds it now: the test no longer shows what the rests add";
  EXPECT_LT(with.translation, 1e-3);
  EXPECT_LT(with.rotation, 1 * M_PI / 180);
}

namespace {
/// Clusters of one generated cell recorded in test/localization/data (each file's point count
/// checked) and the scan's sweep (the demo sweep as one calibration placed it: one file per
/// capture seed, shared by every cell scanned with it).
struct RecordedCell {
  std::vector<ScanCloud> clusters;
  LightSweep sweep;
};
RecordedCell recordedCell(const std::vector<std::pair<std::string, size_t>>& clusters, const std::string& sweep) {
  RecordedCell cell;
  for (const auto& [file, points] : clusters) {
    cell.clusters.push_back(loadCloud(kData + file));
    EXPECT_EQ(cell.clusters.back().size(), points) << file;
  }
  cell.sweep = loadSweep(kData + sweep);
  return cell;
}

/// Recorded clusters of a tuning cell (capture seed 1's calibration) located among `models`
/// with the shipped settings as `set` changes them, on the table z = 0 with the scan's sweep:
/// the error of the one detection against the part's true pose (1e9 unless exactly one).
PoseError locateRecorded(const std::vector<ScanCloud>& clusters, const std::string& model, const LightSweep& sweep,
                         const Eigen::Isometry3d& truth, const std::function<void(MatchingConfig&)>& set, MatchStats* st,
                         PartDetection* found = nullptr) {
  MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  c.viewpoint = kEye;
  set(c);
  const Eigen::Vector4f table(0, 0, 1, 0);
  ModelMatcher m(library(), c);
  const auto d = m.locate(clusters, {model}, st, nullptr, &table, nullptr, &sweep);
  if (found && d.size() == 1) *found = d[0];
  return d.size() != 1 ? PoseError{1e9, 1e9} : poseError(library()->model(model).info, m.centroid(model), d[0].pose, truth);
}
}  // namespace

// A blade lying flat, recorded in generated cell 3044 (capture seed 1's calibration, with the
// scan's sweep): clustering split it, the blade's top in one cluster, its root block's top,
// 10 mm higher across steep unmeasured sides, in another. Polished on the blade's top alone it
// slides along the blade: the top tapers by 0.1 mm per mm, and the scanner loses about a
// millimetre at each edge, so the edges pin it only to several millimetres. Polished again on
// the root block's points too (polish_split_parts), it is found where it lies.
TEST(ModelMatching, APartThatClusteringSplitIsPolishedOnBothPieces) {
  const RecordedCell cell = recordedCell({{"blade_lying_flat_3044.ply", 668}, {"blade_root_top_3044.ply", 327}}, "sweep_capture_seed_1.txt");
  const Eigen::Isometry3d truth = truePose({0.43718378152497961, -0.019730066610289983, 0.00050000054761767377},
                                           {0.3255348811600759, 0, 0, 0.9455300318594303});
  auto run = [&](bool split, MatchStats* st) {
    return locateRecorded(cell.clusters, "blade", cell.sweep, truth, [&](MatchingConfig& c) { c.polish_split_parts = split; }, st);
  };
  MatchStats one, both;
  const PoseError alone = run(false, &one), polished = run(true, &both);
  std::printf("polished on its cluster: %.2f mm, %.2f deg off; on both pieces: %.2f mm, %.2f deg off (%zu polished, moved %.2f mm)\n",
              alone.translation * 1e3, alone.rotation * 180 / M_PI, polished.translation * 1e3,
              polished.rotation * 180 / M_PI, both.split_parts_polished, both.split_polish_moved * 1e3);
  EXPECT_GT(alone.translation, 2e-3) << "found on one piece now: the test no longer shows what the split polish adds";
  EXPECT_EQ(one.split_parts_polished, 0u);
  EXPECT_EQ(both.split_parts_polished, 1u);
  EXPECT_LT(polished.translation, 0.5e-3);
  EXPECT_LT(polished.rotation, 0.5 * M_PI / 180);
}

// A bracket standing on its base plate, recorded in generated cell 3030 (capture seed 3's
// calibration, with the scan's sweep): clustering split it, the base plate and the boss in one
// piece (679 points), the top of the wall, 40 mm higher across its steep unmeasured side, in
// another (119 points). In the evaluation the plate's pose search went astray; here the plate is
// handed over as fragments (counted as evidence, never searched), so that only the wall top is
// searched: its pose, near the truth, is millimetres off (it holds too little of the part to pin
// it) and refused. Its second look polishes it on the plate's points too, and the bracket is
// found where it stands. (Laid into its rest, rest_snap_angle, the wall top's pose is found
// without the second look: off here, to show what the second look does alone.)
TEST(ModelMatching, ARefusedPieceOfASplitPartIsPolishedOnTheOtherPiece) {
  const RecordedCell cell = recordedCell({{"bracket_base_plate_3030.ply", 679}, {"bracket_wall_top_3030.ply", 119}}, "sweep_capture_seed_3.txt");
  const Eigen::Isometry3d truth = truePose({0.50453454515441021, 0.01839150251415636, 0}, {0.73285835121770204, 0, 0, 0.68038124389967658});
  MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  c.viewpoint = kEye;
  c.rest_snap_angle = 0;
  const Eigen::Vector4f table(0, 0, 1, 0);
  const std::vector<Eigen::Vector3f> plate(cell.clusters[0].points.begin(), cell.clusters[0].points.end());
  const ModelInfo& info = library()->model("bracket").info;
  const Eigen::Vector3d centroid = ModelMatcher(library(), c).centroid("bracket");
  auto run = [&](bool look, MatchStats* st) {
    c.split_second_look = look;
    const auto found = ModelMatcher(library(), c).locate({cell.clusters[1]}, {"bracket"}, st, nullptr, &table, nullptr, &cell.sweep, &plate);
    return found.size() != 1 ? PoseError{1e9, 1e9} : poseError(info, centroid, found[0].pose, truth);
  };
  MatchStats once, twice;
  const PoseError first = run(false, &once), second = run(true, &twice);
  std::printf("without the second look: %s; with it: %.2f mm, %.2f deg off\n",
              first.translation > 1 ? "none found" : (std::to_string(first.translation * 1e3) + " mm off").c_str(),
              second.translation * 1e3, second.rotation * 180 / M_PI);
  EXPECT_GT(first.translation, 1.0) << "found without it now: the test no longer shows what the second look adds";
  ASSERT_FALSE(once.rejected.empty());
  EXPECT_LT(poseError(info, centroid, once.rejected[0].pose, truth).translation, 5e-3) << "the refused pose is not near the truth";
  EXPECT_EQ(once.split_second_look, 0u);
  EXPECT_EQ(twice.split_second_look, 1u);
  EXPECT_LT(second.translation, 0.5e-3);
  EXPECT_LT(second.rotation, 0.5 * M_PI / 180);
}

// A cylinder that is not in the library, 48 mm across and 31.1 mm tall, recorded in generated
// cell 3061 (capture seed 3's calibration, with the scan's sweep): the holder upside down on it
// (its flat bottom, 50 x 30 mm, on the cylinder's top) explains the top and overhangs it only
// at its corners. Its arms then reach into the table, which parts rest on, not in (0.97 mm below
// z = 0 here, 0.9 mm below the table the evaluation fitted): with the support limits of 1 mm it
// is taken for a holder, with the shipped 0.5 mm it is refused. The top, 48 mm across, also
// carries on past the holder's 30 mm sides (Surface carried on): the shipped continuation test,
// off here to show the support limits alone, refuses it at 1 mm too.
TEST(ModelMatching, AHolderSunkIntoTheTableByAMillimetreIsRefused) {
  const RecordedCell cell = recordedCell({{"cylinder_distractor_3061.ply", 934}}, "sweep_capture_seed_3.txt");
  auto run = [&](double limit, bool continuation) {
    MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
    c.viewpoint = kEye;
    if (limit > 0) c.max_support_penetration = c.max_support_gap = limit;
    if (!continuation) c.max_continuation = 1;
    const Eigen::Vector4f table(0, 0, 1, 0);
    return ModelMatcher(library(), c).locate(cell.clusters, {"holder"}, nullptr, nullptr, &table, nullptr, &cell.sweep);
  };
  const auto taken = run(0.001, false), shipped = run(0, false);
  EXPECT_TRUE(run(0.001, true).empty()) << "the continuation test does not refuse the holder on the cylinder";
  ASSERT_EQ(taken.size(), 1u) << "the cylinder is not taken for a holder at 1 mm: the test no longer shows what 0.5 mm adds";
  double sunk = 0;
  for (const auto& v : library()->model("holder").mesh.vertices) sunk = std::max(sunk, -(taken[0].pose * v.cast<double>()).z());
  std::printf("holder on the cylinder: fitness %.2f, RMSE %.3f mm, %.2f mm into the table\n", taken[0].fitness,
              taken[0].rmse * 1e3, sunk * 1e3);
  EXPECT_GT(sunk, 0.5e-3);
  EXPECT_TRUE(shipped.empty());
}

// A cylinder that is not in the library, 48.6 mm across and 39.6 mm tall, recorded in generated
// cell 3007 (capture seed 3's calibration, with the scan's sweep): among 24 rest poses, the
// L-bracket upside down, its wall (40 mm) on the table and its base plate's underside up, puts
// that underside on the cylinder's top (coverage 0.96), and no test of the bracket's own surface
// refuses it. The plate is 40 mm wide and the top 48.6 mm across: the top carries on past the
// plate's long edges in its plane, where a bracket's surface ends. With the continuation test
// off it is taken for a bracket; as shipped it is refused.
TEST(ModelMatching, APartFittedOntoALargerObjectsFaceIsRefused) {
  const RecordedCell cell = recordedCell({{"cylinder_distractor_3007.ply", 765}}, "sweep_capture_seed_3.txt");
  const MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  auto run = [&](double max_continuation) {
    MatchingConfig c = shipped;
    c.viewpoint = kEye;
    c.rest_candidates = std::max(c.rest_candidates, 24);
    c.max_continuation = max_continuation;
    const Eigen::Vector4f table(0, 0, 1, 0);
    return ModelMatcher(library(), c).locate(cell.clusters, {"bracket"}, nullptr, nullptr, &table, nullptr, &cell.sweep);
  };
  ASSERT_LT(shipped.max_continuation, 1.0) << "the continuation test is off as shipped";
  const auto off = run(1.0), on = run(shipped.max_continuation);
  ASSERT_EQ(off.size(), 1u) << "the cylinder is not taken for a bracket without the test: it no longer shows what the test adds";
  std::printf("bracket on the cylinder: fitness %.2f, coverage %.2f, continuation %.4f (shipped limit %.4f)\n", off[0].fitness,
              off[0].coverage, off[0].continuation, shipped.max_continuation);
  EXPECT_GT(off[0].continuation, shipped.max_continuation);
  EXPECT_TRUE(on.empty());
}

// A refused pose names every acceptance test it failed, its figure against the limit, in a fixed
// order; a pose that passes them has no reason, and a pair that reached no pose says so.
TEST(ModelMatching, ARefusedPoseNamesEveryTestItFailed) {
  MatchingConfig c;
  c.min_fitness = 0.3;
  c.min_coverage = 0.6;
  c.max_rmse = 0.00016;
  c.max_see_through = 0.005;
  c.max_unseen = 0.045;
  c.max_continuation = 0.01;
  PartDetection d;
  d.fitness = 0.963, d.coverage = 1.0, d.rmse = 0.000169, d.score = 0.963;
  EXPECT_EQ(refusalReasons(d, c), "rmse 0.169 mm > max_rmse 0.160 mm");
  d.fitness = 0.2, d.coverage = 0.5, d.see_through = 0.1, d.unseen = 0.05, d.continuation = 0.02, d.score = 0.1;
  EXPECT_EQ(refusalReasons(d, c),
            "fitness 0.200 < min_fitness 0.300; coverage 0.500 < min_coverage 0.600; rmse 0.169 mm > max_rmse 0.160 mm; "
            "see-through 0.100 > max_see_through 0.005; unseen 0.050 > max_unseen 0.045; continuation 0.0200 > max_continuation 0.0100");
  c.max_continuation = 1.0;  // off: never a reason
  d = PartDetection();
  d.fitness = 0.9, d.coverage = 0.9, d.rmse = 0.0001, d.continuation = 0.5, d.score = 0.81;
  EXPECT_EQ(refusalReasons(d, c), "");
  EXPECT_EQ(refusalReasons(PartDetection(), c), "no pose fitted");
  d.rmse = NAN;  // a figure that is not a number fails its test, as the acceptance refuses it
  EXPECT_EQ(refusalReasons(d, c), "rmse nan mm > max_rmse 0.160 mm");
  // per cluster without a detection, its best refused pose that fitted something
  MatchStats st;
  auto refused = [&](int cluster, const char* model, double fitness, const char* why) {
    PartDetection r;
    r.cluster = cluster, r.model = model, r.fitness = fitness, r.coverage = 0.8, r.score = fitness * 0.8, r.refused_by = why;
    st.rejected.push_back(r);
  };
  refused(0, "holder", 0.21, "fitness 0.210 < min_fitness 0.300");
  refused(0, "bracket", 0.12, "fitness 0.120 < min_fitness 0.300");
  refused(1, "housing", 0.9, "unseen 0.050 > max_unseen 0.045");  // cluster 1 has a part
  st.rejected.push_back(PartDetection());                          // a pair that fitted nothing
  st.rejected.back().cluster = 2;
  PartDetection found;
  found.cluster = 1;
  const std::vector<std::string> lines = refusedClusters({found}, st);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "cluster 0: no part accepted; the best refused, holder (fitness 0.210, coverage 0.800): fitness 0.210 < min_fitness 0.300");
}

// A holder lying on an arm shows the camera its upper arm's outer face, 30 x 32 mm: turned 90
// degrees about the vertical the face fits within what the scanner loses at its edges, and the
// turned pose explains the strip seen through the mouth as the channel's open end, scoring
// higher (cell 3057, capture seed 1: fitness 0.93 against 0.83). It fits the scan less closely
// (RMSE 0.077 against 0.042 mm): the turned poses are polished too, and the closest fits compete.
TEST(ModelMatching, AHolderFoundTurnedAboutTheVerticalIsTurnedBack) {
  const RecordedCell cell = recordedCell({{"holder_on_an_arm_3057.ply", 501}}, "sweep_capture_seed_1.txt");
  const Eigen::Isometry3d truth = truePose({0.6478663229141447, 0.0031897051618338199, 0.02500000037252903},
                                           {0.095751138977414677, -0.7005938333903089, 0.095751138977414663, 0.7005938333903089});
  PartDetection d;
  auto run = [&](bool turn, MatchStats* st) {
    return locateRecorded(cell.clusters, "holder", cell.sweep, truth, [&](MatchingConfig& c) { c.turned_poses = turn; }, st, &d);
  };
  MatchStats off, on;
  const PoseError found = run(false, &off), turned = run(true, &on);
  // the turn that scored higher fits less closely: the scan tells the two apart
  EXPECT_TRUE(d.ambiguous_poses.empty()) << "score share of the best other turn " << d.alternative_score_share;
  std::printf("as found: %.2f mm, %.1f deg off; with the turned poses: %.2f mm, %.2f deg off\n", found.translation * 1e3,
              found.rotation * 180 / M_PI, turned.translation * 1e3, turned.rotation * 180 / M_PI);
  EXPECT_GT(found.rotation, 45 * M_PI / 180) << "found right as it is now: the test no longer shows what the turned poses add";
  EXPECT_EQ(off.turned_poses, 0u);
  EXPECT_EQ(on.turned_poses, 1u);
  EXPECT_LT(turned.translation, 0.5e-3);
  EXPECT_LT(turned.rotation, 1.0 * M_PI / 180);
}

// A holder lying on an arm in generated cell 3043 (the true calibration, with the scan's sweep):
// all 463 points of its cluster lie on the upper arm's outer face, 30 x 32 mm, which the part
// turned by a half about the vertical shows the camera alike (docs/localization.md, Limits). The
// matcher keeps one pose and reports the other as one the scan cannot tell from it; one of the
// two is the part's. As an exact tie only, it is not reported.
TEST(ModelMatching, AHolderTheScanCannotTellFromItsHalfTurnIsReportedAmbiguous) {
  const RecordedCell cell = recordedCell({{"holder_on_an_arm_3043.ply", 463}}, "sweep_true_calibration.txt");
  const Eigen::Isometry3d truth = truePose({0.56124656576073528, 0.01987631119710076, 0.02500000037252903},
                                           {0.65717900086620429, 0.26098996306466965, -0.65717900086620407, 0.26098996306466965});
  const ModelInfo& info = library()->model("holder").info;
  const Eigen::Vector3d centroid = ModelMatcher(library(), config()).centroid("holder");
  PartDetection d;
  MatchStats st;
  double shipped_ratio = 0;
  locateRecorded(cell.clusters, "holder", cell.sweep, truth, [&](MatchingConfig& c) { shipped_ratio = c.ambiguous_score_ratio; }, &st, &d);
  ASSERT_EQ(d.ambiguous_poses.size(), 1u) << "score share of the best other turn " << d.alternative_score_share;
  EXPECT_GE(d.alternative_score_share, shipped_ratio);
  const PoseError kept = poseError(info, centroid, d.pose, truth), other = poseError(info, centroid, d.ambiguous_poses[0], truth);
  std::printf("kept: %.2f mm, %.1f deg off; the other: %.2f mm, %.1f deg off; score share %.3f\n", kept.translation * 1e3,
              kept.rotation * 180 / M_PI, other.translation * 1e3, other.rotation * 180 / M_PI, d.alternative_score_share);
  const PoseError& right = kept.rotation < other.rotation ? kept : other;
  const PoseError& wrong = kept.rotation < other.rotation ? other : kept;
  EXPECT_LT(right.translation, 0.5e-3);
  EXPECT_LT(right.rotation, 1.0 * M_PI / 180);
  EXPECT_GT(wrong.rotation, 170 * M_PI / 180);
  // only an exact tie would be reported at 1: the pose stands, alone
  PartDetection strict;
  locateRecorded(cell.clusters, "holder", cell.sweep, truth, [&](MatchingConfig& c) { c.ambiguous_score_ratio = 1; }, &st, &strict);
  EXPECT_TRUE(strict.ambiguous_poses.empty());
  EXPECT_TRUE(strict.pose.isApprox(d.pose, 1e-9));
}

// A housing standing on an end in generated cell 3052 (capture seed 1's calibration, with the
// scan's sweep): the camera sees its top end face, 50 x 30 mm, whose far end the fan cuts, in one
// cluster, and its boss and lug on a side in another. The end face alone is explained alike by the
// housing standing on either end and by its half turn; the rest pose near the right one, a few
// degrees off after its short ICP, explains a few points fewer (154 of 161 against 161 in the
// evaluation's run): with a quota of three or four rest poses it is never refined and nothing is
// found; with the shipped twelve it is.
TEST(ModelMatching, ARestPoseTiedWithTurnedOnesIsWithinTheQuota) {
  const RecordedCell cell = recordedCell({{"housing_end_face_3052.ply", 294}, {"housing_boss_and_lug_3052.ply", 140}}, "sweep_capture_seed_1.txt");
  const Eigen::Isometry3d truth = truePose({0.64308827300528981, -0.014122856568134931, 0.035000000149011612},
                                           {0.617263164711773, -0.34494374250014548, 0.61726316471177278, 0.34494374250014553});
  auto run = [&](int quota) {
    return locateRecorded(cell.clusters, "housing", cell.sweep, truth, [&](MatchingConfig& c) { c.rest_candidates = quota; }, nullptr);
  };
  const PoseError four = run(4), twelve = run(12);
  std::printf("12 rest poses: %.2f mm, %.2f deg off\n", twelve.translation * 1e3, twelve.rotation * 180 / M_PI);
  EXPECT_GT(four.translation, 5e-3) << "found with four rest poses now: the test no longer shows what the larger quota adds";
  EXPECT_LT(twelve.translation, 1.5e-3);
  EXPECT_LT(twelve.rotation, 1.5 * M_PI / 180);
}

// A sphere touching an upright flanged shaft in generated cell 3156 (capture seed 1's
// calibration, with the scan's sweep), one cluster: the shaft is found, and the sphere's pose,
// right, is refused for unseen surface (0.046 against 0.045). Its side towards the shaft lies in
// the shaft's shadow, but the shaft's side that casts it was not measured, so no scan point lies
// on those beams. Looked at again with the shaft's model shading it, the sphere is found.
namespace {
/// A recorded shaft and sphere located with the shipped settings, the second look on or off.
std::vector<PartDetection> locateShaftAndSphere(const RecordedCell& cell, bool look, MatchStats* st) {
  MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  c.viewpoint = kEye;
  c.unseen_second_look = look;
  const Eigen::Vector4f table(0, 0, 1, 0);
  return ModelMatcher(library(), c).locate(cell.clusters, {"flanged_shaft", "sphere25"}, st, nullptr, &table, nullptr, &cell.sweep);
}
}  // namespace

TEST(ModelMatching, APartShadedByAFoundPartIsLookedAtAgain) {
  const RecordedCell cell = recordedCell({{"shaft_and_sphere_3156.ply", 742}}, "sweep_capture_seed_1.txt");
  const Eigen::Isometry3d sphere = truePose({0.37548552399439833, -0.019222545979400714, 0}, {1, 0, 0, 0});
  MatchStats once, twice;
  const auto first = locateShaftAndSphere(cell, false, &once), second = locateShaftAndSphere(cell, true, &twice);
  const Eigen::Vector3d centroid =
      ModelMatcher(library(), loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml")).centroid("sphere25");
  auto sphereError = [&](const std::vector<PartDetection>& found) {
    for (const auto& d : found)
      if (d.model == "sphere25") return poseError(library()->model("sphere25").info, centroid, d.pose, sphere).translation;
    return 1e9;
  };
  std::printf("found %zu parts, then %zu; the sphere %.2f mm off\n", first.size(), second.size(), sphereError(second) * 1e3);
  ASSERT_EQ(first.size(), 1u) << "the sphere is found at once now: the test no longer shows what the second look adds";
  EXPECT_EQ(first[0].model, "flanged_shaft");
  EXPECT_EQ(once.unseen_second_look, 0u);
  ASSERT_EQ(second.size(), 2u);
  EXPECT_EQ(twice.unseen_second_look, 1u);
  EXPECT_LT(sphereError(second), 0.5e-3);
}

// A sphere 52 mm from an upright flanged shaft in generated cell 3451 (the true calibration,
// with the scan's sweep): the sheet reaches the sphere over the shaft's top, which shades most
// of it, and the scan holds 54 points of its top. Counting what the shaft shades as missing, the
// right pose explains too little (fitness below min_fitness); the second look, with the found
// shaft stopping the camera's rays and the sheet's beams, finds it.
TEST(ModelMatching, APartShadedByAFoundPartIsFoundOnWhatItsLightReached) {
  const RecordedCell cell =
      recordedCell({{"shaft_top_3451.ply", 949}, {"sphere_in_a_shadow_3451.ply", 54}}, "sweep_true_calibration.txt");
  const Eigen::Isometry3d sphere =
      truePose({0.61611187677323098, 0.088461147351226316, 0}, {0.7313732056372243, 0, 0, 0.68197744396419047});
  const MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  MatchStats once, twice;
  const auto first = locateShaftAndSphere(cell, false, &once), second = locateShaftAndSphere(cell, true, &twice);
  ASSERT_EQ(first.size(), 1u) << "the sphere is found at once now: the test no longer shows what the second look adds";
  EXPECT_EQ(first[0].model, "flanged_shaft");
  const auto refused = std::find_if(once.rejected.begin(), once.rejected.end(), [](const PartDetection& d) { return d.model == "sphere25" && d.cluster == 1; });
  ASSERT_NE(refused, once.rejected.end());
  EXPECT_LT(refused->fitness, c.min_fitness);
  EXPECT_GE(refused->fitness, 0.5 * c.min_fitness);
  ASSERT_EQ(second.size(), 2u);
  EXPECT_EQ(twice.unseen_second_look, 1u);
  for (const auto& d : second) {
    if (d.model != "sphere25") continue;
    const double e = poseError(library()->model("sphere25").info, ModelMatcher(library(), c).centroid("sphere25"), d.pose, sphere).translation;
    std::printf("the sphere: fitness %.2f refused, %.2f at the second look; %.2f mm off\n", refused->fitness, d.fitness, e * 1e3);
    EXPECT_GE(d.fitness, c.min_fitness);
    EXPECT_LT(e, 0.5e-3);
  }
}

// The free-space test: with the table seen only where the part does not hide it, the part is
// found and nothing is seen through it; a camera that saw the table through it refuses it.
TEST(ModelMatching, APartTheCameraSawThroughIsRefused) {
  MatchingConfig c = config();
  c.max_see_through = 0.005;
  ModelMatcher m(library(), c);
  const Eigen::Isometry3d truth = onTable(0.5, -0.03, 0.6);
  const TriangleMesh& mesh = library()->model("holder").mesh;
  const ScanCloud view = singleViewCloud(mesh, truth, kEye, 0.001, 2e-5, 41);
  const Eigen::Vector4f table(0, 0, 1, 0);
  const auto seen = seenTable(mesh, truth, 0.06f, false);
  const auto d = m.locate({view}, {"holder"}, nullptr, nullptr, &table, &seen);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_LE(d[0].see_through, 0.005);
  const PoseError e = poseError(library()->model("holder").info, m.centroid("holder"), d[0].pose, truth);
  EXPECT_LT(e.translation, 0.5e-3);
  const auto through = seenTable(mesh, truth, 0.06f, true);
  MatchStats st;
  EXPECT_TRUE(m.locate({view}, {"holder"}, &st, nullptr, &table, &through).empty());
  ASSERT_FALSE(st.rejected.empty());
  EXPECT_GT(st.rejected[0].see_through, 0.3);
  // the refused pose names the test that refused it (cellsight_locate prints it, the evaluation's JSON holds it)
  EXPECT_NE(st.rejected[0].refused_by.find("> max_see_through 0.005"), std::string::npos) << st.rejected[0].refused_by;
  // broken support points (NaN, one 10 km away) neither crash nor blow up the map: it is
  // coarsened to at most 16 M cells, and the part is still found
  auto broken = seen;
  broken.push_back(Eigen::Vector3f::Constant(NAN));
  broken.push_back(Eigen::Vector3f(1e4f, 1e4f, 0.f));
  EXPECT_EQ(m.locate({view}, {"holder"}, nullptr, nullptr, &table, &broken).size(), 1u);
}

// Two parts touching so closely that clustering keeps them together: neither explains 60 % of
// the cluster, so it is searched again asking half; the first found leaves the other's points.
TEST(ModelMatching, TwoTouchingPartsInOneClusterAreBothFound) {
  ModelMatcher m(library(), config());
  // side by side along y, 1 mm apart
  const Eigen::AlignedBox3f ba = library()->model("housing").bounds, bb = library()->model("bracket").bounds;
  const Eigen::Isometry3d a = onTable(0.47, 0.0, 0.0), b = onTable(0.47, ba.max().y() - bb.min().y() + 0.001, 0.0);
  ScanCloud both = singleViewCloud(library()->model("housing").mesh, a, kEye, 0.001, 2e-5, 51);
  const ScanCloud vb = singleViewCloud(library()->model("bracket").mesh, b, kEye, 0.001, 2e-5, 52);
  for (size_t i = 0; i < vb.size(); ++i) both.append(vb.points[i], 1.f);
  const auto d = m.locate({both}, {});
  ASSERT_EQ(d.size(), 2u);
  for (const auto& x : d) {
    const bool is_a = x.model == "housing";
    const PoseError e = poseError(library()->model(x.model).info, m.centroid(x.model), x.pose, is_a ? a : b);
    EXPECT_LT(e.translation, 1e-3) << x.model;
    EXPECT_LT(e.rotation, 1 * M_PI / 180) << x.model;
  }
}

// Three parts touching in one cluster, recorded in generated cell 3296 (capture seed 3's
// calibration, with the scan's sweep): a flanged shaft standing, a holder lying on an arm
// against it and a bracket beside them, 2 306 points. No part explains 60 % of the cluster; at
// the second look (half the coverage) the bracket is found, and what it leaves holds two parts
// again, which needs a second look of its own: max_instances counts the parts a cluster gives,
// not the searches, so all three are found.
TEST(ModelMatching, ThreeTouchingPartsInOneClusterAreAllFound) {
  const RecordedCell cell = recordedCell({{"shaft_holder_bracket_3296.ply", 2306}}, "sweep_capture_seed_3.txt");
  const std::map<std::string, Eigen::Isometry3d> truth = {
      {"flanged_shaft", truePose({0.42913233642106663, -0.031851775935148048, 0}, {0.93650767983258976, 0, 0, 0.3506470670269175})},
      {"holder", truePose({0.39761552364321767, -0.076504137435626896, 0.032000001519918442},
                          {3.3112860595413365e-17, 0.84116789324517005, 0.54077405205268703, -5.1506678400410994e-17})},
      {"bracket", truePose({0.47807154245225686, -0.069188558150701518, 0}, {0.81328354471030828, 0, 0, -0.58186757591692284})}};
  MatchingConfig c = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  c.viewpoint = kEye;
  ASSERT_EQ(c.max_instances, 3);
  const Eigen::Vector4f table(0, 0, 1, 0);
  ModelMatcher m(library(), c);
  const auto found = m.locate(cell.clusters, {}, nullptr, nullptr, &table, nullptr, &cell.sweep);
  ASSERT_EQ(found.size(), 3u);
  for (const auto& d : found) {
    ASSERT_EQ(truth.count(d.model), 1u) << d.model << " is not in the cluster";
    const PoseError e = poseError(library()->model(d.model).info, m.centroid(d.model), d.pose, truth.at(d.model));
    std::printf("%s: %.2f mm, %.2f deg off, coverage %.2f\n", d.model.c_str(), e.translation * 1e3, e.rotation * 180 / M_PI,
                d.coverage);
    EXPECT_LT(e.translation, 1.5e-3) << d.model;
    EXPECT_LT(e.rotation, 1 * M_PI / 180) << d.model;
  }
  // at most two parts per cluster: two of them
  c.max_instances = 2;
  EXPECT_EQ(ModelMatcher(library(), c).locate(cell.clusters, {}, nullptr, nullptr, &table, nullptr, &cell.sweep).size(), 2u);
}

// A bracket standing on its base plate, recorded in generated cell 3460 (the true calibration,
// with the scan's sweep): clustering puts its plate (595 points) and its wall's top, 40 mm up
// (101 points), apart. The plate gives the bracket; on the wall top alone a second bracket is
// fitted lying on its side (fitness 0.59), its model inside the first's (6.6 % of its surface
// deeper than 1 mm), 24 mm from it: farther than the pieces of one split part are merged. Two
// solid parts cannot share space: the better explained stays. (With poses laid into their rests,
// rest_snap_angle, no second bracket is fitted there: off here, to show what the test does alone.)
TEST(ModelMatching, TwoDetectionsThatWouldShareSpaceKeepTheBetterExplained) {
  const RecordedCell cell =
      recordedCell({{"bracket_base_plate_3460.ply", 595}, {"bracket_wall_top_3460.ply", 101}}, "sweep_true_calibration.txt");
  const Eigen::Isometry3d truth =
      truePose({0.39045901427798374, 0.034167931306774063, 0}, {0.63993674883604124, 0, 0, 0.76842758766793218});
  const MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  auto run = [&](double max_interpenetration, MatchStats* st) {
    MatchingConfig c = shipped;
    c.viewpoint = kEye;
    c.max_interpenetration = max_interpenetration;
    c.rest_snap_angle = 0;
    const Eigen::Vector4f table(0, 0, 1, 0);
    return ModelMatcher(library(), c).locate(cell.clusters, {"bracket"}, st, nullptr, &table, nullptr, &cell.sweep);
  };
  ASSERT_LT(shipped.max_interpenetration, 1.0) << "the interpenetration test is off as shipped";
  MatchStats off_st, on_st;
  const auto off = run(1.0, &off_st), on = run(shipped.max_interpenetration, &on_st);
  ASSERT_EQ(off.size(), 2u) << "no second bracket without the test: it no longer shows what the test adds";
  EXPECT_EQ(off_st.interpenetrating, 0u);
  ASSERT_EQ(on.size(), 1u);
  EXPECT_EQ(on_st.interpenetrating, 1u);
  EXPECT_TRUE(std::any_of(on_st.warnings.begin(), on_st.warnings.end(),
                          [](const std::string& w) { return w.find("would share space") != std::string::npos; }));
  const PoseError e = poseError(library()->model("bracket").info, ModelMatcher(library(), shipped).centroid("bracket"), on[0].pose, truth);
  std::printf("kept: %.2f mm, %.2f deg off, fitness %.2f (the other's %.2f)\n", e.translation * 1e3, e.rotation * 180 / M_PI,
              on[0].fitness, std::min(off[0].fitness, off[1].fitness));
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 2 * M_PI / 180);
}

// A second pass (the sheet leaning the other way) lights what the first pass's sheet shaded: its
// detections join the first pass's only where no part was found already.
TEST(ModelMatching, ASecondPassAddsOnlyWhatTheFirstLeftFree) {
  MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  shipped.viewpoint = kEye;
  ASSERT_LT(shipped.max_interpenetration, 1.0) << "the interpenetration test is off as shipped";
  const ModelMatcher m(library(), shipped);
  auto det = [](const std::string& model, const Eigen::Isometry3d& pose) {
    PartDetection d;
    d.model = model;
    d.pose = pose;
    d.fitness = 0.9;
    return d;
  };
  const Eigen::Isometry3d shaft = onTable(0.45, 0.0, 0.0);  // standing: 50 mm across, 62.5 mm tall
  const std::vector<PartDetection> first{det("flanged_shaft", shaft)};
  const std::vector<PartDetection> second{
      det("flanged_shaft", shaft * Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ())),  // the same part, turned: taken
      det("sphere25", onTable(0.455, 0.0, 0.0)),   // another model inside the shaft: taken
      det("sphere25", onTable(0.45, 0.040, 0.0)),  // beside the shaft, 2.5 mm clear of it: added
      det("holder", onTable(0.60, -0.08, 1.0)),    // a part the first pass did not find: added
      det("holder", onTable(0.601, -0.081, 2.0))};  // the same again, in this pass: taken
  MatchStats st;
  const auto merged = m.mergePasses(first, second, &st);
  ASSERT_EQ(merged.size(), 3u);
  EXPECT_EQ(merged[0].pass, 0);
  EXPECT_TRUE(merged[0].pose.isApprox(shaft));
  EXPECT_EQ(merged[1].model, "sphere25");
  EXPECT_EQ(merged[1].pass, 1);
  EXPECT_NEAR(merged[1].pose.translation().y(), 0.040, 1e-12);
  EXPECT_EQ(merged[2].model, "holder");
  EXPECT_EQ(merged[2].pass, 1);
  EXPECT_NEAR(merged[2].pose.translation().x(), 0.60, 1e-12);
  EXPECT_EQ(st.second_pass_added, 2u);
  EXPECT_EQ(st.second_pass_taken, 3u);
  // with the space test off, only the same model near the same place is taken
  MatchingConfig off = shipped;
  off.max_interpenetration = 1;
  MatchStats st_off;
  EXPECT_EQ(ModelMatcher(library(), off).mergePasses(first, second, &st_off).size(), 4u);
  EXPECT_EQ(st_off.second_pass_taken, 2u);
  // nothing to merge, and a model the library lacks
  EXPECT_EQ(m.mergePasses(first, {}).size(), 1u);
  EXPECT_EQ(m.mergePasses({}, first).size(), 1u);
  EXPECT_THROW(m.mergePasses(first, {det("no_such_part", shaft)}), std::out_of_range);
}

namespace {
/// A housing's single view cut across x: `percent` of its points below the cut, the rest above.
struct SplitView {
  Eigen::Isometry3d truth = onTable(0.47, -0.02, 0.7);
  ScanCloud whole, below, above;
};
SplitView splitHousingView(size_t percent) {
  SplitView v;
  v.whole = singleViewCloud(library()->model("housing").mesh, v.truth, kEye, 0.001, 2e-5, 61);
  std::vector<float> xs;
  for (const auto& p : v.whole.points) xs.push_back(p.x());
  std::nth_element(xs.begin(), xs.begin() + xs.size() * percent / 100, xs.end());
  const float cut = xs[xs.size() * percent / 100];
  for (const auto& p : v.whole.points) (p.x() < cut ? v.below : v.above).append(p, 1.f);
  return v;
}
}  // namespace

// Clustering can split a part (a gap in the scan across it): each piece is matched on its own
// cluster, but the fitness counts the scan points of every cluster, so the part is found at its
// full fitness, and only once.
TEST(ModelMatching, APartSplitBetweenTwoClustersIsFoundOnceWhole) {
  const SplitView v = splitHousingView(45);
  const Eigen::Isometry3d& truth = v.truth;
  const ScanCloud &view = v.whole, &a = v.below, &b = v.above;
  ModelMatcher whole(library(), config());
  const auto one = whole.locate({view}, {"housing"});
  ASSERT_EQ(one.size(), 1u);
  MatchStats st;
  const auto split = whole.locate({a, b}, {"housing"}, &st);
  ASSERT_EQ(split.size(), 1u) << "a piece found as a part of its own";
  const PoseError e = poseError(library()->model("housing").info, whole.centroid("housing"), split[0].pose, truth);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  EXPECT_NEAR(split[0].fitness, one[0].fitness, 0.03);
  EXPECT_TRUE(std::any_of(st.warnings.begin(), st.warnings.end(),
                          [](const std::string& w) { return w.find("found twice") != std::string::npos; }));
  // each piece's own points only: the part is short of the other piece's
  MatchingConfig own = config();
  own.fitness_whole_scan = false;
  ModelMatcher per_cluster(library(), own);
  const auto pieces = per_cluster.locate({a, b}, {"housing"});
  std::printf("fitness: one cluster %.3f, split with every cluster's points %.3f, split per cluster:", one[0].fitness,
              split[0].fitness);
  for (const auto& d : pieces) std::printf(" %.3f", d.fitness);
  std::printf(" (%zu found)\n", pieces.size());
  for (const auto& d : pieces) EXPECT_LT(d.fitness, one[0].fitness - 0.2);
}

// A piece of a part's scan too small to be a cluster (the top of a standing bracket's foot) is
// a fragment: never searched, but surface the scan measured, so the part's fitness counts it.
// Fragments that are not finite or lie far from every cluster are left out.
TEST(ModelMatching, FragmentsCountInTheFitness) {
  const SplitView v = splitHousingView(80);
  const Eigen::Isometry3d& truth = v.truth;
  const ScanCloud &view = v.whole, &cluster = v.below;
  const std::vector<Eigen::Vector3f>& fragments = v.above.points;
  ModelMatcher m(library(), config());
  const auto one = m.locate({view}, {"housing"});
  const auto alone = m.locate({cluster}, {"housing"});
  const auto with = m.locate({cluster}, {"housing"}, nullptr, nullptr, nullptr, nullptr, nullptr, &fragments);
  ASSERT_EQ(one.size(), 1u);
  ASSERT_EQ(alone.size(), 1u);
  ASSERT_EQ(with.size(), 1u);
  std::printf("fitness: whole view %.3f, 80 %% of it %.3f, with the rest as fragments %.3f\n", one[0].fitness,
              alone[0].fitness, with[0].fitness);
  EXPECT_LT(alone[0].fitness, one[0].fitness - 0.1);
  EXPECT_NEAR(with[0].fitness, one[0].fitness, 0.03);
  const PoseError e = poseError(library()->model("housing").info, m.centroid("housing"), with[0].pose, truth);
  EXPECT_LT(e.translation, 1e-3);
  auto broken = fragments;
  broken.push_back(Eigen::Vector3f::Constant(NAN));
  broken.push_back(Eigen::Vector3f(1e4f, 1e4f, 0.f));
  const auto odd = m.locate({cluster}, {"housing"}, nullptr, nullptr, nullptr, nullptr, nullptr, &broken);
  ASSERT_EQ(odd.size(), 1u);
  EXPECT_NEAR(odd[0].fitness, with[0].fitness, 1e-9);
  // fragments alone are never searched
  ScanCloud empty;
  EXPECT_TRUE(m.locate({empty}, {"housing"}, nullptr, nullptr, nullptr, nullptr, nullptr, &fragments).empty());
}

// The top of a sphere as the simulated scanner saw it in generated cell 3034 (its side went to
// a touching bracket's cluster): 181 points of its top 8 mm. On a sphere every pair of a given
// distance has the same feature, so votes do not tell poses apart, and PPF gave this cap no pose
// at all; the centre comes from the points and their normals.
TEST(ModelMatching, TheTopOfASphereGivesItsCentre) {
  const Recorded r = locateRecorded("sphere_top_3034.ply", 181, {"sphere25"}, "sphere25",
                                    {0.57247967398705579, 0.0024613539319799649, 0}, {1, 0, 0, 0});
  ASSERT_EQ(r.found.size(), 1u);
  std::printf("sphere top: %.3f mm, fitness %.2f\n", r.error.translation * 1e3, r.found[0].fitness);
  EXPECT_LT(r.error.translation, 0.5e-3);
}

// A housing lying on its side in generated cell 3097 (1 030 points), seen mostly by one large
// face: many poses laying one face or another on it explain nearly every point, and the coarse
// stage's refine_candidates best were all wrong (with refine_candidates_near 0 it is not found).
// The near-ties past the cut are refined too, and it is found.
TEST(ModelMatching, NearTiesPastTheCandidateCutAreRefined) {
  const Recorded r = locateRecorded("housing_on_its_side_3097.ply", 1030, {"housing"}, "housing",
                                    {0.47729718582777453, 0.06813112165373311, 0.02500000037252903},
                                    {0.6071238359179957, -0.6071238359179957, -0.36249227282828894, 0.36249227282828905});
  ASSERT_EQ(r.found.size(), 1u);
  std::printf("housing on its side: %.3f mm %.3f deg, fitness %.2f\n", r.error.translation * 1e3, r.error.rotation * 180 / M_PI,
              r.found[0].fitness);
  EXPECT_LT(r.error.translation, 1e-3);
  EXPECT_LT(r.error.rotation, 1 * M_PI / 180);
}

// A light sheet from the side lights only part of what the camera sees of a bracket; the scan
// holds the lit points. Given the sweep, the fitness counts the model points the sheet could
// reach, and explains the scan; without it, the unlit faces count as missing.
TEST(ModelMatching, FitnessCountsOnlyWhatTheSheetLit) {
  const TriangleMesh& mesh = library()->model("bracket").mesh;
  const Eigen::Isometry3d truth = onTable(0.5, 0.0, 0.6);
  // the sheet x = const sweeps along x; its emitter 0.35 m to the -y side, 0.1 m up
  LightSweep sweep;
  for (int k = 0; k <= 200; ++k) {
    const float x = 0.40f + 0.001f * k;
    sweep.add({x, -0.35f, 0.10f}, Eigen::Vector3f::UnitX(), -x);
  }
  const ScanCloud view = singleViewCloud(mesh, truth, kEye, 0.001, 2e-5, 5);
  const ScanCloud lit = litView(mesh, truth, sweep, 5);
  ASSERT_GT(lit.size(), 300u);
  ASSERT_LT(lit.size(), view.size() * 8 / 10) << "the sheet should leave a good share of the view dark";
  MatchingConfig c = config();
  c.min_fitness = 0.05;  // both found: the figures are compared
  ModelMatcher m(library(), c);
  const auto without = m.locate({lit}, {"bracket"});
  const auto with = m.locate({lit}, {"bracket"}, nullptr, nullptr, nullptr, nullptr, &sweep);
  ASSERT_EQ(without.size(), 1u);
  ASSERT_EQ(with.size(), 1u);
  const PoseError e = poseError(library()->model("bracket").info, m.centroid("bracket"), with[0].pose, truth);
  std::printf("bracket lit from the side: %zu of %zu visible points lit; fitness %.2f with the sweep, %.2f without\n",
              lit.size(), view.size(), with[0].fitness, without[0].fitness);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_GT(with[0].fitness, 0.85);
  EXPECT_LT(without[0].fitness, with[0].fitness - 0.15);
  // check_illumination off: the sweep is not used
  c.check_illumination = false;
  ModelMatcher off(library(), c);
  const auto ignored = off.locate({lit}, {"bracket"}, nullptr, nullptr, nullptr, nullptr, &sweep);
  ASSERT_EQ(ignored.size(), 1u);
  EXPECT_NEAR(ignored[0].fitness, without[0].fitness, 0.02);
}

// The scanner measures little of a face steeper than about 65° to the camera (docs/localization.md,
// Steep faces). A bracket lying on its side 0.22 m from below the camera shows it mostly such
// faces; its scan here holds only the faces within 65°. Counting every visible point alike, the
// right pose is refused (most of what it claims is missing); weighed by the scanner's response
// (fitness_incidence_mid), it is found.
TEST(ModelMatching, SteepFacesTheScannerBarelyMeasuresWeighLittle) {
  const TriangleMesh& mesh = library()->model("bracket").mesh;
  Eigen::Isometry3d truth = onTable(0.52, 0.22, 4.8);
  truth.linear() = truth.linear() * Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const ScanCloud visible = singleViewCloud(mesh, truth, kEye, 0.001, 2e-5, 7);
  const ScanCloud measured = singleViewCloud(mesh, truth, kEye, 0.001, 2e-5, 7, 1.13);
  ASSERT_LT(measured.size() * 3, visible.size()) << "the view should be mostly steep faces";
  ASSERT_GT(measured.size(), 300u);
  MatchingConfig c = config();
  c.fitness_incidence_mid = 0;
  EXPECT_TRUE(ModelMatcher(library(), c).locate({measured}, {"bracket"}).empty());
  c.fitness_incidence_mid = 1.134;
  c.fitness_incidence_width = 0.07;
  ModelMatcher m(library(), c);
  const auto found = m.locate({measured}, {"bracket"});
  ASSERT_EQ(found.size(), 1u);
  const PoseError e = poseError(library()->model("bracket").info, m.centroid("bracket"), found[0].pose, truth);
  std::printf("bracket showing steep faces: %zu of %zu visible points measured; weighted fitness %.3f\n",
              measured.size(), visible.size(), found[0].fitness);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  // the whole view: weighted or not, the fitness is near 1
  const auto whole = m.locate({visible}, {"bracket"});
  ASSERT_EQ(whole.size(), 1u);
  EXPECT_GT(whole[0].fitness, 0.9);
}

// A holder-sized box that is not in the library, seen from above: its top is a flat rectangle
// that the holder's flat bottom (the holder upside down, 50 x 30 mm) explains, overhanging the
// box's 36 mm by 7 mm at each end where the scan saw nothing. That overhang faces the camera and the sheet squarely and nothing
// hid it, so the scan would have measured it: the pose is refused (max_unseen). The holder
// itself, scanned the same way, is found and claims no such surface.
TEST(ModelMatching, SurfaceTheScanWouldHaveMeasuredIsNotClaimed) {
  // the sheet x = const sweeps along x; its emitter above the table, to the -y side
  LightSweep sweep;
  for (int k = 0; k <= 300; ++k) {
    const float x = 0.30f + 0.001f * k;
    sweep.add({x, -0.15f, 0.45f}, Eigen::Vector3f::UnitX(), -x);
  }
  Eigen::Isometry3d T_box = onTable(0.40, 0.01, 0.39);
  T_box.translation().z() = 0.016;  // makeBox is centred
  const ScanCloud box = litView(makeBox({0.036, 0.030, 0.032}), T_box, sweep, 3);
  const Eigen::Isometry3d T_holder = onTable(0.45, 0.02, 0.39);
  const ScanCloud holder = litView(library()->model("holder").mesh, T_holder, sweep, 4);
  ASSERT_GT(box.size(), 300u);
  ASSERT_GT(holder.size(), 300u);

  MatchingConfig c = config();
  c.max_unseen = 1.0;  // off: the box is taken for a holder, and the figure says why it should not be
  MatchStats st;
  const auto taken = ModelMatcher(library(), c).locate({box}, {"holder"}, &st, nullptr, nullptr, nullptr, &sweep);
  ASSERT_EQ(taken.size(), 1u) << "the box's top should fit the holder's bottom well enough to pass the other tests";
  MatchingConfig on = config();
  on.max_unseen = 0.045;  // config/matching.yaml
  ModelMatcher m(library(), on);
  const auto refused = m.locate({box}, {"holder"}, &st, nullptr, nullptr, nullptr, &sweep);
  const auto found = m.locate({holder}, {"holder"}, nullptr, nullptr, nullptr, nullptr, &sweep);
  std::printf("holder on a box: fitness %.2f, unseen %.3f; the holder itself: unseen %.3f\n", taken[0].fitness,
              taken[0].unseen, found.empty() ? -1.0 : found[0].unseen);
  EXPECT_GT(taken[0].unseen, on.max_unseen);
  EXPECT_TRUE(refused.empty());
  ASSERT_EQ(found.size(), 1u);
  EXPECT_LT(poseError(library()->model("holder").info, m.centroid("holder"), found[0].pose, T_holder).translation, 1e-3);
  EXPECT_LT(found[0].unseen, 0.01);
  // without the sweep nothing says where the sheet went: no surface is called unseen
  const auto no_sweep = ModelMatcher(library(), c).locate({box}, {"holder"});
  ASSERT_EQ(no_sweep.size(), 1u);
  EXPECT_EQ(no_sweep[0].unseen, 0.0);
}

// Fine PPF bins make the key range too large for the table's dense index (> 2^24 keys): the
// table falls back to searching its sorted keys and must find the same part.
TEST(ModelMatching, FinePpfBinsUseTheSearchedTable) {
  MatchingConfig c = config();
  c.ppf_angle_bins = 64;
  c.ppf_distance_step = 0.0005;
  ModelMatcher m(library(), c);
  const Eigen::Isometry3d truth = onTable(0.5, -0.02, 1.1);
  const ScanCloud view = singleViewCloud(library()->model("bracket").mesh, truth, kEye, 0.001, 2e-5, 21);
  const auto d = m.locate({view}, {"bracket"});
  ASSERT_EQ(d.size(), 1u);
  const PoseError e = poseError(library()->model("bracket").info, m.centroid("bracket"), d[0].pose, truth);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
}

TEST(ModelMatching, BadInputGivesClearStatus) {
  ModelMatcher m(library(), config());
  ScanCloud empty, nan;
  for (int i = 0; i < 100; ++i) nan.append(Eigen::Vector3f::Constant(NAN), 0.f);
  MatchStats st;
  EXPECT_TRUE(m.locate({empty, nan}, {"bracket"}, &st).empty());
  ASSERT_EQ(st.warnings.size(), 2u);
  EXPECT_NE(st.warnings[1].find("0 finite points"), std::string::npos) << st.warnings[1];
  EXPECT_NE(errorOf([&] { m.locate({empty}, {"no_such_part"}); }).find("unknown model 'no_such_part'"), std::string::npos);
  // a cluster above max_cluster_points is thinned with a warning and still located
  MatchingConfig capped = config();
  capped.max_cluster_points = 1000;
  const Eigen::Isometry3d truth = onTable(0.5, 0.0, 0.9);
  const ScanCloud view = singleViewCloud(library()->model("housing").mesh, truth, kEye, 0.0005, 2e-5, 5);
  ASSERT_GT(view.size(), 4000u);
  ModelMatcher mc(library(), capped);
  MatchStats cs;
  const auto found = mc.locate({view}, {"housing"}, &cs);
  ASSERT_EQ(cs.warnings.size(), 1u);
  EXPECT_NE(cs.warnings[0].find("above max_cluster_points 1000: thinned to"), std::string::npos) << cs.warnings[0];
  ASSERT_EQ(found.size(), 1u);
  EXPECT_LT(poseError(library()->model("housing").info, mc.centroid("housing"), found[0].pose, truth).translation, 1e-3);
  MatchingConfig bad = config();
  bad.coarse = "magic";
  EXPECT_THROW(ModelMatcher(library(), bad), std::invalid_argument);
  MatchingConfig ratio = config();
  ratio.turned_rmse_ratio = 1.5;  // no pose could fit within it of the closest
  EXPECT_THROW(ModelMatcher(library(), ratio), std::invalid_argument);
  MatchingConfig share = config();
  share.ambiguous_score_ratio = -0.1;
  EXPECT_THROW(ModelMatcher(library(), share), std::invalid_argument);
  // the shipped settings load; a typo names file and key
  EXPECT_EQ(loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml").coarse, "ppf");
  const std::string path = ::testing::TempDir() + "/matching_typo.yaml";
  // each file is refused with an error naming the key
  const std::pair<const char*, const char*> refused[] = {
      {"voxel: 0.002\nfitnes_radius: 0.002\n", "fitnes_radius"},
      {"min_fitness: 1.5\n", "min_fitness"},
      {"ppf_max_bucket: 0\n", "ppf_max_bucket"},
      {"refine_candidates_near: 1.2\n", "refine_candidates_near"},
      {"max_view_angle: 1.0\nunseen_view_angle: 1.2\n", "unseen_view_angle"},
      {"max_unseen: -0.1\n", "max_unseen"},
      {"fitness_incidence_mid: 1.5\n", "fitness_incidence_mid"},  // beyond max_view_angle
      {"fitness_incidence_width: 0\n", "fitness_incidence_width"},
      {"rest_candidates: -1\n", "rest_candidates"},
      {"rest_yaw_step: 0\n", "rest_yaw_step"},
      {"rest_end_ratio: 0.5\n", "rest_end_ratio"},
      {"rest_snap_angle: 0.5\n", "rest_snap_angle"},
      {"rest_snap_angle: 0.05\nrest_snap_min_angle: 0.1\n", "rest_snap_min_angle"},
      {"rest_snap_rmse_ratio: 0.9\n", "rest_snap_rmse_ratio"},
      {"max_overhang: 1.5\n", "max_overhang"},
      {"overhang_clearance: 0\n", "overhang_clearance"},
      {"overhang_table_radius: -0.001\n", "overhang_table_radius"},
      {"turned_rmse_ratio: 0\n", "turned_rmse_ratio"},
      {"unseen_second_look: 2\n", "unseen_second_look"},
      {"split_second_look: maybe\n", "split_second_look"},
      {"max_continuation: 1.5\n", "max_continuation"},
      {"continuation_reach: 0\n", "continuation_reach"},
      {"max_continuation: 0.01\ncontinuation_reach: 0.0015\n", "continuation_reach"},  // within fitness_radius
      {"continuation_tolerance: -0.001\n", "continuation_tolerance"},
      {"max_interpenetration: -0.1\n", "max_interpenetration"},
      {"interpenetration_depth: 0\n", "interpenetration_depth"},
      {"turned_rmse_ratio: 1.5\n", "turned_rmse_ratio"},
      {"turned_poses: maybe\n", "turned_poses"},
      {"ambiguous_score_ratio: 1.1\n", "ambiguous_score_ratio"},
  };
  for (const auto& [yaml, key] : refused) {
    std::ofstream(path) << yaml;
    EXPECT_NE(errorOf([&] { loadMatchingConfig(path); }).find(key), std::string::npos) << yaml;
  }
}

// A box rests on each of its six sides, the largest first, its origin half its thickness up; with
// its centre of mass 0.5 mm inside an end, only on its two ends (elsewhere it would tip over).
// The L-bracket also rests on its hull facet across the two flanges' edges.
TEST(RestPoses, HullFacetsThatHoldTheCentreOfMass) {
  const TriangleMesh box = makeBox(Eigen::Vector3d(0.04, 0.02, 0.01));
  std::vector<Eigen::Vector3d> v;
  for (const auto& p : box.vertices) v.push_back(p.cast<double>());
  const auto rests = stableRests(v, Eigen::Vector3d::Zero());
  ASSERT_EQ(rests.size(), 6u);
  EXPECT_NEAR(rests[0].area, 8e-4, 1e-9);
  EXPECT_NEAR(rests[0].height, 0.005, 1e-9);
  EXPECT_NEAR(rests[0].margin, 0.01, 1e-9);
  EXPECT_NEAR(rests[5].height, 0.02, 1e-9);
  for (const auto& r : rests) {
    // resting: the lowest vertex on the table, the facet flat on it
    double lowest = 1;
    int on_table = 0;
    for (const auto& p : v) lowest = std::min(lowest, (r.R * p).z() + r.height);
    for (const auto& p : v) on_table += std::abs((r.R * p).z() + r.height) < 1e-9;
    EXPECT_NEAR(lowest, 0, 1e-9);
    EXPECT_EQ(on_table, 4);
  }
  const auto tipping = stableRests(v, Eigen::Vector3d(0.0195, 0, 0));
  ASSERT_EQ(tipping.size(), 2u);
  for (const auto& r : tipping) EXPECT_NEAR(std::abs((r.R * Eigen::Vector3d::UnitX()).z()), 1, 1e-9);
  EXPECT_TRUE(stableRests({v[0], v[1], v[2]}, Eigen::Vector3d::Zero()).empty());
  EXPECT_TRUE(stableRests({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}, Eigen::Vector3d(0.5, 0.5, 0)).empty());  // flat
  const TriangleMesh& bracket = library()->model("bracket").mesh;
  v.clear();
  for (const auto& p : bracket.vertices) v.push_back(p.cast<double>());
  const auto b = stableRests(v, bracket.surfaceCentroid());
  EXPECT_EQ(b.size(), 5u);
  EXPECT_TRUE(std::any_of(b.begin(), b.end(), [](const RestPose& r) {
    const Eigen::Vector3d down = r.R.transpose() * -Eigen::Vector3d::UnitZ();
    return std::abs(down.z()) > 0.1 && std::abs(down.z()) < 0.99;  // neither flange flat on the table
  }));
}

namespace {
/// The Stanford bunny's shipped pose bun045 -> bun000 (4x4, row by row).
Eigen::Isometry3d bunnyTruth(const std::string& dir) {
  std::ifstream tf(dir + "/T_bun045_to_bun000.txt");
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) tf >> M(r, c);
  return Eigen::Isometry3d(M);
}
}  // namespace

// Real data (../shared/data/pointclouds): a reference scan as the model (thesis: "CAD mesh or
// reference cloud"), whole-scene search (no cluster to cover).
TEST(ModelMatchingRealData, Bunny045OntoBunny000) {
  const std::string dir = std::string(CELLSIGHT_SOURCE_DIR) + "/../shared/data/pointclouds/stanford_bunny";
  if (!std::ifstream(dir + "/T_bun045_to_bun000.txt")) GTEST_SKIP() << "real data not found at " << dir << " (../shared/data)";
  const Eigen::Isometry3d truth = bunnyTruth(dir);
  auto lib = std::make_shared<ModelLibrary>();
  const Eigen::Vector3f sensor(0, 0, 1);  // the range scanner looked down -z in scan coordinates
  lib->addCloudModel("bun045", loadCloud(dir + "/bun045.ply"), sensor);
  const ScanCloud scene = loadCloud(dir + "/bun000.ply");
  MatchingConfig cfg;
  cfg.viewpoint = sensor;
  cfg.voxel = 0.003;
  cfg.normal_radius = 0.006;
  cfg.ppf_sampling = 0.005;
  cfg.ppf_distance_step = 0.005;
  cfg.inlier_distance = 0.004;
  cfg.fitness_radius = 0.002;
  cfg.min_coverage = 0;  // bun000 holds surface bun045 never saw
  cfg.min_fitness = 0.3;
  cfg.max_rmse = 0.002;
  cfg.max_instances = 1;
  ModelMatcher m(lib, cfg);
  MatchStats st;
  const auto d = m.locate({scene}, {}, &st);
  ASSERT_EQ(d.size(), 1u);
  const PoseError e = poseError(lib->model("bun045").info, m.centroid("bun045"), d[0].pose, truth);
  std::printf("bun045 -> bun000: %.3f mm %.3f deg, fitness %.2f, rmse %.3f mm, %.2f s (%zu + %zu points)\n",
              e.translation * 1e3, e.rotation * 180 / M_PI, d[0].fitness, d[0].rmse * 1e3, st.seconds,
              lib->model("bun045").source_cloud.size(), scene.size());
  EXPECT_LT(e.translation, 2e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
}

TEST(ModelMatchingRealData, PclMilkCartonInItsKinectScene) {
  const std::string dir = std::string(CELLSIGHT_SOURCE_DIR) + "/../shared/data/pointclouds/pcl";
  if (!std::ifstream(dir + "/milk.pcd")) GTEST_SKIP() << "real data not found at " << dir << " (../shared/data)";
  auto lib = std::make_shared<ModelLibrary>();
  const Eigen::Vector3f kinect = Eigen::Vector3f::Zero();  // the model was cut out of this scene: same frame
  lib->addCloudModel("milk", loadCloud(dir + "/milk.pcd"), kinect);
  const ScanCloud scene = loadCloud(dir + "/milk_cartoon_all_small_clorox.pcd");
  MatchingConfig cfg;
  cfg.viewpoint = kinect;
  cfg.voxel = 0.005;
  cfg.normal_radius = 0.012;
  cfg.ppf_sampling = 0.01;
  cfg.ppf_distance_step = 0.008;
  cfg.inlier_distance = 0.008;
  cfg.icp_spacing = 0.002;
  cfg.fitness_radius = 0.005;
  cfg.min_coverage = 0;  // a whole Kinect scene, not a cluster
  cfg.min_fitness = 0.3;
  cfg.max_rmse = 0.005;
  cfg.max_instances = 1;
  ModelMatcher m(lib, cfg);
  MatchStats st;
  const auto d = m.locate({scene}, {}, &st);
  ASSERT_EQ(d.size(), 1u);
  const PoseError e = poseError(lib->model("milk").info, m.centroid("milk"), d[0].pose, Eigen::Isometry3d::Identity());
  std::printf("milk in milk_cartoon_all_small_clorox: %.3f mm %.3f deg, fitness %.2f, rmse %.3f mm, %.2f s (%zu points)\n",
              e.translation * 1e3, e.rotation * 180 / M_PI, d[0].fitness, d[0].rmse * 1e3, st.seconds, scene.size());
  EXPECT_LT(e.translation, 5e-3);
  EXPECT_LT(e.rotation, 2 * M_PI / 180);
}

// The same two real cases with no hand-tuned settings: the defaults scaled to the model's size
// and the scene's resolution and scatter (what cellsight_locate uses without --matching); and the
// milk carton searched in the bunny scan, where it is not.
TEST(ModelMatchingRealData, ScaledDefaultsFindBunnyAndMilk) {
  const std::string root = std::string(CELLSIGHT_SOURCE_DIR) + "/../shared/data/pointclouds";
  if (!std::ifstream(root + "/pcl/milk.pcd") || !std::ifstream(root + "/stanford_bunny/bun045.ply"))
    GTEST_SKIP() << "real data not found at " << root;
  struct Case {
    std::string model, scene;
    Eigen::Vector3f sensor;
    Eigen::Isometry3d truth;
    double max_t, max_r_deg;
  };
  const std::vector<Case> cases = {
      {root + "/stanford_bunny/bun045.ply", root + "/stanford_bunny/bun000.ply", Eigen::Vector3f(0, 0, 1),
       bunnyTruth(root + "/stanford_bunny"), 2e-3, 1.0},
      {root + "/pcl/milk.pcd", root + "/pcl/milk_cartoon_all_small_clorox.pcd", Eigen::Vector3f::Zero(),
       Eigen::Isometry3d::Identity(), 5e-3, 2.0}};
  for (const Case& c : cases) {
    auto lib = std::make_shared<ModelLibrary>();
    lib->addCloudModel("m", loadCloud(c.model), c.sensor);
    const ScanCloud scene = loadCloud(c.scene);
    const double diagonal = lib->model("m").bounds.diagonal().norm();
    MatchingConfig cfg = scaledMatchingConfig(MatchingConfig(), diagonal, scene);
    cfg.viewpoint = c.sensor;
    cfg.min_coverage = 0;
    cfg.max_instances = 1;
    ModelMatcher m(lib, cfg);
    MatchStats st;
    const auto d = m.locate({scene}, {}, &st);
    ASSERT_EQ(d.size(), 1u) << c.model;
    const PoseError e = poseError(lib->model("m").info, m.centroid("m"), d[0].pose, c.truth);
    std::printf("%s, scaled defaults (voxel %.1f mm): %.3f mm %.3f deg, fitness %.2f\n", c.model.c_str(), cfg.voxel * 1e3,
                e.translation * 1e3, e.rotation * 180 / M_PI, d[0].fitness);
    EXPECT_LT(e.translation, c.max_t) << c.model;
    EXPECT_LT(e.rotation, c.max_r_deg * M_PI / 180) << c.model;
  }
  // a part that is not there: the milk carton in the bunny scan fits its best pose to 4.9 mm,
  // which the voxel-scaled RMSE limit (0.75 voxel) let through; the scan's scatter does not
  auto lib = std::make_shared<ModelLibrary>();
  lib->addCloudModel("milk", loadCloud(root + "/pcl/milk.pcd"), Eigen::Vector3f::Zero());
  const ScanCloud bunny = loadCloud(root + "/stanford_bunny/bun000.ply");
  ScanFigures scan;
  MatchingConfig cfg = scaledMatchingConfig(MatchingConfig(), lib->model("milk").bounds.diagonal().norm(), bunny, &scan);
  cfg.min_coverage = 0;
  cfg.max_instances = 1;
  ModelMatcher m(lib, cfg);
  MatchStats st;
  EXPECT_TRUE(m.locate({bunny}, {}, &st).empty());
  ASSERT_FALSE(st.rejected.empty());
  std::printf("milk in bun000: refused (%s); scatter %.3f mm\n", st.rejected[0].refused_by.c_str(), scan.noise * 1e3);
  EXPECT_NE(st.rejected[0].refused_by.find("> max_rmse"), std::string::npos);
}

namespace {

/// A 20 x 20 cm plane sampled every millimetre, scattered along its normal by `sigma`.
ScanCloud noisyPlane(double sigma) {
  std::mt19937 rng(5);
  std::normal_distribution<float> n(0.f, static_cast<float>(sigma));
  ScanCloud c;
  for (int i = 0; i < 200; ++i)
    for (int j = 0; j < 200; ++j) c.append(Eigen::Vector3f(i * 1e-3f, j * 1e-3f, sigma > 0 ? n(rng) : 0.f), 1.f);
  return c;
}

}  // namespace

// The RMSE limit of the scaled settings follows the scan's scatter off its surface: twice it,
// within [0.1, 0.5] voxel.
TEST(ScaledSettings, RmseLimitFollowsTheScansScatter) {
  const double diagonal = 0.1;  // voxel 2 mm (diagonal / 50; the spacing is 1 mm)
  ScanFigures f;
  MatchingConfig c = scaledMatchingConfig(MatchingConfig(), diagonal, noisyPlane(0), &f);
  EXPECT_NEAR(c.voxel, 0.002, 1e-4);
  EXPECT_NEAR(f.spacing, 0.001, 1e-5);
  EXPECT_LT(f.noise, 1e-6);
  EXPECT_NEAR(c.max_rmse, 0.1 * c.voxel, 1e-9);  // the floor
  c = scaledMatchingConfig(MatchingConfig(), diagonal, noisyPlane(0.0003), &f);
  EXPECT_NEAR(f.noise, 0.0003, 0.00006);  // ~12 points in the 2 mm ball, which cuts some of it off
  EXPECT_NEAR(c.max_rmse, 2 * f.noise, 1e-9);
  ScanCloud lattice;  // no surface at all: a 3-D lattice of 1 mm, 3 cm a side
  for (int i = 0; i < 30; ++i)
    for (int j = 0; j < 30; ++j)
      for (int k = 0; k < 30; ++k) lattice.append(Eigen::Vector3f(i, j, k) * 1e-3f, 1.f);
  c = scaledMatchingConfig(MatchingConfig(), diagonal, lattice, &f);
  EXPECT_GT(2 * f.noise, 0.5 * c.voxel);
  EXPECT_NEAR(c.max_rmse, 0.5 * c.voxel, 1e-9);  // the cap
  // the estimate itself, with a ball well above the noise
  EXPECT_NEAR(medianPlaneResidual(noisyPlane(0.0005), 0.006), 0.0005, 0.00005);
  // too sparse for a plane (fewer than 6 neighbours in the ball): 0
  EXPECT_EQ(medianPlaneResidual(noisyPlane(0), 0.0015), 0.0);
  EXPECT_EQ(medianPlaneResidual(ScanCloud(), 0.01), 0.0);
}

namespace {

/// A view without what lies within `loss` of a crease of the part (at `truth`): the scanner's
/// loss at edges, the same at every edge.
ScanCloud erodedAtCreases(const ScanCloud& view, const Eigen::Isometry3d& truth, const PlanarFaces& faces, double loss) {
  ScanCloud out;
  for (const auto& p : view.points) {
    const Eigen::Vector3d q = truth.inverse() * p.cast<double>();
    double d = 1;
    for (const auto& g : faces.groups) {
      for (const auto& [a, b] : g.creases) {
        const Eigen::Vector3d e = b - a;
        const double u = std::clamp((q - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
        d = std::min(d, (q - a - u * e).norm());
      }
    }
    if (d > loss) out.append(p, 0.f);
  }
  return out;
}

}  // namespace

// A scanner loses a little at every edge (segment ends, the last line before an edge), so a
// flat top's scanned patch is smaller than the face and slides inside it; ICP stops where the
// first points reach an edge. Centring in the slack puts the pose in the middle: with the same
// loss at every edge, at the truth.
TEST(ModelMatching, CentringInTheSlackUndoesEvenEdgeLoss) {
  MatchingConfig on = config(), off = config();
  off.icp_centre_slack = false;
  ModelMatcher centred(library(), on), pinned(library(), off);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(0, 1);
  const Eigen::Vector4f table(0, 0, 1, 0);
  std::vector<double> e_on, e_off;
  for (const std::string part : {"blade", "housing", "holder"}) {
    const TriangleMesh& mesh = library()->model(part).mesh;
    const PlanarFaces faces = planarFaces(mesh);
    for (int t = 0; t < 3; ++t) {
      const Eigen::Isometry3d truth = onTable(0.40 + 0.24 * U(rng), -0.09 + 0.18 * U(rng), 2 * M_PI * U(rng));
      const ScanCloud view = singleViewCloud(mesh, truth, kEye, 0.0005, 2e-5, rng());
      const ScanCloud eroded = erodedAtCreases(view, truth, faces, 0.001);
      for (auto* m : {&centred, &pinned}) {
        const auto det = m->locate({eroded}, {part}, nullptr, nullptr, &table);
        ASSERT_EQ(det.size(), 1u) << part;
        const PoseError e = poseError(library()->model(part).info, m->centroid(part), det[0].pose, truth);
        (m == &centred ? e_on : e_off).push_back(e.translation);
      }
    }
  }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  std::printf("1 mm edge loss, 9 views: median error centred %.3f mm, pinned %.3f mm\n", median(e_on) * 1e3,
              median(e_off) * 1e3);
  EXPECT_LT(median(e_on), 0.15e-3);
  EXPECT_LT(median(e_on), 0.5 * median(e_off));
}

// Where a laser line runs off an edge it reads a little below the face, so those points lie
// closer to the wall under the edge, which the scanner never saw, than to the face they are on.
// Matched to that wall they pin the part sideways wherever they fall. A standing shaft seen from
// above, its top rim with such an arc (0.5 mm low, its radius drifting 0.2 mm along it): faces
// with nothing beyond icp_edge_band of their creases count as unseen, and the slack is centred
// without them.
TEST(ModelMatching, MixedEdgePointsDoNotPinThePart) {
  MatchingConfig on = config(), off = config();
  off.icp_edge_band = 0;
  ModelMatcher dropping(library(), on), pinned(library(), off);
  const std::string part = "flanged_shaft";
  const TriangleMesh& mesh = library()->model(part).mesh;
  const PlanarFaces faces = planarFaces(mesh);
  const double top = mesh.bounds().max().z();
  const Eigen::Vector4f table(0, 0, 1, 0);
  std::vector<double> e_on, e_off;
  for (int t = 0; t < 3; ++t) {
    const Eigen::Isometry3d truth = onTable(0.50 + 0.02 * t, 0.06, 0.3 * t);
    const ScanCloud view = singleViewCloud(mesh, truth, kEye, 0.0005, 2e-5, 40 + t);
    ScanCloud scan = erodedAtCreases(view, truth, faces, 0.001);
    for (double az = -100; az <= -80; az += 0.25) {  // the mixed arc (model frame, shaft axis at x = y = 0)
      const double r = 0.00885 + 0.0002 * (az + 100) / 20, a = az * M_PI / 180;
      scan.append((truth * Eigen::Vector3d(r * std::cos(a), r * std::sin(a), top - 0.0005)).cast<float>(), 0.f);
    }
    for (auto* m : {&dropping, &pinned}) {
      const auto det = m->locate({scan}, {part}, nullptr, nullptr, &table);
      ASSERT_EQ(det.size(), 1u) << (m == &dropping ? "dropping" : "pinned");
      const PoseError e = poseError(library()->model(part).info, m->centroid(part), det[0].pose, truth);
      (m == &dropping ? e_on : e_off).push_back(e.translation);
    }
  }
  std::sort(e_on.begin(), e_on.end());
  std::sort(e_off.begin(), e_off.end());
  std::printf("standing shaft with a mixed rim arc, 3 views: median error %.3f mm (unseen faces dropped), %.3f mm (kept)\n",
              e_on[1] * 1e3, e_off[1] * 1e3);
  EXPECT_LT(e_on[1], 0.15e-3);
  EXPECT_LT(e_on[1], 0.5 * e_off[1]);
}

// Prepared models on disk: a second matcher loads them instead of preparing, and finds the same
// poses to the last bit; a damaged file is prepared again; other settings use another file.
TEST(ModelCache, PreparedModelsLoadFromDiskWithTheSameResult) {
  const std::string dir = cellsight_test::tempDir() + "/cache";
  MatchingConfig c = config();
  c.model_cache_dir = dir;
  const std::vector<std::string> ids = {"housing", "bracket"};
  const Eigen::Isometry3d truth = onTable(0.5, 0.02, 0.7);
  const ScanCloud view = singleViewCloud(library()->model("housing").mesh, truth, kEye, 0.001, 2e-5, 5);
  ModelMatcher cold(library(), c);
  cold.prepare(ids);
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files.push_back(e.path().string());
  ASSERT_EQ(files.size(), 2u);
  ModelMatcher warm(library(), c);  // loads (its speed: bench_localization, model_preparation_ours)
  warm.prepare(ids);
  const auto a = cold.locate({view}, ids), b = warm.locate({view}, ids);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(a[0].model, b[0].model);
  EXPECT_TRUE(a[0].pose.isApprox(b[0].pose, 0.0));
  EXPECT_EQ(a[0].fitness, b[0].fitness);
  // a damaged file: prepared again (same result) and rewritten
  const auto size0 = std::filesystem::file_size(files[0]);
  std::filesystem::resize_file(files[0], size0 / 2);
  ModelMatcher again(library(), c);
  again.prepare(ids);
  const auto d = again.locate({view}, ids);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_TRUE(d[0].pose.isApprox(a[0].pose, 0.0));
  EXPECT_EQ(std::filesystem::file_size(files[0]), size0);
  // settings that shape the preparation key another file
  c.ppf_sampling *= 1.1;
  ModelMatcher other(library(), c);
  other.prepare({"bracket"});
  size_t n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) n += e.is_regular_file();
  EXPECT_EQ(n, 3u);
}

// refine(): a located part polished on a second scan of the cell. A pose 0.7 mm and 0.4° off
// comes back to the truth; a scan without the part, or a move past refine_max_shift, leaves the
// pose as it was and says why; an unknown model throws.
TEST(ModelMatching, RefineOnASecondScan) {
  const std::string part = "housing";
  const ModelEntry& e = library()->model(part);
  const Eigen::Isometry3d truth = onTable(0.5, 0.02, 0.7);
  const ScanCloud second = singleViewCloud(e.mesh, truth, kEye, 0.0005, 2e-5, 11);
  const Eigen::Vector4f table(0, 0, 1, 0);
  ModelMatcher matcher(library(), config());
  PartDetection d;
  d.model = part;
  d.pose = Eigen::Translation3d(0.0006, -0.0003, 0) * truth * Eigen::AngleAxisd(0.007, Eigen::Vector3d::UnitZ());
  const PoseError before = poseError(e.info, matcher.centroid(part), d.pose, truth);
  MatchStats st;
  auto out = matcher.refine(second, {d}, &st, nullptr, &table);
  ASSERT_EQ(out.size(), 1u);
  ASSERT_TRUE(out[0].refined) << (st.warnings.empty() ? "" : st.warnings[0]);
  const PoseError after = poseError(e.info, matcher.centroid(part), out[0].pose, truth);
  std::printf("refined on a second scan: %.3f mm / %.3f deg -> %.3f mm / %.3f deg\n", before.translation * 1e3,
              before.rotation * 180 / M_PI, after.translation * 1e3, after.rotation * 180 / M_PI);
  EXPECT_LT(after.translation, 0.1e-3);
  EXPECT_LT(after.rotation, 0.1 * M_PI / 180);
  // the part is not in this scan: kept, with the reason
  ScanCloud elsewhere = second;
  for (auto& p : elsewhere.points) p.x() += 0.2f;
  out = matcher.refine(elsewhere, {d}, &st, nullptr, &table);
  EXPECT_FALSE(out[0].refined);
  EXPECT_TRUE(out[0].pose.isApprox(d.pose, 0.0));
  ASSERT_EQ(st.warnings.size(), 1u);
  EXPECT_NE(st.warnings[0].find("refine_min_points"), std::string::npos) << st.warnings[0];
  // a move beyond refine_max_shift: kept, with the reason
  MatchingConfig strict = config();
  strict.refine_max_shift = 0.0002;
  out = ModelMatcher(library(), strict).refine(second, {d}, &st, nullptr, &table);
  EXPECT_FALSE(out[0].refined);
  EXPECT_TRUE(out[0].pose.isApprox(d.pose, 0.0));
  ASSERT_EQ(st.warnings.size(), 1u);
  EXPECT_NE(st.warnings[0].find("refine_max_shift"), std::string::npos) << st.warnings[0];
  PartDetection unknown;
  unknown.model = "no_such_part";
  EXPECT_THROW(matcher.refine(second, {unknown}), std::out_of_range);
}

// An upright holder touching a cylinder that is not in the library, recorded in tuning cell 3317
// (capture seed 3's calibration, with the scan's sweep): one cluster of 1332 points, 635 of them
// the holder's (its arms' tops and the channel's floor), the rest the cylinder's. PPF proposes
// no pose near the holder, and the rest poses centred on the cluster lie between the two, 30 mm
// off, too far for their short ICP. Laid with their ends on the cluster's ends, one of them is
// the holder's.
TEST(ModelMatching, APartTouchingAnotherIsLaidOnTheClustersEnd) {
  const RecordedCell cell = recordedCell({{"holder_and_cylinder_3317.ply", 1332}}, "sweep_capture_seed_3.txt");
  const Eigen::Isometry3d truth =
      truePose({0.60311553099495996, 0.010497322274686444, 0}, {0.97342536410773195, 0, 0, 0.22900449888971477});
  const PoseError off =
      locateRecorded(cell.clusters, "holder", cell.sweep, truth, [](MatchingConfig& c) { c.rest_end_ratio = 0; }, nullptr);
  const PoseError on = locateRecorded(cell.clusters, "holder", cell.sweep, truth, [](MatchingConfig&) {}, nullptr);
  std::printf("holder touching a cylinder: %.2f mm, %.2f deg off; centred only: %s\n", on.translation * 1e3,
              on.rotation * 180 / M_PI, off.translation < 1 ? std::to_string(off.translation * 1e3).c_str() : "not found");
  EXPECT_GT(off.translation, 5e-3) << "found without the ends: the test no longer shows what they add";
  EXPECT_LT(on.translation, 1e-3);
  EXPECT_LT(on.rotation, 1 * M_PI / 180);
}

// A bracket standing on the outer face of its wall, recorded in generated cell 3159 (the true
// calibration, with the scan's sweep) in one cluster with a flanged shaft it touches. The camera
// sees the base plate's end, a strip 40 x 5 mm 60 mm up, and the wall's inner face 5 mm up; the
// strip's few points leave the tilt loose. Polished freely the pose settles tilted and is refused
// here (located on the cluster alone); laid into the rest it is nearest (rest_snap_angle) and
// polished with its tilt held, it is accepted where the part lies.
TEST(ModelMatching, APoseALittleTiltedFromARestIsLaidIntoIt) {
  const RecordedCell cell = recordedCell({{"bracket_on_its_end_and_shaft_3159.ply", 862}}, "sweep_true_calibration.txt");
  const Eigen::Isometry3d truth =
      truePose({0.55760297870308628, 0.066673023926280536, 0.029999999329447746},
               {-0.38185936769090145, 0.59513311393897816, 0.38185936769090134, 0.59513311393897839});
  const MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  ASSERT_GT(shipped.rest_snap_angle, 0) << "laying poses into their rests is off as shipped";
  const Eigen::Vector3d up(0, 0, 1);
  // the tilt: the angle between the table's normal in the pose's and in the truth's model frame
  auto tilt = [&](const Eigen::Isometry3d& T) {
    return std::acos(std::clamp((T.linear().transpose() * up).dot(truth.linear().transpose() * up), -1.0, 1.0));
  };
  auto run = [&](double snap, PartDetection* found, MatchStats* st) {
    MatchingConfig c = shipped;
    c.viewpoint = kEye;
    c.rest_snap_angle = snap;
    const Eigen::Vector4f table(0, 0, 1, 0);
    ModelMatcher m(library(), c);
    for (const auto& x : m.locate(cell.clusters, {"bracket", "flanged_shaft"}, st, nullptr, &table, nullptr, &cell.sweep))
      if (x.model == "bracket") {
        *found = x;
        return true;
      }
    return false;
  };
  PartDetection off, on;
  MatchStats st_off, st_on;
  const bool found_off = run(0, &off, &st_off), found_on = run(shipped.rest_snap_angle, &on, &st_on);
  const PartDetection* refused = nullptr;
  for (const auto& r : st_off.rejected)
    if (r.model == "bracket" && (!refused || r.score > refused->score)) refused = &r;
  ASSERT_FALSE(found_off) << "found with the tilt left free (" << tilt(off.pose) * 180 / M_PI
                          << " deg tilted): the test no longer shows what the rests add";
  ASSERT_NE(refused, nullptr);
  std::printf("free: refused, %.2f deg tilted (%s); laid into its rest: %.2f deg tilted, fitness %.3f, unseen %.3f\n",
              tilt(refused->pose) * 180 / M_PI, refused->refused_by.c_str(), tilt(on.pose) * 180 / M_PI, on.fitness,
              on.unseen);
  EXPECT_GT(tilt(refused->pose), 1.5 * M_PI / 180);
  ASSERT_TRUE(found_on);
  EXPECT_LT(tilt(on.pose), 0.3 * M_PI / 180);
  const PoseError e = poseError(library()->model("bracket").info, ModelMatcher(library(), config()).centroid("bracket"), on.pose, truth);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  EXPECT_LT(e.translation, 2e-3);
}

// A holder fitted upside down onto a box distractor (43.0 x 28.9 x 32.0 mm), recorded in tuning
// cell 3095 (true calibration, with the scan's sweep and the table points the clustering kept
// around it): the holder's 50 x 30 mm top, centred on the box's, overhangs it by 3.5 mm at each
// end. That is within what the unseen test leaves to a scanner's lost edges (unseen_radius, 3 mm)
// and within the see-through map's eroded border, so both pass it; but the camera measured the
// table past those ends, where the holder would hide it, and the overhang test refuses it. The
// holder lying on an arm beside it, the cell's own, is found.
TEST(ModelMatching, AHolderFittedOntoASmallerBoxIsRefusedForItsOverhang) {
  const RecordedCell cell =
      recordedCell({{"holder_on_a_box_3095.ply", 606}, {"holder_on_an_arm_3095.ply", 408}}, "sweep_true_calibration.txt");
  const std::vector<Eigen::Vector3f> table_points = loadCloud(kData + "table_around_a_box_3095.ply").points;
  ASSERT_EQ(table_points.size(), 2797u);
  const Eigen::Isometry3d truth =
      truePose({0.54094596021514052, 0.059280680966321171, 0.014999999664723873},
               {0.66002237839202316, -0.66002237839202293, 0.25371334222255071, -0.25371334222255076});
  const MatchingConfig shipped = loadMatchingConfig(std::string(CELLSIGHT_SOURCE_DIR) + "/config/matching.yaml");
  ASSERT_LT(shipped.max_overhang, 1) << "the overhang test is off as shipped";
  const Eigen::Vector4f table(0, 0, 1, 0);
  auto run = [&](double max_overhang, MatchStats* st) {
    MatchingConfig c = shipped;
    c.viewpoint = kEye;
    c.max_overhang = max_overhang;
    return ModelMatcher(library(), c).locate(cell.clusters, {"holder"}, st, nullptr, &table, &table_points, &cell.sweep);
  };
  MatchStats st_off, st_on;
  const auto off = run(1.0, &st_off), on = run(shipped.max_overhang, &st_on);
  // without the test: the holder on the box passes every other one
  const PartDetection* on_box = nullptr;
  for (const auto& d : off)
    if (d.cluster == 0) on_box = &d;
  ASSERT_NE(on_box, nullptr) << "no holder fitted onto the box: the test no longer shows what the overhang test adds";
  std::printf("on the box: fitness %.3f, see-through %.3f, unseen %.3f, overhang %.3f\n", on_box->fitness, on_box->see_through,
              on_box->unseen, on_box->overhang);
  EXPECT_LE(on_box->see_through, shipped.max_see_through);
  EXPECT_LE(on_box->unseen, shipped.max_unseen);
  EXPECT_GT(on_box->overhang, shipped.max_overhang);
  // with it: refused, and named so; the cell's holder stays found
  ASSERT_EQ(on.size(), 1u);
  EXPECT_EQ(on[0].cluster, 1);
  std::printf("the cell's holder: overhang %.3f\n", on[0].overhang);
  EXPECT_LE(on[0].overhang, shipped.max_overhang);
  const PoseError e = poseError(library()->model("holder").info, ModelMatcher(library(), config()).centroid("holder"), on[0].pose, truth);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  bool named = false;
  for (const auto& r : st_on.rejected)
    named = named || (r.cluster == 0 && r.refused_by.find("> max_overhang") != std::string::npos);
  EXPECT_TRUE(named) << "no refused pose on the box names the overhang test";
}
