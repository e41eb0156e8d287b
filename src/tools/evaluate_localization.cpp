// cellsight_evaluate_localization: localisation figures against ground truth.
// Usage: cellsight_evaluate_localization SUBCOMMAND [OPTIONS]   (--help on the tool and each subcommand)
//   demo       detections of the demo scan vs the simulator's truth → detections.json
//              --detections detections_raw.json [--scene S.yaml] [--models F] [--root R]
//              [--max-t-mm 5] [--max-r-deg 5] [--json out.json]; exit 3 unless every part is found
//   occlusion  the thesis's random-walk occlusion test on single-view clouds of our parts
//              [--parts blade,housing,holder] [--trials 100] [--from 0.25] [--to 0.75] [--step 0.05]
//              [--ks 20] [--min-fitness F] + the sweep options below
//   outliers   uniform outliers with random normals in the workspace box, 0…200 % of the points
//              [--parts blade,housing,holder,bracket] [--trials 50] [--ratios 0,0.25,0.5,1,1.5,2]
//              + the sweep options below
//   cells      random cells (scene generator) scanned in-process, clustered, located: P/R/F1
//              --seeds N... | --seeds-file config/heldout_seeds.yaml [--out DIR] [--json out.json]
//   descriptors  FPFH vs the learned descriptor in the same RANSAC pipeline: held-out laser views of
//              our parts and the real UWA / PCL scenes [--views 12] [--json F] [--png F]
//              [--limit-beats-fpfh MARGIN] (exit 4 unless learned beats FPFH)
//   (a part in a real scan from files: cellsight_locate)
//   sweep options (occlusion, outliers): [--search all|self] [--root repo] [--scene S.yaml]
//              [--models folder] [--matching matching.yaml] [--max-t-mm 2] [--max-r-deg 2]
//              [--json out.json] [--png curves.png]
//   --png of a sweep: success-rate curves drawn by /usr/bin/gnuplot; the data and the script stay
//   beside it (curves.png.dat, curves.png.gp: re-plot with `cd <folder> && gnuplot curves.png.gp`).
//   No gnuplot, or a failing one: a warning, the JSON is still written (it is the result).
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/eval/scene_generator.hpp"
#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/localization/scan_localization.hpp"
#include "cellsight/sim/scene.hpp"
#include "cli_args.hpp"
#include "gnuplot.hpp"
#include "descriptor_eval.hpp"
#include "evaluate_localization.hpp"
#include "json_pose.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace {

const double kDeg = M_PI / 180;

using Options = cellsight_tools::EvalOptions;
using cellsight_tools::nonEmpty;
using cellsight_tools::runOcclusion;
using cellsight_tools::runOutliers;
using cellsight_tools::ScoredDetection;
using cellsight_tools::scoreDetections;
using cellsight_tools::describeScanPoints;
using cellsight_tools::kOnSurface;
using cellsight_tools::kFitsBoth;

using cellsight_tools::median;
using cellsight_tools::writeJson;

int runDemo(const Options& o) {
  const Scene scene = loadScene(o.orRoot(o.scene, "config/scenes/demo.yaml"));
  auto lib = std::make_shared<const ModelLibrary>(o.orRoot(o.models, "config/models"));
  ModelMatcher centroids(lib, MatchingConfig());
  std::ifstream f(o.detections);
  if (!f) throw std::runtime_error("cannot read --detections '" + o.detections + "'");
  json raw;
  try {
    f >> raw;
  } catch (const std::exception& e) {
    throw std::runtime_error(o.detections + ": not valid JSON: " + e.what());
  }
  std::vector<ScoredDetection> dets;
  for (const json& d : raw["detections"]) {
    dets.push_back({d.at("model"), cellsight_tools::poseFromJson(d), d.at("fitness"), d.at("coverage"), d.at("rmse").get<double>()});
    for (const auto& a : d.value("ambiguous_poses", json::array())) dets.back().ambiguous_poses.push_back(cellsight_tools::poseFromJson(a));
    dets.back().alternative_score_share = d.value("alternative_score_share", 0.0);
  }
  // "found": the right model within 5 mm / 5° (a gross-error test); the errors are reported as measured
  DetectionCounts counts;
  std::vector<double> terr, rerr;
  json out = scoreDetections(scene, *lib, centroids, dets, o.max_t_mm * 1e-3, o.max_r_deg * kDeg, &counts, &terr, &rerr);
  out["locate_seconds"] = raw.value("locate_seconds", 0.0);
  for (auto& p : out["parts"])
    if (p["found"].get<bool>()) p["locate_seconds"] = out["locate_seconds"];
  writeJson(o.json, out);
  std::printf("demo: %d/%zu parts found, %d false, median %.3f mm %.3f deg, locate %.3f s\n", counts.tp, scene.objects.size(),
              counts.fp, median(terr), median(rerr), out["locate_seconds"].get<double>());
  return counts.fn == 0 && counts.fp == 0 ? 0 : 3;
}

/// One finished scan of a cell (scanner/scan_pipeline's finish, as the nodes do), the sweep that
/// lit it and the camera centre as the scanner knows them and, for scoring only, the object each
/// of its points lies on and the scan's surface error (SurfaceDistance::stats).
struct CellScan {
  ScanCloud cloud;
  std::optional<LightSweep> light;
  Eigen::Vector3f viewpoint = Eigen::Vector3f::Zero();
  std::vector<int> on_object;
  double surface_rms = 0;  ///< m
};

/// A scan clustered as the nodes do, as one pass of the localization pipeline; with
/// --dump-clusters, what the matcher is given written beside it.
ScanPass clusteredPass(const Scene& scene, const CellScan& scan, PassRole role, const ClusteringConfig& ccfg,
                       const Options& o, const std::string& suffix) {
  const ClusteringResult cr = clusterScene(scan.cloud, ccfg);
  ScanPass pass = scanPass(role, cr, scan.viewpoint, scan.light);
  if (!o.dump_clusters.empty()) {  // what the matcher was given, for a look in a viewer
    makeDirs(o.dump_clusters);
    const std::string stem = o.dump_clusters + "/" + scene.name + suffix;
    for (size_t i = 0; i < pass.clusters.size(); ++i) saveCloud(stem + "_cluster_" + std::to_string(i) + ".ply", pass.clusters[i]);
    ScanCloud support;  // the table points the free-space test (max_see_through) reads
    for (const auto& p : cr.support_points) support.append(p, 0.f);
    saveCloud(stem + "_support.ply", support);
    ScanCloud fragments;  // unclustered points: evidence for the fitness and unseen tests only
    for (const auto& p : cr.fragments) fragments.append(p, 0.f);
    if (fragments.size() > 0) saveCloud(stem + "_fragments.ply", fragments);
    // the sweep the illumination and unseen tests read
    if (scan.light) saveSweep(stem + "_sweep.txt", *scan.light);
  }
  return pass;
}

std::vector<size_t> clusterSizes(const ScanPass& pass) {
  std::vector<size_t> sizes;
  for (const auto& c : pass.clusters) sizes.push_back(c.size());
  return sizes;
}

/// A finished scan clustered and located as the nodes do (locateScan), scored against the
/// scene's truth; with `second`, a second scan of the cell that adds the parts the first left
/// unfound (PassRole::kAddDetections).
json locateAndScore(const Scene& scene, const CellScan& scan, const ModelLibrary& lib, ModelMatcher& matcher,
                    const ClusteringConfig& ccfg, const Options& o, DetectionCounts* counts, std::vector<double>* terr,
                    std::vector<double>* rerr, const CellScan* second = nullptr) {
  std::vector<ScanPass> passes{clusteredPass(scene, scan, PassRole::kDetect, ccfg, o, "")};
  if (second) passes.push_back(clusteredPass(scene, *second, PassRole::kAddDetections, ccfg, o, "_pass2"));
  const LocatedScan located = locateScan(matcher, passes);
  const MatchStats& st = located.stats;
  const std::vector<PartDetection>& found = located.parts;
  const ScanCloud& cloud = scan.cloud;
  std::vector<ScoredDetection> dets;
  for (const auto& d : found)
    dets.push_back({d.model, d.pose, d.fitness, d.coverage, d.rmse, d.see_through, d.unseen, d.continuation,
                    d.overhang, d.alternative_score_share, d.ambiguous_poses, d.pass});
  json sj = scoreDetections(scene, lib, matcher, dets, o.max_t_mm * 1e-3, o.max_r_deg * kDeg, counts, terr, rerr);
  // a missed part: the pose of its model nearest the truth that validation refused, with the
  // figures it failed on
  for (auto& p : sj["parts"]) {
    if (p["found"].get<bool>() || p.value("distractor", false)) continue;
    for (const auto& o : scene.objects) {
      if (o.name != p["name"].get<std::string>()) continue;
      double nearest = 1e9;
      for (const auto& r : st.rejected) {
        if (r.model != o.model) continue;
        const PoseError e = poseError(lib.model(o.model).info, matcher.centroid(o.model), r.pose, o.T_base_object);
        if (e.translation >= nearest) continue;
        nearest = e.translation;
        p["nearest_rejected"] = {{"fitness", r.fitness},       {"coverage", r.coverage},
                                 {"rmse_mm", r.rmse * 1e3},    {"see_through", r.see_through}, {"overhang", r.overhang}, {"unseen", r.unseen},
                                 {"continuation", r.continuation}, {"cluster", r.cluster},       {"pass", r.pass},
                                 {"t_err_mm", e.translation * 1e3},
                                 {"r_err_deg", e.rotation / kDeg},
                                 {"refused_by", r.refused_by},
                                 {"pose", cellsight_tools::poseToJson(r.pose)}};
      }
    }
  }
  // every pose validation refused (the best per cluster and model), and whether it was right:
  // the figures right and wrong poses reach, for choosing acceptance thresholds on tuning cells
  sj["rejected"] = json::array();
  std::vector<const PartDetection*> listed;  // a cluster searched again (half the coverage) refuses the same pose twice
  for (const auto& r : st.rejected) {
    if (std::any_of(listed.begin(), listed.end(), [&](const PartDetection* l) {
          return l->model == r.model && l->cluster == r.cluster && l->pass == r.pass && l->pose.isApprox(r.pose, 1e-9);
        }))
      continue;
    listed.push_back(&r);
    double t_err = 1e9, r_err = 1e9;
    for (const auto& o : scene.objects) {
      if (o.model != r.model) continue;
      const PoseError e = poseError(lib.model(o.model).info, matcher.centroid(o.model), r.pose, o.T_base_object);
      if (e.translation < t_err) t_err = e.translation, r_err = e.rotation;
    }
    sj["rejected"].push_back({{"model", r.model},
                              {"cluster", r.cluster},
                              {"pass", r.pass},
                              {"fitness", r.fitness},
                              {"coverage", r.coverage},
                              {"rmse_mm", r.rmse * 1e3},
                              {"see_through", r.see_through},
                              {"overhang", r.overhang},
                              {"unseen", r.unseen},
                              {"continuation", r.continuation},
                              {"refused_by", r.refused_by},
                              {"right", t_err <= o.max_t_mm * 1e-3 && r_err <= o.max_r_deg * kDeg}});
  }
  if (!scan.on_object.empty() && second) {  // what either scan measured of each part
    ScanCloud both = cloud;
    std::vector<int> on = scan.on_object;
    on.resize(cloud.size(), -1);
    for (const auto& p : second->cloud.points) both.append(p, 0.f);
    on.insert(on.end(), second->on_object.begin(), second->on_object.end());
    describeScanPoints(scene, lib, both, on, dets, &sj);
  } else if (!scan.on_object.empty()) {
    describeScanPoints(scene, lib, cloud, scan.on_object, dets, &sj);
  }
  sj["cluster_sizes"] = clusterSizes(passes.front());
  sj["points"] = cloud.size();
  sj["clusters"] = passes.front().clusters.size();
  if (second) {
    sj["second_pass"] = {{"points", second->cloud.size()},
                         {"cluster_sizes", clusterSizes(passes.back())},
                         {"found", located.passes.back().found.size()},
                         {"added", st.second_pass_added},
                         {"taken", st.second_pass_taken},
                         {"locate_seconds", located.passes.back().stats.seconds}};
  }
  sj["locate_seconds"] = st.seconds;
  sj["split_parts_polished"] = st.split_parts_polished;
  sj["turned_poses"] = st.turned_poses;
  sj["interpenetrating"] = st.interpenetrating;
  return sj;
}

/// A finished scan file located in-process (clustering + matching with the repository's
/// settings) and scored: the localisation figures of a scan made another way (e.g. the demo's
/// frames triangulated again with another calibration). Exit 3 unless every part is found.
int runCloud(const Options& o) {
  const Scene scene = loadScene(o.orRoot(o.scene, "config/scenes/demo.yaml"));
  auto lib = std::make_shared<const ModelLibrary>(o.orRoot(o.models, "config/models"));
  const MatchingConfig cfg = loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml"));
  const ClusteringConfig ccfg = loadClusteringConfig(o.root + "/config/clustering.yaml");
  ModelMatcher matcher(lib, cfg);
  matcher.prepare({});
  CellScan scan;
  scan.cloud = loadCloud(o.cloud);
  if (scan.cloud.size() == 0) throw std::runtime_error(o.cloud + ": the cloud is empty");
  // the visible-surface test's viewpoint: the calibrated camera, else the scene file's
  scan.viewpoint = (o.calibration.empty() ? scene.scanner_camera.T_base_camera
                                          : ScannerCalibration::fromFolder(o.calibration).T_base_camera)
                       .translation()
                       .cast<float>();
  DetectionCounts counts;
  std::vector<double> terr, rerr;
  json out = locateAndScore(scene, scan, *lib, matcher, ccfg, o, &counts, &terr, &rerr);
  out["cloud"] = o.cloud;
  writeJson(o.json, out);
  std::printf("cloud: %d/%zu parts found, %d false, median %.3f mm %.3f deg\n", counts.tp, scene.objects.size(), counts.fp,
              median(terr), median(rerr));
  return counts.fn == 0 && counts.fp == 0 ? 0 : 3;
}

/// The second pass's image-noise seed is the cell's plus this (another scan, other noise).
constexpr uint64_t kSecondPassNoise = 1000003;

/// A generated cell scanned in-process along `sweep` with `cal` (frames rendered where the robot
/// as built takes the flange; image noise from `noise_seed`) and finished as the node does (finishScan);
/// the light sheet frame by frame and the camera centre as the scanner knows them (the poses the robot
/// reported, the calibration); each point's object from the truth.
CellScan scanCell(const Scene& scene, const ScannerRenderer& renderer, const Trajectory& sweep, const ScannerCalibration& cal,
                  const ScannerSettings& settings, const RobotErrorModel& robot, uint64_t noise_seed) {
  CellScan s;
  s.viewpoint = cal.T_base_camera.translation().cast<float>();
  s.cloud = finishScan(simulateScan(renderer, sweep.poses, cal, settings.line, settings.triangulation, noise_seed, nullptr, &robot),
                       settings, s.viewpoint);
  s.light = LightSweep::fromFlangePoses(sweep.poses, cal.T_flange_laser, settings.laser_fan_angle / 2);
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : s.cloud.points) pts.push_back(p.cast<double>());
  s.surface_rms = SurfaceDistance(scene).stats(pts, &s.on_object, kOnSurface).rms;
  return s;
}

/// Random cells (eval/scene_generator) scanned in-process (the demo sweep unless told) and the nodes' crop
/// and outlier filter, clustered and located: detection P/R/F1 and errors over the seeds.
int runCells(const Options& o, const std::vector<uint64_t>& seeds, const std::string& out_dir) {
  const std::string models = o.orRoot(o.models, "config/models"), base = o.orRoot(o.scene, "config/scenes/demo.yaml");
  auto lib = std::make_shared<const ModelLibrary>(models);
  const MatchingConfig cfg = loadMatchingConfig(o.orRoot(o.matching, "config/matching.yaml"));
  const ClusteringConfig ccfg = loadClusteringConfig(o.root + "/config/clustering.yaml");
  const ScannerSettings settings = loadScannerSettings(o.root + "/config/scanner.yaml");
  const Trajectory sweep = loadTrajectory(o.root + "/config/trajectories.yaml", o.trajectory);
  const bool two_passes = !o.second_pass.empty();
  const Trajectory sweep2 = two_passes ? loadTrajectory(o.root + "/config/trajectories.yaml", o.second_pass) : Trajectory();
  ModelMatcher matcher(lib, cfg);
  matcher.prepare({});
  DetectionCounts total;
  std::vector<double> terr, rerr, rms;
  const bool own_calibration = !o.calibration.empty();
  json out = {{"calibration", own_calibration ? o.calibration : "the simulator's true calibration"},
              {"trajectory", o.trajectory},
              {"second_pass", two_passes ? json(o.second_pass) : json(nullptr)},
              {"success", {{"max_t_mm", o.max_t_mm}, {"max_r_deg", o.max_r_deg}}},
              {"seeds", json::array()}};
  int unmeasured = 0, fits_both = 0;  // misses with no scan point on the part; whose points a false pose fits
  size_t second_added = 0;            // detections the second pass added
  for (const uint64_t seed : seeds) {
    const GeneratedScene g = generateScene(base, models, seed, {}, out_dir);
    const ScannerRenderer renderer(std::make_shared<CellGeometry>(g.scene));
    // the cell as built (the base scene's as_built section): its robot errs, the scan uses the
    // given calibration or the truth
    const RobotErrorModel robot(g.scene.as_built.robot);
    const ScannerCalibration cal =
        own_calibration ? ScannerCalibration::fromFolder(o.calibration) : scannerCalibrationOf(g.scene);
    const CellScan scan = scanCell(g.scene, renderer, sweep, cal, settings, robot, seed);
    // the second pass: another scan of the same cell (its own image noise), located on its own
    CellScan second;
    if (two_passes) second = scanCell(g.scene, renderer, sweep2, cal, settings, robot, seed + kSecondPassNoise);
    DetectionCounts counts;
    std::vector<double> t1, r1;
    json sj = locateAndScore(g.scene, scan, *lib, matcher, ccfg, o, &counts, &t1, &r1, two_passes ? &second : nullptr);
    sj["seed"] = seed;
    sj["scene"] = g.file;
    sj["surface_error_rms_mm"] = scan.surface_rms * 1e3;
    rms.push_back(scan.surface_rms * 1e3);
    if (two_passes) second_added += sj["second_pass"]["added"].get<size_t>();
    out["seeds"].push_back(sj);
    total.tp += counts.tp;
    total.fp += counts.fp;
    total.fn += counts.fn;
    total.ambiguous_tp += counts.ambiguous_tp;
    total.ambiguous_fp += counts.ambiguous_fp;
    total.ambiguous_fp_alternative_right += counts.ambiguous_fp_alternative_right;
    for (const auto& p : sj["parts"]) {
      if (p["found"].get<bool>() || p.value("distractor", false)) continue;
      if (p.value("scan_points", 0) == 0) ++unmeasured;
      for (const auto& f : sj["false_detections"])
        if (f.value("nearest_object", std::string()) == p["name"].get<std::string>() && f.value("part_points_on_it", 0.0) >= kFitsBoth) {
          ++fits_both;
          break;
        }
    }
    terr.insert(terr.end(), t1.begin(), t1.end());
    rerr.insert(rerr.end(), r1.begin(), r1.end());
    std::printf("seed %llu: %d found, %d missed, %d false (%zu objects, %zu distractors), median %.3f mm %.3f deg\n",
                static_cast<unsigned long long>(seed), counts.tp, counts.fn, counts.fp, g.scene.objects.size(),
                g.distractors.size(), median(t1), median(r1));
    std::fflush(stdout);
  }
  out["tp"] = total.tp;
  out["fp"] = total.fp;
  out["fn"] = total.fn;
  // the misses the scan's points cannot decide: parts it holds no point of, and parts whose points
  // a false detection of their model fits as well (describeScanPoints)
  out["fn_no_scan_point"] = unmeasured;
  out["fn_points_fit_a_false_pose"] = fits_both;
  if (two_passes) out["second_pass_added"] = second_added;
  // detections the matcher reported ambiguous (a turn fits about as well): right ones, false
  // ones, and false ones whose alternative pose is the part's
  out["ambiguous_found"] = total.ambiguous_tp;
  out["ambiguous_false"] = total.ambiguous_fp;
  out["ambiguous_false_alternative_right"] = total.ambiguous_fp_alternative_right;
  // the same counts with a reported ambiguity whose other pose is the part's taken as that part
  // found (the cell knows it must check the part's orientation): beside the strict figures, not
  // instead of them
  DetectionCounts lenient = total;
  lenient.tp += total.ambiguous_fp_alternative_right;
  lenient.fp -= total.ambiguous_fp_alternative_right;
  lenient.fn -= total.ambiguous_fp_alternative_right;
  out["ambiguity_counted_found"] = {{"tp", lenient.tp},
                                    {"fp", lenient.fp},
                                    {"fn", lenient.fn},
                                    {"precision", lenient.precision()},
                                    {"recall", lenient.recall()},
                                    {"f1", lenient.f1()}};
  out["precision"] = total.precision();
  out["recall"] = total.recall();
  out["f1"] = total.f1();
  out["median_t_err_mm"] = median(terr);
  out["median_r_err_deg"] = median(rerr);
  out["surface_error_rms_mm_median"] = median(rms);
  out["surface_error_rms_mm_max"] = rms.empty() ? 0.0 : *std::max_element(rms.begin(), rms.end());
  // the limits a test sets (issue: thresholds derived from the measured distribution)
  json failed = json::array();
  if (o.limit_rms_mm > 0 && out["surface_error_rms_mm_max"].get<double>() > o.limit_rms_mm)
    failed.push_back("surface RMS " + std::to_string(out["surface_error_rms_mm_max"].get<double>()) + " mm > " +
                     std::to_string(o.limit_rms_mm));
  if (o.limit_t_mm > 0 && median(terr) > o.limit_t_mm)
    failed.push_back("median translation error " + std::to_string(median(terr)) + " mm > " + std::to_string(o.limit_t_mm));
  if (o.limit_r_deg > 0 && median(rerr) > o.limit_r_deg)
    failed.push_back("median rotation error " + std::to_string(median(rerr)) + " deg > " + std::to_string(o.limit_r_deg));
  if (o.limit_recall > 0 && total.recall() < o.limit_recall)
    failed.push_back("recall " + std::to_string(total.recall()) + " < " + std::to_string(o.limit_recall));
  out["limits_failed"] = failed;
  writeJson(o.json, out);
  std::printf("cells: %d found, %d missed (%d with no scan point on the part, %d whose scan points a false pose of its model "
              "fits as well), %d false\n",
              total.tp, total.fn, unmeasured, fits_both, total.fp);
  std::printf("cells: reported ambiguous (a turn fits about as well): %d of the found, %d of the false (%d whose other pose "
              "is the part's)\n",
              total.ambiguous_tp, total.ambiguous_fp, total.ambiguous_fp_alternative_right);
  std::printf("cells: with those whose other pose is the part's counted as found: P %.3f R %.3f F1 %.3f\n", lenient.precision(),
              lenient.recall(), lenient.f1());
  std::printf("cells: %zu seeds, P %.3f R %.3f F1 %.3f, median %.3f mm %.3f deg, surface RMS median %.4f mm max %.4f mm\n",
              seeds.size(), total.precision(), total.recall(), total.f1(), median(terr), median(rerr), median(rms),
              out["surface_error_rms_mm_max"].get<double>());
  if (two_passes)
    std::printf("cells: the second pass (%s) added %zu detections where the first (%s) had none\n", o.second_pass.c_str(),
                second_added, o.trajectory.c_str());
  for (const auto& f : failed) std::printf("cells: LIMIT EXCEEDED: %s\n", f.get<std::string>().c_str());
  return failed.empty() ? 0 : 4;
}


/// --root, --scene, --models (demo and the sweeps).
void addSceneOptions(CLI::App* c, Options& o) {
  c->add_option("--root", o.root, "repository root: the defaults of --scene, --models, --matching lie under it")
      ->check(CLI::ExistingDirectory)
      ->capture_default_str();
  c->add_option("--scene", o.scene, "scene YAML [default: <root>/config/scenes/demo.yaml]")->check(CLI::ExistingFile);
  c->add_option("--models", o.models, "model library folder [default: <root>/config/models]")->check(CLI::ExistingDirectory);
}

void addSuccessOptions(CLI::App* c, Options& o) {
  using cellsight_tools::positive;
  c->add_option("--max-t-mm", o.max_t_mm, "success: translation error at most this [mm]")->check(positive())->capture_default_str();
  c->add_option("--max-r-deg", o.max_r_deg, "success: rotation error at most this [deg]")->check(positive())->capture_default_str();
}

/// The options shared by occlusion and outliers.
void addSweepOptions(CLI::App* c, Options& o) {
  addSceneOptions(c, o);
  c->add_option("--matching", o.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  c->add_option("--search", o.search, "all: every model searched (identify and locate); self: the part's own model (locate)")
      ->check(CLI::IsMember({"all", "self"}))
      ->capture_default_str();
  c->add_option("--parts", o.parts, "model ids, comma-separated")->delimiter(',')->capture_default_str();
  c->add_option("--trials", o.trials, "random views per part and level")->check(cellsight_tools::positiveInt())->capture_default_str();
  addSuccessOptions(c, o);
  c->add_option("--json", o.json, "write the figures to this JSON file");
  c->add_option("--png", o.png, "draw the success-rate curves (gnuplot) to this PNG; <png>.dat and <png>.gp stay beside it");
}

}  // namespace

int main(int argc, char** argv) {
  using cellsight_tools::fraction;
  using cellsight_tools::positive;
  CLI::App app("Localisation figures against ground truth: the demo scan's detections, the occlusion and outlier "
               "sweeps on single-view clouds, random cells.",
               "cellsight_evaluate_localization");
  app.require_subcommand(1);

  Options demo;
  demo.max_t_mm = demo.max_r_deg = 5;  // "found": the right model within 5 mm / 5° (a gross-error test)
  CLI::App* c_demo =
      app.add_subcommand("demo", "detections of the demo scan vs the simulator's truth (exit 3 unless every part is found)");
  c_demo->add_option("--detections", demo.detections, "detections_raw.json of the demo")->required()->check(CLI::ExistingFile);
  addSceneOptions(c_demo, demo);
  addSuccessOptions(c_demo, demo);
  c_demo->add_option("--json", demo.json, "write the figures to this JSON file");

  Options cld;
  cld.max_t_mm = cld.max_r_deg = 5;  // as demo
  CLI::App* c_cld = app.add_subcommand(
      "cloud", "a finished scan file clustered and located in-process with the repository's settings, scored against "
               "the scene's truth (exit 3 unless every part is found)");
  c_cld->add_option("--cloud", cld.cloud, "the scan (PLY, PCD), cropped and filtered as the nodes finish it")
      ->required()
      ->check(CLI::ExistingFile);
  addSceneOptions(c_cld, cld);
  c_cld->add_option("--matching", cld.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  c_cld->add_option("--calibration", cld.calibration,
                    "calibration folder whose scanner camera is the viewpoint [default: the scene file's camera]")
      ->check(CLI::ExistingDirectory);
  addSuccessOptions(c_cld, cld);
  c_cld->add_option("--json", cld.json, "write the figures to this JSON file");

  Options occ;
  occ.trials = 100;
  occ.parts = {"blade", "housing", "holder"};
  CLI::App* c_occ = app.add_subcommand("occlusion", "the thesis's random-walk occlusion test on single-view clouds of the parts");
  addSweepOptions(c_occ, occ);
  c_occ->add_option("--from", occ.from, "first occlusion share")->check(fraction())->capture_default_str();
  c_occ->add_option("--to", occ.to, "last occlusion share")->check(fraction())->capture_default_str();
  c_occ->add_option("--step", occ.step, "occlusion share step")->check(positive())->capture_default_str();
  c_occ->add_option("--ks", occ.ks, "random-walk k_s")->check(cellsight_tools::positiveInt())->capture_default_str();
  CLI::Option* min_fitness =
      c_occ->add_option("--min-fitness", occ.min_fitness, "validation fitness threshold [default: the matching settings']")
          ->check(fraction());

  Options outl;
  outl.trials = 50;
  outl.parts = {"blade", "housing", "holder", "bracket"};
  outl.ratios = {0, 0.25, 0.5, 1, 1.5, 2};
  CLI::App* c_out =
      app.add_subcommand("outliers", "uniform outliers with random normals in the workspace box, a ratio of the part's points");
  addSweepOptions(c_out, outl);
  c_out->add_option("--ratios", outl.ratios, "outlier ratios, comma-separated (1 = as many outliers as part points)")
      ->delimiter(',')
      ->check(cellsight_tools::nonNegative())
      ->capture_default_str();


  Options cells;
  cells.max_t_mm = cells.max_r_deg = 5;  // found: the right model within 5 mm / 5° (as the demo)
  std::vector<uint64_t> cell_seeds;
  std::string seeds_file, cells_out = "/tmp/cellsight_cells";
  CLI::App* c_cells = app.add_subcommand("cells", "random cells (scene generator) scanned in-process, clustered and located: "
                                                  "detection P/R/F1 and errors over seeds");
  addSceneOptions(c_cells, cells);
  addSuccessOptions(c_cells, cells);
  c_cells->add_option("--matching", cells.matching, "matching settings YAML [default: <root>/config/matching.yaml]")
      ->check(CLI::ExistingFile);
  c_cells->add_option("--seeds", cell_seeds, "scene seeds");
  c_cells->add_option("--trajectory", cells.trajectory, "the scan's trajectory (config/trajectories.yaml)")
      ->capture_default_str();
  c_cells->add_option("--second-pass", cells.second_pass,
                      "scan each cell again along this trajectory (e.g. reverse_sweep: the sheet leaning the other way), "
                      "locate on it alike and add the parts found where the first pass found none");
  c_cells->add_option("--dump-clusters", cells.dump_clusters, "write every scene's clusters (and its support points) as PLY into this folder");
  c_cells->add_option("--seeds-file", seeds_file, "a seeds file, e.g. config/heldout_seeds.yaml")->check(CLI::ExistingFile);
  c_cells->add_option("--out", cells_out, "where the generated scenes go")->capture_default_str();
  c_cells->add_option("--json", cells.json, "write the figures to this JSON file");
  c_cells->add_option("--calibration", cells.calibration,
                      "scan with this calibration folder (a self-calibration) instead of the simulator's truth")
      ->check(CLI::ExistingDirectory);
  c_cells->add_option("--limit-rms-mm", cells.limit_rms_mm, "exit 4 if any scene's surface RMS exceeds this [mm]")
      ->check(positive());
  c_cells->add_option("--limit-t-mm", cells.limit_t_mm, "exit 4 if the median translation error exceeds this [mm]")
      ->check(positive());
  c_cells->add_option("--limit-r-deg", cells.limit_r_deg, "exit 4 if the median rotation error exceeds this [deg]")
      ->check(positive());
  c_cells->add_option("--limit-recall", cells.limit_recall, "exit 4 if the recall is below this")->check(fraction());

  cellsight_tools::DescriptorEvalOptions desc;
  CLI::App* c_desc = app.add_subcommand("descriptors", "FPFH against the learned descriptor in the same RANSAC pipeline: "
                                                       "held-out laser views of our parts, real UWA / PCL scenes");
  c_desc->add_option("--root", desc.root, "the package folder (config/)")->capture_default_str();
  c_desc->add_option("--data", desc.data, "real point-cloud data [default: <root>/../shared/data/pointclouds]");
  c_desc->add_option("--parts", desc.parts, "parts, comma-separated")->delimiter(',')->capture_default_str();
  c_desc->add_option("--views", desc.views, "held-out views per part")->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--learned", desc.learned, "model trained with local reference frames")->capture_default_str();
  c_desc->add_option("--augment", desc.augment, "model trained by rotation augmentation")->capture_default_str();
  c_desc->add_option("--rotations", desc.rotations, "turns of the multi-rotation method")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--max-iterations", desc.max_iterations, "RANSAC hypotheses at most (every method)")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  c_desc->add_option("--sampling", desc.sampling,
                     "RANSAC sampling for every method and case: guided (one match, then two that agree with it, "
                     "from each scene point's nearest model descriptors) or uniform (three mutual matches, the thesis's)")
      ->check(CLI::IsMember({"guided", "uniform"}))
      ->capture_default_str();
  bool no_real = false;
  c_desc->add_flag("--no-real", no_real, "leave out the real scenes");
  c_desc->add_option("--json", desc.json, "write the figures to this JSON file");
  c_desc->add_option("--png", desc.png, "write the success plot to this PNG");
  c_desc->add_option("--limit-beats-fpfh", desc.limit_recall_margin,
                     "exit 4 unless the learned (LRF) descriptor's recall exceeds FPFH's by this and its registration "
                     "success is higher")
      ->check(cellsight_tools::nonNegative());

  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  desc.real = !no_real;
  if (!seeds_file.empty()) {
    YamlMap m(loadYamlFile(seeds_file), seeds_file);
    for (const auto& s : m.raw("seeds")) cell_seeds.push_back(s.as<uint64_t>());
    m.getString("base");
    m.finish();
  }
  occ.min_fitness_given = min_fitness->count() > 0;
  return cellsight_tools::runTool([&] {
    if (c_demo->parsed()) return runDemo(demo);
    if (c_cld->parsed()) return runCloud(cld);
    if (c_occ->parsed()) return runOcclusion(occ);
    if (c_out->parsed()) return runOutliers(outl);
    if (c_desc->parsed()) return cellsight_tools::runDescriptorEvaluation(desc);
    if (c_cells->parsed()) {
      if (cell_seeds.empty()) throw std::invalid_argument("cells: give --seeds or --seeds-file");
      return runCells(cells, cell_seeds, cells_out);
    }
    return 2;  // not reached: a subcommand is required
  });
}
